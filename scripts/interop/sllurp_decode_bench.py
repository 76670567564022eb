"""Baseline: how fast sllurp 2.0.1 decodes RO_ACCESS_REPORT frames.

Reads a file of concatenated LLRP RO_ACCESS_REPORT frames (type 61) and decodes
each frame with `sllurp.llrp.LLRPMessage(msgbytes=frame)`, which is exactly what
sllurp's client does for every message it receives (LLRPReaderClient.
raw_data_received). The file is decoded once to check the TagReportData count,
then again and again for at least MIN_SECONDS (default 2) of wall time.
Prints one JSON line; frames / tag_reports are the counts in the file and
seconds is the mean time of one pass over it:
  {"impl":"sllurp-2.0.1","frames":N,"tag_reports":M,"seconds":S,
   "tag_reports_per_sec":R,"passes":P}

Usage (with the venv's python):
  sllurp_decode_bench.py FRAMES.bin EXPECTED_TAG_REPORTS [MIN_SECONDS]
  sllurp_decode_bench.py --make OUT.bin TAGS_PER_FRAME FRAMES   # write test input
  sllurp_decode_bench.py --selftest    # build 1/10/100-tag frames, check, bench
"""
import json
import os
import struct
import sys
import tempfile
import time

import sllurp
from sllurp.llrp import LLRPMessage

IMPINJ = 25882


# ---- test input: hand-built frames (not sllurp's encoder) ------------------
def tag_report(i):
    """TagReportData: EPC-96, AntennaID, PeakRSSI, ChannelIndex, First/Last
    SeenTimestampUTC, TagSeenCount, ImpinjRFPhaseAngle, ImpinjPeakRSSI."""
    epc = struct.pack("!IQ", 0x30340242, 0x201D8C0000000000 + i)
    ts = 1_700_000_000_000_000 + 1000 * i
    body = (b"\x8d" + epc
            + struct.pack("!BH", 0x81, 1 + i % 4)              # AntennaID
            + struct.pack("!Bb", 0x86, -40 - i % 30)           # PeakRSSI
            + struct.pack("!BH", 0x87, 1 + i % 50)             # ChannelIndex
            + struct.pack("!BQ", 0x82, ts)                     # FirstSeenUTC
            + struct.pack("!BQ", 0x84, ts + 500)               # LastSeenUTC
            + struct.pack("!BH", 0x88, 1 + i % 7)              # TagSeenCount
            + struct.pack("!HHIIH", 1023, 14, IMPINJ, 56, (i * 37) % 4096)
            + struct.pack("!HHIIh", 1023, 14, IMPINJ, 57, -4000 - 25 * (i % 100)))
    return struct.pack("!HH", 240, 4 + len(body)) + body


def ro_access_report(msg_id, n_tags, first=0):
    body = b"".join(tag_report(first + k) for k in range(n_tags))
    return struct.pack("!HII", (1 << 10) | 61, 10 + len(body), msg_id) + body


def make_frames(tags_per_frame, frames):
    return b"".join(ro_access_report(f + 1, tags_per_frame, f * tags_per_frame)
                    for f in range(frames))


# ---- benchmark -------------------------------------------------------------
def split_frames(data):
    frames, pos = [], 0
    while pos < len(data):
        first, length, _ = struct.unpack_from("!HII", data, pos)
        if first & 0x3FF != 61 or length < 10 or pos + length > len(data):
            sys.exit("bench: not an RO_ACCESS_REPORT frame at offset %d" % pos)
        frames.append(data[pos:pos + length])
        pos += length
    return frames


def decode_all(frames):
    """One pass, the way sllurp's client decodes; returns TagReportData lists."""
    return [LLRPMessage(msgbytes=f).msgdict["RO_ACCESS_REPORT"]["TagReportData"]
            for f in frames]


def bench(data, expected, min_seconds=2.0):
    frames = split_frames(data)
    reports = [t for tags in decode_all(frames) for t in tags]
    if len(reports) != expected:
        sys.exit("bench: sllurp decoded %d TagReportData, expected %d"
                 % (len(reports), expected))
    if reports and not all("ImpinjRFPhaseAngle" in t and "ImpinjPeakRSSI" in t
                           for t in reports):
        print("bench: warning: sllurp did not decode the Impinj custom params",
              file=sys.stderr)
    passes, start = 0, time.perf_counter()
    while True:
        decode_all(frames)
        passes += 1
        elapsed = time.perf_counter() - start
        if elapsed >= min_seconds:
            break
    per_pass = elapsed / passes
    return {"impl": "sllurp-" + sllurp.__version__, "frames": len(frames),
            "tag_reports": len(reports), "seconds": round(per_pass, 9),
            "tag_reports_per_sec": round(len(reports) / per_pass, 1),
            "passes": passes}


def selftest():
    # 1. values decode correctly, including the Impinj custom parameters
    tags = decode_all([ro_access_report(7, 3, first=41)])[0]
    t = tags[2]  # i = 43
    want = {"EPC-96": b"30340242201d8c000000002b",  # sllurp hexlifies EPCs
            "AntennaID": 4, "PeakRSSI": -53, "ChannelIndex": 44,
            "FirstSeenTimestampUTC": 1_700_000_000_043_000,
            "LastSeenTimestampUTC": 1_700_000_000_043_500, "TagSeenCount": 2,
            "ImpinjRFPhaseAngle": (43 * 37) % 4096, "ImpinjPeakRSSI": -5075}
    got = {k: t.get(k) for k in want}
    if len(tags) != 3 or got != want:
        sys.exit("selftest: decoded %d reports; mismatch:\n got  %r\n want %r"
                 % (len(tags), got, want))
    print("selftest: sllurp decodes all fields incl. ImpinjRFPhaseAngle/"
          "ImpinjPeakRSSI: %r" % {k: t[k] for k in sorted(t)}, file=sys.stderr)
    # 2. short benchmark runs over 1/10/100 tag reports per frame
    for per_frame, n_frames in ((1, 200), (10, 50), (100, 10)):
        with tempfile.NamedTemporaryFile(suffix=".bin", delete=False) as f:
            f.write(make_frames(per_frame, n_frames))
        try:
            with open(f.name, "rb") as fh:
                print(json.dumps(bench(fh.read(), per_frame * n_frames, 0.2), separators=(",", ":")))
        finally:
            os.unlink(f.name)


def main(argv):
    if argv[:1] == ["--selftest"]:
        return selftest()
    if argv[:1] == ["--make"] and len(argv) == 4:
        with open(argv[1], "wb") as f:
            f.write(make_frames(int(argv[2]), int(argv[3])))
        return
    if len(argv) not in (2, 3):
        sys.exit(__doc__)
    with open(argv[0], "rb") as f:
        data = f.read()
    min_s = float(argv[2]) if len(argv) == 3 else 2.0
    print(json.dumps(bench(data, int(argv[1]), min_s), separators=(",", ":")))


if __name__ == "__main__":
    main(sys.argv[1:])
