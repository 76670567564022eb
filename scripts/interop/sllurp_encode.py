"""Capture the exact LLRP frames that sllurp 2.0.1 sends, for interop tests.

Runs sllurp's own `sllurp inventory` command (the click command, in-process)
against a tiny fake reader on 127.0.0.1 (ephemeral port), once per option
variant, and records every byte the client writes. The fake reader greets the
client with a ConnectionAttemptEvent(Success), answers each request with a
success response of the right type, sends a KEEPALIVE once the ROSpec is
enabled and hangs up after the KEEPALIVE_ACK. Messages that `sllurp inventory`
never sends (START/STOP/DISABLE_ROSPEC, CLOSE_CONNECTION) are produced through
sllurp's LLRPClient API with an in-memory transport (label prefix `api/`).

Output (stdout, or the file given as argv[1]): one frame per line,
`<variant>/<MESSAGE_NAME> <hex>`. Variants `plain` and `impinj` list their whole
sequence; every other variant lists only frames whose body differs from the
same message in `plain` (use --all to list everything). Message IDs are
sllurp's own (a per-connection counter starting at 1), so output is stable.

Usage: .venv/bin/python scripts/interop/sllurp_encode.py [OUT] [--all] [--debug]
"""
import logging
import socket
import struct
import sys
import threading
import time

import sllurp
from sllurp.cli import inventory as inventory_cmd
from sllurp.llrp import LLRPClient, LLRPReaderConfig, LLRPReaderState

# option variants of `sllurp inventory` (label prefix -> extra CLI args)
VARIANTS = [
    ("plain", []),
    ("impinj", ["--impinj-reports"]),
    ("a0", ["-a", "0"]),
    ("a0impinj", ["-a", "0", "--impinj-reports"]),
    ("a12", ["-a", "1,2"]),
    ("n1", ["-n", "1"]),
    ("t2", ["-t", "2.5"]),
    ("t2n5", ["-t", "2", "-n", "5"]),
    ("search2", ["--impinj-search-mode", "2"]),
    ("filter", ["--tag-filter-mask", "e2801160"]),
    ("extcfg", ["--impinj-extended-configuration"]),
    ("mode", ["--mode-identifier", "1002", "-T", "12500"]),
    ("power5", ["-X", "5", "-s", "1", "-P", "16"]),
    ("freqauto", ["-f", "0"]),
    ("freqlist", ["-f", "1,2,3"]),
    ("nokeepalive", ["--keepalive-interval", "0"]),
]

NAMES = {1: "GET_READER_CAPABILITIES", 2: "GET_READER_CONFIG",
         3: "SET_READER_CONFIG", 14: "CLOSE_CONNECTION", 20: "ADD_ROSPEC",
         21: "DELETE_ROSPEC", 22: "START_ROSPEC", 23: "STOP_ROSPEC",
         24: "ENABLE_ROSPEC", 25: "DISABLE_ROSPEC", 40: "ADD_ACCESSSPEC",
         41: "DELETE_ACCESSSPEC", 42: "ENABLE_ACCESSSPEC",
         43: "DISABLE_ACCESSSPEC", 62: "KEEPALIVE",
         64: "ENABLE_EVENTS_AND_REPORTS", 72: "KEEPALIVE_ACK"}
IMPINJ = 25882
REQUIRED = ["GET_READER_CAPABILITIES", "GET_READER_CONFIG",
            "ENABLE_EVENTS_AND_REPORTS", "SET_READER_CONFIG",
            "DELETE_ACCESSSPEC", "DELETE_ROSPEC", "ADD_ROSPEC",
            "ENABLE_ROSPEC", "KEEPALIVE_ACK"]


# ---- hand-built reader -> client bytes (LLRP 1.0.1, version 1) ----------
def msg(mtype, mid, body=b""):
    return struct.pack("!HII", (1 << 10) | mtype, 10 + len(body), mid) + body


def impinj_msg(subtype, mid, body=b""):
    return msg(1023, mid, struct.pack("!IB", IMPINJ, subtype) + body)


def tlv(ptype, body=b""):
    return struct.pack("!HH", ptype, 4 + len(body)) + body


