"""Torque-gain calibration of the gyro-only filter (`propid replay --aiding gyro --vehicle-out CORRECTED.json`,
docs/real-data.md "Gyro only with a calibrated vehicle file").

From the gyro alone the filter sees kf only through the torque gain kf L / J, and on real logs
that gain reads low (errors in the rotor-speed regressor, closed-loop content; docs/real-data.md).
Logs that also carry the accelerometer, of a vehicle with a known mass, measure the absolute
thrust. The rule (fixed before it was run on any real log; it uses no reference value):

- replay every calibration log twice: as asked (gyro only) and with the accelerometer (the same
  options plus `--aiding gyro+accel`, the thrust-torque scale on, its walk by the per-log rule);
- per replay the fleet kf = mean over logs of the mean over rotors of kf_mean;
- c = fleet kf with the accelerometer / fleet kf gyro only;
- corrected file: Jxx and Jyy times c (the gyro then reads c times higher for the same rate
  data; Jzz kept: the thrust torques act on roll and pitch only, and km has no absolute sensor),
  kf_nominal rescaled so its mean is the accelerometer fleet kf; everything else as given
  (an esc_delay_s in the file stays, as both replays used it).

The correction is measured with the estimator that will use it: a scale measured another way
(least squares, the thrust-torque scale state's mean) does not transfer, because the gyro-only
value on these logs depends on the filter's memory (docs/real-data.md). Replay later logs with
the same options (e.g. `--thrust-coeff-rel-walk auto`) and the corrected file.
"""

from __future__ import annotations

import copy
import dataclasses
import statistics

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.replay.options import ReplayOptions


def check_calibration_inputs(vehicle: Vehicle, logs: list[FlightLog], options: ReplayOptions) -> None:
    """Judged before any replay: the calibration needs the gyro-only filter, a mass and accelerometer logs."""
    if options.aiding != "gyro":
        raise UserError("--vehicle-out calibrates the gyro-only filter: give --aiding gyro")
    if options.unit_inertia:
        raise UserError("--vehicle-out cannot be combined with --unit-inertia (no inertia to correct)")
    if vehicle.mass is None or vehicle.inertia is None:
        raise UserError("--vehicle-out needs the vehicle file's mass and inertia (the accelerometer replay measures "
                        "the absolute thrust with the mass)")
    for log in logs:
        acc = log.acc
        if acc is None or not np.isfinite(acc).any():
            name = log.path.name if log.path else "a log"
            raise UserError(f"--vehicle-out: {name} has no accelerometer columns (acc_x..acc_z) to calibrate with")


def accelerometer_options(options: ReplayOptions) -> ReplayOptions:
    """The calibration replay: the same options with the accelerometer, the torque scale and its walk rule."""
    return dataclasses.replace(options, aiding="gyro+accel", torque_scale="on", torque_scale_walk="auto",
                               thrust_coeff_walk=None, progress=False)


def fleet_kf(summaries: list[dict]) -> float:
    return statistics.fmean(statistics.fmean(s["kf_mean"]) for s in summaries)


def torque_gain_correction(vehicle: Vehicle, gyro: list[dict], accel: list[dict]) -> tuple[Vehicle, dict]:
    """The corrected vehicle from the two replays of the same logs, and what was done."""
    if not gyro or len(gyro) != len(accel):
        raise UserError("--vehicle-out: one gyro-only and one accelerometer replay per calibration log needed")
    kf_gyro, kf_accel = fleet_kf(gyro), fleet_kf(accel)
    if not (kf_gyro > 0 and kf_accel > 0 and np.isfinite(kf_gyro) and np.isfinite(kf_accel)):
        raise UserError(f"--vehicle-out: no usable calibration (gyro-only fleet kf {kf_gyro:.3g}, "
                        f"with the accelerometer {kf_accel:.3g})")
    gain = kf_accel / kf_gyro
    out = copy.deepcopy(vehicle)
    inertia = np.array(vehicle.inertia, dtype=float)
    inertia[0, 0] *= gain
    inertia[1, 1] *= gain
    out.inertia = inertia
    nominal = np.asarray(vehicle.kf_nominal, dtype=float) if vehicle.kf_nominal is not None else None
    if nominal is not None:
        out.kf_nominal = [float(v) for v in nominal * (kf_accel / float(np.mean(nominal)))]
    else:
        out.kf_nominal = [kf_accel] * vehicle.rotor_count
    info = {"logs": len(gyro), "kf_gyro_only": kf_gyro, "kf_with_accelerometer": kf_accel, "torque_gain": gain,
            "inertia": [float(v) for v in np.diag(inertia)], "kf_nominal": out.kf_nominal,
            "rule": "Jxx, Jyy x (fleet kf with the accelerometer / fleet kf gyro only); kf_nominal's mean = the "
                    "accelerometer fleet kf"}
    out.notes = ((vehicle.notes or "") + f" Torque gain calibrated by propid replay --vehicle-out on {len(gyro)} "
                 f"log(s): gyro-only fleet kf {kf_gyro:.4g}, with the accelerometer {kf_accel:.4g}, Jxx and Jyy x "
                 f"{gain:.4g}, kf_nominal mean {kf_accel:.4g}; replay with the same gyro-only options.").strip()
    return out, info
