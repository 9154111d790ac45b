"""`propid convert`: any supported flight log -> flight-log v1 CSV (+ vehicle JSON)."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from propid.errors import UserError
from propid.flightlog import read_vehicle, vehicle_path_for, write_flightlog
from propid.importers import FORMATS, import_log
from propid.importers.motor_order import parse_motor_map

NAME = "convert"
HELP = "convert a Betaflight blackbox, PX4 ULog, MAVLink tlog or v1 CSV into flight-log v1 (SI, body FLU)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", metavar="INPUT", help="log file (.bbl/.bfl, .ulg, .tlog, .csv)")
    parser.add_argument("--format", choices=FORMATS, default="auto", help="input format (default: from the file)")
    parser.add_argument("--vehicle", metavar="V.json", help="vehicle file: rotor count and rotor order to map motors onto")
    parser.add_argument("--log-index", type=int, default=1, metavar="K",
                        help="Betaflight: which log inside the file, 1-based as the blackbox explorer counts (default 1)")
    parser.add_argument("--motor-map", metavar="M1,M2,...",
                        help="controller motor number (1-based) of each vehicle rotor, overriding the quadrant match")
    parser.add_argument("--gyro-topic", default="sensor_combined", choices=["sensor_combined", "vehicle_angular_velocity"],
                        help="ULog: gyro topic (default sensor_combined: bias included, as the filter expects)")
    parser.add_argument("--out", required=True, metavar="OUT.csv", help="flight-log v1 CSV to write")
    parser.add_argument("--checks", action="store_true",
                        help="also print the independent least-squares checks (needs --vehicle)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    vehicle = read_vehicle(args.vehicle) if args.vehicle else None
    motor_map = None
    if args.motor_map:
        count = vehicle.rotor_count if vehicle else len(args.motor_map.split(","))
        motor_map = parse_motor_map(args.motor_map, count)
    if args.log_index < 1:
        raise UserError("--log-index counts from 1")
    log, info = import_log(args.input, args.format, vehicle, args.log_index, motor_map, args.gyro_topic,
                           progress=not args.no_progress)
    out = Path(args.out)
    if out.resolve() == Path(args.input).resolve():
        raise UserError("--out must differ from the input file")
    out.parent.mkdir(parents=True, exist_ok=True)
    write_flightlog(out, log)
    if vehicle is not None and vehicle.path is not None:
        target = vehicle_path_for(out)
        if target.resolve() != vehicle.path.resolve():
            shutil.copyfile(vehicle.path, target)
    print(f"wrote {out}: {len(log)} rows, {log.rotor_count} rotors, {log.t[-1] - log.t[0]:.2f} s")
    print(json.dumps(info, indent=None, default=str))
    if args.checks:
        if vehicle is None:
            raise UserError("--checks needs --vehicle")
        from propid.realdata_checks import check_log, format_checks

        log.path = out
        print(format_checks(check_log(log, vehicle)))
    return 0
