"""`propid table1`: render a campaign's table1.json as markdown (and a PNG), beside the paper's values."""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import table1
from propid.errors import UserError
from propid.outputs import check_figure, check_not_inputs, check_writable, write_text

NAME = "table1"
HELP = "render Table 1 (table1.json from `propid campaign`) as markdown beside the paper's values"
DEFAULT_TABLE = "build/results/table1.json"  # where `make table1` writes it


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("table", nargs="?", default=DEFAULT_TABLE, metavar="TABLE1.json",
                        help=f"campaign result (default {DEFAULT_TABLE})")
    parser.add_argument("--png", metavar="OUT.png", help="also draw the table as a PNG figure")
    parser.add_argument("--out", metavar="OUT.md", help="write the markdown here instead of stdout")
    parser.add_argument("--no-paper", action="store_true", help="our values only")


def run(args: argparse.Namespace) -> int:
    if args.out:
        check_writable(args.out, "--out")
    if args.png:
        check_figure(args.png, "--png")
    check_not_inputs((("--out", args.out), ("--png", args.png)), [args.table])
    if args.table == DEFAULT_TABLE and not Path(args.table).exists():
        raise UserError(f"no {DEFAULT_TABLE} here: run `make table1` (or `propid campaign --out build/results`) "
                        "first, or name a campaign's table1.json")
    table = table1.load_table(args.table)
    text = table1.render_markdown(table, with_paper=not args.no_paper)
    bound = table1.render_bound_markdown(table)
    if bound:
        text += "\nConvergence against the Cramér-Rao bound (propid.crlb):\n\n" + bound
    if args.out:
        write_text(args.out, text)
        print(f"wrote {args.out}")
    else:
        print(text, end="")
    if args.png:
        table1.render_png(table, args.png, with_paper=not args.no_paper)
        print(f"wrote {args.png}")
    return 0
