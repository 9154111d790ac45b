"""The gyro's constant bias measured against the logged attitude (`--gyro-bias attitude`).

The measured torque J dw/dt + w x (J w) takes its rate from the gyro. A constant bias b
leaves J dw/dt alone but puts b x (J w) + w x (J b) into the gyroscopic term: on roll
(Jzz - Jyy)(b_z w_y + b_y w_z), on pitch -(Jzz - Jxx)(b_z w_x + b_x w_z). With a nearly
constant sum_i s_i Omega_i (rotors of unequal coefficients hover at unequal speeds) the b_z
part has the shape of rotor_gyroscopic's column, J_r (sum s_i Omega_i)(w_y, -w_x): on a
low-noise gyro a bias of a few mrad/s reads as a rotor inertia (docs/xsim.md). The
attitude, when logged, measures the rate without that bias: q' = q (0, w)/2 for a
body-to-world q, so w = 2 vec(conj(q) q'); the bias is the median of gyro - w over the
flying rows (robust to the attitude estimator's corrections and to outliers).
"""

from __future__ import annotations

import numpy as np

MODES = ("off", "attitude")
# A bias above this is not a gyro's (or the attitude is not the body's): not applied.
MAX_BIAS_RAD_S = 0.2
MIN_ATTITUDE_ROWS = 0.5  # share of the flying rows with a logged attitude


def attitude_rate(t: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """(n, 3) body rate [rad/s] from (n, 4) attitude quaternions (w, x, y, z; body -> world),
    central differences on the log's time stamps; the sign of q made continuous first."""
    q = np.array(quat, dtype=float, copy=True)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    flip = np.cumsum(np.concatenate([[0], (np.sum(q[1:] * q[:-1], axis=1) < 0).astype(int)])) % 2 == 1
    q[flip] *= -1.0
    dq = np.gradient(q, t, axis=0)
    w, v = q[:, 0], q[:, 1:]
    dw, dv = dq[:, 0], dq[:, 1:]
    # vec(conj(q) dq) = w dv - dw v - v x dv
    return 2.0 * (w[:, None] * dv - dw[:, None] * v - np.cross(v, dv))


def gyro_bias_from_attitude(t: np.ndarray, gyro: np.ndarray, quat: np.ndarray | None,
                            rows: np.ndarray) -> dict:
    """The bias over `rows` (indices), or why it was not measured. Returns a dict with
    `applied` (bool), `value` ([3] rad/s or None) and `why` when not applied."""
    if quat is None:
        return {"applied": False, "value": None, "why": "no attitude columns"}
    finite = np.isfinite(quat).all(axis=1) & np.isfinite(gyro).all(axis=1)
    usable = rows[finite[rows]]
    if usable.size < MIN_ATTITUDE_ROWS * rows.size or usable.size < 10:
        return {"applied": False, "value": None, "why": "attitude logged on too few flying rows"}
    ok = np.flatnonzero(finite)
    rate = np.full_like(np.asarray(gyro, dtype=float), np.nan)
    rate[ok] = attitude_rate(np.asarray(t)[ok], np.asarray(quat)[ok])
    bias = np.nanmedian(gyro[usable] - rate[usable], axis=0)
    if not np.all(np.isfinite(bias)) or np.any(np.abs(bias) > MAX_BIAS_RAD_S):
        return {"applied": False, "value": [float(b) for b in bias],
                "why": f"a bias above {MAX_BIAS_RAD_S} rad/s: the attitude does not follow the gyro"}
    return {"applied": True, "value": [float(b) for b in bias]}
