"""The corrected vehicle file calibrated for the filter that will use it (`propid gap --vehicle-out`,
docs/gap.md "Corrected vehicle").

gap's carried effects come from its own fits (least squares, the instrument above the loop's band).
A torque scale measured that way does not transfer to the gyro-only filter, whose reading depends on
its memory and on the model terms it runs with (docs/real-data.md "Why the larger J moves kf so
little"): the correction must be measured with the estimator that uses it. So, after the fits:

- the fit logs with accelerometer columns, of a vehicle with a mass and an inertia, are replayed
  through the firmware filter with gap's corrected file in the chain the file is meant for
  (`chain_options`: gyro only, `--segment flying`, the file's rotor_inertia, aero_damping and
  gyro_scale as `propid replay` takes them, the disturbance states at its loop_bandwidth_hz, the
  per-log delay rule unless the file keeps an esc_delay_s, the walk rule, `--skip-repeats`), and
  again with the accelerometer (replay/calibration.accelerometer_options of the same options: the
  same model terms, so the two replays differ only in the aiding);
- replay/calibration.torque_gain_correction turns the two into c = accelerometer fleet kf /
  gyro-only fleet kf, applied on top of gap's effects (Jxx, Jyy x c, kf_nominal's mean = the
  accelerometer fleet kf).

The fit logs' own accelerometer kf is the reference; the hold-out logs are never used. c is applied only
where it is measured (the guard, docs/gap.md "Only a measured gain"): at a nearly constant collective
thrust (a hover, a level circle) the accelerometer cannot tell kf from its own bias, and without torque
excitation the gyro-only side is not known either. The guard (`guard="torque-gain"`, the default) reads
the filter's own covariance on both replays of every log:
- per replay the relative std of the ROTOR MEAN of kf (the fleet kf is a rotor mean; the accelerometer pins
  the rotors' sum, and how they differ is seen by the gyro alone and does not enter c), its median over the
  second half of the log's samples (not its last sample); per log sqrt(accelerometer^2 + gyro only^2);
  over logs sqrt(sum of squares) / n;
- with 3 or more logs also the logs' agreement: the std of their references / sqrt(n) / their mean, which
  sees a set the filter is sure of but that disagrees (a payload, another vehicle);
the larger must be at most 5 %, so that c's 95 % interval lies inside the 10 % the file is meant to
deliver. `rotor-mean` is the same without the gyro-only side; `final` the guard before (per log the mean
over rotors of kf's final relative std with the accelerometer, an upper bound on the rotor mean's that is
loose by the inverse of the thrust-torque scale state; pooled the same way). Without an accelerometer, a
mass or an inertia, or when the guard refuses, the file is gap's corrected file as before, and
`calibration` says why.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.gap.filtercheck import chain_options
from propid.replay.calibration import accelerometer_options, torque_gain_correction

REFERENCE_MAX_REL_STD = 0.05  # the reference's 95 % interval (1.96 std) inside the 10 % target


class UnpinnedReference(UserError):
    """The accelerometer-aided kf is not known well enough to calibrate with; `details` says how well."""

    def __init__(self, message: str, details: dict):
        super().__init__(message)
        self.details = details


GUARDS = ("torque-gain", "rotor-mean", "final")
DEFAULT_GUARD = "torque-gain"
MIN_LOGS_FOR_SPREAD = 3  # the logs' spread as a std needs a few of them


def reference_rel_std(accel_summaries: list[dict]) -> float:
    """The guard before (`final`): per log the mean over rotors of kf's final relative std, pooled over logs as
    sqrt(sum of squares) / n."""
    per_log = []
    for s in accel_summaries:
        std, mean = np.asarray(s["kf_std"], dtype=float), np.asarray(s["kf_mean"], dtype=float)
        per_log.append(float(np.mean(std / mean)) if np.all(mean > 0) else float("inf"))
    value = float(np.sqrt(np.sum(np.square(per_log))) / len(per_log))
    return value if np.isfinite(value) else float("inf")


def claimed_rotor_mean_rel_std(series: np.ndarray) -> float:
    """One log's claim: the median, over the second half of the recorded samples, of the rotor mean kf's relative
    std (NaN where not recorded)."""
    values = np.asarray(series, dtype=float)
    later = values[values.size // 2:]
    later = later[~np.isnan(later)]
    if not later.size:
        return float("inf")
    value = float(np.median(later))
    return value if np.isfinite(value) else float("inf")


def reference_guard(per_log_claimed: list[float], per_log_reference: list[float]) -> dict:
    """A guard's figures (module text) from per-log claimed relative stds and the logs' references: the claim
    pooled over logs, the logs' spread (None with fewer than MIN_LOGS_FOR_SPREAD logs) and the larger of the two."""
    claimed = np.asarray(per_log_claimed, dtype=float)
    refs = np.asarray(per_log_reference, dtype=float)
    pooled = float(np.sqrt(np.sum(np.square(claimed))) / claimed.size)
    pooled = pooled if np.isfinite(pooled) else float("inf")
    spread = None
    if refs.size >= MIN_LOGS_FOR_SPREAD:
        mean = float(np.mean(refs))
        spread = float(np.std(refs, ddof=1) / np.sqrt(refs.size) / mean) if mean > 0 else float("inf")
        spread = spread if np.isfinite(spread) else float("inf")
    return {"claimed": pooled, "spread": spread, "reference_rel_std": max(pooled, spread or 0.0),
            "per_log_claimed": [float(v) for v in claimed]}


