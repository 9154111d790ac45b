"""Rotor thrust that depends on the airspeed, carried into the accelerometer row (docs/real-data.md "The square
runs' offset with the accelerometer").

At a fixed rotor speed a rotor's thrust changes with the air it meets. Blade-element theory at fixed pitch gives
two first-order terms, both in the body frame (mocap velocity rotated by the attitude, no wind):
- climb (axial inflow): the inflow through the disc grows with the climb speed, the blades' angle of attack falls,
  thrust drops by `d Omega_i v_z` per rotor (d < 0; frame drag along z has the same form at a near-constant
  rotor speed). Regressor sum_i Omega_i v_z,b [rad/s m/s], coefficient `thrust_climb_coeff` [N/(rad/s m/s)].
- translational (edgewise speed): the advancing blade sees more dynamic pressure, thrust rises by `c v_h^2` per
  rotor (c > 0; the theta mu^2 / 2 term, Omega^2 mu^2 = v_h^2 / R^2: no rotor speed). Regressor N v_h^2
  [(m/s)^2], coefficient `thrust_translational_coeff` [N/(m/s)^2 per rotor].
The filter's accelerometer row is `f_z = sum kf_i Omega_i^2 / m + b_az`; with known coefficients the replay
removes the terms from the measurement before pushing it, `f_z - (d x_climb + c x_trans) / m`, so the filter's
row holds again. The coefficients are fitted by least squares on flights of the vehicle (`fit_thrust_aero`),
pooled with one intercept per flight (the accelerometer bias may differ between flights) and one shared kf.
"""

from __future__ import annotations

import copy
from types import MappingProxyType

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.signals import log_body_velocity, segments

TERMS = ("climb", "translational")
VEHICLE_KEYS = MappingProxyType({"climb": "thrust_climb_coeff", "translational": "thrust_translational_coeff"})
MIN_SEGMENT_S = 0.5  # flying stretches shorter than this are left out of the fit (take-off, landing blips)


def regressors(log: FlightLog, rotor_speed: np.ndarray | None = None) -> dict[str, np.ndarray] | None:
    """Per row: {"climb": sum_i Omega_i v_z,b, "translational": N v_h^2}; None without velocity/attitude.
    `rotor_speed` overrides the log's (e.g. with spikes and gaps repaired)."""
    velocity = log_body_velocity(log)
    if velocity is None:
        return None
    speeds = log.rotor_speed if rotor_speed is None else rotor_speed
    return {"climb": speeds.sum(axis=1) * velocity[:, 2],
            "translational": speeds.shape[1] * (velocity[:, 0] ** 2 + velocity[:, 1] ** 2)}


def cleaned_rotor_speeds(log: FlightLog) -> np.ndarray:
    from propid.realdata_checks import absurd_speed_limit, clean_rotor_speeds

    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    return speeds


