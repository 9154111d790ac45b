"""`propid damage-bench`: randomized propeller-damage flights with the firmware detector."""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import damage_bench
from propid.campaign import locate_sitl
from propid.errors import UserError
from propid.outputs import check_directory, check_figure

NAME = "damage-bench"
HELP = ("fly randomized damaged (and undamaged) SITL flights with the damage detector; "
        "write damage_bench.json (docs/damage.md)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="build/results", metavar="DIR",
                        help="output directory (default build/results)")
    parser.add_argument("--damaged", type=int, default=200, help="damaged flights (default 200)")
    parser.add_argument("--undamaged", type=int, default=100,
                        help="undamaged flights with effects on (default 100)")
    parser.add_argument("--duration", type=float, default=6.0, help="flight length [s] (default 6)")
    parser.add_argument("--seed", type=int, default=1000, help="base seed (default 1000)")
    parser.add_argument("--false-alarm-rate", type=float, metavar="PER_H",
                        help="detector design false alarms per flight hour (default: library's 1e-3)")
    parser.add_argument("--no-filter-accel", action="store_true",
                        help="the filter without its accelerometer aiding (the bench's configuration "
                             "before it was adopted, docs/damage.md)")
    parser.add_argument("--library-accel-bias-prior", action="store_true",
                        help="the accelerometer bias prior of the library (0.5 m/s^2) in place of the "
                             "IMU datasheet's zero-g offset (the bench's configuration before it was "
                             "adopted, docs/damage.md)")
    parser.add_argument("--late-oracle", type=float, metavar="S",
                        help="also fly each damaged flight's Oracle told S seconds after the loss "
                             "(--oracle-damage-delay) and report it against the Oracle told at once: the "
                             "share of the 1.5x a detector that takes S uses up (docs/damage.md)")
    parser.add_argument("--sitl-arg", action="append", default=[], metavar="ARG",
                        help="extra propid_sitl argument for every flight, repeatable, e.g. "
                             "--sitl-arg=--filter-rate-noise --sitl-arg=0.001")
    parser.add_argument("--sitl", metavar="PATH", help="propid_sitl binary (default $PROPID_BUILD_DIR/sitl/propid_sitl)")
    parser.add_argument("--workers", type=int, default=2, help="parallel flights (default 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--png", metavar="OUT.png", help="plot (default OUT/damage_bench.png)")


def run(args: argparse.Namespace) -> int:
    if args.damaged < 1 or args.undamaged < 0 or not args.duration > 5.0:
        raise UserError("need >= 1 damaged flight, >= 0 undamaged and a duration above 5 s "
                        "(damages fall between 2 and 5.5 s)")
    if args.late_oracle is not None and not 0.0 < args.late_oracle <= 1.0:
        raise UserError("--late-oracle: a delay in (0, 1] s")
    check_directory(args.out, "--out")
    if args.png:
        check_figure(args.png, "--png")
    config = damage_bench.BenchConfig(
        sitl=Path(args.sitl) if args.sitl else locate_sitl(None), out_dir=Path(args.out),
        damaged=args.damaged, undamaged=args.undamaged, duration_s=args.duration,
        base_seed=args.seed, workers=args.workers, false_alarms_per_hour=args.false_alarm_rate,
        filter_accel=not args.no_filter_accel,
        accel_bias_std=None if args.library_accel_bias_prior else damage_bench.ACCEL_BIAS_STD, late_oracle_s=args.late_oracle, sitl_args=list(args.sitl_arg))
    result = damage_bench.run_bench(config, progress=not args.no_progress)
    print(damage_bench.render(result), end="")
    for error in result["errors"]:
        print(f"flight error: {error}")
    png = Path(args.png) if args.png else config.out_dir / "damage_bench.png"
    damage_bench.render_png(result, png)
    print(f"wrote {config.out_dir / 'damage_bench.json'} and {png}")
    return 0
