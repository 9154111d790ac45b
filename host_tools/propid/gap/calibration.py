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

The fit logs' own accelerometer kf is the reference; the hold-out logs are never used. It is a
reference only where the accelerometer pinned it: at a nearly constant collective thrust (a hover,
a level circle) the accelerometer cannot tell kf from its own bias, and the accelerometer-aided kf
follows the gyro or wanders (SITL: 1.48x the truth on a step flight, docs/gap.md). The guard uses the
filter's own claimed uncertainty: per log the mean over rotors of kf's final relative std (an upper
bound on the rotor mean's, the rotors' errors being correlated along the weakly seen scale), over
logs sqrt(sum of squares) / n; the calibration runs only if that is at most 5 %, so that the
reference's 95 % interval lies inside the 10 % the file is meant to deliver. Without an
accelerometer, a mass or an inertia, or with an unpinned reference, the file is gap's corrected
file as before, and `calibration` says why.
"""

from __future__ import annotations

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.gap.filtercheck import chain_options, replay_summary
from propid.replay.calibration import accelerometer_options, torque_gain_correction

REFERENCE_MAX_REL_STD = 0.05  # the reference's 95 % interval (1.96 std) inside the 10 % target


class UnpinnedReference(UserError):
    """The accelerometer-aided kf is not known well enough to calibrate with; `details` says how well."""

    def __init__(self, message: str, details: dict):
        super().__init__(message)
        self.details = details


def reference_rel_std(accel_summaries: list[dict]) -> float:
    """The accelerometer-aided fleet kf's relative std, from the filter's own final stds (module text)."""
    per_log = []
    for s in accel_summaries:
        std, mean = np.asarray(s["kf_std"], dtype=float), np.asarray(s["kf_mean"], dtype=float)
        per_log.append(float(np.mean(std / mean)) if np.all(mean > 0) else float("inf"))
    value = float(np.sqrt(np.sum(np.square(per_log))) / len(per_log))
    return value if np.isfinite(value) else float("inf")


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


def calibrate(logs: list[FlightLog], vehicle: Vehicle, corrected: Vehicle, progress=None) -> tuple[Vehicle, dict]:
    """gap's corrected file calibrated with the filter on the fit logs: (the file, what was done).
    Raises UserError when it cannot be done; the caller decides whether that falls back."""
    why = unavailable(vehicle, logs)
    if why:
        raise UserError(f"gap calibration: {why}")
    gyro_options = chain_options(corrected, skip_repeats=True, walk=True)
    accel_options = accelerometer_options(gyro_options)
    used, skipped, gyro, accel = [], [], [], []
    for log in logs:
        name = log.path.name if log.path else "log"
        if not _has_accelerometer(log):
            skipped.append({"log": name, "why": "no accelerometer columns"})
        else:
            try:
                g = replay_summary(log, corrected, gyro_options)
                a = replay_summary(log, corrected, accel_options)
            except UserError as exc:
                skipped.append({"log": name, "why": str(exc)})
            else:
                used.append(name)
                gyro.append(g)
                accel.append(a)
        if progress:
            progress()
    if not used:
        raise UserError("gap calibration: no fit log could be replayed with the accelerometer: "
                        + "; ".join(f"{s['log']}: {s['why']}" for s in skipped))
    sigma = reference_rel_std(accel)
    if sigma > REFERENCE_MAX_REL_STD:
        kf_gyro = float(np.mean([np.mean(s["kf_mean"]) for s in gyro]))
        kf_accel = float(np.mean([np.mean(s["kf_mean"]) for s in accel]))
        raise UnpinnedReference(
            f"gap calibration: the accelerometer did not pin kf on the fit logs (its fleet kf's relative std "
            f"{100 * sigma:.1f} % > {100 * REFERENCE_MAX_REL_STD:.0f} %: too little change of the collective thrust "
            f"to tell kf from the accelerometer bias)",
            {"reference_rel_std": sigma, "reference_max_rel_std": REFERENCE_MAX_REL_STD, "logs": used,
             "kf_gyro_only": kf_gyro, "kf_with_accelerometer": kf_accel, "torque_gain_not_applied": kf_accel / kf_gyro})
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
        "per_log_kf_gyro_only": [float(np.mean(s["kf_mean"])) for s in gyro],
        "per_log_kf_with_accelerometer": [float(np.mean(s["kf_mean"])) for s in accel],
        "inertia_before": [float(v) for v in np.diag(np.asarray(corrected.inertia, dtype=float))],
        "inertia": found["inertia"],
        "kf_nominal": found["kf_nominal"],
        "calibration_replay": {"gyro_only": _options_record(gyro_options),
                               "with_accelerometer": _options_record(accel_options)},
        "replay_options": dict(_options_record(gyro_options), command=chain_command(calibrated)),
        "rule": RULE + f"; only when the accelerometer-aided fleet kf's relative std is at most "
                       f"{100 * REFERENCE_MAX_REL_STD:.0f} %",
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
                           progress=None) -> tuple[Vehicle, dict]:
    """mode: auto (calibrate when possible, else gap's file and why), on (must calibrate), off."""
    if mode == "off":
        return corrected, not_calibrated("--calibration off", corrected)
    try:
        return calibrate(logs, vehicle, corrected, progress)
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
