"""`propid real-data`: the optional terms on a directory of real logs (docs/real-data.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from propid import real_data
from propid.errors import UserError
from propid.outputs import check_directory
from propid.replay.averaging import MEAN_ESTIMATORS

NAME = "real-data"
HELP = ("replay every log of a real-data directory in each mode of the filter's optional terms; "
        "write real_data.json and print the tables (docs/real-data.md)")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data", required=True, metavar="DIR", help="directory of flight-log v1 CSVs of one vehicle")
    parser.add_argument("--vehicle", metavar="V.json", help="vehicle file (default: the one *.vehicle.json in DIR)")
    parser.add_argument("--reference-kf", type=float, metavar="KF",
                        help="independent kf the results are divided by for display (not used by any rule); "
                             "needed by the replays and --thrust-evidence, not by --km-evidence")
    parser.add_argument("--out", default="build/results", metavar="DIR", help="output directory (default build/results)")
    parser.add_argument("--modes", default=",".join(m[0] for m in real_data.MODES),
                        help="comma list of modes (default all: " + ", ".join(m[0] for m in real_data.MODES) + ")")
    parser.add_argument("--mean-window", choices=("from-crossing", "at-least-half"), default="from-crossing",
                        help="the window of every replay's kf_mean/km_mean (propid replay --mean-window; default "
                             "from-crossing)")
    parser.add_argument("--mean-estimator", choices=MEAN_ESTIMATORS, default="inverse-variance",
                        help="what every replay's kf_mean/km_mean reports (propid replay --mean-estimator; default "
                             "inverse-variance); the other means' figures are printed beside it")
    parser.add_argument("--skip-missing", action="store_true",
                        help="exit 0 with a note when DIR does not exist (for make real-data without ../shared)")
    parser.add_argument("--thrust-evidence", action="store_true",
                        help="instead of the replays: per-log least-squares fits of m acc_z on sum Omega^2 with a free "
                             "bias and candidate airspeed/attitude terms (climb, translational, z drag, misalignment, "
                             "ground effect); print the table, write thrust_evidence.json (docs/real-data.md)")
    parser.add_argument("--km-evidence", action="store_true",
                        help="instead of the replays: per log, how much the flight tells about the rotors' km (yaw "
                             "excitation per input channel, least-squares km with white and Newey-West stds, the "
                             "filter model's bound, the flight time 5 %% would need); print the table, write "
                             "km_evidence.json (docs/real-data.md)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    data = Path(args.data)
    if data.exists() and not data.is_dir():
        raise UserError(f"--data {data}: a file, not a directory of logs")
    if not data.is_dir():
        if args.skip_missing:
            print(f"real-data: skipped, {data} not found (the real logs are not distributed with the repository)")
            return 0
        raise UserError(f"--data {data}: no such directory")
    if args.thrust_evidence and args.km_evidence:
        raise UserError("--thrust-evidence and --km-evidence: choose one")
    if not args.km_evidence and args.reference_kf is None:
        raise UserError("--reference-kf is needed (the kf the tables are divided by); only --km-evidence goes without")
    check_directory(args.out, "--out")
    if args.vehicle:
        vehicle = Path(args.vehicle)
    else:
        found = sorted(data.glob("*.vehicle.json"))
        if len(found) != 1:
            raise UserError(f"{data}: {len(found)} *.vehicle.json files; give --vehicle")
        vehicle = found[0]
    if args.thrust_evidence:
        return _thrust_evidence(data, vehicle, args)
    if args.km_evidence:
        return _km_evidence(data, vehicle, args)
    known = {m[0] for m in real_data.MODES}
    modes = tuple(m for m in args.modes.split(",") if m)
    unknown = sorted(set(modes) - known)
    if unknown or not modes:
        raise UserError(f"--modes: unknown {', '.join(unknown) or '(empty)'}; choose from {', '.join(sorted(known))}")
    if not args.reference_kf > 0:
        raise UserError("--reference-kf must be positive")
    config = real_data.RealDataConfig(data_dir=data, vehicle=vehicle, out_dir=Path(args.out),
                                      reference_kf=args.reference_kf, modes=modes, mean_window=args.mean_window,
                                      mean_estimator=args.mean_estimator)
    result = real_data.run_real_data(config, progress=not args.no_progress)
    print(real_data.render(result), end="")
    print(f"wrote {config.out_dir / 'real_data.json'}")
    return 0


def _thrust_evidence(data: Path, vehicle_path: Path, args: argparse.Namespace) -> int:
    import json

    from propid.flightlog import read_flightlog, read_vehicle, run_name
    from propid.outputs import write_text
    from propid.thrust_evidence import render_evidence, thrust_evidence

    if not args.reference_kf > 0:
        raise UserError("--reference-kf must be positive")
    vehicle = read_vehicle(vehicle_path)
    paths = sorted(data.glob("*.csv"))
    if not paths:
        raise UserError(f"no *.csv logs in {data}")
    logs = {run_name(p): read_flightlog(p, vehicle) for p in paths}
    try:
        entries = thrust_evidence(logs, vehicle, args.reference_kf)
    except ValueError as exc:
        raise UserError(f"--thrust-evidence: {exc}") from None
    print(f"slope kf over the reference {args.reference_kf:.3g} (display only); {len(logs)} runs")
    print(render_evidence(entries), end="")
    out = Path(args.out) / "thrust_evidence.json"
    write_text(out, json.dumps(entries, indent=2) + "\n")
    print(f"wrote {out}")
    return 0


def _km_evidence(data: Path, vehicle_path: Path, args: argparse.Namespace) -> int:
    import json

    from propid.flightlog import read_flightlog, read_vehicle, run_name
    from propid.km_evidence import km_evidence, render_km_evidence
    from propid.outputs import write_text

    vehicle = read_vehicle(vehicle_path)
    paths = sorted(data.glob("*.csv"))
    if not paths:
        raise UserError(f"no *.csv logs in {data}")
    iterator = paths
    if not args.no_progress:
        from tqdm import tqdm

        iterator = tqdm(paths, desc="km-evidence", unit="log")
    entries = {}
    for path in iterator:
        entries[run_name(path)] = km_evidence(read_flightlog(path, vehicle), vehicle)
    print(f"km relative to the vehicle file's nominal; {len(entries)} runs")
    print(render_km_evidence(entries), end="")
    out = Path(args.out) / "km_evidence.json"
    write_text(out, json.dumps(entries, indent=2) + "\n")
    print(f"wrote {out}")
    return 0
