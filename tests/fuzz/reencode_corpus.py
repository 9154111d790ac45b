#!/usr/bin/env python3
"""Re-encode fuzz inputs written for the harness layout without the geometry byte.

tests/fuzz/fuzz_api.c reads, after the rotor count, arm and plus/X bytes, one
geometry byte (< 128: the symmetric frame, as before; else per-rotor planar
positions and yaw signs). An input of the older layout keeps its meaning when a
0 is inserted at offset 3: the same configuration and the same calls. Inputs
shorter than 3 bytes read the missing bytes as 0 either way and are copied
unchanged. libFuzzer names corpus files by the SHA-1 of their content; such
names are renamed to the new content's hash, other names (regression-*) kept.

    tests/fuzz/reencode_corpus.py SRC_DIR DST_DIR
"""
import argparse
import hashlib
import pathlib
import re
import sys

GEOMETRY_OFFSET = 3  # after rotor count, arm, plus/X
SYMMETRIC = b"\x00"


def reencode(data: bytes) -> bytes:
    if len(data) < GEOMETRY_OFFSET:
        return data
    return data[:GEOMETRY_OFFSET] + SYMMETRIC + data[GEOMETRY_OFFSET:]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("src", type=pathlib.Path, help="directory of inputs in the older layout")
    parser.add_argument("dst", type=pathlib.Path, help="directory to write the re-encoded inputs to")
    args = parser.parse_args(argv)
    if not args.src.is_dir():
        print(f"reencode_corpus: error: {args.src} is not a directory", file=sys.stderr)
        return 2
    args.dst.mkdir(parents=True, exist_ok=True)
    count = 0
    for path in sorted(p for p in args.src.iterdir() if p.is_file()):
        data = reencode(path.read_bytes())
        name = path.name
        if re.fullmatch(r"[0-9a-f]{40}", name):
            name = hashlib.sha1(data).hexdigest()
        (args.dst / name).write_bytes(data)
        count += 1
    print(f"reencode_corpus: {count} inputs -> {args.dst}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
