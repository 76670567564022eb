#!/usr/bin/env python3
"""One sllurp 3.0.5 session through its library API, ending with sllurp's own clean close.

Connects to HOST:PORT with LLRPReaderClient, lets sllurp run its usual setup and start an
inventory on every antenna (a report for every tag; antenna, channel, peak RSSI, seen count
and timestamps in each report), waits until it has seen N tag reports (TagReportData entries,
counted while sllurp is in STATE_INVENTORYING, as sllurp drops the others) or the timeout
passes, then calls sllurp's disconnect() and waits for it with join(timeout).
Prints ONE JSON line and exits 0 when the close was clean, 1 otherwise:

  {"reports": n, "clean": true|false, "state": "STATE_...", "error": "...", "seconds": t, ...}

What sllurp 3.0.5 does on disconnect() (sllurp/llrp.py, LLRPReaderClient.disconnect and
LLRPClient.stopPolitely): it sends DELETE_ACCESSSPEC (all), on its response DELETE_ROSPEC
(all), and on that response sets STATE_DISCONNECTED, closes its socket (shutdown(SHUT_RDWR),
close()) and calls the disconnected callbacks; the reader thread then leaves its loop. It
never sends CLOSE_CONNECTION. "clean" here means exactly that path ran: both responses came
back with Success after disconnect() was called, the final state is STATE_DISCONNECTED, the
disconnected callback ran once and not before those responses (i.e. not through
on_lost_connection: the peer did not close first), sllurp's socket is closed (None), its
reader thread ended within the timeout, no exception was raised in this thread, and sllurp
logged no warning or error after disconnect() but the benign ones in BENIGN (a
"Disconnected from server" warning means the peer closed the connection first).

The check "sllurp race" names a race inside sllurp 3.0.5 itself: disconnect() runs
stopPolitely in the caller's thread, which sends DELETE_ACCESSSPEC and only then registers the
callback that goes on to DELETE_ROSPEC; when sllurp's reader thread handles the response first
(it is busy with tag reports and holds the GIL), nothing sends DELETE_ROSPEC and the close
never completes (state stays STATE_SENT_DELETE_ACCESSSPEC, the socket open, the thread alive).

--widen-race MS sleeps in the main thread between that send and the registration (to show the
race); --disconnect-in-callback calls disconnect() from sllurp's reader thread instead (inside
the tag report callback), which closes the window.

With --repeat K, K sessions run one after the other in this process (--gap seconds between a
close and the next connect, default 0), one JSON line each (with "run"); the exit status is 0
only if all were clean.

Usage: sllurp3_session.py HOST PORT [--reports N] [--timeout S] [--close-timeout S]
                          [--antennas 0] [--repeat K] [--gap S] [--log FILE] [--debug]
                          [--disconnect-in-callback] [--widen-race MS]
"""
import argparse
import json
import logging
import sys
import threading
import time

from sllurp.llrp import LLRPReaderClient, LLRPReaderConfig, LLRPReaderState
from sllurp.log import set_general_debug

# What sllurp logs in a session that still closes cleanly: a read that split a frame header;
# a tag report in flight when disconnect() switched the state under the reader thread (its
# handleMessage reads the state twice, unlocked: an RO_ACCESS_REPORT passes the "inventorying"
# check, then meets STATE_SENT_DELETE_ACCESSSPEC). Listed in "warnings", not counted as unclean.
BENIGN = ("Too few bytes", "unexpected response RO_ACCESS_REPORT when deleting AccessSpec")