RULE = ("c = fleet kf with the accelerometer / fleet kf gyro only, both replays of the fit logs with gap's corrected "
        "file in the chain below; Jxx, Jyy x c on top of gap's effects, kf_nominal's mean = the accelerometer fleet kf")


def chain_command(vehicle: Vehicle, walk: bool = True) -> str:
    """The `propid replay` options of the chain (the CLI's defaults cover rotor inertia, gyro scale, delay)."""
    disturbance = " --disturbance on" if vehicle.loop_bandwidth_hz is not None else ""
    return ("--segment flying --aiding gyro --aero-damping auto" + disturbance
            + (" --thrust-coeff-rel-walk auto" if walk else "") + " --skip-repeats")


def _options_record(options) -> dict:
    keep = ("segment", "aiding", "esc_delay", "rotor_inertia", "aero_damping", "gyro_scale", "torque_scale",
            "disturbance", "thrust_coeff_walk", "skip_repeats", "torque_scale_walk")
    return {k: getattr(options, k) for k in keep}


def _has_accelerometer(log: FlightLog) -> bool:
    return log.acc is not None and bool(np.isfinite(log.acc).any())


def unavailable(vehicle: Vehicle, logs: list[FlightLog]) -> str | None:
    """Why the calibration cannot run on these logs and this vehicle, or None."""
    if vehicle.mass is None:
        return "the vehicle file has no mass (the accelerometer measures thrust / mass)"
    if vehicle.inertia is None:
        return "the vehicle file has no inertia (nothing to scale)"
    if not any(_has_accelerometer(log) for log in logs):
        return "no fit log has accelerometer columns (acc_x..acc_z)"
    return None


ROTOR_MEAN_STD_EVERY = 5  # the rotor mean's std on every 5th sample of the accelerometer replay


def _claimed_replay(log: FlightLog, vehicle: Vehicle, options) -> tuple[dict, float]:
    """A calibration replay's summary and the log's claimed rotor-mean std (filtercheck.replay_summary's
    fallback to every row when no row is flying)."""
    from propid.replay import replay

    try:
        result = replay(log, vehicle, options)
    except UserError:
        if options.segment != "flying":
            raise
        result = replay(log, vehicle, replace(options, segment="all"))
    return result.summary, claimed_rotor_mean_rel_std(result.series["kf_rotor_mean_rel_std"])


