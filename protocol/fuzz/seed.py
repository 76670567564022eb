#!/usr/bin/env python3
"""Seeds the fuzz corpora (run from anywhere): message_decode and frame_split from the golden
vectors, structured with inputs of its two modes (see fuzz_targets/structured.rs)."""
import hashlib, json, pathlib, struct

root = pathlib.Path(__file__).resolve().parent
for d in ("frame_split", "message_decode", "structured"):
    (root / "corpus" / d).mkdir(parents=True, exist_ok=True)

def put(target, data):
    name = hashlib.sha1(data).hexdigest()
    (root / "corpus" / target / name).write_bytes(data)

for f in sorted((root.parent / "vectors").glob("*.json")):
    v = json.loads(f.read_text())
    frame = bytes.fromhex("".join(v["hex"].split()))
    put("frame_split", frame)
    if len(frame) >= 10:
        put("message_decode", frame[:2] + frame[10:])

# structured, seeded mode (odd first byte): Gen seed (8 bytes) and the index of a typed
# message (taken modulo their number), without edits and with one edit of each kind: wrap
# parameter k in 70 ParameterErrors, duplicate it 3 times, move it, copy it, drop it. A
# count is a band byte then its value (see `Input::count`).
edits = lambda k: [bytes([0, 0, k, 0, 192, 0, 70]), bytes([1, 0, k, 0, 3]),
                   bytes([2, 0, k, 0, 8]), bytes([3, 0, k, 0, 5]), bytes([4, 0, k])]
for k in range(64):
    for seed in range(2):
        base = b"\x01" + struct.pack(">QB", seed * 1000 + k, k)
        put("structured", base)
        for edit in edits(k):
            put("structured", base + edit)

# structured, program mode (even first byte): message header (version 1, typed message k,
# id 1), then ops (0 open a TLV, 3 close, 6 TV, 7 field bytes, 9 repeat, 10 nest
# ParameterErrors): an ERROR_MESSAGE whose LLRPStatus holds ParameterErrors 70 deep; an
# RO_ACCESS_REPORT with one TagReportData (EPC-96) repeated as often as fits.
header = lambda k: bytes([0, 0, 0, 0, k, 0, 0, 0, 1])
status = bytes([0, 0, 0, 62]) + bytes([7, 3, 0, 100, 0, 0])
put("structured", b"\x00" + header(44) + status + bytes([10, 192, 0, 70, 1, 31, 0, 200]))
report = bytes([0, 0, 0, 44]) + bytes([6, 12]) + bytes(range(12)) + bytes([3])
put("structured", b"\x00" + header(39) + report + bytes([9, 255]))
