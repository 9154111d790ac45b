"""propid gap --gyro-bias attitude: the gyro's constant bias measured against the logged attitude
and removed before the measured torque's gyroscopic term w x (J w) (gap/gyro_bias.py). Without it,
on a low-noise gyro a bias of a few mrad/s on z reads as a rotor inertia: its torque
(Jzz - Jxx) b_z (w_y, -w_x) has rotor_gyroscopic's shape when sum_i s_i Omega_i is nearly
constant, as on a vehicle whose rotors differ (found on RotorPy flights, docs/xsim.md)."""

from __future__ import annotations

import numpy as np
import pytest

from propid.flightlog import FlightLog, Rotor, Vehicle
from propid.gap import analysis
from propid.gap.gyro_bias import attitude_rate, gyro_bias_from_attitude
from propid.gap.prep import Band

KF, KM, ARM, MASS = 2.3e-8, 7.8e-10, 0.043, 0.03
INERTIA = np.diag([1.43e-5, 1.43e-5, 2.89e-5])
POSITIONS = np.array([[1, 1, 0], [1, -1, 0], [-1, -1, 0], [-1, 1, 0]]) * ARM / np.sqrt(2)
YAW_SIGNS = np.array([1, -1, 1, -1.0])
# unequal propellers: they hover at unequal speeds, so sum_i s_i Omega_i is not 0
KF_ROTOR = KF * np.array([1.06, 0.96, 1.02, 0.93])
KM_ROTOR = KM * np.array([0.95, 1.07, 0.97, 1.04])


def _rates(t):
    """Body rate (n, 3) and its derivative: roll/pitch sweeps and a slow large yaw."""
    parts = (((0, 0.6, 1.1), (0, 0.4, 2.3), (0, 0.2, 4.1)), ((1, 0.5, 0.9), (1, 0.4, 1.9), (1, 0.2, 3.7)),
             ((2, 1.4, 0.15), (2, 0.3, 0.7)))
    w, dw = np.zeros((t.size, 3)), np.zeros((t.size, 3))
    for axis_parts in parts:
        for axis, amplitude, freq in axis_parts:
            a = 2 * np.pi * freq
            w[:, axis] += amplitude * np.sin(a * t + axis)
            dw[:, axis] += amplitude * a * np.cos(a * t + axis)
    return w, dw


def _attitude(t, w):
    """Body-to-world quaternions (w, x, y, z) integrated from the body rate (exact per step)."""
    q = np.zeros((t.size, 4))
    q[0] = (1, 0, 0, 0)
    for k in range(1, t.size):
        rot = 0.5 * (w[k - 1] + w[k]) * (t[k] - t[k - 1])
        angle = np.linalg.norm(rot)
        dq = np.concatenate([[np.cos(angle / 2)], np.sinc(angle / (2 * np.pi)) * rot / 2])
        a, b = q[k - 1], dq  # q_k = q_{k-1} (x) dq (body-frame increment)
        q[k] = (a[0] * b[0] - a[1:] @ b[1:], *(a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:])))
    return q


def _flight(bias_z_sign: float, seed: int = 1, rate: float = 500.0, duration: float = 16.0):
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * rate)) / rate
    w, dw = _rates(t)
    torque = dw @ INERTIA.T + np.cross(w, w @ INERTIA.T)
    allocation = np.vstack([KF_ROTOR, KF_ROTOR * POSITIONS[:, 1], -KF_ROTOR * POSITIONS[:, 0],
                            KM_ROTOR * YAW_SIGNS])
    # climbs and descents: the collective thrust varies as in flight
    thrust = MASS * (9.81 + 1.5 * np.sin(2 * np.pi * 0.8 * t) + 0.8 * np.sin(2 * np.pi * 2.9 * t + 1.0))
    wrench = np.column_stack([thrust, torque])
    speed_sq = np.linalg.solve(allocation, wrench.T).T
    assert speed_sq.min() > 0
    speeds = np.sqrt(speed_sq)
    # the bias on z with the sign that makes its torque a positive rotor inertia
    spin = float(np.mean(speeds @ YAW_SIGNS))
    bias = np.array([0.005, -0.01, bias_z_sign * np.sign(spin) * 0.008])
    gyro = w + bias + 1.5e-3 * rng.standard_normal(w.shape)
    q = _attitude(t, w)
    q[::7] *= -1.0  # a quaternion and its negative are one attitude
    extra = {"qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "is_flying": np.ones(t.size)}
    log = FlightLog(t=t, gyro=gyro, rotor_speed=speeds, extra=extra)
    vehicle = Vehicle(name="synthetic-x", rotors=[Rotor(tuple(p), int(s)) for p, s in zip(POSITIONS, YAW_SIGNS)],
                      mass=MASS, inertia=INERTIA, kf_nominal=KF, km_nominal=KM)
    return log, vehicle, bias, w, q


def test_attitude_rate_is_the_body_rate_whatever_the_quaternion_sign():
    log, _, _, w, q = _flight(1.0, duration=4.0)
    rate = attitude_rate(log.t, q)
    inner = slice(5, -5)
    assert np.max(np.abs(rate[inner] - w[inner])) < 2e-3 * np.max(np.abs(w))


def test_the_bias_is_measured_and_refused_where_the_attitude_cannot_say():
    log, _, bias, _, q = _flight(1.0, duration=4.0)
    rows = np.arange(log.t.size)
    found = gyro_bias_from_attitude(log.t, log.gyro, q, rows)
    assert found["applied"] and np.allclose(found["value"], bias, atol=2e-4)
    assert not gyro_bias_from_attitude(log.t, log.gyro, None, rows)["applied"]
    sparse = q.copy()
    sparse[::3] = np.nan  # two rows in three keep their attitude: still measured
    assert gyro_bias_from_attitude(log.t, log.gyro, sparse, rows)["applied"]
    sparse[: int(0.6 * rows.size)] = np.nan
    assert "too few" in gyro_bias_from_attitude(log.t, log.gyro, sparse, rows)["why"]
    # an attitude that is not the body's (here: the gyro shifted by 1 rad/s) is no bias measurement
    refused = gyro_bias_from_attitude(log.t, log.gyro + 1.0, q, rows)
    assert not refused["applied"] and "above" in refused["why"]


def _gyroscopic(result):
    return next(e for e in result["effects"] if e["id"] == "rotor_gyroscopic")


@pytest.mark.parametrize("bias_z_sign", [1.0, -1.0])
def test_a_gyro_bias_is_not_taken_for_a_rotor_inertia_with_the_attitude(bias_z_sign):
    log, vehicle, bias, _, _ = _flight(bias_z_sign)
    measured = analysis.run([log], vehicle, [], analysis.Options(Band(), progress=False, gyro_bias="attitude"))
    assert measured["significant"] == [] and measured["verdict"] == "none"
    entry = next(iter(measured["gyro_bias"]["per_log"].values()))
    assert entry["applied"] and np.allclose(entry["value"], bias, atol=2e-4)
    assert abs(_gyroscopic(measured)["explained_fraction"]) < 0.05
    # as logged, the bias's torque is rotor_gyroscopic's shape: it takes much of the residual, with the
    # sign of a positive rotor inertia when b_z has the sign of sum s_i Omega_i (then named: false)
    logged = analysis.run([log], vehicle, [], analysis.Options(Band(), progress=False))
    gyroscopic = _gyroscopic(logged)
    assert gyroscopic["explained_fraction"] > 0.1
    assert np.sign(gyroscopic["params"]["rotor_inertia"]) == bias_z_sign
    assert ("rotor_gyroscopic" in logged["significant"]) == (bias_z_sign > 0)
