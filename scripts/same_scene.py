#!/usr/bin/env python3
"""Compares two scene folders file by file: the same files, the same bytes, report.json and report.md
without their timing sections (the only place two runs of one build may differ). Exits 1 and names
the files that differ.

    python3 scripts/same_scene.py out/single/demo out/merged/demo
"""
import json
import os
import sys


def files(root):
    return sorted(os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs)


def body(root, rel):
    data = open(os.path.join(root, rel), "rb").read()
    if rel == "report.json":
        v = json.loads(data)
        v.pop("timing")
        return json.dumps(v, sort_keys=True).encode()
    if rel == "report.md":
        return data[: data.index(b"## Timing")]
    return data


def main():
    a, b = sys.argv[1], sys.argv[2]
    fa, fb = files(a), files(b)
    if fa != fb:
        only_a, only_b = sorted(set(fa) - set(fb)), sorted(set(fb) - set(fa))
        sys.exit(f"{a} and {b} hold other files: only in the first {only_a[:5]}, only in the second {only_b[:5]}")
    differ = [r for r in fa if body(a, r) != body(b, r)]
    if differ:
        sys.exit(f"{len(differ)} files differ between {a} and {b}: {differ[:5]}")
    print(f"{len(fa)} files, byte-identical (reports without timing)")


if __name__ == "__main__":
    main()
