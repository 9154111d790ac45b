"""`propid plot`: draw a flight log (SITL CSV, `propid log` CSV or .tlog) to a PNG."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from propid import plotting
from propid.errors import UserError
from propid.outputs import check_writable

NAME = "plot"
HELP = "plot coefficient estimates (+-1 sigma, truth when known), rotor speeds and body rates to a PNG"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log", type=Path, required=True, metavar="FILE",
                        help="flight log: .csv (SITL log or `propid log --csv`) or .tlog")
    parser.add_argument("--out", type=Path, required=True, metavar="PNG", help="output image")
    parser.add_argument("--truth", type=Path, metavar="CSV",
                        help="take true_kf_i/true_km_i/true_bg_* from this SITL log "
                             "(e.g. to overlay truth on a recorded .tlog)")
    parser.add_argument("--summary", type=Path, metavar="JSON",
                        help="the simulator's --summary-json of this run: vehicle, trajectory and effects go into "
                             "the title (default: LOG.summary.json beside the log, if present)")
    parser.add_argument("--title", help="figure title (default: the log's file name, vehicle, trajectory, effects)")
    parser.add_argument("--dpi", type=int, default=110, help="resolution (default 110)")


def run(args: argparse.Namespace) -> int:
    if args.out.suffix.lower() != ".png":
        raise UserError(f"--out {args.out}: the output is a PNG (name it *.png)")
    if not 20 <= args.dpi <= 1200:
        raise UserError(f"--dpi {args.dpi}: choose 20..1200")
    if args.summary is not None and not args.summary.is_file():
        raise UserError(f"--summary {args.summary}: no such file")
    check_writable(args.out, "--out")
    flight = plotting.load_flight(args.log)
    if args.summary is not None:
        flight.context.update(plotting.run_context(args.log, args.summary))
    if args.truth is not None:
        plotting.add_truth(flight, plotting.load_flight(args.truth))
    out = plotting.plot_flight(flight, args.out, title=args.title, dpi=args.dpi)
    print(f"wrote {out}", file=sys.stderr)
    return 0
