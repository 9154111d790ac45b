"""`propid effects-demo`: SITL flights with each modelled effect, the filter's matching term off and on."""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import effects_demo
from propid.campaign import locate_sitl
from propid.errors import UserError
from propid.outputs import check_directory

NAME = "effects-demo"
HELP = ("fly SITL flights with com_offset, rotor_drag, rotor_inertia, esc_delay, the filter's matching "
        "term off and on; write effects_demo.json and print the table (docs/math.md §13)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="build/results", metavar="DIR", help="output directory (default build/results)")
    parser.add_argument("--seeds", type=int, default=3, help="seeds per cell (default 3)")
    parser.add_argument("--duration", type=float, default=20.0, help="flight length [s] (default 20)")
    parser.add_argument("--effects", default=",".join(case[0] for case in effects_demo.CASES),
                        help="comma list of the cases to fly (default: all: "
                             + ", ".join(case[0] for case in effects_demo.CASES) + ")")
    parser.add_argument("--sitl", metavar="PATH", help="propid_sitl binary (default $PROPID_BUILD_DIR/sitl/propid_sitl)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    known = {case[0] for case in effects_demo.CASES}
    cases = tuple(name for name in args.effects.split(",") if name)
    unknown = sorted(set(cases) - known)
    if unknown or not cases:
        raise UserError(f"--effects: unknown {', '.join(unknown) or '(empty)'}; choose from {', '.join(sorted(known))}")
    if args.seeds < 1 or not args.duration > 0:
        raise UserError("--seeds must be >= 1 and --duration positive")
    check_directory(args.out, "--out")
    config = effects_demo.DemoConfig(sitl=Path(args.sitl) if args.sitl else locate_sitl(None), out_dir=Path(args.out),
                                     seeds=args.seeds, duration_s=args.duration, cases=cases)
    result = effects_demo.run_demo(config, progress=not args.no_progress)
    print(effects_demo.render(result), end="")
    print(f"wrote {config.out_dir / 'effects_demo.json'}")
    return 0
