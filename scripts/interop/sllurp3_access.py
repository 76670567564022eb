#!/usr/bin/env python3
"""One tag-memory access through sllurp 3.0.5's library, as `sllurp access` would do it.

Neither sllurp release on PyPI has a working `sllurp access` command: 2.0.1's fails in its
own encoder (encode_AccessSpecStopTrigger takes one argument where its caller passes two, so
no AccessSpec is ever sent), and 3.0.x ships without its command-line verbs (sllurp.verb is
missing from the wheel). This script does what that command does, with sllurp 3.0.5's
LLRPReaderClient unmodified: connect, start an inventory, add and enable one AccessSpec
(start_access_spec) with a C1G2Write (--write HEX) or a C1G2Read (--read N words) of bank
--mb from --word-ptr, stopping after one execution, wait for the first tag report carrying
its result, then disconnect. Prints ONE JSON line:

  {"result": {...the OpSpecResult as sllurp decoded it, bytes as hex...}, "epc": "...",
   "error": null | "..."}

and exits 0 when a result arrived, 1 otherwise.

Usage: sllurp3_access.py HOST PORT (--write HEX | --read N) [--mb 3] [--word-ptr 0]
                         [--password 0] [--timeout 20]
"""
import argparse
import json
import os
import sys
import threading
import time

from sllurp.llrp import C1G2Read, C1G2Write, LLRPReaderClient, LLRPReaderConfig, LLRPReaderState


def plain(v):
    """sllurp's decoded values as JSON: bytes as hex."""
    if isinstance(v, (bytes, bytearray)):
        return v.hex()
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("host")
    ap.add_argument("port", type=int)
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--write", help="words to write, as hex (4 digits a word)")
    what.add_argument("--read", type=int, help="words to read")
    ap.add_argument("--mb", type=int, default=3, help="memory bank (3 user)")
    ap.add_argument("--word-ptr", type=int, default=0)
    ap.add_argument("--password", type=lambda s: int(s, 0), default=0)
    ap.add_argument("--timeout", type=float, default=20.0)
    args = ap.parse_args()

    if args.write is not None:
        data = bytes.fromhex(args.write)
        op = C1G2Write(
            OpSpecID=1,
            AccessPassword=args.password,
            MB=args.mb,
            WordPtr=args.word_ptr,
            WriteDataWordCount=len(data) // 2,
            WriteData=data,
        )
        key = "C1G2WriteOpSpecResult"
    else:
        op = C1G2Read(
            OpSpecID=1,
            AccessPassword=args.password,
            MB=args.mb,
            WordPtr=args.word_ptr,
            WordCount=args.read,
        )
        key = "C1G2ReadOpSpecResult"

    config = LLRPReaderConfig(
        {
            "antennas": [0],
            "tx_power": 0,
            "report_every_n_tags": 1,
            "start_inventory": True,
            "reset_on_connect": True,
            "reconnect": False,
            "tag_content_selector": {"EnableAntennaID": True, "EnableAccessSpecID": True},
        }
    )
    reader = LLRPReaderClient(args.host, args.port, config)
    got = {}
    done = threading.Event()
    started = threading.Event()

    def on_state(r, state):
        if not started.is_set():
            started.set()
            r.start_access_spec(op, stop_after_count=1)

    def on_tags(_reader, tags):
        for tag in tags:
            if key in tag and not done.is_set():
                got["result"] = plain(tag[key])
                got["epc"] = plain(tag.get("EPC-96") or tag.get("EPC"))
                done.set()

    reader.add_state_callback(LLRPReaderState.STATE_INVENTORYING, on_state)
    reader.add_tag_report_callback(on_tags)
    error = None
    try:
        reader.connect()
        done.wait(args.timeout)
    except Exception as e:  # noqa: BLE001 - reported in the JSON line
        error = repr(e)
    finally:
        try:
            reader.disconnect()
            reader.join(10)
        except Exception as e:  # noqa: BLE001
            error = error or repr(e)
    print(json.dumps({"result": got.get("result"), "epc": got.get("epc"), "error": error}), flush=True)
    return 0 if "result" in got else 1


if __name__ == "__main__":
    # sllurp 3.0.5's reader thread is not a daemon, and its disconnect() can lose a race with
    # it (see sllurp3_session.py) and leave it running: end the process without waiting.
    os._exit(main())
