#!/usr/bin/env python3
"""Whether files look alike in an engine: reads a log of scripts/engines/check_babylon.mjs and, for
each pair FILE=REFERENCE given, checks that FILE's frame covers the same share of the view (within
0.3 percentage points) with the same mean colour (within 0.02 per channel) as REFERENCE's. Used
for compact outputs (16-bit vertices, meshopt) against their f32 twins.

    same_frames.py LOG FILE=REFERENCE [FILE=REFERENCE ...]

Paths as the log prints them (check_babylon.mjs prints absolute paths). Exits 1 on a difference
or a file missing from the log.
"""
import re
import sys

COVERAGE_PP = 0.3
COLOUR = 0.02


def frames(log):
    out = {}
    for line in open(log):
        m = re.match(r"ok\s+(\S+): .*frame ([0-9.]+) % covered, mean rgb ([0-9.]+) ([0-9.]+) ([0-9.]+)", line)
        if m:
            out[m.group(1)] = [float(x) for x in m.groups()[1:]]
    return out


def main():
    log, pairs = sys.argv[1], sys.argv[2:]
    seen = frames(log)
    bad = []
    for pair in pairs:
        file, ref = pair.split("=", 1)
        got, want = seen.get(file), seen.get(ref)
        if got is None or want is None:
            bad.append(f"{file} or {ref}: no frame in {log}")
        elif abs(got[0] - want[0]) > COVERAGE_PP or max(abs(a - b) for a, b in zip(got[1:], want[1:])) > COLOUR:
            bad.append(f"{file}: {got[0]} % covered, mean rgb {got[1:]}; {ref}: {want[0]} %, {want[1:]}")
    print("\n".join(bad) or f"{len(pairs)} files look as their references do (coverage within {COVERAGE_PP} %, mean colour within {COLOUR})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