class Records(logging.Handler):
    """Keeps sllurp's log records (warnings and up, with the time they were logged)."""

    def __init__(self):
        super().__init__(level=logging.WARNING)
        self.records = []

    def emit(self, record):
        self.records.append((time.monotonic(), record.levelname, record.getMessage()))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("host")
    ap.add_argument("port", type=int)
    ap.add_argument("--reports", type=int, default=5, help="tag reports to wait for (5)")
    ap.add_argument("--timeout", type=float, default=20.0, help="longest wait for them, s (20)")
    ap.add_argument("--close-timeout", type=float, default=10.0, help="join timeout, s (10)")
    ap.add_argument("--antennas", default="0", help="comma-separated; 0 = all (default)")
    ap.add_argument("--repeat", type=int, default=1, help="sessions, one after the other (1)")
    ap.add_argument("--gap", type=float, default=0.0, help="pause between sessions, s (0)")
    ap.add_argument("--log", help="write sllurp's log (with thread names) to this file")
    ap.add_argument("--debug", action="store_true", help="sllurp debug logging (into --log)")
    ap.add_argument(
        "--disconnect-in-callback",
        action="store_true",
        help="call disconnect() from the tag report callback (sllurp's reader thread), which "
        "avoids sllurp's stopPolitely race, instead of from the main thread",
    )
    ap.add_argument(
        "--widen-race",
        type=float,
        default=0.0,
        metavar="MS",
        help="sleep MS after sllurp sends DELETE_ACCESSSPEC from the main thread, before it "
        "registers its callback: makes sllurp's race (nearly) certain, to show it",
    )
    args = ap.parse_args()

    root = logging.getLogger()
    root.setLevel(logging.DEBUG if args.debug else logging.INFO)
    if args.log:
        fh = logging.FileHandler(args.log, mode="w")
        fh.setFormatter(
            logging.Formatter("%(relativeCreated)9.1f %(threadName)s %(levelname)s %(message)s")
        )
        root.addHandler(fh)
    set_general_debug(args.debug)

    status = 0
    for run in range(args.repeat):
        if run and args.gap > 0:
            time.sleep(args.gap)
        out = session(args)
        if args.repeat > 1:
            out["run"] = run + 1
        print(json.dumps(out), flush=True)
        if not out["clean"]:
            status = 1
    return status


