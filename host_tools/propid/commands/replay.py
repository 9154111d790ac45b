"""`propid replay`: run a flight log through the firmware filter (C library) and report."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from propid.errors import UserError
from propid.flightlog import other_vehicle_files, read_flightlog, read_vehicle, vehicle_path_for
from propid.outputs import check_not_inputs, check_writable, write_text
from propid.replay.averaging import MEAN_ESTIMATORS
from propid.replay.start import HOLD_S

NAME = "replay"
HELP = "replay a flight-log v1 CSV through the firmware filter: per-rotor kf/km, gyro biases, JSON + plot"


def _noise_std(text: str):
    return _word_or_number(text, ("auto",), float, lambda v: 0.0 <= v <= 1.0e4,
                           "a std in rad/s or 'auto'", f"{text}: the std [rad/s] must be between 0 and 10000")


def _timing_error(text: str):
    return _word_or_number(text, ("auto", "off"), float, lambda v: 0.0 <= v <= 1.0,
                           "a time in s, 'auto' or 'off'", f"{text}: the time [s] must be between 0 and 1")


def _walk(text: str):
    return _word_or_number(text, ("auto",), float, lambda v: 0.0 <= v <= 10.0,
                           "a walk in 1/sqrt(s) or 'auto'", f"{text}: the walk must be between 0 and 10 [1/sqrt(s)]")


# propid_config_t fields a user may override from the command line (name, type, help).
OVERRIDES = [
    ("thrust_coeff_rel_std0", float, "prior std of kf relative to nominal (library default 0.3)"),
    ("drag_coeff_rel_std0", float, "prior std of km relative to nominal"),
    ("gyro_bias_std0", float, "prior std of the gyro biases [rad/s]"),
    ("rate_std0", float, "prior std of the body rates [rad/s]"),
    ("gyro_noise_density", float, "gyro white noise [rad/s/sqrt(Hz)] (default: measured on the log)"),
    ("gyro_sample_rate_hz", float, "gyro rate the density applies to [Hz] (default: the log's rate)"),
    ("rate_process_noise", float, "unmodelled angular acceleration [rad/s^2/sqrt(Hz)] (default: measured on the log)"),
    ("thrust_coeff_rel_walk", _walk, "random walk of kf/kf_nominal [1/sqrt(s)], or auto (gyro only, without the "
                                     "thrust-torque scale): sqrt(0.02^2 + q^2) with q the --torque-scale-walk auto "
                                     "rule's change of the 2-10 Hz torque gain measured on the log"),
    ("drag_coeff_rel_walk", float, "random walk of km/km_nominal [1/sqrt(s)]"),
    ("gyro_bias_walk", float, "random walk of the gyro biases [rad/s/sqrt(s)]"),
    ("gate_sigma", float, "innovation gate [std]; <= 0 disables"),
    ("gate_max_consecutive", int, "gated samples in a row before an axis is re-opened"),
    ("gyro_range", float, "|gyro| above this is a saturated sensor [rad/s]"),
    ("rotor_stale_us", int, "rotor data older than this at a gyro sample is stale [us]"),
    ("max_gyro_gap_us", int, "a longer gap between gyro samples is a time jump (resync) [us]"),
    ("converged_rel_std", float, "relative error a converged claim bounds (claimed at 3 std below it); "
                              "the averaging window starts at 1 std below it"),
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--log", required=True, nargs="+", metavar="FLIGHT.csv",
                        help="flight-log v1 CSV (see `propid convert`); several logs of one vehicle give a fleet "
                             "summary (mean, run-to-run spread) as well")
    parser.add_argument("--vehicle", metavar="V.json", help="vehicle file (default: FLIGHT.vehicle.json beside the log)")
    parser.add_argument("--json", metavar="OUT.json",
                        help="write the summary (JSON) here; '-' writes it to stdout and moves the readable "
                             "report to stderr (default: no JSON, the report on stdout)")
    parser.add_argument("--plot", metavar="PNG",
                        help="one log: kf, km (+-1 sigma) and gyro biases over time; several logs: per-run kf "
                             "relative to --reference-kf, beside the least-squares checks")
    parser.add_argument("--table", metavar="OUT.md", help="several logs: write the per-run validation table (Markdown)")
    parser.add_argument("--segment", choices=["all", "flying"], default="all",
                        help="replay every row, or only flying rows (is_flying column, else every rotor above "
                             "1/3 of the median spinning speed); gaps are bridged with propid_resync (default all)")
    parser.add_argument("--start", choices=["first", "flying"], default="first",
                        help="where the filter starts: the segment's first row (default), or flying: the first row "
                             f"from which the vehicle flies {HOLD_S:g} s without a break (a simulator's untrimmed start or "
                             "a take-off left out; the noise and delay rules still measure on the whole segment)")
    parser.add_argument("--streams", choices=["auto", "rows", "events"], default="auto",
                        help="rows: every row is one gyro and one rotor sample; events: a row carries whichever "
                             "stream is non-empty (ULog/tlog conversions); auto (default) decides from the log")
    parser.add_argument("--mean-window", choices=("from-crossing", "at-least-half"), default="from-crossing",
                        help="the window kf_mean_window/km_mean_window average over: from the first sample whose std is under the "
                             "convergence bar (default), or from it or the replay's midpoint, whichever is earlier "
                             "(every mean over at least half of the samples; evaluated, docs/real-data.md)")
    parser.add_argument("--mean-estimator", choices=MEAN_ESTIMATORS, default="inverse-variance",
                        help="what kf_mean/km_mean report: every recorded estimate weighted by 1/std^2 (default; no "
                             "threshold), the plain mean over --mean-window's window, or the time mean of the estimate "
                             "smoothed backwards under the coefficient walk; all are always in the JSON as "
                             "kf_mean_inverse_variance, kf_mean_window and kf_mean_smoothed (docs/real-data.md)")
    parser.add_argument("--skip-repeats", action="store_true",
                        help="treat a row whose gyro (or rotor speeds) exactly repeat the previous row as no new "
                             "sample (logs resampled by sample-and-hold)")
    delay = parser.add_mutually_exclusive_group()
    delay.add_argument("--esc-delay", type=_esc_delay, default="default", metavar="auto|vehicle|S",
                       help="telemetry delay the filter holds (its own delay buffer, docs/math.md §12): S seconds, "
                            "> 0 the logged rotor speeds lag the gyro, < 0 the gyro lags; auto: the per-log rule (the "
                            "whole-sample lag, -50..50 ms, that maximises the 2-10 Hz correlation of modelled and "
                            "measured roll/pitch torque in the filter's own discretisation; 0 for event-style logs); "
                            "vehicle: the vehicle file's esc_delay_s. Default: the vehicle file's esc_delay_s when it "
                            "has one, else auto. 0: replay as recorded")
    delay.add_argument("--rotor-delay", type=_delay, default=None, metavar="S|auto",
                       help="older spelling: rotor speeds act S seconds after their logged time, i.e. --esc-delay -S")
    parser.add_argument("--prefilter", type=_prefilter, default=None, metavar="HZ|auto|off",
                        help="matched causal low-pass (critically damped, 2nd order) of the gyro AND the rotor "
                             "speed squared before the filter; auto: cut-off where the torque-model coherence "
                             "falls below 0.5 (default off; docs/real-data.md)")
    parser.add_argument("--diagnostic-highpass", type=float, metavar="HZ",
                        help="DIAGNOSTIC ONLY: remove content below HZ from gyro and rotor speed squared (common "
                             "offset trick, symmetric vehicles; pins the rotors to one kf) to show what slow "
                             "unmodelled moments cost (docs/real-data.md)")
    parser.add_argument("--aiding", choices=["auto", "gyro", "gyro+accel"], default="auto",
                        help="measurements the filter fuses: gyro only, or gyro + the accelerometer's z specific "
                             "force (pins the kf scale); auto (default): gyro+accel when the log has acc_* columns "
                             "and the vehicle file a mass")
    parser.add_argument("--disturbance", choices=["on", "off"], default="off",
                        help="the filter's disturbance-torque states (a slowly varying body torque: CoM offset, "
                             "aerodynamic moments); default off")
    parser.add_argument("--disturbance-bandwidth", type=float, default=None, metavar="HZ",
                        help="with --disturbance on: the states' bandwidth; they then take the torque residual "
                             "below it (what the vehicle's attitude controller cancels) and kf/km learn above it "
                             "(docs/math.md §7); default: the vehicle file's loop_bandwidth_hz (written by "
                             "propid gap --vehicle-out) when it has one, else the library's slow walk")
    parser.add_argument("--instrument", choices=["off", "commands"], default="off",
                        help="commands: the log's cmd_i columns (motor commands 0..1) go to the filter "
                             "(propid_push_motor_command) and its rotor input becomes the first stage's projection "
                             "of the telemetry on them, so the telemetry's error stays out of the regressor "
                             "(docs/math.md §16); default off")
    parser.add_argument("--command-lag", type=_lag, default="auto", metavar="auto|S",
                        help="with --instrument commands: the first stage's motor lag [s]; auto (default): the "
                             "per-log rule (the lag whose lagged command explains most of the speed^2)")
    parser.add_argument("--command-memory", type=float, default=None, metavar="S",
                        help="with --instrument commands: the first stage's forgetting time [s] (default 10)")
    parser.add_argument("--command-min-f", type=float, default=0.0, metavar="F",
                        help="with --instrument commands: the weak-instrument guard, a rotor keeps its telemetry "
                             "while the F statistic of its first stage (over the fit's effective sample count) is "
                             "below F (docs/math.md §16); default 0: no guard")
    parser.add_argument("--rotor-inertia", choices=["auto", "on", "off"], default="auto",
                        help="model the rotors' yaw reaction and gyroscopic torque with the vehicle file's "
                             "rotor_inertia (auto, the default: when it is given)")
    parser.add_argument("--aero-damping", choices=["auto", "on", "off"], default="off",
                        help="model the airframe's aerodynamic rate damping (a body torque -d_a omega_a) with the "
                             "vehicle file's aero_damping [N m s/rad] (docs/math.md §17; auto: when it is given; "
                             "default off)")
    parser.add_argument("--gyro-scale", choices=["auto", "off"], default="auto",
                        help="divide the gyro by the vehicle file's gyro_scale (the gyro reads s_a x the true "
                             "rate) before the filter (auto, the default: when the file has it)")
    parser.add_argument("--torque-scale", choices=["auto", "on", "off"], default="auto",
                        help="with the accelerometer, also estimate the scale of the thrust torques relative to the "
                             "vehicle file's inertia and arms, so kf's scale comes from the accelerometer alone "
                             "(auto, the default: on with --aiding gyro+accel)")
    parser.add_argument("--torque-scale-walk", metavar="auto|W", type=_walk,
                        help="let that scale follow a torque gain that changes within the flight: random walk W "
                             "[1/sqrt(s)], or auto: measured on the log from the change of the 2-10 Hz torque gain "
                             "between 4 s windows (docs/real-data.md). Default: a constant scale")
    parser.add_argument("--rotor-speed-noise", metavar="auto|SIGMA", type=_noise_std,
                        help="std of a rotor-speed sample's error [rad/s], carried into the rate process noise "
                             "(docs/math.md §14), or auto: measured on the log's rotor-speed stream (second "
                             "differences of new samples; docs/real-data.md). Default: exact rotor speeds")
    parser.add_argument("--rotor-speed-noise-time", metavar="S", type=float,
                        help="correlation time of that error [s] (default: auto's median sample interval, "
                             "or one step with a given SIGMA)")
    parser.add_argument("--rotor-timing-error", metavar="auto|off|S", type=_timing_error, default="off",
                        help="std of a rotor-speed report's age error [s], one error common to the rotors of a "
                             "report: while the speeds change fast (a rotor driven to 0 and back, a take-off) the "
                             "step's input is off by that time x du/dt and the filter carries it in the rate "
                             "process noise (docs/math.md §14), or auto: the median interval between new "
                             "rotor-speed samples. Default off (exact timing; docs/sitl.md 'Log' for when it helps)")
    parser.add_argument("--input-error-compensation", choices=["on", "off"], default="off",
                        help="with --rotor-speed-noise: remove from each coefficient update the average part "
                             "that rotor-speed error explains (errors-in-variables bias; docs/math.md §14). "
                             "Default off")
    parser.add_argument("--vehicle-out", metavar="CORRECTED.json",
                        help="gyro only (--aiding gyro), logs with accelerometer columns, vehicle with a mass: also "
                             "replay every log with the accelerometer and write the vehicle file whose Jxx, Jyy are "
                             "scaled so this gyro-only replay reads the accelerometer's fleet kf (kf_nominal = that "
                             "kf); replay other logs of the vehicle with it and the same options (docs/real-data.md)")
    parser.add_argument("--thrust-aero", choices=["on", "off"], default="off",
                        help="on: remove the vehicle file's airspeed terms of the rotor thrust (thrust_climb_coeff: "
                             "d sum_i Omega_i v_z, thrust_translational_coeff: c N v_h^2, body-frame mocap velocity) "
                             "from acc_z before the filter (docs/real-data.md). Default off")
    parser.add_argument("--thrust-aero-out", metavar="OUT.json",
                        help="fit those two coefficients by least squares on the given logs (m acc_z = kf sum "
                             "Omega^2 + terms + one intercept per log, flying rows) and write the vehicle file with "
                             "them; needs acc_*, vx..vz and qw..qz columns and the vehicle's mass")
    parser.add_argument("--thrust-aero-terms", default="climb,translational", metavar="TERMS",
                        help="with --thrust-aero-out: the terms to fit, a comma list of climb, translational "
                             "(default both)")
    parser.add_argument("--unit-inertia", action="store_true",
                        help="run with J = identity: estimates are kf/J and km/Jzz ratios (for vehicles without inertia)")
    parser.add_argument("--kf-nominal", type=float, help="prior mean of kf (overrides the vehicle file)")
    parser.add_argument("--km-nominal", type=float, help="prior mean of km (overrides the vehicle file)")
    parser.add_argument("--noise", choices=["auto", "nis", "default"], default="auto",
                        help="auto: gyro noise and unmodelled angular acceleration measured on the log; "
                             "nis: as auto, then the angular-acceleration noise scaled until the mean normalised "
                             "innovation squared is 1 (several replays); default: the library defaults (SITL)")
    parser.add_argument("--max-rotor-speed", type=float, metavar="RAD_S",
                        help="reject larger rotor speeds (default: 2x the 99.9th percentile of the log's speeds)")
    group = parser.add_argument_group("filter configuration overrides (propid_config_t fields)")
    for name, kind, text in OVERRIDES:
        group.add_argument(f"--{name.replace('_', '-')}", dest=f"cfg_{name}", type=kind, metavar="X", help=text)
    parser.add_argument("--reference-kf", type=float, help="independent kf to draw on the plot and compare with")
    parser.add_argument("--checks", action="store_true",
                        help="also run the independent least-squares checks (thrust from acc_z vs torque fits per band)")
    parser.add_argument("--band-table", metavar="OUT.md",
                        help="with --checks: per run and band (0.5-2, 2-5, 5-10, 10-20 Hz) the torque-derived kf "
                             "and km beside the accelerometer thrust kf (Markdown)")
    parser.add_argument("--band-plot", metavar="PNG",
                        help="with --checks and --reference-kf: torque and thrust kf per band, one line per run")
    parser.add_argument("--dpi", type=_dpi, default=80, help="resolution of --plot/--band-plot PNGs (default 80)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _word_or_number(text: str, words: tuple[str, ...], convert, in_range, expected: str, out_of_range: str):
    """argparse type: one of `words` as written, or a number (`convert`) that `in_range` accepts."""
    if text in words:
        return text
    try:
        value = convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}") from None
    if not in_range(value):
        raise argparse.ArgumentTypeError(out_of_range)
    return value


def _delay(text: str):
    return _word_or_number(text, ("auto",), float, lambda v: -1.0 <= v <= 1.0,
                           "seconds or 'auto'", "rotor delay must be within -1..1 s")


def _esc_delay(text: str):
    return _word_or_number(text, ("auto", "vehicle", "default"), float, lambda v: -1.0 <= v <= 1.0,
                           "seconds, 'auto' or 'vehicle'", "the ESC delay must be within -1..1 s")


def _prefilter(text: str):
    value = _word_or_number(text, ("auto", "off"), float, lambda v: v > 0,
                            "a cut-off in Hz, 'auto' or 'off'", "the pre-filter cut-off must be positive")
    return None if value == "off" else value


def _dpi(text: str) -> int:
    return _word_or_number(text, (), int, lambda v: 20 <= v <= 1200,
                           "a whole number of dots per inch", "dpi must be within 20..1200")


def _lag(text: str):
    if text == "auto":
        return text
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give auto or a lag in seconds") from None
    if not (math.isfinite(value) and 1.0e-4 <= value <= 1.0):
        raise argparse.ArgumentTypeError(f"{text!r}: the lag must be within 0.0001..1 s")
    return value


def _finite_json(value):
    """JSON has no NaN: write null instead."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite_json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_json(v) for v in value]
    return value


