"""`propid real-data`: the docs/real-data.md table of the filter's optional terms on a
directory of real logs of one vehicle (the 17 Crazyflie 2.1 Brushless runs), with one command.

Rules, fixed before this command was first run and not chosen by agreement with any
reference value (the reference kf only divides the results for display):
- every log replayed through the C filter with `propid replay`'s defaults: flying segment,
  noise measured on the log (--noise auto), the telemetry delay the filter holds from the
  vehicle file's esc_delay_s, else the per-log rule (--esc-delay default);
- modes (the optional terms, docs/math.md §7-9): gyro only; + rotor inertia; + disturbance
  torque; + accelerometer (torque scale off); + accelerometer with the thrust-torque scale;
  all combined. Every other setting is the library default. Added later: + accelerometer with the
  scale as a random walk whose rate the per-log rule of replay/scale_walk.py measures (that rule was
  written before it was run, but after a sweep of fixed walks on these logs: docs/real-data.md).
  Added later, each rule fixed on the simulator before its first run here: gyro only, and the scale-walk
  mode, each with the rotor-speed error of replay/input_noise.py's per-log rule and the
  errors-in-variables compensation of the coefficient update (docs/math.md §14);
- added later (docs/real-data.md "Gyro only with a calibrated vehicle file"; the rules were written before their
  first run here, but after the walk sweep of that page): gyro only with the coefficient walk by the per-log
  torque-gain rule (--thrust-coeff-rel-walk auto); and the same with the vehicle file calibrated by
  replay/calibration.py (--vehicle-out) on the OTHER half of the runs: logs in sorted order, odd positions
  (1, 3, ..) calibrate the even ones and vice versa, so every run of that mode is held out;
- added later (docs/real-data.md "The controller's cancellation"; the rule was written before their first run
  here, after the instrumented band fits of these logs): the disturbance states with a bandwidth
  (DISTURBANCE_BANDWIDTH_HZ below, docs/math.md §7) beside gyro only, the scale-walk mode and the gyro-only walk
  chain (calibrated as above);
- added later (docs/real-data.md "Repeated rows"; the rule was written before the calibrated and accelerometer
  modes were run, after the uncalibrated gyro-only mode had been seen): the scale-walk mode and the gyro-only walk
  chain (calibrated as above) with exact repeats of the previous row skipped (`--skip-repeats`);
- added later (docs/real-data.md "The square runs' offset with the accelerometer"; the rule was written before their
  first run here, after the same correction had been emulated outside the repository): the scale-walk mode with the
  climb term of the rotor thrust removed from the accelerometer's z (replay/thrust_aero.py), its coefficient fitted
  on the OTHER half of the runs (odd/even as above); and, as a diagnostic only, the same with the translational term
  too, which failed the physical selection written before (its per-run sign changes with the trajectory);
- added later (docs/real-data.md "The combined chain"; rule D was written before their first run, after the skip and
  climb modes had been seen): the scale-walk mode with the repeated rows skipped AND the climb term fitted on the other
  half; beside it, diagnostics only: the climb fitted on each run itself, and the same chain + the rotor inertia;
- "square" runs are the logs whose name starts with "square", the others are the rest;
- per run: kf = mean over rotors of the converged-part mean; rotor spread = the worst
  rotor's |kf_i / run mean - 1|; km converged = the filter's own claim at the end for all rotors (3 x the relative
  std below converged_rel_std, 5 %, and the consistency monitor vouching: docs/reliability.md "Converged claims");
  beside it the final relative std of the worst rotor's km and of the mean km (the yaw channel's combination,
  km_evidence.py), whose median over runs says how far from a claim the runs are.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass
from pathlib import Path

from propid.errors import UserError
from propid.outputs import write_text

# The disturbance states' bandwidth of the band modes [Hz], fixed before their first run here: the lower edge of
# the band where the instrumented torque fits of these logs agree between runs (a run-to-run criterion, not the
# reference; docs/real-data.md "The controller's cancellation"). A vehicle's own attitude-loop bandwidth belongs here.
DISTURBANCE_BANDWIDTH_HZ = 5.0
# (name, what it is, ReplayOptions fields)
MODES = [
    ("gyro", "gyro only", dict(aiding="gyro", rotor_inertia="off", disturbance="off", torque_scale="off")),
    ("rotor_inertia", "+ rotor inertia", dict(aiding="gyro", rotor_inertia="on", disturbance="off", torque_scale="off")),
    ("disturbance", "+ disturbance torque", dict(aiding="gyro", rotor_inertia="off", disturbance="on", torque_scale="off")),
    ("accel", "+ accelerometer, torque scale off", dict(aiding="gyro+accel", rotor_inertia="off", disturbance="off",
                                                        torque_scale="off")),
    ("accel_scale", "+ accelerometer with the torque scale", dict(aiding="gyro+accel", rotor_inertia="off",
                                                                  disturbance="off", torque_scale="on")),
    ("combined", "all: accelerometer + torque scale + disturbance + rotor inertia",
     dict(aiding="gyro+accel", rotor_inertia="on", disturbance="on", torque_scale="on")),
    ("accel_scale_walk", "+ accelerometer with the torque scale as a random walk (per-log rule)",
     dict(aiding="gyro+accel", rotor_inertia="off", disturbance="off", torque_scale="on",
          torque_scale_walk="auto")),
    ("gyro_input_error", "gyro only + rotor-speed error (per-log rule) with its errors-in-variables compensation",
     dict(aiding="gyro", rotor_inertia="off", disturbance="off", torque_scale="off", rotor_speed_noise="auto",
          input_error_compensation=True)),
    ("accel_scale_walk_input_error", "+ accelerometer, scale walk (rule) + rotor-speed error with its compensation",
     dict(aiding="gyro+accel", rotor_inertia="off", disturbance="off", torque_scale="on", torque_scale_walk="auto",
          rotor_speed_noise="auto", input_error_compensation=True)),
]


def _variant(base: str, name: str, what: str, **extra) -> tuple[str, str, dict]:
    """Mode `name`: the mode `base` above with the options in extra added."""
    options = next(options for mode, _, options in MODES if mode == base)
    return (name, what, {**options, **extra})


# The disturbance states with a bandwidth (above it the controller does not cancel).
BAND = dict(disturbance="on", disturbance_bandwidth=DISTURBANCE_BANDWIDTH_HZ)
MODES += [
    _variant("gyro", "gyro_band", "gyro only + disturbance states of 5 Hz bandwidth (above them the controller does "
             "not cancel)", **BAND),
    _variant("accel_scale_walk", "accel_scale_walk_band", "+ accelerometer, scale walk (rule) + disturbance states of "
             "5 Hz bandwidth", **BAND),
    ("gyro_walk", "gyro only, coefficient walk by the per-log torque-gain rule",
     dict(aiding="gyro", rotor_inertia="off", disturbance="off", torque_scale="off", thrust_coeff_walk="auto")),
    ("gyro_walk_calibrated", "the same, vehicle file calibrated with the accelerometer on the other half of the runs",
     dict(aiding="gyro", rotor_inertia="off", disturbance="off", torque_scale="off", thrust_coeff_walk="auto")),
]
MODES += [
    _variant("gyro_walk", "gyro_walk_band", "gyro only, coefficient walk (rule) + disturbance states of 5 Hz bandwidth",
             **BAND),
    _variant("gyro_walk_calibrated", "gyro_walk_band_calibrated", "the same with the 5 Hz disturbance states, vehicle "
             "file calibrated on the other half", **BAND),
]
# The motor commands as the rotor input's instrument (docs/math.md §16), beside the same mode without it.
MODES += [
    _variant("gyro", "gyro_instrument", "gyro only, rotor input from the motor commands' first stage (instrument)",
             instrument="commands"),
    _variant("gyro_band", "gyro_band_instrument", "gyro only + 5 Hz disturbance states + the commands' instrument",
             instrument="commands"),
    _variant("accel_scale_walk", "accel_scale_walk_instrument", "+ accelerometer, scale walk (rule) + the commands' "
             "instrument", instrument="commands"),
]
# The same with the first stage's weak-instrument guard (docs/math.md §16): F >= 10 (the usual rule of thumb for a
# first stage) and F >= 200 (the fitted slope's relative std 1/sqrt(2 F) within the 5 % per-rotor tolerance).
MODES += [
    _variant(base, f"{base}_instrument_f{min_f}", f"{what}, weak-instrument guard F >= {min_f}",
             instrument="commands", command_min_f=float(min_f))
    for base, what in (("gyro", "gyro only + the commands' instrument"),
                       ("accel_scale_walk", "+ accelerometer, scale walk (rule) + the commands' instrument"))
    for min_f in (10, 200)
]
# Exact repeats of the previous row are no new sample (--skip-repeats): a logger that samples separately streamed
# blocks by sample-and-hold writes a lost packet as a copy of the previous one (docs/real-data.md "Repeated rows").
SKIP = dict(skip_repeats=True)
MODES += [
    _variant("accel_scale_walk", "accel_scale_walk_skip", "+ accelerometer, scale walk (rule), repeated rows skipped",
             **SKIP),
    _variant("gyro_walk", "gyro_walk_skip", "gyro only, coefficient walk (rule), repeated rows skipped", **SKIP),
    _variant("gyro_walk", "gyro_walk_skip_calibrated", "the same, vehicle file calibrated with the accelerometer "
             "(repeated rows skipped) on the other half of the runs", **SKIP),
]
# The airspeed terms of the rotor thrust (replay/thrust_aero.py) removed from the accelerometer's z, their
# coefficients fitted on the OTHER half of the runs (odd/even as the calibrated modes): mode -> the terms fitted.
AERO = dict(thrust_aero="on")
MODES += [
    _variant("accel_scale_walk", "accel_scale_walk_climb", "+ accelerometer, scale walk (rule), climb term of the "
             "thrust (fitted on the other half of the runs)", **AERO),
    _variant("accel_scale_walk", "accel_scale_walk_climb_lift", "diagnostic: the same with the climb and the "
             "translational terms (the latter failed its selection)", **AERO),
]
# The two best accelerometer rules as one chain (scale walk, repeated rows skipped, the climb term fitted on the other
# half); beside it, diagnostics only: the climb fitted on each run itself, and the chain with the rotor inertia (more
# yaw information for km). Rules written before their first run: docs/real-data.md "The combined chain".
MODES += [
    _variant("accel_scale_walk_skip", "accel_scale_walk_skip_climb", "+ accelerometer, scale walk (rule), repeated rows "
             "skipped, climb term (fitted on the other half of the runs)", **AERO),
    _variant("accel_scale_walk_skip", "accel_scale_walk_skip_climb_own", "diagnostic: the same, climb term fitted on "
             "each run itself", **AERO),
    _variant("accel_scale_walk_skip", "accel_scale_walk_skip_climb_inertia", "diagnostic: the same as the chain above "
             "(climb fitted on the other half) + rotor inertia", **AERO, rotor_inertia="on"),
]
AERO_FITTED = {"accel_scale_walk_climb": ("climb",), "accel_scale_walk_climb_lift": ("climb", "translational"),
               "accel_scale_walk_skip_climb": ("climb",), "accel_scale_walk_skip_climb_own": ("climb",),
               "accel_scale_walk_skip_climb_inertia": ("climb",)}
# Of those, the modes whose terms are fitted on each run itself instead of on the other half.
AERO_OWN_RUN = {"accel_scale_walk_skip_climb_own"}
# A calibrated mode: (its gyro-only mode, the accelerometer mode), both replayed with the file as given.
CALIBRATED = {"gyro_walk_calibrated": ("gyro_walk", "accel_scale_walk"),
              "gyro_walk_band_calibrated": ("gyro_walk_band", "accel_scale_walk"),
              "gyro_walk_skip_calibrated": ("gyro_walk_skip", "accel_scale_walk_skip")}
ROTOR_WITHIN = 0.05
# The replay's means kept beside kf_mean in each run's summary (kf_mean_<name>; replay/averaging.py)
OTHER_MEANS = ("window", "inverse_variance", "smoothed")


@dataclass
class RealDataConfig:
    data_dir: Path
    vehicle: Path
    out_dir: Path
    reference_kf: float
    modes: tuple[str, ...] = tuple(mode[0] for mode in MODES)
    mean_window: str = "from-crossing"  # every replay's kf_mean window (replay/averaging.py)
    mean_estimator: str = "inverse-variance"  # what every replay's kf_mean reports (replay/averaging.py)


def _cv(values: list[float]) -> float:
    return statistics.stdev(values) / statistics.fmean(values) if len(values) > 1 else float("nan")


def run_summary(summary: dict, reference_kf: float) -> dict:
    kf = summary["kf_mean"]
    mean = statistics.fmean(kf)
    # Every estimator's figures from the same replay (replay/averaging.py), kf_mean being one of them, for comparison.
    others = {}
    for estimator in OTHER_MEANS:
        kf_other = summary[f"kf_mean_{estimator}"]
        mean_other = statistics.fmean(kf_other)
        others[f"kf_{estimator}_over_reference"] = mean_other / reference_kf
        others[f"rotor_spread_{estimator}"] = max(abs(k / mean_other - 1.0) for k in kf_other)
    return {
        "kf_over_reference": mean / reference_kf,
        "rotor_spread": max(abs(k / mean - 1.0) for k in kf),
        **others,
        "km": statistics.fmean(summary["km_mean"]),
        "km_converged": all(summary["converged"]["km"]),
        "km_converged_rotors": sum(summary["converged"]["km"]),
        "rotor_count": len(summary["converged"]["km"]),
        "km_worst_rotor_rel_std": max(s / k for s, k in zip(summary["km_std"],
                                                           summary["config"]["drag_coeff_nominal"])),
        "km_mean_rel_std": summary["km_combination_std"]["yaw"],
        # The claim's two parts apart: every rotor's 3 std below converged_rel_std, and the monitor's veto at the end.
        "km_std_within_claim": all(3.0 * s < summary["config"].get("converged_rel_std", 0.05) * k
                                   for s, k in zip(summary["km_std"], summary["config"]["drag_coeff_nominal"])),
        "model_mismatch": summary["model_mismatch"],
        "accel_bias": summary["accel_bias"],  # None: no accelerometer fused
        "torque_scale": summary["torque_scale"],
        "torque_scale_walk": summary["config"].get("torque_scale_walk", 0.0),
        "esc_delay_s": summary["esc_delay_s"],
        "finite": summary["finite"],
        "kf_rotors_over_reference": [k / reference_kf for k in kf],
        # If the rotors were equal: the chance that every one is within 5 % by the filter's own final covariance.
        "p_every_rotor_within_5pct": summary["kf_rotor_spread_bound"]["p_every_rotor_within"],
        "rotor_deviation_chi2": summary["kf_rotor_spread_bound"]["chi_squared"],
        # With the commands' instrument: the share of rotor inputs its weak-instrument guard left to the telemetry.
        "instrument_guarded_share": _guarded_share(summary, len(kf)),
    }


def _guarded_share(summary: dict, rotor_count: int) -> float | None:
    counters = summary.get("counters", {})
    samples = counters.get("rotor_accepted", 0) * rotor_count
    if not counters.get("command_accepted") or samples == 0:
        return None
    return counters.get("instrument_guarded", 0) / samples


def mode_summary(runs: dict[str, dict]) -> dict:
    names = sorted(runs)
    square = [runs[n]["kf_over_reference"] for n in names if n.startswith("square")]
    other = [runs[n]["kf_over_reference"] for n in names if not n.startswith("square")]
    kf = [runs[n]["kf_over_reference"] for n in names]
    km = [runs[n]["km"] for n in names]
    return {
        "runs": len(names),
        "kf_fleet_over_reference": statistics.fmean(kf), "kf_run_cv": _cv(kf),
        "square_runs": len(square), "square_kf": statistics.fmean(square) if square else float("nan"),
        "square_cv": _cv(square) if square else float("nan"),
        "other_runs": len(other), "other_kf": statistics.fmean(other) if other else float("nan"),
        "other_cv": _cv(other) if other else float("nan"),
        "worst_rotor_spread": max(runs[n]["rotor_spread"] for n in names),
        "runs_every_rotor_within_5pct": sum(runs[n]["rotor_spread"] <= ROTOR_WITHIN for n in names),
        **{f"{estimator}_mean": _estimator_figures([runs[n] for n in names], estimator) for estimator in OTHER_MEANS},
        "runs_every_rotor_within_5pct_if_equal": sum(runs[n]["p_every_rotor_within_5pct"] for n in names),
        "km_fleet": statistics.fmean(km), "km_cv": _cv(km),
        "runs_km_converged": sum(runs[n]["km_converged"] for n in names),
        "km_worst_rotor_rel_std_median": statistics.median(runs[n]["km_worst_rotor_rel_std"] for n in names),
        "km_mean_rel_std_median": statistics.median(runs[n]["km_mean_rel_std"] for n in names),
        "km_worst_rotor_rel_std_best_run": min(runs[n]["km_worst_rotor_rel_std"] for n in names),
        "runs_km_std_within_claim": sum(runs[n].get("km_std_within_claim", False) for n in names),
        "runs_model_mismatch": sum(runs[n].get("model_mismatch", False) for n in names),
        "accel_bias_median": _median_or_none([runs[n]["accel_bias"] for n in names]),
        "all_finite": all(runs[n]["finite"] for n in names),
    }


def _estimator_figures(runs: list[dict], estimator: str) -> dict | None:
    """The kf figures of the mode with every run's kf_mean_window, kf_mean_inverse_variance or kf_mean_smoothed
    (estimator: a key of OTHER_MEANS) in place of its kf_mean (None for runs summarised before that mean was kept
    beside it)."""
    if not all(f"kf_{estimator}_over_reference" in r for r in runs):
        return None
    kf = [r[f"kf_{estimator}_over_reference"] for r in runs]
    return {"kf_fleet_over_reference": statistics.fmean(kf), "kf_run_cv": _cv(kf),
            "worst_rotor_spread": max(r[f"rotor_spread_{estimator}"] for r in runs),
            "runs_every_rotor_within_5pct": sum(r[f"rotor_spread_{estimator}"] <= ROTOR_WITHIN for r in runs)}


def _median_or_none(values: list) -> float | None:
    """The median of the values that exist; None when none does (a gyro-only mode has no accelerometer bias)."""
    present = [v for v in values if v is not None]
    return statistics.median(present) if present else None


def halves(logs: list[Path]) -> tuple[list[Path], list[Path]]:
    """Sorted order, 1-based odd positions and even positions."""
    return logs[0::2], logs[1::2]


def _cross_calibrated(name: str, logs: list[Path], vehicle, raw: dict) -> tuple[dict, dict]:
    """Each half's runs get the vehicle file calibrated on the other half (replay/calibration.py):
    (the vehicle per (mode, log), what each calibration found)."""
    from propid.replay.calibration import torque_gain_correction

    gyro_mode, accel_mode = CALIBRATED[name]
    out, infos = {}, {}
    odd, even = halves(logs)
    for fit, held_out, label in ((odd, even, "odd"), (even, odd, "even")):
        if not fit or not held_out:
            raise UserError(f"{name}: needs at least two logs (one per half)")
        fixed, info = torque_gain_correction(vehicle, [raw[(gyro_mode, p)] for p in fit],
                                             [raw[(accel_mode, p)] for p in fit])
        infos[f"{name}: calibrated on the {label} positions"] = dict(info, logs=[p.name for p in fit])
        out.update({(name, p): fixed for p in held_out})
    return out, infos


def _cross_fitted_thrust(name: str, logs: list[Path], vehicle, loaded: dict) -> tuple[dict, dict]:
    """Each half's runs get the vehicle file with the thrust terms of AERO_FITTED[name] fitted on the other half
    (replay/thrust_aero.py), or on each run itself for a mode in AERO_OWN_RUN: (the vehicle per (mode, log), what
    each fit found)."""
    from dataclasses import replace

    from propid.replay.thrust_aero import VEHICLE_KEYS, fit_thrust_aero

    out, infos = {}, {}
    if name in AERO_OWN_RUN:
        pairs = [([p], [p], p.name) for p in logs]
    else:
        odd, even = halves(logs)
        pairs = [(odd, even, "the odd positions"), (even, odd, "the even positions")]
    for fit_on, held_out, label in pairs:
        if not fit_on or not held_out:
            raise UserError(f"{name}: needs at least two logs (one per half)")
        fit = fit_thrust_aero([loaded[p] for p in fit_on], vehicle, AERO_FITTED[name])
        fitted = replace(vehicle, **{VEHICLE_KEYS[t]: c for t, c in fit["coefficients"].items()})
        infos[f"{name}: thrust terms fitted on {label}"] = dict(fit, logs=[p.name for p in fit_on])
        out.update({(name, p): fitted for p in held_out})
    return out, infos


def run_real_data(config: RealDataConfig, progress: bool = True) -> dict:
    from propid.flightlog import read_flightlog, read_vehicle, run_name
    from propid.replay import ReplayOptions, replay

    logs = sorted(config.data_dir.glob("*.csv"))
    if not logs:
        raise UserError(f"no *.csv logs in {config.data_dir}")
    vehicle = read_vehicle(config.vehicle)
    wanted = set(config.modes)
    for name, needs in CALIBRATED.items():
        if name in wanted:
            wanted.update(needs)  # a calibrated mode is built from these two replays of every log
    modes = [mode for mode in MODES if mode[0] in wanted]
    calibrated = [mode for mode in modes if mode[0] in CALIBRATED]
    modes = [mode for mode in modes if mode[0] not in CALIBRATED]
    jobs = [(mode, path) for mode in modes + calibrated for path in logs]
    iterator = jobs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(jobs, desc="real-data", unit="replay")
    loaded: dict[Path, object] = {}
    per_mode: dict[str, dict] = {mode[0]: {} for mode in modes + calibrated}
    raw: dict[tuple[str, Path], dict] = {}
    corrected: dict[tuple[str, Path], object] = {}
    calibrations: dict[str, dict] = {}
    for (name, _, fields), path in iterator:
        if path not in loaded:
            loaded[path] = read_flightlog(path, vehicle)
        options = ReplayOptions(segment="flying", esc_delay="default", progress=False,
                                mean_window=config.mean_window, mean_estimator=config.mean_estimator, **fields)
        use = vehicle
        if name in AERO_FITTED:
            if (name, path) not in corrected:
                for other in logs:  # the fit reads every log
                    if other not in loaded:
                        loaded[other] = read_flightlog(other, vehicle)
                vehicles, infos = _cross_fitted_thrust(name, logs, vehicle, loaded)
                corrected.update(vehicles)
                calibrations.update(infos)
            use = corrected[(name, path)]
        if name in CALIBRATED:
            if (name, path) not in corrected:
                vehicles, infos = _cross_calibrated(name, logs, vehicle, raw)
                corrected.update(vehicles)
                calibrations.update(infos)
            use = corrected[(name, path)]
        summary = replay(loaded[path], use, options).summary
        raw[(name, path)] = summary
        per_mode[name][run_name(path)] = run_summary(summary, config.reference_kf)
    result = {
        "rules": __doc__.strip(),
        "data_dir": str(config.data_dir), "vehicle": str(config.vehicle), "reference_kf": config.reference_kf,
        "mean_window": config.mean_window,
        "mean_estimator": config.mean_estimator,
        "modes": [{"name": name, "what": what, "options": fields, "summary": mode_summary(per_mode[name]),
                   "runs": per_mode[name]} for name, what, fields in modes + calibrated],
        "calibrations": calibrations,
    }
    write_text(config.out_dir / "real_data.json", json.dumps(result, indent=2) + "\n")
    return result


def _percent(value: float) -> str:
    """A ratio as a whole percent; '-' where it is undefined (a CV of fewer than two runs)."""
    return f"{100 * value:.0f}%" if math.isfinite(value) else "-"


def _group(kf: float, cv: float) -> str:
    """A group's kf over the reference and its CV; '-' for a group without runs (no square runs)."""
    return f"{kf:.2f} ({_percent(cv)})" if math.isfinite(kf) else "-"


