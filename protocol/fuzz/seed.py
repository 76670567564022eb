#!/usr/bin/env python3
"""Seeds the fuzz corpora from the golden vectors (run from protocol/fuzz/)."""
import hashlib, json, pathlib

root = pathlib.Path(__file__).resolve().parent
for d in ("frame_split", "message_decode"):
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