def calibrate(logs: list[FlightLog], vehicle: Vehicle, corrected: Vehicle, progress=None,
              guard: str = DEFAULT_GUARD) -> tuple[Vehicle, dict]:
    """gap's corrected file calibrated with the filter on the fit logs: (the file, what was done).
    Raises UserError when it cannot be done; the caller decides whether that falls back."""
    if guard not in GUARDS:
        raise UserError(f"gap calibration guard {guard!r}: one of {', '.join(GUARDS)}")
    why = unavailable(vehicle, logs)
    if why:
        raise UserError(f"gap calibration: {why}")
    gyro_options = chain_options(corrected, skip_repeats=True, walk=True)
    accel_options = replace(accelerometer_options(gyro_options), rotor_mean_std_every=ROTOR_MEAN_STD_EVERY)
    gyro_options = replace(gyro_options, rotor_mean_std_every=ROTOR_MEAN_STD_EVERY)
    used, skipped, gyro, accel, claimed, gyro_claimed = [], [], [], [], [], []
    for log in logs:
        name = log.path.name if log.path else "log"
        if not _has_accelerometer(log):
            skipped.append({"log": name, "why": "no accelerometer columns"})
        else:
            try:
                g, g_claimed = _claimed_replay(log, corrected, gyro_options)
                a, a_claimed = _claimed_replay(log, corrected, accel_options)
            except UserError as exc:
                skipped.append({"log": name, "why": str(exc)})
            else:
                used.append(name)
                gyro.append(g)
                accel.append(a)
                claimed.append(a_claimed)
                gyro_claimed.append(g_claimed)
        if progress:
            progress()
    if not used:
        raise UserError("gap calibration: no fit log could be replayed with the accelerometer: "
                        + "; ".join(f"{s['log']}: {s['why']}" for s in skipped))
    per_log_reference = [float(np.mean(s["kf_mean"])) for s in accel]
    figures = reference_guard(claimed, per_log_reference)
    per_log_gain = [float(np.hypot(a, g)) for a, g in zip(claimed, gyro_claimed)]
    gain_figures = reference_guard(per_log_gain, per_log_reference)
    final_bound = reference_rel_std(accel)
    chosen = {"torque-gain": gain_figures, "rotor-mean": figures}.get(guard)
    sigma = chosen["reference_rel_std"] if chosen else final_bound
    guard_record = {"guard": guard, "reference_rel_std_final_bound": final_bound,
                    "reference_rel_std_claimed": figures["claimed"], "reference_rel_std_spread": figures["spread"],
                    "torque_gain_rel_std_claimed": gain_figures["claimed"],
                    "per_log_rotor_mean_rel_std": figures["per_log_claimed"],
                    "per_log_gyro_only_rotor_mean_rel_std": [float(v) for v in gyro_claimed]}
    if sigma > REFERENCE_MAX_REL_STD:
        kf_gyro = float(np.mean([np.mean(s["kf_mean"]) for s in gyro]))
        kf_accel = float(np.mean(per_log_reference))
        spread_decides = chosen is not None and (chosen["spread"] or 0.0) > chosen["claimed"]
        gyro_decides = guard == "torque-gain" and figures["reference_rel_std"] <= REFERENCE_MAX_REL_STD
        why = ("the fit logs' accelerometer references disagree (their fleet kf's relative std from their spread "
               f"{100 * sigma:.1f} % > {100 * REFERENCE_MAX_REL_STD:.0f} %: a payload, another vehicle or unlike flights)"
               if spread_decides else
               f"the gyro-only replays did not pin kf on the fit logs (the torque gain c's relative std {100 * sigma:.1f} % "
               f"> {100 * REFERENCE_MAX_REL_STD:.0f} %: too little torque excitation to measure what the file corrects)"
               if gyro_decides else
               f"the accelerometer did not pin kf on the fit logs (its fleet kf's relative std "
               f"{100 * sigma:.1f} % > {100 * REFERENCE_MAX_REL_STD:.0f} %: too little change of the collective thrust "
               f"to tell kf from the accelerometer bias)")
        raise UnpinnedReference(
            f"gap calibration: {why}",
            {"reference_rel_std": sigma, "reference_max_rel_std": REFERENCE_MAX_REL_STD, "logs": used,
             "kf_gyro_only": kf_gyro, "kf_with_accelerometer": kf_accel, "torque_gain_not_applied": kf_accel / kf_gyro,
             "per_log_kf_with_accelerometer": per_log_reference, **guard_record})
    calibrated, found = torque_gain_correction(corrected, gyro, accel)
    calibrated.notes = ((corrected.notes or "") + f" Calibrated by propid gap with the filter on {len(used)} fit "
                        f"log(s): Jxx, Jyy x {found['torque_gain']:.4g} on top of the effects above, kf_nominal mean "
                        f"{found['kf_with_accelerometer']:.4g}; replay with: {chain_command(calibrated)}.").strip()
    info = {
        "calibrated": True,
        "logs": used,
        "skipped": skipped,
        "torque_gain": found["torque_gain"],
        "kf_gyro_only": found["kf_gyro_only"],
        "kf_with_accelerometer": found["kf_with_accelerometer"],
        "reference_rel_std": sigma,
        "reference_max_rel_std": REFERENCE_MAX_REL_STD,
        **guard_record,
        "per_log_kf_gyro_only": [float(np.mean(s["kf_mean"])) for s in gyro],
        "per_log_kf_with_accelerometer": [float(np.mean(s["kf_mean"])) for s in accel],
        "inertia_before": [float(v) for v in np.diag(np.asarray(corrected.inertia, dtype=float))],
        "inertia": found["inertia"],
        "kf_nominal": found["kf_nominal"],
        "calibration_replay": {"gyro_only": _options_record(gyro_options),
                               "with_accelerometer": _options_record(accel_options)},
        "replay_options": dict(_options_record(gyro_options), command=chain_command(calibrated)),
        "rule": RULE + f"; only when the accelerometer-aided fleet kf's relative std is at most "
                       f"{100 * REFERENCE_MAX_REL_STD:.0f} % (guard {guard})",
    }
    return calibrated, info


