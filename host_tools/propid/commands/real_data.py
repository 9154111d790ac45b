"""`propid real-data`: the optional terms on a directory of real logs (docs/real-data.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import real_data
from propid.errors import UserError

NAME = "real-data"
HELP = ("replay every log of a real-data directory in each mode of the filter's optional terms; "
        "write real_data.json and print the tables (docs/real-data.md)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", required=True, metavar="DIR", help="directory of flight-log v1 CSVs of one vehicle")
    parser.add_argument("--vehicle", metavar="V.json", help="vehicle file (default: the one *.vehicle.json in DIR)")
    parser.add_argument("--reference-kf", type=float, required=True,
                        help="independent kf the results are divided by for display (not used by any rule)")
    parser.add_argument("--out", default="build/results", metavar="DIR", help="output directory (default build/results)")
    parser.add_argument("--modes", default=",".join(m[0] for m in real_data.MODES),
                        help="comma list of modes (default all: " + ",".join(m[0] for m in real_data.MODES) + ")")
    parser.add_argument("--skip-missing", action="store_true",
                        help="exit 0 with a note when DIR does not exist (for make real-data without ../shared)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    data = Path(args.data)
    if not data.is_dir():
        if args.skip_missing:
            print(f"real-data: skipped, {data} not found (the real logs are not distributed with the repository)")
            return 0
        raise UserError(f"--data {data}: no such directory")
    if args.vehicle:
        vehicle = Path(args.vehicle)
    else:
        found = sorted(data.glob("*.vehicle.json"))
        if len(found) != 1:
            raise UserError(f"{data}: {len(found)} *.vehicle.json files; give --vehicle")
        vehicle = found[0]
    known = {m[0] for m in real_data.MODES}
    modes = tuple(m for m in args.modes.split(",") if m)
    unknown = sorted(set(modes) - known)
    if unknown or not modes:
        raise UserError(f"--modes: unknown {', '.join(unknown) or '(empty)'}; choose from {', '.join(sorted(known))}")
    if not args.reference_kf > 0:
        raise UserError("--reference-kf must be positive")
    config = real_data.RealDataConfig(data_dir=data, vehicle=vehicle, out_dir=Path(args.out),
                                      reference_kf=args.reference_kf, modes=modes)
    result = real_data.run_real_data(config, progress=not args.no_progress)
    print(real_data.render(result), end="")
    print(f"wrote {config.out_dir / 'real_data.json'}")
    return 0
