"""`propid gap`: diagnose the sim-to-real gap of flight logs (docs/gap.md)."""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
from pathlib import Path

import numpy as np

from propid.errors import UserError
from propid.flightlog import other_vehicle_files, read_flightlog, read_vehicle, vehicle_path_for, write_vehicle
from propid.gap.log_order import canonical_order
from propid.gap.scoring import BLOCK_FOLD_RULES, BLOCK_FOLDS, REPLICATION_FOLDS
from propid.gap.significance import REPLICATION_STATISTICS
from propid.outputs import check_directory, check_not_inputs, check_writable, write_text

NAME = "gap"
HELP = ("diagnose the sim-to-real gap: base fit, where the model misses, which unmodelled effect, "
        "how far it shrinks; corrected vehicle file")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log", required=True, action="extend", nargs="+", metavar="A.csv",
                        help="flight-log v1 CSV(s) of one vehicle to fit on (repeatable)")
    parser.add_argument("--vehicle", metavar="V.json",
                        help="vehicle file (default: the one beside the logs, X.csv -> X.vehicle.json; logs beside "
                             "different vehicle files need it)")
    parser.add_argument("--holdout", action="extend", nargs="+", default=[], metavar="C.csv",
                        help="logs never used to fit: the before/after figures are measured on them")
    parser.add_argument("--json", metavar="OUT.json", help="write the result here (default: print it)")
    parser.add_argument("--report", metavar="DIR", help="write DIR/index.html with plots")
    parser.add_argument("--vehicle-out", metavar="CORRECTED.json",
                        help="write the vehicle file corrected with the significant effects' parameters")
    parser.add_argument("--calibration", choices=("auto", "on", "off"), default="auto",
                        help="with --vehicle-out: replay the fit logs through the firmware filter gyro only and with "
                             "the accelerometer, in the chain the file is meant for, and scale Jxx, Jyy so the "
                             "gyro-only filter reads the accelerometer's kf (docs/gap.md, Corrected vehicle); auto "
                             "(default): when the fit logs have accelerometer columns and the vehicle a mass and "
                             "inertia, else the file is gap's effects alone and OUT.json says why; on: an error "
                             "instead; off: never")
    parser.add_argument("--calibration-guard", choices=("torque-gain", "rotor-mean", "final"), default="torque-gain",
                        help="with --vehicle-out: when the calibration is measured well enough to apply (docs/gap.md, "
                             "Corrected vehicle, 'Only a pinned reference'), at most 5 %%: torque-gain (default): the "
                             "relative std of c from both replays' rotor mean kf (the filter's covariance, its median "
                             "over each log's second half), and with 3 or more logs the references' spread; "
                             "rotor-mean: the same without the gyro-only replays; final: the guard before, the "
                             "accelerometer replays' final kf relative std, mean over rotors")
    parser.add_argument("--highpass", default="auto", metavar="HZ|auto",
                        help="torque axes: slow disturbance torques below this are a nuisance; auto (default): the "
                             "lowest of 0.2/0.5/1/2/5 Hz at which the roll/pitch kf no longer depends on the band")
    parser.add_argument("--lowpass", type=float, default=25.0, metavar="HZ",
                        help="upper band edge (default 25 Hz, at most a quarter of the sample rate)")
    parser.add_argument("--no-filter", action="store_true",
                        help="skip the firmware-filter replay before/after (faster)")
    parser.add_argument("--repeats", choices=("samples", "missing"), default="samples",
                        help="rows whose gyro triple (rotor speeds) equal the previous row's bit for bit, a logger's "
                             "copies of lost packets, in the fits: samples (default) or missing (torque and Omega^2 "
                             "interpolated across them; evaluated, not the default). Reported either way; the "
                             "filter check always skips them (--skip-repeats)")
    parser.add_argument("--lag-evidence", choices=("raw", "whitened"), default="raw",
                        help="the stream lag's held-out evidence: 'raw' (2 s blocks of the band-passed rows, the "
                             "default) or 'whitened' (the effects' replication test on whitened rows, each log's own lag "
                             "on its own rows when there are several; evaluated, docs/gap.md 'Stream alignment')")
    parser.add_argument("--ground-effect-height", choices=("com", "hub"), default="com",
                        help="ground_effect's height: 'com' (the logged pz for every rotor, the default) or 'hub' "
                             "(each rotor's hub height from the logged attitude; evaluated, not the default: "
                             "docs/gap.md 'Effect library')")
    parser.add_argument("--replication", choices=REPLICATION_STATISTICS, default="improvement",
                        help="the effects' held-out replication statistic: 'improvement' (the held-out residual "
                             "reduction, the default) or 'prediction' (the held-out residual along what the effect's "
                             "training-fold fit predicts; evaluated, not the default: docs/gap.md, SITL accuracy 'The score test "
                             "again')")
    parser.add_argument("--replication-folds", choices=REPLICATION_FOLDS, default="time",
                        help="the held-out replication's folds with one or two logs: 'time' (the 1 s blocks, index "
                             "mod 5, the default) or 'excitation' (a 1 s block holding more than a fold's share of the "
                             "effect's regressor energy is split over the folds; evaluated, not the default: "
                             "docs/gap.md, SITL accuracy 'Folds balanced by excitation')")
    parser.add_argument("--block-folds", choices=BLOCK_FOLD_RULES, default=BLOCK_FOLDS,
                        help="the cross-validation folds with one or two logs: 'phases' (1 s blocks numbered within "
                             "each log from its own start, index mod 5, in five partitions whose grids are offset by "
                             "0.2 s, the held-out sums averaged over them: neither the logs' order nor a log's first "
                             "row decides the folds) or 'first-row' (one partition, the blocks numbered across the "
                             f"logs in canonical order); default {BLOCK_FOLDS!r} (docs/gap.md 'Scoring')")
    parser.add_argument("--gyro-bias", choices=("off", "attitude"), default="off",
                        help="the gyro's constant bias before the measured torque's gyroscopic term w x (J w): "
                             "'off' (the default: the gyro as logged) or 'attitude' (measured against the logged "
                             "attitude and removed; evaluated, docs/gap.md 'Data preparation')")
    parser.add_argument("--lag-nuisance", choices=("logged", "shifted"), default="logged",
                        help="the stream alignment's nuisance columns (rotor_gyroscopic, rotor_drag, com_offset, "
                             "aero_damping): 'logged' (built once from the logged rotor stream, the default) or "
                             "'shifted' (built at each candidate lag from the stream shifted by it; evaluated, not "
                             "the default: docs/gap.md 'Stream alignment')")
    parser.add_argument("--thrust-offset", choices=("segment", "none"), default="none",
                        help="the thrust axis's constant (the accelerometer's zero-g offset times the mass): "
                             "'segment' (a free constant per flying segment: only the collective thrust's "
                             "variations set kf_thrust; the fitted offset per log in OUT.json "
                             "base_fit_details.thrust_offset; evaluated, not the default) or 'none' (the default: "
                             "through the origin, kf_thrust carries the offset as 1 + b_z/g); docs/gap.md "
                             "'Base model'")
    parser.add_argument("--explainable", action="store_true",
                        help="also measure how much of the held-out residual any linear filter of the logged "
                             "non-gyro signals predicts, and the gyro-noise floor (OUT.json `explainable`; a "
                             "diagnostic, off by default: on effect-free SITL flights it reads the sensor chain's "
                             "residual, not 0: docs/gap.md 'How far')")
    parser.add_argument("--no-progress", "--quiet", dest="quiet", action="store_true",
                        help="no progress bar (--quiet: the older spelling)")