STATUS_OK = tlv(287, struct.pack("!HH", 0, 0))  # LLRPStatus M_Success, ""


def capabilities():
    fw = b"5.14.0.240"
    gdc = tlv(137, struct.pack("!HHIIH", 4, 0x4000, IMPINJ, 2001002, len(fw))
              + fw + tlv(139, struct.pack("!Hh", 1, 0))     # RxSensitivity
              + tlv(141, struct.pack("!HH", 4, 4))           # GPIOCapabilities
              + b"".join(tlv(140, struct.pack("!HHB", a, 1, 1))  # PerAntAirProto
                         for a in range(1, 5)))
    llrpcaps = tlv(142, struct.pack("!BBHIIIII", 0x00, 1, 0, 1, 32, 1, 508, 8))
    power = b"".join(tlv(145, struct.pack("!Hh", i, 1000 + 100 * (i - 1)))
                     for i in range(1, 22))          # 10.00 .. 30.00 dBm
    hops = [902750 + 500 * i for i in range(50)]
    freq = tlv(146, b"\x80" + tlv(147, struct.pack("!BBH", 1, 0, len(hops))
                                  + struct.pack("!%dI" % len(hops), *hops)))
    modes = b"".join(tlv(329, struct.pack("!IBBBBIIIII", mid, 0x80, m, 2, 1,
                                          bdr, 1500, 6250, 25000, 6250))
                     for mid, m, bdr in [(1000, 0, 640000), (1002, 2, 274000),
                                         (2, 2, 274000), (3, 3, 256000)])
    reg = tlv(143, struct.pack("!HH", 840, 1)
              + tlv(144, power + freq + tlv(328, modes)))
    c1g2 = tlv(327, struct.pack("!BH", 0x40, 2))
    return STATUS_OK + gdc + llrpcaps + reg + c1g2


def greeting():
    now_us = int(time.time() * 1e6)
    return msg(63, 0, tlv(246, tlv(128, struct.pack("!Q", now_us))
                          + tlv(256, struct.pack("!H", 0))))


def split_frames(data):
    """Split a byte stream on the 10-byte LLRP header; yield (name, frame, type)."""
    pos = 0
    while pos < len(data):
        if len(data) - pos < 10:
            raise ValueError("trailing %d bytes" % (len(data) - pos))
        first, length, _ = struct.unpack_from("!HII", data, pos)
        mtype, ver = first & 0x3FF, (first >> 10) & 7
        if ver != 1 or length < 10 or pos + length > len(data):
            raise ValueError("bad header at %d: %s" % (pos, data[pos:pos + 10].hex()))
        frame = data[pos:pos + length]
        if mtype == 1023:
            vendor, sub = struct.unpack_from("!IB", frame, 10)
            name = ("IMPINJ_ENABLE_EXTENSIONS" if (vendor, sub) == (IMPINJ, 21)
                    else "CUSTOM_%d_%d" % (vendor, sub))
        else:
            name = NAMES.get(mtype, "TYPE%d" % mtype)
        yield name, frame, mtype
        pos += length


class FakeReader(threading.Thread):
    """Accepts one connection, answers like a cooperative reader, records all."""

    def __init__(self, timeout=3.0):
        super().__init__(daemon=True)
        self.srv = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.srv.bind(("127.0.0.1", 0))
        self.srv.listen(1)
        self.srv.settimeout(timeout)
        self.port = self.srv.getsockname()[1]
        self.deadline = time.monotonic() + timeout
        self.frames = []
        self.error = None

    def run(self):
        try:
            self.serve()
        finally:
            self.srv.close()

    def serve(self):
        try:
            conn, _ = self.srv.accept()
        except OSError as exc:
            self.error = "no connection: %s" % exc
            return
        buf = b""
        with conn:
            conn.sendall(greeting())
            while time.monotonic() < self.deadline:
                conn.settimeout(max(0.05, self.deadline - time.monotonic()))
                try:
                    chunk = conn.recv(65536)
                except socket.timeout:
                    self.error = "timed out waiting for the client"
                    break
                if not chunk:
                    break
                buf += chunk
                # consume complete frames only
                while len(buf) >= 10:
                    length = struct.unpack_from("!I", buf, 2)[0]
                    if len(buf) < length:
                        break
                    frame, buf = buf[:length], buf[length:]
                    if self.answer(conn, frame):
                        return

    def answer(self, conn, frame):
        """Reply to one frame; return True when the session is over."""
        name, _, mtype = next(split_frames(frame))
        self.frames.append((name, frame))
        mid = struct.unpack_from("!I", frame, 6)[0]
        if name == "IMPINJ_ENABLE_EXTENSIONS":
            conn.sendall(impinj_msg(22, mid, STATUS_OK))
        elif mtype == 1:
            conn.sendall(msg(11, mid, capabilities()))
        elif mtype in (2, 3, 20, 21, 22, 23, 24, 25, 41, 42, 43):
            conn.sendall(msg(mtype + 10, mid, STATUS_OK))
            if mtype == 24:   # ROSpec enabled: poke the client with a KEEPALIVE
                conn.sendall(msg(62, 0xCAFE))
        elif mtype == 14:
            conn.sendall(msg(4, mid, STATUS_OK))
            return True
        elif mtype == 72:     # KEEPALIVE_ACK: we have seen everything
            return True
        return False


