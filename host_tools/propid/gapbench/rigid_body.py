"""The nominal rigid-body model on a flight's analysis grid: response and regressors.

Per axis (roll, pitch, yaw, thrust) the model the filter assumes is

    J dw/dt + w x (J w) = sum_i r_i x (kf_i W_i^2 e_z) + sum_i yaw_sign_i km_i W_i^2 e_z
    m a_z               = sum_i kf_i W_i^2

(w the gyro rate, W_i the rotor speeds, a the accelerometer's specific force).
The bench uses it twice: the detectability index (with the true coefficients) and
the least-squares baseline (fitting them). Signals are resampled to a uniform
grid, low-passed with a zero-phase spectral filter at `cutoff_hz` (the body-rate
derivative amplifies gyro noise as f^2; effects live in the flight's band),
differentiated in the same step, trimmed at the ends and decimated to about
2.5 samples per cutoff period so neighbouring samples are nearly independent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from propid.flightlog import FlightLog, Vehicle

CUTOFF_HZ = 10.0
TRIM_S = 0.5       # filter edge transient dropped at each end
SETTLE_S = 0.5     # start-up transient (the vehicle settles from its start state)
AXES = ("roll", "pitch", "yaw", "thrust")


def lowpass(x: np.ndarray, fs: float, cutoff_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-phase low-pass of the columns of x and their time derivative.

    The linear trend is removed first (so the periodic extension has no jump), the
    spectrum is cut with a raised-cosine edge from 0.7 to 1.0 x cutoff, and the
    trend is added back.
    """
    x = np.asarray(x, dtype=float)
    flat = x.ndim == 1
    if flat:
        x = x[:, None]
    n = x.shape[0]
    idx = np.arange(n)
    slope = (x[-1] - x[0]) / max(n - 1, 1)
    trend = x[0] + np.outer(idx, slope)
    detrended = x - trend
    # Mirror-extend to damp end effects of the periodic assumption.
    extended = np.concatenate([detrended, detrended[::-1]], axis=0)
    spectrum = np.fft.rfft(extended, axis=0)
    freq = np.fft.rfftfreq(extended.shape[0], d=1.0 / fs)
    edge = np.clip((freq - 0.7 * cutoff_hz) / (0.3 * cutoff_hz), 0.0, 1.0)
    gain = 0.5 * (1.0 + np.cos(np.pi * edge))
    gain[freq >= cutoff_hz] = 0.0
    filtered = np.fft.irfft(spectrum * gain[:, None], n=extended.shape[0], axis=0)[:n]
    derivative = np.fft.irfft(spectrum * (gain * 2j * np.pi * freq)[:, None],
                              n=extended.shape[0], axis=0)[:n]
    out = filtered + trend
    dout = derivative + slope * fs
    return (out[:, 0], dout[:, 0]) if flat else (out, dout)


@dataclass
class Grid:
    """A flight's signals, low-passed and decimated; None where the log lacks a column."""
    t: np.ndarray
    rate: np.ndarray            # (n, 3) gyro [rad/s]
    rate_dot: np.ndarray        # (n, 3)
    speed: np.ndarray           # (n, N) rotor speeds [rad/s]
    speed_dot: np.ndarray
    speed_sq: np.ndarray        # (n, N) low-passed W^2
    speed_sq_dot: np.ndarray
    acc: np.ndarray | None      # (n, 3)
    quat: np.ndarray | None     # (n, 4) wxyz
    vel: np.ndarray | None      # (n, 3) world
    pos: np.ndarray | None      # (n, 3) world
    extra: dict[str, np.ndarray]


def _uniform(log: FlightLog) -> tuple[np.ndarray, float, np.ndarray]:
    """Rows from the first complete gyro + rotor sample, on a uniform time grid."""
    ok = np.all(np.isfinite(log.gyro), axis=1) & np.all(np.isfinite(log.rotor_speed), axis=1)
    if not np.any(ok):
        raise ValueError("no complete gyro and rotor-speed sample")
    first = int(np.argmax(ok))
    t = log.t[first:]
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        raise ValueError("time does not advance")
    grid = np.arange(t[0], t[-1] + 0.5 * dt, dt)
    return grid, dt, np.arange(first, len(log.t))


