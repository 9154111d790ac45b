"""`propid convert`: any supported flight log -> flight-log v1 CSV (+ vehicle JSON)."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from propid.errors import UserError
from propid.outputs import check_not_inputs, check_writable
from propid.flightlog import read_vehicle, vehicle_path_for, write_flightlog
from propid.importers import FORMATS, detect_format, import_log
from propid.importers.motor_order import parse_motor_map

NAME = "convert"
HELP = "convert a Betaflight blackbox, PX4 ULog, MAVLink tlog or v1 CSV into flight-log v1 (SI, body FLU)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("input", metavar="INPUT", help="log file (.bbl/.bfl, .ulg, .tlog, .csv)")
    parser.add_argument("--format", choices=FORMATS, default="auto", help="input format (default: from the file)")
    parser.add_argument("--vehicle", metavar="V.json", help="vehicle file: rotor count and rotor order to map motors onto")
    parser.add_argument("--log-index", type=int, metavar="K",
                        help="Betaflight: which log inside the file, 1-based as the blackbox explorer counts "
                             "(default 1; a file with several logs lists them)")
    parser.add_argument("--motor-map", metavar="M1,M2,...",
                        help="controller motor number (1-based) of each vehicle rotor, overriding the quadrant match")
    parser.add_argument("--gyro-topic", default="sensor_combined", choices=["sensor_combined", "vehicle_angular_velocity"],
                        help="ULog: gyro topic (default sensor_combined: bias included, as the filter expects)")
    parser.add_argument("--out", required=True, metavar="OUT.csv", help="flight-log v1 CSV to write")
    parser.add_argument("--checks", action="store_true",
                        help="also print the independent least-squares checks (needs --vehicle)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def check_output(out: Path, input_path: Path) -> None:
    """Everything about --out that can be known before any work."""
    check_not_inputs([("--out", out)], [input_path])
    if out.is_dir():
        raise UserError(f"--out {out}: a directory, give a file name")
    if out.suffix.lower() != ".csv":
        raise UserError(f"--out {out}: flight-log v1 is a .csv file")
    check_writable(out, "--out")


def run(args: argparse.Namespace) -> int:
    # Every argument is checked before any work and before anything is written.
    input_path = Path(args.input)
    out = Path(args.out)
    if not input_path.is_file():
        raise UserError(f"cannot read {input_path}: " + ("a directory" if input_path.is_dir() else "no such file"))
    check_output(out, input_path)
    if args.checks and not args.vehicle:
        raise UserError("--checks needs --vehicle")
    if args.log_index is not None and args.log_index < 1:
        raise UserError("--log-index counts from 1")
    vehicle = read_vehicle(args.vehicle) if args.vehicle else None
    if vehicle is not None:  # copied beside the output
        check_writable(vehicle_path_for(out), "--out's vehicle file")
    motor_map = None
    if args.motor_map:
        count = vehicle.rotor_count if vehicle else len(args.motor_map.split(","))
        motor_map = parse_motor_map(args.motor_map, count)
    fmt = detect_format(input_path) if args.format == "auto" else args.format
    if args.log_index is not None and fmt != "betaflight":
        raise UserError(f"--log-index applies to Betaflight logs; {input_path} is {fmt}")
    log, info = import_log(input_path, fmt, vehicle, args.log_index, motor_map, args.gyro_topic,
                           progress=not args.no_progress)
    if info.get("log_count", 1) > 1 and args.log_index is None:
        listing = ", ".join(f"{entry['index']} ({entry['bytes'] / 1e6:.2f} MB)" for entry in info.get("logs", []))
        print(f"note: {input_path} holds {info['log_count']} logs: {listing}; converted log 1 "
              "(give --log-index K for another)", file=sys.stderr)
    write_flightlog(out, log)
    if vehicle is not None and vehicle.path is not None:
        target = vehicle_path_for(out)
        if not target.exists() or target.resolve() != vehicle.path.resolve():
            shutil.copyfile(vehicle.path, target)
    print(f"wrote {out}: {len(log)} rows, {log.rotor_count} rotors, {log.t[-1] - log.t[0]:.2f} s")
    print(json.dumps(info, indent=None, default=str))
    if args.checks:
        from propid.realdata_checks import check_log, format_checks

        log.path = out
        print(format_checks(check_log(log, vehicle)))
    return 0