def _vehicle_content(path: Path):
    """A vehicle file's content without its free-text notes (the SITL names the seed there)."""
    try:
        content = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return path.read_bytes()
    if isinstance(content, dict):
        content.pop("notes", None)
    return content


def default_vehicle_path(log_paths: list[str]) -> Path:
    """The vehicle file beside the logs (X.csv -> X.vehicle.json), whatever their order: the first by
    path name of those that exist; all that exist must say the same (notes aside), else the logs do
    not say which vehicle they are of."""
    beside = sorted({vehicle_path_for(p) for p in log_paths})
    present = [p for p in beside if p.exists()]
    if not present:
        return beside[0]
    first = _vehicle_content(present[0])
    differing = [str(p) for p in present[1:] if _vehicle_content(p) != first]
    if differing:
        raise UserError(f"the logs' vehicle files differ ({present[0]} and {differing[0]}): give --vehicle V.json")
    return present[0]


def _clean(obj):
    """JSON-ready: numpy scalars to Python, NaN/Inf to null."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    return obj


def without_unflown_logs(logs: list, vehicle, options) -> tuple[list, list[dict]]:
    """With several fitted logs, the ones without a flying segment to fit (a ground run, a log
    cut short) are left out and listed, so one such log does not stop the diagnosis of the
    others; the result is then that of the other logs alone. Alone, or all of them, it stays
    the one-line error."""
    from propid.gap.prep import NoFlyingSegment, prepare_flight

    if len(logs) < 2:
        return logs, []
    checked = vehicle
    if vehicle.inertia is None:  # as the analysis runs it (unit inertia)
        checked = copy.deepcopy(vehicle)
        checked.inertia = np.eye(3)
    kept, left_out, last_error = [], [], None
    for log in logs:
        try:
            prepare_flight(log, checked, options.band, repeats=options.repeats)
        except NoFlyingSegment as exc:
            left_out.append({"log": str(log.path), "why": str(exc)})
            last_error = exc
            continue
        kept.append(log)
    if not kept:
        raise last_error
    return kept, left_out


def run(args: argparse.Namespace) -> int:
    from propid.gap import analysis
    from propid.gap.prep import Band

    auto = args.highpass == "auto"
    try:
        highpass = 1.0 if auto else float(args.highpass)
    except ValueError:
        raise UserError(f"--highpass: expected a frequency in Hz or 'auto', got {args.highpass!r}") from None
    if not (highpass >= 0 and args.lowpass > highpass):
        raise UserError("--lowpass must be above --highpass (both in Hz, >= 0)")
    vehicle_path = Path(args.vehicle) if args.vehicle else default_vehicle_path(args.log)
    if not vehicle_path.exists():
        raise UserError(f"no vehicle file: {vehicle_path} (give --vehicle V.json){other_vehicle_files(args.log[0])}")
    vehicle = read_vehicle(vehicle_path)
    if args.calibration == "on" and not args.vehicle_out:
        raise UserError("--calibration on needs --vehicle-out (the calibration is of the written file)")
    if args.vehicle_out:
        check_writable(args.vehicle_out, "--vehicle-out")
    if args.json:  # before the analysis, not after minutes of it
        check_writable(args.json, "--json")
    if args.report:
        check_directory(args.report, "--report")
    check_not_inputs((("--vehicle-out", args.vehicle_out), ("--json", args.json)),
                     [vehicle_path, *args.log, *args.holdout])
    # the calibration and the filter check below take the logs in the analysis's canonical order too
    logs = canonical_order([read_flightlog(p, vehicle) for p in args.log])
    holdout = canonical_order([read_flightlog(p, vehicle) for p in args.holdout])
    options = analysis.Options(Band(highpass, args.lowpass, thrust_offset=args.thrust_offset == "segment"), progress=not args.quiet, auto_highpass=auto,
                               repeats=args.repeats, lag_evidence=args.lag_evidence,
                               ground_effect_height=args.ground_effect_height, replication=args.replication,
                               replication_folds=args.replication_folds, block_folds=args.block_folds, gyro_bias=args.gyro_bias, lag_nuisance=args.lag_nuisance,
                               explainable=args.explainable)
    logs, left_out = without_unflown_logs(logs, vehicle, options)
    for entry in left_out:
        print(f"propid gap: left out {entry['why']}", file=sys.stderr)
    try:
        result = analysis.run(logs, vehicle, holdout, options)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:
        raise UserError(f"cannot analyse these logs: {exc}") from None
    if left_out:
        result["inputs"]["left_out"] = left_out
    internal = result.pop("_internal")
    corrected = internal["corrected"]
    progress = internal["progress"]
    if args.vehicle_out:
        from propid.gap.calibration import calibrate_or_fall_back

        progress.grow(len(logs))  # the calibration's replays, one step per fit log
        corrected, result["calibration"] = calibrate_or_fall_back(args.calibration, logs, vehicle, corrected,
                                                                  progress=lambda: progress(1),
                                                                  guard=args.calibration_guard)
        if result["calibration"]["calibrated"] and result.get("base_fit_after"):
            from propid.gap.calibration import base_fit_with_calibrated_inertia

            inertia_fit = next((e["params"] for e in result["effects"]
                                if e["id"] == "inertia_error" and e["significant"]), {})
            file_over_fit = {key: inertia_fit[f"{axis}_least_squares"] / inertia_fit[axis]
                             for key, axis in (("kf_roll", "inertia_scale_xx"), ("kf_pitch", "inertia_scale_yy"))
                             if f"{axis}_least_squares" in inertia_fit}
            result["calibration"]["base_fit_after_with_calibrated_inertia"] = base_fit_with_calibrated_inertia(
                result["base_fit_after"], result["calibration"]["torque_gain"], file_over_fit)
    else:
        from propid.gap.calibration import not_calibrated

        result["calibration"] = not_calibrated("no --vehicle-out: the calibration runs only when a file is written")
    if not args.no_filter:
        from propid.gap.filtercheck import filter_before_after

        walk = bool(result["calibration"]["calibrated"])  # the chain the calibrated file is meant for
        if vehicle.inertia is None:
            # the replay's own error would advise its --unit-inertia option, which gap does not have
            result["filter"] = {"error": "the vehicle file has no inertia, and the firmware check reads kf in SI "
                                         "units (`propid replay --unit-inertia` replays such logs for kf/J; "
                                         "--no-filter skips this check)"}
        else:
            progress.grow(len(holdout or logs))  # one step per replayed log (before and after)
            try:
                result["filter"] = filter_before_after(holdout or logs, vehicle, corrected,
                                                       progress=lambda: progress(1), walk=walk)
            except UserError as exc:
                result["filter"] = {"error": str(exc)}
    progress.close()
    if args.vehicle_out:
        write_vehicle(args.vehicle_out, corrected)
    result = _clean(result)
    text = json.dumps(result, indent=1)
    if args.json:
        write_text(args.json, text + "\n")
    if args.report:
        from propid.gap.report import write_report

        write_report(result, args.report)
    if args.json:
        print(f"verdict: {result['verdict']} (significant: {', '.join(result['significant']) or 'none'})")
        if args.vehicle_out:
            cal = result["calibration"]
            if cal["calibrated"]:
                print(f"calibrated with the filter on {len(cal['logs'])} fit log(s): Jxx, Jyy x {cal['torque_gain']:.4g}; "
                      f"wrote {args.vehicle_out}; replay it with: {cal['replay_options']['command']}")
            else:
                print(f"not calibrated with the filter ({cal['why']}); wrote {args.vehicle_out}")
    else:
        print(text)
    return 0