def _resample(grid: np.ndarray, t: np.ndarray, values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    out = np.empty((grid.size, values.shape[1]))
    for k in range(values.shape[1]):
        column = values[:, k]
        good = np.isfinite(column)
        if not np.any(good):
            return None
        out[:, k] = np.interp(grid, t[good], column[good])
    return out


def make_grid(log: FlightLog, cutoff_hz: float = CUTOFF_HZ, extra_names: tuple[str, ...] = ()
              ) -> Grid:
    grid_t, dt, rows = _uniform(log)
    fs = 1.0 / dt
    cutoff = min(cutoff_hz, 0.4 * fs)
    t = log.t[rows]

    def smooth(values):
        if values is None:
            return None, None
        resampled = _resample(grid_t, t, values[rows])
        if resampled is None:
            return None, None
        return lowpass(resampled, fs, cutoff)

    rate, rate_dot = smooth(log.gyro)
    speed, speed_dot = smooth(log.rotor_speed)
    speed_sq, speed_sq_dot = smooth(log.rotor_speed ** 2)
    acc, _ = smooth(log.acc)
    quat, _ = smooth(log.quat)
    if quat is not None:
        quat = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    vel, _ = smooth(log.group(("vx", "vy", "vz")))
    pos, _ = smooth(log.group(("px", "py", "pz")))
    extra = {}
    for name in extra_names:
        if name in log.extra:
            extra[name] = _resample(grid_t, t, log.extra[name][rows])[:, 0]

    step = max(1, int(round(fs / (2.5 * cutoff))))
    keep = np.zeros(grid_t.size, dtype=bool)
    lo, hi = grid_t[0] + TRIM_S + SETTLE_S, grid_t[-1] - TRIM_S
    keep[::step] = True
    keep &= (grid_t >= lo) & (grid_t <= hi)
    if np.count_nonzero(keep) < 20:
        raise ValueError("flight too short for the analysis")

    def cut(a):
        return None if a is None else a[keep]

    return Grid(t=grid_t[keep], rate=rate[keep], rate_dot=rate_dot[keep], speed=speed[keep],
                speed_dot=speed_dot[keep], speed_sq=speed_sq[keep], speed_sq_dot=speed_sq_dot[keep],
                acc=cut(acc), quat=cut(quat), vel=cut(vel), pos=cut(pos),
                extra={k: v[keep] for k, v in extra.items()})


def inertia_matrix(vehicle: Vehicle) -> np.ndarray:
    if vehicle.inertia is None:
        raise ValueError("the vehicle file has no inertia")
    return np.asarray(vehicle.inertia, dtype=float)


def response(grid: Grid, vehicle: Vehicle) -> np.ndarray:
    """(4, n): J dw/dt + w x Jw per body axis, and m a_z (NaN without accelerometer/mass)."""
    inertia = inertia_matrix(vehicle)
    jw = grid.rate @ inertia.T
    torque = grid.rate_dot @ inertia.T + np.cross(grid.rate, jw)
    thrust = (np.full(grid.t.size, np.nan) if grid.acc is None or vehicle.mass is None
              else vehicle.mass * grid.acc[:, 2])
    return np.vstack([torque.T, thrust[None, :]])


def nominal_regressors(grid: Grid, vehicle: Vehicle, speed_sq: np.ndarray | None = None
                       ) -> np.ndarray:
    """(4, n, 2N): columns kf_1..kf_N, km_1..km_N of the nominal model."""
    sq = grid.speed_sq if speed_sq is None else speed_sq
    pos = vehicle.positions
    signs = vehicle.yaw_signs
    count = pos.shape[0]
    n = sq.shape[0]
    x = np.zeros((4, n, 2 * count))
    x[0, :, :count] = sq * pos[:, 1]
    x[1, :, :count] = -sq * pos[:, 0]
    x[2, :, count:] = sq * signs
    x[3, :, :count] = sq
    return x


def model_torques(grid: Grid, vehicle: Vehicle, kf: np.ndarray, km: np.ndarray) -> np.ndarray:
    """(4, n): the nominal model's roll/pitch/yaw torque and thrust with these coefficients."""
    return nominal_regressors(grid, vehicle) @ np.concatenate([kf, km])
