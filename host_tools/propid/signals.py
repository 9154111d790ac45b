"""Signal-processing helpers shared by the replay, its pre-filters and the least-squares
checks: sample interval, contiguous segments, gap holding, the measured body torque and the
Newey-West long-run covariance of autocorrelated scores.

The measured torque is the rigid-body equation read backwards: with the body rate w
from the gyro and its derivative dw/dt, tau = J dw/dt + w x (J w). Callers choose the
derivative (central differences, np.gradient or one Euler step), because each must
match the discretisation it is compared with.
"""

from __future__ import annotations

import math

import numpy as np


def median_dt(t: np.ndarray) -> float:
    """Median of the positive time steps [s]: the log's nominal sample interval."""
    steps = np.diff(t)
    return float(np.median(steps[steps > 0]))


def measured_torque(rate: np.ndarray, rate_dot: np.ndarray, inertia: np.ndarray) -> np.ndarray:
    """Body torque (n, 3) [N m] that explains the body rate: J dw/dt + w x (J w)."""
    inertia = np.asarray(inertia, dtype=float)
    return rate_dot @ inertia.T + np.cross(rate, rate @ inertia.T)


def world_to_body(quat: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """World-frame vectors (n, 3) in the body frame, by the attitude quaternions (n, 4; w, x, y, z;
    body -> world): R^T v per row. NaN rows stay NaN."""
    w, x, y, z = np.asarray(quat, dtype=float).T
    rot = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=1)  # body -> world
    return np.einsum("nji,nj->ni", rot, vectors)


def log_body_velocity(log, missing: float = np.nan) -> np.ndarray | None:
    """A flight log's world velocity (vx, vy, vz) rotated into the body frame with its attitude;
    None when the log has no velocity or no attitude. Rows with either missing get `missing`
    (NaN by default; 0 for fits that take every row as a regressor)."""
    quat = log.quat
    velocity = log.group(("vx", "vy", "vz"))
    if quat is None or velocity is None:
        return None
    body = world_to_body(quat, velocity)
    return body if np.isnan(missing) else np.nan_to_num(body, nan=missing)


def segments(mask: np.ndarray, min_length: int) -> list[tuple[int, int]]:
    """[start, stop) index ranges of contiguous True runs at least min_length long."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops) if b - a >= min_length]


def hold_gaps(x: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Replace bad samples by the last good one before them (the next good one at the start),
    i.e. what the filter itself does with a rejected rotor sample (zero-order hold)."""
    out = x.copy()
    for k in range(x.shape[1]):
        good = np.flatnonzero(~bad[:, k])
        if good.size == 0:
            continue
        idx = np.searchsorted(good, np.arange(x.shape[0]), side="right") - 1
        idx = np.where(idx < 0, 0, idx)
        out[:, k] = x[good[idx], k]
    return out


def segment_starts(mask: np.ndarray, t: np.ndarray, dt: float) -> np.ndarray:
    """Indices where a recursive filter over the masked rows must restart: the first row
    of every contiguous masked run, and every row after a time gap (> 1.5 dt)."""
    steps = np.diff(t)
    gap = np.concatenate([[True], (steps > 1.5 * dt)])
    return np.flatnonzero(mask & (gap | ~np.concatenate([[False], mask[:-1]])))


def repeats_previous_row(values: np.ndarray) -> np.ndarray:
    """Mask of the rows whose every column equals, bit for bit, the previous row that logs this stream
    (NaN never does): a logger that samples separately streamed blocks by sample-and-hold writes a lost
    packet as such a copy (docs/real-data.md "Repeated rows"). The previous row logging the stream, not
    the previous row: in an events log the other stream's rows lie between two samples of this one."""
    same = np.zeros(len(values), dtype=bool)
    logged = np.flatnonzero(np.any(np.isfinite(values), axis=1))
    same[logged[1:]] = np.all(values[logged[1:]] == values[logged[:-1]], axis=1)
    return same


def bartlett_long_run_covariance(scores: np.ndarray, bandwidth: float) -> np.ndarray | float:
    """Newey-West long-run covariance of the rows of `scores` (n x k; a 1-D array: its scalar variance):
    sum over |lag| <= floor(bandwidth) of (1 - |lag| / (bandwidth + 1)) scores[t]' scores[t - lag]. The
    Bartlett weights keep it positive semi-definite; a sum of n autocorrelated terms has this variance. The
    one implementation behind `propid gap`'s tests and `propid real-data --km-evidence`'s coloured std."""
    scores = np.asarray(scores, dtype=float)
    column = scores.ndim == 1
    rows = scores[:, None] if column else scores
    omega = rows.T @ rows
    for lag in range(1, min(int(math.floor(bandwidth)), rows.shape[0] - 1) + 1):
        cross = rows[lag:].T @ rows[:-lag]
        omega += (1.0 - lag / (bandwidth + 1.0)) * (cross + cross.T)
    return float(omega[0, 0]) if column else omega
