"""Stream alignment: which samples a log row carries, how the C library feeds rotor samples
into a prediction step, and how much later than logged the rotor speeds act on the body."""

from __future__ import annotations

import math

import numpy as np

from propid.flightlog import FlightLog, Vehicle
from propid.realdata_checks import absurd_speed_limit, flying_mask
from propid.replay.options import US
from propid.signals import hold_gaps, measured_torque, median_dt, segments

def detect_streams(log: FlightLog) -> str:
    """'events' if some rows carry rotor speeds but no gyro (separate time bases)."""
    gyro_missing = np.all(~np.isfinite(log.gyro), axis=1)
    rotor_missing = np.all(~np.isfinite(log.rotor_speed), axis=1)
    if np.any(gyro_missing & ~rotor_missing) and np.any(rotor_missing & ~gyro_missing):
        return "events"
    return "rows"


def gyro_rows_view(log: FlightLog) -> FlightLog:
    """An events log as the filter sees it: its gyro rows, each with the rotor speeds (and every other
    column) in force at its time, i.e. the latest logged at or before it (NaN before the first).
    What measures on rows that carry both streams (noise, accelerometer noise) measures on this; a
    rows log is returned as it is."""
    if detect_streams(log) != "events":
        return log
    gyro_rows = np.flatnonzero(np.any(np.isfinite(log.gyro), axis=1))
    t = log.t[gyro_rows]

    def in_force(values: np.ndarray, logged: np.ndarray) -> np.ndarray:
        index = np.searchsorted(log.t[logged], t, side="right") - 1
        held = values[logged][np.maximum(index, 0)]
        held[index < 0] = np.nan
        return held

    speeds = in_force(log.rotor_speed, np.any(np.isfinite(log.rotor_speed), axis=1))
    extra = {name: in_force(values, np.isfinite(values)) if np.isfinite(values).any() else values[gyro_rows]
             for name, values in log.extra.items()}
    return FlightLog(t=t, gyro=log.gyro[gyro_rows], rotor_speed=speeds, extra=extra, path=log.path)


def gyro_rows_with_mask(log: FlightLog, mask: np.ndarray) -> tuple[FlightLog, np.ndarray]:
    """gyro_rows_view and the row mask carried to its rows (a rows log and its mask as they are)."""
    if detect_streams(log) != "events":
        return log, mask
    return gyro_rows_view(log), mask[np.any(np.isfinite(log.gyro), axis=1)]


def filter_input_rule() -> str:
    """How the loaded C library turns rotor samples into the input of one prediction step
    (t_k-1, t_k]: "zoh" (the latest rotor sample) or "trapezoid" (mean of the sample that was
    latest at t_k-1 and the latest one), from probe_input_ratio."""
    ratio = probe_input_ratio()
    return "trapezoid" if abs(ratio - 0.5) < abs(ratio - 1.0) else "zoh"


def probe_input_ratio() -> float:
    """Probe the loaded library through its API (three filter steps, cheap, so it is asked
    each time rather than cached): a symmetric quad, negligible measurement weight, one step
    in which a single rotor speeds up. Returns the predicted rate change over the full step
    change: 1 for a zero-order hold, 0.5 for a trapezoidal input."""
    from propid import cfilter

    arm, kf, inertia = 0.1, 1e-6, 1e-3
    config = cfilter.FilterConfig.symmetric(4, arm, math.pi / 4, 1.0, kf, 1e-8, [inertia] * 3,
                                            rate_std0=1e-4, gyro_noise_density=10.0, gyro_sample_rate_hz=100.0,
                                            gate_sigma=0.0, thrust_coeff_rel_std0=1e-3, drag_coeff_rel_std0=1e-3,
                                            gyro_bias_std0=1e-4)
    probe = cfilter.CFilter(config)
    base, fast = [500.0] * 4, [1000.0, 500.0, 500.0, 500.0]
    for k, speeds in enumerate((base, base, fast)):
        t_us = US + k * 10_000
        probe.push_rotor_speeds(t_us, speeds)
        probe.push_gyro(t_us, [0.0, 0.0, 0.0])
    position = np.array(config.positions[0])
    torque = kf * (fast[0] ** 2 - base[0] ** 2) * np.array([position[1], -position[0]])
    full_step = 0.01 * torque / inertia
    return float(np.dot(probe.estimate().body_rate[:2], full_step) / np.dot(full_step, full_step))


