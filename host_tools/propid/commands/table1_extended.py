"""`propid table1-extended`: the Table 1 campaign per vehicle preset (quads, hexa, octo)."""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import table1_extended
from propid.campaign import CampaignConfig, locate_sitl
from propid.errors import UserError
from propid.outputs import check_directory

NAME = "table1-extended"
HELP = ("Table 1 per vehicle preset: quads in all modes, hexa/octo in Filter and Oracle; "
        "writes table1_extended.json (docs/results.md)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default="build/results", metavar="DIR",
                        help="output directory (default build/results)")
    parser.add_argument("--trials", type=int, default=30, help="flights per cell (default 30)")
    parser.add_argument("--seed", type=int, default=1, help="seed of trial 0 (default 1)")
    parser.add_argument("--duration", type=float, default=10.0, help="flight length [s] (default 10)")
    parser.add_argument("--quads-only", action="store_true", help="leave out the hexa and octo presets")
    parser.add_argument("--presets", metavar="LIST",
                        help="comma-separated subset of the presets (default: all of them)")
    parser.add_argument("--null-dither", type=float, default=table1_extended.MULTI_NULL_DITHER,
                        metavar="FRACTION",
                        help="null-space excitation of the hexa and octo presets, fraction of the "
                             f"mean Omega^2 (default {table1_extended.MULTI_NULL_DITHER}; 0 = off)")
    parser.add_argument("--cramer-rao", action="store_true",
                        help="also compute the Cramér-Rao bound along every flight (slower)")
    parser.add_argument("--sitl", metavar="PATH", help="propid_sitl binary (default $PROPID_BUILD_DIR/sitl/propid_sitl)")
    parser.add_argument("--workers", type=int, default=2, help="parallel flights (default 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    if args.trials < 1 or not args.duration > 0:
        raise UserError("--trials must be >= 1 and --duration positive")
    if not 0.0 <= args.null_dither <= 0.5:
        raise UserError("--null-dither must be within [0, 0.5]")
    check_directory(args.out, "--out")
    presets = None
    if args.presets:
        presets = tuple(name.strip() for name in args.presets.split(",") if name.strip())
        known = table1_extended.QUAD_PRESETS + table1_extended.MULTI_PRESETS
        unknown = [name for name in presets if name not in known]
        if unknown:
            raise UserError(f"unknown preset(s) {', '.join(unknown)} (known: {', '.join(known)})")
    base = CampaignConfig(out_dir=Path(args.out).resolve(), sitl=locate_sitl(args.sitl),
                          trials=args.trials, base_seed=args.seed, duration_s=args.duration,
                          workers=args.workers, cramer_rao=args.cramer_rao)
    plan = table1_extended.presets_and_modes(include_multirotors=not args.quads_only, presets=presets)
    if not plan:
        raise UserError("no preset left to fly (--presets with --quads-only?)")
    table = table1_extended.run_extended(base, plan, progress=not args.no_progress,
                                         null_dither=args.null_dither)
    print(table1_extended.render(table), end="")
    print(f"wrote {base.out_dir / 'table1_extended.json'}")
    return 0