def check_arguments(args: argparse.Namespace, log_paths: list[Path]) -> None:
    """Every argument that can be judged without replaying, judged before any work."""
    several = len(log_paths) > 1
    if (args.band_table or args.band_plot) and not args.checks:
        raise UserError("--band-table/--band-plot need --checks")
    if args.band_plot and not args.reference_kf:
        raise UserError("--band-plot needs --reference-kf (the plot is relative to it)")
    if args.plot and several and not args.reference_kf:
        raise UserError("--plot with several logs needs --reference-kf (the plot is relative to it)")
    if (args.prefilter is not None or args.diagnostic_highpass is not None) and args.skip_repeats:
        raise UserError("--prefilter/--diagnostic-highpass cannot be combined with --skip-repeats")
    if (args.prefilter is not None or args.diagnostic_highpass is not None) and args.streams == "events":
        raise UserError("--prefilter/--diagnostic-highpass need a rows log, not --streams events")
    if args.reference_kf is not None and not args.reference_kf > 0:
        raise UserError("--reference-kf must be positive")
    outputs = (("--json", args.json), ("--plot", args.plot), ("--table", args.table),
               ("--vehicle-out", args.vehicle_out), ("--thrust-aero-out", args.thrust_aero_out),
               ("--band-table", args.band_table), ("--band-plot", args.band_plot))
    for option, value in outputs:
        if value and value != "-":
            check_writable(value, option)
    check_not_inputs(outputs, [*log_paths, Path(args.vehicle) if args.vehicle else vehicle_path_for(log_paths[0])])
    for option in ("plot", "band_plot"):
        value = getattr(args, option)
        if value and not value.lower().endswith(".png"):
            raise UserError(f"--{option.replace('_', '-')} {value}: the plot is written as PNG (use .png)")
    for path in log_paths:
        if not path.is_file():
            raise UserError(f"cannot read {path}: " + ("a directory" if path.is_dir() else "no such file"))


