"""The command line every generator shares: write its file, or `--check` that the file in the
tree is what it generates (exit 1 and say so when not)."""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Callable


def generator_main(name: str, description: str, default_out: pathlib.Path, generate: Callable[[], str]) -> int:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--out", type=pathlib.Path, default=default_out, help=f"output file (default {default_out})")
    parser.add_argument("--check", action="store_true",
                        help="exit 1 when the output file is not what this script generates")
    args = parser.parse_args()
    text = generate()
    if args.check:
        current = args.out.read_text() if args.out.exists() else ""
        if current != text:
            print(f"{name}: {args.out} is not current: run firmware/codegen/{name}.py", file=sys.stderr)
            return 1
        print(f"{name}: {args.out} is current")
        return 0
    args.out.write_text(text)
    print(f"{name}: wrote {args.out}")
    return 0