def session(args):
    """One connection, inventory, and sllurp's clean close; what happened, as a dict."""
    t0 = time.monotonic()
    records = Records()
    root = logging.getLogger()
    root.addHandler(records)
    logging.getLogger(__name__).info("session starts")

    antennas = [int(a) for a in args.antennas.split(",")]
    config = LLRPReaderConfig(
        {
            "antennas": antennas,
            "tx_power": 0,
            "report_every_n_tags": 1,
            "start_inventory": True,
            "reset_on_connect": True,
            "reconnect": False,
            "tag_content_selector": {
                "EnableROSpecID": False,
                "EnableSpecIndex": False,
                "EnableInventoryParameterSpecID": False,
                "EnableAntennaID": True,
                "EnableChannelIndex": True,
                "EnablePeakRSSI": True,
                "EnableFirstSeenTimestamp": True,
                "EnableLastSeenTimestamp": True,
                "EnableTagSeenCount": True,
                "EnableAccessSpecID": False,
            },
        }
    )
    reader = LLRPReaderClient(args.host, args.port, config)

    lock = threading.Lock()
    st = {
        "reports": 0,
        "ignored": 0,
        "disconnect_at": None,
        "delete_accessspec": None,  # success of the response after disconnect()
        "delete_rospec": None,
        "responses_at": None,
        "disconnected_calls": 0,
        "disconnected_at": None,
        # sllurp's own callback for DELETE_ACCESSSPEC_RESPONSE (which sends DELETE_ROSPEC) was
        # not yet registered when the response was handled (checked below).
        "unregistered": None,
    }
    enough = threading.Event()
    gone = threading.Event()

    def on_tags(_reader, tags):
        with lock:
            if reader.llrp.state != LLRPReaderState.STATE_INVENTORYING:
                # sllurp ignores these (its handleMessage): reports of an ROSpec an earlier
                # client left running, before this session's reset, or after disconnect().
                st["ignored"] += len(tags)
                return
            st["reports"] += len(tags)
            if st["reports"] < args.reports or enough.is_set():
                return
            enough.set()
            if args.disconnect_in_callback:
                st["disconnect_at"] = time.monotonic()
        if args.disconnect_in_callback:
            # In sllurp's reader thread: DELETE_ACCESSSPEC is sent and its callback registered
            # before this thread can read the response.
            reader.disconnect()

    def on_msg(_reader, lmsg):
        name = lmsg.getName()
        with lock:
            if st["disconnect_at"] is None:
                return
            key = "delete_accessspec" if name == "DELETE_ACCESSSPEC_RESPONSE" else "delete_rospec"
            if key == "delete_accessspec":
                # Message callbacks run just before sllurp's state machine handles the message
                # (raw_data_received); .get does not add to the defaultdict.
                st["unregistered"] = not reader.llrp._deferreds.get(name)  # noqa: SLF001
            st[key] = bool(lmsg.isSuccess())
            if key == "delete_rospec":
                st["responses_at"] = time.monotonic()

    def on_disconnected(_reader):
        with lock:
            st["disconnected_calls"] += 1
            if st["disconnected_at"] is None:
                st["disconnected_at"] = time.monotonic()
        gone.set()

    reader.add_tag_report_callback(on_tags)
    reader.add_message_callback("DELETE_ACCESSSPEC_RESPONSE", on_msg)
    reader.add_message_callback("DELETE_ROSPEC_RESPONSE", on_msg)
    reader.add_disconnected_callback(on_disconnected)
    if args.widen_race > 0:
        send = reader.llrp.sendMessage

        def slow_after_delete_accessspec(msg_dict):
            ids = send(msg_dict)
            if "DELETE_ACCESSSPEC" in msg_dict and threading.current_thread() is threading.main_thread():
                time.sleep(args.widen_race / 1000.0)  # releases the GIL, as a preemption would
            return ids

        reader.llrp.sendMessage = slow_after_delete_accessspec

    errors = []
    try:
        reader.connect()
        deadline = t0 + args.timeout
        while not enough.is_set() and not gone.is_set() and time.monotonic() < deadline:
            enough.wait(0.05)
        if not enough.is_set():
            errors.append(
                "the connection was lost before %d tag reports" % args.reports
                if gone.is_set()
                else "no %d tag reports within %.0f s" % (args.reports, args.timeout)
            )
        if not (args.disconnect_in_callback and enough.is_set()):
            with lock:
                st["disconnect_at"] = time.monotonic()
            reader.disconnect()
        reader.join(args.close_timeout)
    except Exception as e:  # noqa: BLE001 - reported, not hidden
        errors.append("exception: %s: %s" % (type(e).__name__, e))

    state = LLRPReaderState.getStateName(reader.llrp.state)
    if state is None or not str(state).startswith("STATE_"):
        state = str(reader.llrp.state)
    alive = reader.is_alive()
    with lock:
        s = dict(st)
    if s["unregistered"]:
        # LLRPReaderClient.disconnect() (caller's thread) runs LLRPClient.stopPolitely, which
        # sends DELETE_ACCESSSPEC, then sets the state, then registers the callback that sends
        # DELETE_ROSPEC. sllurp's reader thread handled the response in between and found no
        # callback, so DELETE_ROSPEC is never sent and the close never completes.
        errors.append(
            "sllurp race: DELETE_ACCESSSPEC_RESPONSE handled before disconnect() registered "
            "its callback, so DELETE_ROSPEC was never sent"
        )
    if s["disconnect_at"] is not None:
        if s["delete_accessspec"] is not True:
            errors.append("DELETE_ACCESSSPEC_RESPONSE after disconnect(): %s" % s["delete_accessspec"])
        if s["delete_rospec"] is not True:
            errors.append("DELETE_ROSPEC_RESPONSE after disconnect(): %s" % s["delete_rospec"])
    if state != "STATE_DISCONNECTED":
        errors.append("final state %s" % state)
    if s["disconnected_calls"] != 1:
        errors.append("disconnected callback called %d times" % s["disconnected_calls"])
    elif s["responses_at"] is None or s["disconnected_at"] < s["responses_at"]:
        errors.append("disconnected callback before DELETE_ROSPEC_RESPONSE (connection lost)")
    if reader._socket is not None:  # noqa: SLF001 - sllurp keeps no public socket state
        try:
            fd = reader._socket.fileno()  # noqa: SLF001
        except Exception:  # noqa: BLE001
            fd = "?"
        errors.append("sllurp's socket still open (fd %s)" % fd)
    if alive:
        errors.append("sllurp's reader thread still running after join(%.0f s)" % args.close_timeout)
    after = [
        "%s: %s" % (lvl, msg.strip())
        for t, lvl, msg in records.records
        if s["disconnect_at"] is not None and t >= s["disconnect_at"]
        and not msg.startswith(BENIGN)
    ]
    errors.extend("sllurp logged %s" % a for a in after)
    if alive:
        # Leave nothing behind: sllurp's own forced close (its thread then leaves select).
        reader.hard_disconnect()
        reader.join(2)
    root.removeHandler(records)

    out = {
        "reports": s["reports"],
        "clean": not errors,
        "state": state,
        "error": "; ".join(errors),
        "seconds": round(time.monotonic() - t0, 3),
        "close_ms": None
        if s["disconnect_at"] is None or s["disconnected_at"] is None
        else round((s["disconnected_at"] - s["disconnect_at"]) * 1000, 1),
        "ignored": s["ignored"],
        "race": bool(s["unregistered"]),
        "warnings": ["%s: %s" % (lvl, msg.strip()) for _, lvl, msg in records.records],
    }
    return out


if __name__ == "__main__":
    sys.exit(main())