def rotor_table(summary: dict) -> str:
    """Per-rotor kf and km: kf_mean/km_mean +- the final 1-sigma, and flags."""
    unit_inertia = summary.get("mode") == "unit_inertia"
    kf_unit = "kf/J" if unit_inertia else "kf [N/(rad/s)^2]"
    km_unit = "km/Jzz" if unit_inertia else "km [N m/(rad/s)^2]"
    flagged = "*" if summary.get("warnings") else ""
    lines = [f"  {'rotor':<6}{kf_unit:>28}{km_unit:>30}   converged kf/km{flagged}"]
    for k in range(len(summary["kf"])):
        conv = "/".join("yes" if summary["converged"][c][k] else "no" for c in ("kf", "km"))
        lines.append(f"  {k + 1:<6}{summary['kf_mean'][k]:>17.4g} +- {summary['kf_std'][k]:<8.2g}"
                     f"{summary['km_mean'][k]:>19.4g} +- {summary['km_std'][k]:<8.2g}   {conv}")
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    lines.append(f"  {'mean':<6}{mean(summary['kf_mean']):>17.4g}{'':12}{mean(summary['km_mean']):>19.4g}")
    return "\n".join(lines)


def report(summary: dict, out) -> None:
    name = Path(summary["log"]).name if summary["log"] else "log"
    print(f"{name}: {summary['duration_s']:.1f} s, {summary['rows_replayed']} rows ({summary['segment']}), "
          f"gyro {summary['gyro_rate_hz']:.0f} Hz, rotor speeds {summary['rotor_rate_hz']:.0f} Hz, "
          f"ESC delay {round(1e3 * summary['esc_delay_s'])} ms", file=out)  # an int: never "-0 ms"
    what = {"inverse-variance": "every estimate weighted by 1/std^2",
            "smoothed": "time mean of the estimate smoothed under the coefficient walk"}
    print("  kf, km: " + what.get(summary.get("mean_estimator"), "mean over the converged part")
          + " +- final 1 sigma", file=out)
    print(rotor_table(summary), file=out)
    combination = summary.get("km_combination_std")
    if combination:  # what the flight's yaw excitation determined (docs/real-data.md "km: what the information allows")
        # Roll and pitch measure rotor differences: the diagonals of a quad X, opposite rotors of a plus, a mix on
        # a hexa or octo; so named by their channel, not their shape.
        print(f"  km combinations, final relative std: mean km (yaw channel) {100 * combination['yaw']:.1f} %, "
              f"CW/CCW balance (collective) {100 * combination['collective']:.1f} %, rotor differences (roll, "
              f"pitch channels) {100 * combination['roll']:.1f} %, {100 * combination['pitch']:.1f} %", file=out)
    if summary["rejected"]:
        rejected = ", ".join(f"{count} {name.removeprefix('PROPID_ERR_')}" for name, count in summary["rejected"].items())
        print(f"  rejected samples: {rejected}", file=out)
    for warning in summary.get("warnings", []):
        print(f"  * warning: {warning}", file=out)