def not_calibrated(why: str, vehicle: Vehicle | None = None) -> dict:
    """What `calibration` says when the file is gap's corrected file as before; the replay options are
    those of gap's firmware check (no walk rule), with which such a file was evaluated."""
    out = {"calibrated": False, "why": why}
    if vehicle is not None:
        out["replay_options"] = {"command": chain_command(vehicle, walk=False),
                                 "note": "not calibrated with the filter: the torque scale is gap's fits'"}
    return out


def calibrate_or_fall_back(mode: str, logs: list[FlightLog], vehicle: Vehicle, corrected: Vehicle,
                           progress=None, guard: str = DEFAULT_GUARD) -> tuple[Vehicle, dict]:
    """mode: auto (calibrate when possible, else gap's file and why), on (must calibrate), off."""
    if mode == "off":
        return corrected, not_calibrated("--calibration off", corrected)
    try:
        return calibrate(logs, vehicle, corrected, progress, guard)
    except UserError as exc:
        if mode == "on":
            raise
        out = not_calibrated(str(exc).removeprefix("gap calibration: "), corrected)
        return corrected, dict(out, **getattr(exc, "details", {}))


def base_fit_with_calibrated_inertia(base_fit_after: dict, gain: float, file_over_fit: dict | None = None) -> dict:
    """gap's after-fit read with the calibrated Jxx, Jyy: the roll/pitch torque kf is linear in the axis
    inertia, so it is the after-fit's times the calibrated inertia over the inertia the after-fit used:
    c times `file_over_fit` (per axis, the written file's torque scale over the after-fit's: the file
    carries the least-squares scale, the after-fit the instrument's; 1 when they are the same); thrust and
    yaw unchanged. Shown beside the after-fit: the filter's torque scale and the fits' are different
    estimators' and need not agree."""
    file_over_fit = file_over_fit or {}
    out = {}
    for key, entry in base_fit_after.items():
        if key in ("kf_roll", "kf_pitch") and isinstance(entry, dict) and entry.get("value") is not None:
            g = gain * file_over_fit.get(key, 1.0)
            out[key] = {"value": entry["value"] * g, "ci": [v * g if v is not None else None for v in entry.get("ci") or []]}
        else:
            out[key] = entry
    return out