def fit_thrust_aero(logs: list[FlightLog], vehicle: Vehicle, terms: tuple[str, ...] = TERMS) -> dict:
    """Pooled least squares over the flying rows of `logs`:
    m acc_z = kf sum_i Omega_i^2 + sum_k c_k x_k + b_run (one intercept per log).
    Returns {"kf": .., "coefficients": {term: c}, "rows": n, "logs": count}."""
    from propid.realdata_checks import flying_mask

    unknown = [t for t in terms if t not in TERMS]
    if unknown or not terms:
        raise UserError(f"thrust terms must be among {', '.join(TERMS)}, got {', '.join(terms) or 'none'}")
    if vehicle.mass is None:
        raise UserError("the thrust terms need the vehicle's mass (the accelerometer's force scale)")
    blocks_y, blocks_x, intercepts = [], [], []
    for index, log in enumerate(logs):
        acc = log.acc
        speeds = cleaned_rotor_speeds(log)
        x = regressors(log, speeds)
        if acc is None or x is None:
            raise UserError(f"{log.path or 'log'}: the thrust terms need acc_*, velocity (vx, vy, vz) and "
                            "attitude (qw..qz) columns")
        rate = 1.0 / float(np.median(np.diff(log.t)))
        rows = np.zeros(len(log), dtype=bool)
        for a, b in segments(flying_mask(log), min_length=int(MIN_SEGMENT_S * rate)):
            rows[a:b] = True
        columns = [(speeds**2).sum(axis=1)] + [x[t] for t in terms]
        rows &= np.isfinite(acc[:, 2]) & np.all(np.isfinite(np.column_stack(columns)), axis=1)
        if rows.sum() < 10:
            continue
        blocks_y.append(vehicle.mass * acc[rows, 2])
        blocks_x.append(np.column_stack([c[rows] for c in columns]))
        intercepts.append((index, int(rows.sum())))
    if not blocks_y:
        raise UserError("no flying rows with the accelerometer, velocity and attitude to fit the thrust terms on")
    total = sum(n for _, n in intercepts)
    design = np.zeros((total, 1 + len(terms) + len(intercepts)))
    start = 0
    for k, (block, (_, n)) in enumerate(zip(blocks_x, intercepts)):
        design[start:start + n, :1 + len(terms)] = block
        design[start:start + n, 1 + len(terms) + k] = 1.0
        start += n
    coeffs, *_ = np.linalg.lstsq(design, np.concatenate(blocks_y), rcond=None)
    return {"kf": float(coeffs[0]), "coefficients": {t: float(coeffs[1 + j]) for j, t in enumerate(terms)},
            "rows": total, "logs": len(intercepts)}


def vehicle_coefficients(vehicle: Vehicle) -> dict[str, float]:
    """The vehicle file's thrust-term coefficients that are set ({} when none)."""
    return {term: float(getattr(vehicle, key)) for term, key in VEHICLE_KEYS.items()
            if getattr(vehicle, key) is not None}


def specific_force_correction(log: FlightLog, vehicle: Vehicle) -> np.ndarray:
    """Per row, what the vehicle file's thrust terms add to the body-z specific force [m/s^2]
    (subtract it from acc_z); NaN where the velocity, attitude or rotor speeds are missing."""
    coefficients = vehicle_coefficients(vehicle)
    if not coefficients:
        raise UserError("--thrust-aero on needs thrust_climb_coeff and/or thrust_translational_coeff in the "
                        "vehicle file (fit them with `propid replay ... --thrust-aero-out`)")
    if vehicle.mass is None:
        raise UserError("--thrust-aero needs the vehicle's mass")
    x = regressors(log, cleaned_rotor_speeds(log))
    if x is None:
        raise UserError(f"{log.path or 'log'}: --thrust-aero needs velocity (vx, vy, vz) and attitude (qw..qz) "
                        "columns")
    force = sum(c * x[term] for term, c in coefficients.items())
    return force / vehicle.mass


def carry_thrust_aero(log: FlightLog, vehicle: Vehicle, mode: str) -> tuple[FlightLog, str]:
    """`--thrust-aero on`: the log with the vehicle file's thrust terms removed from acc_z (rows without a
    velocity or attitude lose their accelerometer sample); `off`: the log as it is. And the note."""
    if mode not in ("on", "off"):
        raise UserError(f"--thrust-aero {mode!r}: choose on or off")
    if mode == "off":
        return log, "not modelled"
    if log.acc is None:
        raise UserError("--thrust-aero on needs the accelerometer columns acc_x/acc_y/acc_z")
    correction = specific_force_correction(log, vehicle)
    out = copy.copy(log)
    out.extra = dict(log.extra)
    out.extra["acc_z"] = log.extra["acc_z"] - correction
    terms = ", ".join(f"{VEHICLE_KEYS[t]} {c:.4g}" for t, c in vehicle_coefficients(vehicle).items())
    return out, f"vehicle file: {terms}; removed from acc_z before the filter"
