#!/usr/bin/env python3
"""Extracts the tag reports from a `sllurp inventory` log file as JSON, one report per line.

sllurp 2.0.1 logs each RO_ACCESS_REPORT's tags as `saw tag(s): <pprint of a list of dicts>`,
spread over several log lines; this reads them back with ast.literal_eval. Bytes are written as
lower-case hex (the EPC, which sllurp gives as ASCII hex, as is). Usage: sllurp_tags.py LOGFILE
"""
import ast
import json
import re
import sys

STAMP = re.compile(r"^\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d+ ")


def plain(v):
    if isinstance(v, bytes):
        # sllurp already renders EPCs as ASCII hex; other bytes become hex here.
        text = v.decode("ascii", errors="replace")
        if text and all(c in "0123456789abcdefABCDEF" for c in text):
            return text.lower()
        return v.hex()
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v


def main(path):
    text = open(path, encoding="utf-8", errors="replace").read().splitlines()
    i = 0
    while i < len(text):
        line = text[i]
        k = line.find("saw tag(s): ")
        if k < 0:
            i += 1
            continue
        chunk = [line[k + len("saw tag(s): "):]]
        i += 1
        while i < len(text) and not STAMP.match(text[i]):
            chunk.append(text[i])
            i += 1
        tags = ast.literal_eval("\n".join(chunk))
        print(json.dumps(plain(tags)))


if __name__ == "__main__":
    main(sys.argv[1])
