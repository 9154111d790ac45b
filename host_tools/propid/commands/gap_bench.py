"""`propid gap-bench`: blind benchmark of `propid gap` on SITL flights with known effects."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

from propid.campaign import locate_sitl
from propid.errors import UserError
from propid.gapbench.magnitudes import EFFECTS
from propid.gapbench.runner import SINGLE_THREADED_BLAS, BenchConfig, default_tool_command, run_bench
from propid.gapbench.table import render
from propid.outputs import check_directory, check_writable

NAME = "gap-bench"
HELP = ("blind benchmark of `propid gap`: SITL flights with known effects, answer key apart, "
        "scored next to a least-squares baseline")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="build/gap-bench", metavar="DIR",
                        help="work directory: flights/ (what the tool sees), answers/ (the truth), "
                             "tool/, baseline/ (default build/gap-bench)")
    parser.add_argument("--result", default="build/results/gap_bench.json", metavar="FILE",
                        help="scored result (default build/results/gap_bench.json)")
    parser.add_argument("--seed", type=int, default=1, help="seed of the flight plan (default 1)")
    parser.add_argument("--singles-per-effect", type=int, default=5,
                        help="flights per effect alone (default 5)")
    parser.add_argument("--pairs", type=int, default=15, help="flights with two effects (default 15)")
    parser.add_argument("--nones", type=int, default=15, help="effect-free flights (default 15)")
    parser.add_argument("--effects", default=",".join(EFFECTS),
                        help=f"comma list of the effects to draw from (default all {len(EFFECTS)}: {', '.join(EFFECTS)})")
    parser.add_argument("--flights-per-diagnosis", type=int, default=1, metavar="K",
                        help="flights of one vehicle per diagnosis (default 1): the first as with 1, "
                             "K - 1 more with the same effects and strengths, their own noise and "
                             "trajectory; `propid gap` gets all K logs (docs/gap-bench.md)")
    parser.add_argument("--duration", type=float, default=12.0, help="flight length [s] (default 12)")
    parser.add_argument("--workers", type=int, default=2, help="parallel flights (default 2)")
    parser.add_argument("--tool-command", default=None, metavar="'CMD'",
                        help="the diagnosis to benchmark, called with --log/--vehicle/--json (and --report "
                             "with --reports) "
                             "(default: this package's `propid gap --no-filter --quiet`: the "
                             "filter replay is not scored)")
    parser.add_argument("--reports", action="store_true",
                        help="also write each flight's HTML report (tool/ID_report; not scored, slower)")
    parser.add_argument("--no-tool", action="store_true", help="score the baseline only")
    parser.add_argument("--time-budget", type=float, default=None, metavar="S",
                        help="start no new flight after S seconds; score the flights done "
                             "(flights run in a seeded random order, so those are a fair sample)")
    parser.add_argument("--sitl", metavar="PATH",
                        help="propid_sitl binary (default $PROPID_BUILD_DIR/sitl/propid_sitl)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    started_as_command = sys.argv[1:2] == [NAME]
    if started_as_command and any(os.environ.get(k) != v for k, v in SINGLE_THREADED_BLAS.items()):
        # numpy's BLAS reads its thread count when loaded: start again single-threaded
        sys.stdout.flush()
        os.execve(sys.executable, [sys.executable, "-m", "propid.cli"] + sys.argv[1:],
                  dict(os.environ, **SINGLE_THREADED_BLAS))
    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown or not effects:
        raise UserError(f"--effects: expected a comma list of {', '.join(EFFECTS)}, got {args.effects!r}")
    for option in ("singles_per_effect", "pairs", "nones"):
        if getattr(args, option) < 0:
            raise UserError(f"--{option.replace('_', '-')} must not be negative")
    if args.pairs and len(effects) < 2:
        raise UserError("--pairs needs at least two --effects")
    if not args.duration >= 4.0:
        raise UserError("--duration must be at least 4 s")
    if not 1 <= args.flights_per_diagnosis <= 10:
        raise UserError("--flights-per-diagnosis must be 1 to 10")
    if args.workers < 1:
        raise UserError("--workers must be at least 1")
    check_directory(args.out, "--out")
    check_writable(args.result, "--result")
    tool = None if args.no_tool else (shlex.split(args.tool_command) if args.tool_command
                                      else default_tool_command())
    config = BenchConfig(
        out_dir=Path(args.out).resolve(), result_path=Path(args.result).resolve(),
        sitl=locate_sitl(args.sitl), seed=args.seed, singles_per_effect=args.singles_per_effect,
        pairs=args.pairs, nones=args.nones, effects=effects, duration_s=args.duration,
        workers=args.workers, tool_command=tool, time_budget_s=args.time_budget,
        reports=args.reports, flights_per_diagnosis=args.flights_per_diagnosis,
    )
    result = run_bench(config, progress=not args.no_progress)
    print(render(result))
    for error in result["errors"][:10]:
        print(f"flight failed: {error}")
    if result["cancelled_flights"]:
        print(f"time budget: {result['cancelled_flights']} of {result['planned_flights']} "
              "planned flights not flown")
    print(f"{len(result['flights'])} flights in {result['runtime_s']['total']:.0f} s; "
          f"wrote {config.result_path}")
    return 0 if not result["errors"] else 1