def run_inventory(args):
    reader = FakeReader()
    reader.start()
    inventory_cmd.main(args=["127.0.0.1", "-p", str(reader.port)] + args,
                       prog_name="sllurp inventory", standalone_mode=False)
    reader.join(4)
    return reader


def api_frames():
    """Messages `sllurp inventory` never sends, via LLRPClient's own API."""
    sent = []
    client = LLRPClient(LLRPReaderConfig(), transport_tx_write=sent.append)
    rospec = client.getROSpec()
    client.send_START_ROSPEC(None, rospec, onCompletion=lambda *a: None)
    client.sendMessage({"STOP_ROSPEC": {"ROSpecID": rospec["ROSpecID"]}})
    client.state = LLRPReaderState.STATE_INVENTORYING  # so pause() sends
    client.pause()                                      # DISABLE_ROSPEC
    client.sendMessage({"CLOSE_CONNECTION": {}})
    client.send_KEEPALIVE_ACK()
    return [(n, f) for n, f, _ in split_frames(b"".join(sent))]


def main():
    argv = [a for a in sys.argv[1:] if not a.startswith("--")]
    list_all = "--all" in sys.argv
    logging.basicConfig(level=logging.DEBUG if "--debug" in sys.argv
                        else logging.CRITICAL, stream=sys.stderr)
    if sllurp.__version__ != "2.0.1":
        sys.exit("sllurp_encode: need sllurp 2.0.1, found %s" % sllurp.__version__)

    started = time.monotonic()
    captured = {}
    for variant, args in VARIANTS:   # stop at the first failure: stays fast
        reader = run_inventory(args)
        captured[variant] = reader.frames
        names = [n for n, _ in reader.frames]
        need = REQUIRED + (["IMPINJ_ENABLE_EXTENSIONS"] if "impinj" in variant else [])
        missing = [n for n in need if n not in names]
        if missing or reader.error:
            sys.exit("sllurp_encode: variant %s (sllurp inventory %s) did not "
                     "send the expected messages\n  missing: %s%s\n  got: %s" % (
                         variant, " ".join(args) or "(defaults)",
                         ", ".join(missing) or "-",
                         "\n  fake reader: " + reader.error if reader.error else "",
                         " ".join(names) or "nothing"))
    captured["api"] = api_frames()

    plain_body = {n: f[10:] for n, f in captured["plain"]}
    lines, seen = [], set()
    for variant, frames in captured.items():
        for name, frame in frames:
            if (not list_all and variant not in ("plain", "impinj", "api")
                    and plain_body.get(name) == frame[10:]):
                continue
            line = "%s/%s %s" % (variant, name, frame.hex())
            if line not in seen:
                seen.add(line)
                lines.append(line)

    text = "\n".join(lines) + "\n"
    if argv:
        with open(argv[0], "w") as out:
            out.write(text)
    else:
        sys.stdout.write(text)
    if "--debug" in sys.argv:
        print("captured %d frames in %.2fs" % (len(lines), time.monotonic() - started),
              file=sys.stderr)


if __name__ == "__main__":
    main()
