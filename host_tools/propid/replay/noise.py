"""Noise levels for the filter: measured on the log ('auto') and tuned on the filter's own
innovations ('nis')."""

from __future__ import annotations

import math

import numpy as np

from propid.flightlog import FlightLog
from propid.realdata_checks import absurd_speed_limit
from propid.replay.options import ReplayOptions, ReplayResult
from propid.signals import measured_torque, median_dt

def estimate_noise(log: FlightLog, vehicle_inertia: np.ndarray, positions, signs, mask) -> dict:
    """Noise levels for the filter from the log itself (the 'auto' rule, docs/real-data.md).

    The filter models the body rate as driven by the rotor torques plus white angular
    acceleration noise q (rate_process_noise), seen through a gyro with white noise sigma.
    1. Fit per-rotor kf and km to the log by least squares with the filter's own torque
       model (so a wrong nominal does not count as 'unmodelled').
    2. Residual rate increments over k samples, r_k = w[n+k] - w[n] - sum(a_fit) dt, have
       variance q^2 k dt + 2 sigma^2: from k = 1 and k = K (about 50 ms) both follow.
    Only the log and the vehicle file's geometry and inertia enter; variances use the
    central 99 % of the increments (glitches out). Floors: sigma >= 1 mrad/s (below any
    MEMS gyro's noise or quantisation), q >= 1e-3 rad/s^2/sqrt(Hz)."""
    dt = median_dt(log.t)
    gyro = log.gyro
    speeds = log.rotor_speed
    ok = mask.copy()
    ok &= np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(speeds), axis=1)
    ok &= np.all(np.nan_to_num(speeds, nan=0.0) <= absurd_speed_limit(speeds), axis=1)
    inner = ok.copy()  # central differences need both neighbours, apart in time (the
    inner[1:-1] &= ok[:-2] & ok[2:]  # format lets t repeat: "t never decreases")
    span = log.t[2:] - log.t[:-2]
    inner[1:-1] &= span > 0
    inner[[0, -1]] = False
    if inner.sum() < 100:
        return {}
    rate_dot = np.zeros_like(gyro)
    rate_dot[1:-1] = (gyro[2:] - gyro[:-2]) / np.where(span > 0, span, 1.0)[:, None]
    torque = measured_torque(gyro, rate_dot, vehicle_inertia)
    u = np.where(np.isfinite(speeds), speeds, 0.0) ** 2
    n = u.shape[1]

    def design(rows):
        zeros = np.zeros((rows.sum(), n))
        return np.vstack([
            np.hstack([u[rows] * positions[:, 1], zeros]),
            np.hstack([-u[rows] * positions[:, 0], zeros]),
            np.hstack([zeros, u[rows] * signs]),
        ])

    target = np.concatenate([torque[inner, 0], torque[inner, 1], torque[inner, 2]])
    coeffs, *_ = np.linalg.lstsq(design(inner), target, rcond=None)
    all_rows = np.ones(len(log), dtype=bool)
    fitted_torque = (design(all_rows) @ coeffs).reshape(3, -1).T
    accel_fit = fitted_torque @ np.linalg.inv(vehicle_inertia).T  # gyroscopic term is small here

    def robust_var(x):  # variance of the central 99 % (glitches out, repeated samples kept)
        lo, hi = np.percentile(x, [0.5, 99.5], axis=0)
        return np.array([np.var(x[(x[:, a] >= lo[a]) & (x[:, a] <= hi[a]), a]) for a in range(3)])

    def increment_var(k):
        start = np.arange(len(log) - k)
        valid = np.ones(start.size, dtype=bool)
        for j in range(k + 1):
            valid &= ok[start + j]
        cum = np.vstack([np.zeros((1, 3)), np.cumsum(accel_fit * dt, axis=0)])
        resid = (gyro[start + k] - gyro[start]) - (cum[start + k] - cum[start])
        return robust_var(resid[valid]) if valid.sum() > 50 else None

    k_long = max(2, int(round(0.05 / dt)))
    var_1, var_k = increment_var(1), increment_var(k_long)
    if var_1 is None or var_k is None:
        return {}
    q2 = np.maximum((var_k - var_1) / ((k_long - 1) * dt), 0.0)
    sigma2 = np.maximum((var_1 - q2 * dt) / 2.0, 0.0)
    rate_hz = 1.0 / dt
    gyro_sigma = math.sqrt(float(np.mean(sigma2)))
    return {
        "gyro_sample_rate_hz": rate_hz,
        "gyro_noise_density": max(gyro_sigma, 1e-3) / math.sqrt(rate_hz),
        "rate_process_noise": max(math.sqrt(float(np.mean(q2))), 1e-3),
    }



NIS_TOLERANCE = 0.05
NIS_MAX_ITERATIONS = 8


def replay_nis(log: FlightLog, vehicle: Vehicle, options: ReplayOptions) -> ReplayResult:
    """--noise nis: gyro noise by the 'auto' rule, then rate_process_noise q scaled until the
    filter's own innovations are consistent with it: mean normalised innovation squared
    nu^2/S over the gyro axes = 1 (within NIS_TOLERANCE). nu^2/S ~ 1/q^2 when the process
    noise dominates S; secant steps on log NIS against log q converge in a few replays.
    Uses no coefficient value."""
    from dataclasses import replace

    from propid.replay.config import build_config
    from propid.replay.run import replay  # the replay calls back here for --noise nis

    base = replace(options, noise="auto")
    given = options.overrides.get("rate_process_noise")
    q = float(given) if given else float(build_config(vehicle, log, replace(base, overrides={}))[0].get(
        "rate_process_noise", 1.0))
    history = []
    result = None
    for _ in range(NIS_MAX_ITERATIONS):
        result = replay(log, vehicle, replace(base, overrides={**options.overrides, "rate_process_noise": q}))
        nis = result.summary["nis_mean"]
        history.append({"rate_process_noise": q, "nis_mean": nis})
        if not np.isfinite(nis) or nis <= 0 or abs(nis - 1.0) < NIS_TOLERANCE:
            break
        # secant step on log NIS vs log q (slope -2 when the process noise dominates S)
        slope = -2.0
        if len(history) >= 2:
            (q0, n0), (q1, n1) = [(h["rate_process_noise"], h["nis_mean"]) for h in history[-2:]]
            if q0 != q1 and n0 > 0 and n1 > 0:
                slope = float(np.clip(math.log(n1 / n0) / math.log(q1 / q0), -2.0, -0.1))
        q = float(np.clip(q * math.exp(-math.log(nis) / slope), 1e-4, 1e4))
    result.summary["config_notes"]["noise"] = (
        "nis: gyro noise by the auto rule; rate_process_noise scaled until the mean normalised innovation "
        "squared of this replay is 1")
    result.summary["config_notes"]["nis_iterations"] = history
    return result


def nis_mean(series: dict, skip_s: float = 2.0) -> float:
    """Mean normalised innovation squared nu^2/S over the gyro axes and the accepted samples
    after the first skip_s seconds (1 for a consistent filter)."""
    nis = series.get("nis")
    if nis is None or nis.size == 0:
        return float("nan")
    late = series["t"] >= series["t"][0] + skip_s
    values = nis[late] if late.any() else nis
    return float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")

