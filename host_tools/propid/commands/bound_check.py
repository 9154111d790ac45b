"""`propid bound-check`: is a campaign cell's convergence miss the filter's or the flight's?"""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import bound_check, outputs, table1
from propid.errors import UserError

NAME = "bound-check"
HELP = ("Monte-Carlo errors of an efficient estimator (and of the filter's covariance loadings) "
        "along a campaign's kept logs, under Table 1's convergence criterion (docs/results.md)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("campaign", metavar="DIR",
                        help="output directory of `propid campaign --keep-logs` (table1.json and logs/)")
    parser.add_argument("--trajectory", default="circle", choices=table1.TRAJECTORIES,
                        help="trajectory of the cell (default circle)")
    parser.add_argument("--mode", default="filter", choices=table1.MODES, help="mode of the cell (default filter)")
    parser.add_argument("--loadings", default=",".join(bound_check.LOADINGS), metavar="LIST",
                        help="covariance recursions to compare, of " + ", ".join(bound_check.LOADINGS)
                             + " (default all)")
    parser.add_argument("--realisations", type=int, default=200, metavar="R",
                        help="Monte-Carlo noise realisations per flight (default 200)")
    parser.add_argument("--z-excess", action="store_true",
                        help="instead: the Filter's height RMSE over the Oracle's from the collective-thrust "
                             "error through the z loop, flown vs an efficient estimator (needs the cell's "
                             "Oracle logs too)")
    parser.add_argument("--json", metavar="FILE", help="also write every flight's figures to FILE")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    loadings = tuple(name.strip() for name in args.loadings.split(",") if name.strip())
    if not loadings:
        raise UserError("--loadings is empty")
    if args.realisations < 1:
        raise UserError("--realisations must be >= 1")
    if args.json:
        outputs.check_writable(args.json, "--json")
        campaign = Path(args.campaign)
        outputs.check_not_inputs([("--json", args.json)],
                                 [campaign / "table1.json", *sorted((campaign / "logs").glob("*"))])
    if args.z_excess:
        result = bound_check.z_excess_campaign(Path(args.campaign), args.trajectory,
                                               realisations=args.realisations, progress=not args.no_progress)
        print(bound_check.render_z_excess(result), end="")
    else:
        result = bound_check.check_campaign(Path(args.campaign), args.trajectory, args.mode,
                                            loadings=loadings, realisations=args.realisations,
                                            progress=not args.no_progress)
        print(bound_check.render(result), end="")
    if args.json:
        bound_check.write_json(result, Path(args.json))
        print(f"wrote {args.json}")
    return 0
