"""`propid observability`: Lie-derivative observability rank of the filter's model for a vehicle."""

from __future__ import annotations

import argparse
import json

from propid.errors import UserError
from propid.flightlog import read_vehicle
from propid.outputs import check_not_inputs, check_writable, write_text

NAME = "observability"
HELP = ("symbolic Lie-derivative observability rank of the filter's model (sympy) for a vehicle "
        "file and measurement set; what is unobservable at hover")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--vehicle", required=True, metavar="V.json",
                        help="flight-log v1 vehicle file (needs inertia, kf_nominal, km_nominal)")
    parser.add_argument("--measure", default="gyro", metavar="gyro|gyro,accel",
                        help="measurement set (default gyro; accel adds the specific force along body z)")
    parser.add_argument("--max-order", type=int, default=4,
                        help="highest Lie-derivative order (default %(default)s; "
                             "the search stops earlier once an order adds no rank)")
    parser.add_argument("--json", metavar="OUT.json", help="also write the result as JSON")


def run(args: argparse.Namespace) -> int:
    from propid import observability  # sympy takes a while to import: only when asked

    measurements = tuple(name.strip() for name in args.measure.split(",") if name.strip())
    if "gyro" not in measurements:
        raise UserError(f"--measure: the filter always has the gyro; expected gyro or gyro,accel, "
                        f"got {args.measure!r}")
    if args.json:  # before the symbolic work, not after it
        check_writable(args.json, "--json")
        check_not_inputs([("--json", args.json)], [args.vehicle])
    vehicle = read_vehicle(args.vehicle)
    result = observability.analyse(vehicle, measurements, max_order=args.max_order)
    print(observability.render_text(result), end="")
    if args.json:
        write_text(args.json, json.dumps(result.to_json(), indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0