def run(args: argparse.Namespace) -> int:
    from propid.plotting import plot_fleet, plot_replay
    from propid.replay import ReplayOptions, fleet_summary, replay, validation_table

    log_paths = [Path(p) for p in args.log]
    check_arguments(args, log_paths)
    vehicle_path = Path(args.vehicle) if args.vehicle else vehicle_path_for(log_paths[0])
    if not args.vehicle and not vehicle_path.is_file():
        raise UserError(f"no --vehicle given and no {vehicle_path.name} beside the log"
                        f"{other_vehicle_files(log_paths[0])}")
    vehicle = read_vehicle(vehicle_path)
    logs = [read_flightlog(path, vehicle) for path in log_paths]  # every file checked before any replay
    overrides = {
        name: getattr(args, f"cfg_{name}") for name, _, _ in OVERRIDES if getattr(args, f"cfg_{name}") is not None
    }
    thrust_coeff_walk = overrides.pop("thrust_coeff_rel_walk") if overrides.get("thrust_coeff_rel_walk") == "auto" else None
    options = ReplayOptions(
        segment=args.segment,
        start=args.start,
        streams=args.streams,
        unit_inertia=args.unit_inertia,
        kf_nominal=args.kf_nominal,
        km_nominal=args.km_nominal,
        noise=args.noise,
        max_rotor_speed=args.max_rotor_speed,
        overrides=overrides,
        skip_repeats=args.skip_repeats,
        mean_window=args.mean_window,
        mean_estimator=args.mean_estimator,
        esc_delay=None if args.rotor_delay is not None else args.esc_delay,
        rotor_delay_s=args.rotor_delay if args.rotor_delay is not None else 0.0,
        prefilter_hz=args.prefilter,
        diagnostic_highpass_hz=args.diagnostic_highpass,
        aiding=args.aiding,
        disturbance=args.disturbance,
        disturbance_bandwidth=args.disturbance_bandwidth,
        instrument=args.instrument,
        command_lag=args.command_lag,
        command_memory=args.command_memory,
        command_min_f=args.command_min_f,
        rotor_inertia=args.rotor_inertia,
        aero_damping=args.aero_damping,
        gyro_scale=args.gyro_scale,
        thrust_aero=args.thrust_aero,
        torque_scale=args.torque_scale,
        torque_scale_walk=args.torque_scale_walk,
        thrust_coeff_walk=thrust_coeff_walk,
        rotor_speed_noise=args.rotor_speed_noise,
        rotor_speed_noise_time=args.rotor_speed_noise_time,
        rotor_timing_error=args.rotor_timing_error,
        input_error_compensation=args.input_error_compensation == "on",
        progress=not args.no_progress and len(log_paths) == 1,
    )
    if args.vehicle_out:
        from propid.replay.calibration import check_calibration_inputs

        check_calibration_inputs(vehicle, logs, options)
    text_out = sys.stderr if args.json == "-" else sys.stdout
    if args.thrust_aero_out:
        from dataclasses import replace as with_fields

        from propid.flightlog import write_vehicle
        from propid.replay.thrust_aero import VEHICLE_KEYS, fit_thrust_aero

        terms = tuple(t for t in args.thrust_aero_terms.split(",") if t)
        fit = fit_thrust_aero(logs, vehicle, terms)
        vehicle_fitted = with_fields(vehicle, **{VEHICLE_KEYS[t]: c for t, c in fit["coefficients"].items()})
        write_vehicle(args.thrust_aero_out, vehicle_fitted)
        print(f"thrust terms over {fit['logs']} logs ({fit['rows']} flying rows): "
              + ", ".join(f"{VEHICLE_KEYS[t]} {c:.4g}" for t, c in fit["coefficients"].items())
              + f" (kf {fit['kf']:.4g}); wrote {args.thrust_aero_out}", file=text_out)
    runs = logs
    if len(logs) > 1 and not args.no_progress:
        from tqdm import tqdm

        runs = tqdm(logs, desc="replay", unit="log")
    results, summaries = [], []
    for log in runs:
        result = replay(log, vehicle, options)
        summary = result.summary
        if args.reference_kf:
            summary["reference_kf"] = args.reference_kf
            summary["kf_mean_over_reference"] = sum(summary["kf_mean"]) / len(summary["kf_mean"]) / args.reference_kf
        if args.checks:
            from propid.realdata_checks import check_log, format_checks

            summary["checks"] = check_log(log, vehicle, unit_inertia=args.unit_inertia)
            if len(logs) == 1:
                print(format_checks(summary["checks"]), file=text_out)
        results.append(result)
        summaries.append(summary)
    for summary in summaries:
        report(summary, text_out)
    if len(summaries) == 1:
        output = summaries[0]
    else:
        fleet = fleet_summary(summaries, args.reference_kf)
        output = {"fleet": fleet, "runs": summaries}
        text = f"fleet of {fleet['runs']}: kf mean {fleet['kf_fleet_mean']:.4g} (run-to-run CV {fleet['kf_run_cv']:.1%})"
        if args.reference_kf:
            text += f" = {fleet['kf_fleet_over_reference']:.3f} x reference {args.reference_kf:.4g}"
        print(text + f"; km mean {fleet['km_fleet_mean']:.4g} (CV {fleet['km_run_cv']:.1%})", file=text_out)
    if args.vehicle_out:
        from propid.flightlog import write_vehicle
        from propid.replay.calibration import accelerometer_options, torque_gain_correction

        accel = [replay(log, vehicle, accelerometer_options(options)).summary for log in logs]
        corrected, info = torque_gain_correction(vehicle, summaries, accel)
        write_vehicle(args.vehicle_out, corrected)
        output = dict(output, calibration=info)
        print(f"calibration: gyro-only fleet kf {info['kf_gyro_only']:.4g}, with the accelerometer "
              f"{info['kf_with_accelerometer']:.4g}: Jxx, Jyy x {info['torque_gain']:.4g}; wrote {args.vehicle_out}",
              file=text_out)
    if args.table:
        write_text(args.table, validation_table(summaries, args.reference_kf) + "\n")
        print(f"wrote {args.table}", file=text_out)
    if args.json:
        text = json.dumps(_finite_json(output), indent=2)
        if args.json == "-":
            print(text)
        else:
            write_text(args.json, text + "\n")
            print(f"wrote {args.json}", file=text_out)
    if args.band_table or args.band_plot:
        from propid.realdata_checks import band_evidence_table, plot_band_evidence

        names = [Path(s["log"]).stem if s.get("log") else "log" for s in summaries]
        checks = [s["checks"] for s in summaries]
        if args.band_table:
            write_text(args.band_table, band_evidence_table(checks, names, args.reference_kf) + "\n")
            print(f"wrote {args.band_table}", file=text_out)
        if args.band_plot:
            plot_band_evidence(checks, names, args.band_plot, args.reference_kf, dpi=args.dpi)
            print(f"wrote {args.band_plot}", file=text_out)
    if args.plot:
        if len(results) == 1:
            plot_replay(results[0], args.plot, title=_plot_title(log_paths[0], vehicle, args), dpi=args.dpi,
                        reference_kf=args.reference_kf)
        else:
            plot_fleet(summaries, args.plot, args.reference_kf, dpi=args.dpi)
        print(f"wrote {args.plot}", file=text_out)
    return 0


def _plot_title(log_path: Path, vehicle, args: argparse.Namespace) -> str:
    parts = [log_path.name, f"vehicle {vehicle.name or (vehicle.path.name if vehicle.path else '?')}"]
    parts.append(f"segment {args.segment}")
    if args.prefilter is not None:
        parts.append(f"pre-filter {args.prefilter}")
    return ", ".join(parts)
