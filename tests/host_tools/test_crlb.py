"""Cramér-Rao bound along a trajectory (propid.crlb): against a dense recursion, and
what it must say on trajectories with known observability."""

from __future__ import annotations

import math

import numpy as np

from propid import crlb
from propid.flightlog import parse_vehicle

N = 4
KF, KM = 2.3e-8, 7.8e-10
INERTIA = np.diag([1.43e-5, 1.43e-5, 2.89e-5])
CONFIG = crlb.BoundConfig(gyro_noise_density=math.radians(0.014), rate_process_noise=4e-4,
                          rate_std0=0.01, coeff_rel_std0=0.11547, bias_std0=0.0100767)


def vehicle():
    rotors = [{"position": [0.043 * math.cos(a), 0.043 * math.sin(a), 0.0], "yaw_sign": s}
              for a, s in zip(np.arange(N) * math.pi / 2, (1, -1, 1, -1))]
    return parse_vehicle({"name": "q", "mass": 0.03, "inertia": [1.43e-5, 1.43e-5, 2.89e-5],
                          "rotors": rotors, "kf_nominal": KF, "km_nominal": KM})


def columns(rate: np.ndarray, speeds: np.ndarray, dt: float = 0.002) -> dict[str, np.ndarray]:
    samples = rate.shape[0]
    cols = {"t": np.arange(samples) * dt}
    gyro = rate.copy()
    gyro[0] = np.nan  # the first row has no gyro sample yet, as in a SITL log
    for k, axis in enumerate("xyz"):
        cols[f"gyro_{axis}"] = gyro[:, k]
        cols[f"true_w{axis}"] = rate[:, k]
    for i in range(N):
        cols[f"omega_{i + 1}"] = speeds[:, i]
    return cols


def excited(samples: int = 1500):
    t = np.arange(samples) * 0.002
    rate = np.vstack([2.0 * np.sin(7 * t), 1.5 * np.cos(5 * t), 3.0 * np.sin(3 * t + 0.3)]).T
    speeds = 1800 + 200 * np.vstack([np.sin(11 * t + i) for i in range(N)]).T
    return rate, speeds


def dense_bound(cols, veh, config):
    """The same recursion with dense matrices (F built in full, batch update)."""
    rows = np.flatnonzero(np.isfinite(cols["gyro_x"]))
    t = cols["t"][rows]
    omega = np.vstack([cols[f"true_w{a}"][rows] for a in "xyz"]).T
    u = np.vstack([cols[f"omega_{i}"][rows] for i in range(1, N + 1)]).T ** 2
    j_inv = np.linalg.inv(INERTIA)
    z = np.array([0.0, 0.0, 1.0])
    a = np.array([j_inv @ np.cross(p, z) * KF for p in veh.positions]).T
    d = np.array([j_inv @ z * s * KM for s in veh.yaw_signs]).T
    n = 6 + 2 * N
    P = np.diag([config.rate_std0 ** 2] * 3 + [config.coeff_rel_std0 ** 2] * (2 * N)
                + [config.bias_std0 ** 2] * 3)
    H = np.hstack([np.eye(3), np.zeros((3, 2 * N)), np.eye(3)])
    stds = []
    for k in range(t.size):
        dt = t[k] - t[k - 1] if k else t[1] - t[0]
        if k:
            m = 0.5 * (omega[k] + omega[k - 1])
            eps = 1e-6
            jac = np.zeros((3, 3))
            for c in range(3):  # finite differences of the gyroscopic term
                e = np.zeros(3)
                e[c] = eps
                g = lambda w: -j_inv @ np.cross(w, INERTIA @ w)
                jac[:, c] = (g(m + e) - g(m - e)) / (2 * eps)
            ubar = 0.5 * (u[k] + u[k - 1])
            F = np.eye(n)
            F[0:3, 0:3] += dt * jac
            F[0:3, 3:3 + N] = dt * a * ubar
            F[0:3, 3 + N:3 + 2 * N] = dt * d * ubar
            Q = np.zeros((n, n))
            Q[0:3, 0:3] = np.eye(3) * config.rate_process_noise ** 2 * dt
            P = F @ P @ F.T + Q
        S = H @ P @ H.T + np.eye(3) * config.gyro_noise_density ** 2 / dt
        K = P @ H.T @ np.linalg.inv(S)
        P = (np.eye(n) - K @ H) @ P
        stds.append(np.sqrt(np.diag(P)))
    return np.array(stds)


def test_matches_a_dense_recursion():
    rate, speeds = excited(300)
    cols = columns(rate, speeds)
    bound = crlb.bound_along_log(cols, vehicle(), CONFIG)
    dense = dense_bound(cols, vehicle(), CONFIG)
    ours = np.hstack([bound.kf_std, bound.km_std, bound.bias_std])
    np.testing.assert_allclose(ours, dense[:, 3:], rtol=1e-6)


def test_excited_flight_reaches_the_band_and_only_tightens():
    rate, speeds = excited()
    bound = crlb.bound_along_log(columns(rate, speeds), vehicle(), CONFIG)
    coeff = np.hstack([bound.kf_std, bound.km_std])
    assert np.all(np.diff(coeff, axis=0) <= 1e-15)  # constant coefficients: never forgets
    times = bound.bound_times(0.1 * CONFIG.coeff_rel_std0, 0.1 * CONFIG.bias_std0)
    assert times["t_bound_coeff_s"] is not None and times["t_bound_coeff_s"] < 1.0
    assert times["t_bound_bias_s"] is not None
    assert times["t_bound3_coeff_s"] is None or times["t_bound3_coeff_s"] >= times["t_bound_coeff_s"]


def test_hover_never_separates_opposite_rotors_nor_biases():
    samples = 1500
    rate = np.zeros((samples, 3))
    speeds = np.full((samples, N), 1800.0)
    bound = crlb.bound_along_log(columns(rate, speeds), vehicle(), CONFIG)
    times = bound.bound_times(0.1 * CONFIG.coeff_rel_std0, 0.1 * CONFIG.bias_std0)
    assert times["t_bound_coeff_s"] is None and times["t_bound_bias_s"] is None
    # kf_1 + kf_3 unseen: each kf keeps at least half its prior variance
    assert np.all(bound.kf_std[-1] >= CONFIG.coeff_rel_std0 / math.sqrt(2) * 0.999)
    # the biases are not separated from the rates at rest
    assert np.all(bound.bias_std[-1] > 0.5 * CONFIG.rate_std0)


def test_quieter_gyro_gives_an_earlier_bound():
    rate, speeds = excited()
    cols = columns(rate, speeds)
    loud = crlb.bound_times_for_log(cols, vehicle(), CONFIG)
    quiet_config = crlb.BoundConfig(**{**CONFIG.__dict__, "gyro_noise_density": CONFIG.gyro_noise_density / 5})
    quiet = crlb.bound_times_for_log(cols, vehicle(), quiet_config)
    assert quiet["t_bound_coeff_s"] < loud["t_bound_coeff_s"]