def _bias(value: float | None) -> str:
    """The accelerometer bias median; '-' for a mode that fused no accelerometer."""
    return "-" if value is None else f"{value:.2f}"


def render(result: dict) -> str:
    ref = result["reference_kf"]
    lines = [f"kf over the reference {ref:.3g} N/(rad/s)^2 (display only); {result['modes'][0]['summary']['runs']} runs",
             "",
             "| mode | fleet kf / ref | run CV | square runs (CV) | other runs (CV) | worst rotor vs its run mean "
             "| runs with every rotor within 5 % | km fleet (CV) | runs with all km converged | accel bias median [m/s^2] |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for mode in result["modes"]:
        s = mode["summary"]
        lines.append(
            f"| {mode['what']} | {s['kf_fleet_over_reference']:.3f} | {_percent(s['kf_run_cv'])} "
            f"| {_group(s['square_kf'], s['square_cv'])} | {_group(s['other_kf'], s['other_cv'])} "
            f"| {100 * s['worst_rotor_spread']:.0f}% | {s['runs_every_rotor_within_5pct']}/{s['runs']} "
            f"| {s['km_fleet']:.3g} ({_percent(s['km_cv'])}) | {s['runs_km_converged']}/{s['runs']} "
            f"| {_bias(s['accel_bias_median'])} |")
    estimator = result.get("mean_estimator", "window")
    for other in OTHER_MEANS:
        key = f"{other}_mean"
        if estimator.replace("-", "_") != other and all(m["summary"].get(key) for m in result["modes"]):
            lines += ["", f"kf_mean is the {estimator} mean; with each replay's {other} mean (kf_mean_{other}) "
                      "instead: fleet kf / ref, run CV, worst rotor, runs with every rotor within 5 %: " + "; ".join(
                          f"{m['name']} {w['kf_fleet_over_reference']:.3f}, {_percent(w['kf_run_cv'])}, "
                          f"{100 * w['worst_rotor_spread']:.0f}%, {w['runs_every_rotor_within_5pct']}/"
                          f"{m['summary']['runs']}" for m in result["modes"] for w in [m["summary"][key]])]
    lines += ["", "Runs with every rotor within 5 % expected if the rotors were equal, by the filter's own final "
              "covariance (replay/rotor_spread.py): " + "; ".join(
                  f"{m['name']} {m['summary']['runs_every_rotor_within_5pct_if_equal']:.1f}" for m in result["modes"])]
    lines += ["", "km relative std at the end, median over runs, worst rotor / the mean km, and the best run's worst "
              "rotor (a claim needs every rotor 3 x below 5 % and the monitor vouching); runs whose std alone passes, "
              "runs the monitor withdrew at the end (docs/real-data.md \"km: what the information allows\"): "
              + "; ".join(f"{m['name']} {100 * m['summary']['km_worst_rotor_rel_std_median']:.0f} / "
                          f"{100 * m['summary']['km_mean_rel_std_median']:.0f} % "
                          f"(best {100 * m['summary']['km_worst_rotor_rel_std_best_run']:.0f} %; "
                          f"{m['summary']['runs_km_std_within_claim']}, {m['summary']['runs_model_mismatch']})"
                          for m in result["modes"])]
    names = sorted(result["modes"][0]["runs"])
    walks = next((m["runs"] for m in result["modes"] if m["name"] == "accel_scale_walk"), None)
    lines += ["", "| run | ESC delay [ms] | " + ("scale walk (rule) [1/sqrt(s)] | " if walks else "")
              + " | ".join(f"{m['name']}: kf (rotor spread, km conv.)" for m in result["modes"]) + " |",
              "|---|---|" + ("---|" if walks else "") + "---|" * len(result["modes"])]
    for name in names:
        delay = result["modes"][0]["runs"][name]["esc_delay_s"]
        cells = []
        for mode in result["modes"]:
            r = mode["runs"][name]
            cells.append(f"{r['kf_over_reference']:.2f} ({100 * r['rotor_spread']:.0f}%, {r['km_converged_rotors']}/{r['rotor_count']})")
        walk = f"{walks[name]['torque_scale_walk']:.3f} | " if walks else ""
        lines.append(f"| {name} | {1e3 * delay + 0.0:.0f} | " + walk + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