DELAY_BAND_HZ = (2.0, 10.0)
MAX_ROTOR_DELAY_S = 0.05


def estimate_esc_delay(log: FlightLog, vehicle: Vehicle, mask: np.ndarray | None = None,
                       unit_inertia: bool = False) -> float:
    """The per-log telemetry-delay rule (docs/real-data.md): esc_delay_s [s], > 0 when the logged
    rotor speeds lag the gyro, < 0 when the gyro lags; -estimate_rotor_delay."""
    return -estimate_rotor_delay(log, vehicle, mask, unit_inertia)


def estimate_rotor_delay(log: FlightLog, vehicle: Vehicle, mask: np.ndarray | None = None,
                         unit_inertia: bool = False) -> float:
    """Delay of the angular-acceleration response behind the logged rotor speeds, in whole
    samples of the log (negative: the response leads, i.e. the rotor telemetry lags), by the
    filter's own discretisation: with the rotor samples held m samples (the firmware's delay
    buffer, or pushed m samples late) the Euler step (t_{n+m-1}, t_{n+m}] integrates u[n].
    The rule regresses the measured torque of that step, J (w[k] - w[k-1])/dt + w x Jw, on
    the model's roll and pitch regressors u[k - m] (with a trapezoidal library input,
    0.5 (u[k - m] + u[k - m - 1]): filter_input_rule) (both band-passed to 2-10 Hz per flying
    segment) for m = -50 .. 50 ms and takes the m with the largest R^2 (sum over roll and
    pitch), i.e. the peak of the normalised cross-correlation of modelled and measured
    torque. Scale-free: it uses no coefficient value."""
    from propid.realdata_checks import clean_rotor_speeds, lagged_fit

    steps = np.diff(log.t)
    dt = median_dt(log.t)
    rate = 1.0 / dt
    if DELAY_BAND_HZ[1] >= 0.45 * rate:
        return 0.0
    inertia = np.eye(3) if unit_inertia or vehicle.inertia is None else np.asarray(vehicle.inertia)
    mask = flying_mask(log) if mask is None else mask
    uniform = np.ones(len(log), dtype=bool)
    uniform[1:] &= np.abs(steps - dt) < 0.5 * dt
    segs = segments(mask & uniform, int(max(2.0 * rate, 50)))
    if not segs:
        return 0.0
    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    gyro = hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    step_rate = np.zeros_like(gyro)
    step_rate[1:] = (gyro[1:] - gyro[:-1]) / dt
    torque = measured_torque(gyro, step_rate, inertia)
    u = speeds**2
    if filter_input_rule() == "trapezoid":  # the step integrates the mean of the previous and the latest sample
        u = np.vstack([u[:1], 0.5 * (u[1:] + u[:-1])])
    pos = vehicle.positions
    regs = [(u * pos[:, 1]).sum(axis=1, keepdims=True), (-u * pos[:, 0]).sum(axis=1, keepdims=True)]
    segs = [(max(a, 1), b) for a, b in segs]  # the first row of a segment has no step
    best, best_score = 0, -np.inf
    max_lag = int(round(MAX_ROTOR_DELAY_S * rate))
    for lag in sorted(range(-max_lag, max_lag + 1), key=abs):  # ties: the smaller shift
        score = sum(lagged_fit(torque[:, axis], regs[axis], segs, rate, DELAY_BAND_HZ, range(lag, lag + 1)).r2
                    for axis in range(2))
        if np.isfinite(score) and score > best_score:
            best, best_score = lag, score
    return best * dt

