"""The per-log rule for the thrust-torque scale's random walk (propid/replay/scale_walk.py) and
the replay's --torque-scale-walk option."""

from __future__ import annotations

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog, parse_vehicle
from propid.replay import ReplayOptions, replay
from propid.replay.scale_walk import WINDOW_S, estimate_scale_walk, window_gains
from synthetic_vehicles import x_quad

KF = 3.0e-8
KM = 1.0e-10
ARM = 0.035
MASS = 0.045
VEHICLE = x_quad("walk-x", MASS, [2.5e-5, 2.8e-5, 4.9e-5], ARM, KF, KM)


def flight(gain_late: float, duration: float = 48.0, rate: float = 100.0, seed: int = 3,
           gain_early: float = 1.0, collective: float = 0.0) -> FlightLog:
    """Rotor speeds around hover with multisine roll/pitch/yaw differentials; the body rates
    integrate the torques the rotors make, the roll/pitch ones at gain_early for the first half
    and gain_late after it (what the gyro sees changes, the thrust does not); `collective` [rad/s] adds a
    slow swing of every rotor's speed (climb and descent) that tells the accelerometer's bias from kf. Rate feedback
    keeps the rates bounded; the accelerometer reads the thrust over the mass."""
    rng = np.random.default_rng(seed)
    vehicle = parse_vehicle(VEHICLE)
    pos, signs = vehicle.positions, vehicle.yaw_signs
    inertia = np.array(VEHICLE["inertia"])
    n = int(duration * rate)
    t = np.arange(n) / rate
    hover = np.sqrt(MASS * 9.81 / (4 * KF))
    demand = np.zeros((n, 3))
    for axis in range(3):
        freqs, phases = rng.uniform(1.0, 6.0, 4), rng.uniform(0, 2 * np.pi, 4)
        demand[:, axis] = np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None]).sum(axis=0)
    omega = np.zeros(3)
    gyro = np.zeros((n, 3))
    speeds = np.zeros((n, 4))
    for k in range(n):
        gyro[k] = omega
        cmd = demand[k] - 3.0 * omega
        # differential speed per rotor from the roll (y), pitch (-x) and yaw demands
        speeds[k] = hover + collective * np.sin(2 * np.pi * 0.4 * t[k]) + 40.0 * (cmd[0] * np.sign(pos[:, 1]) - cmd[1] * np.sign(pos[:, 0]) + 0.5 * cmd[2] * signs)
        u = speeds[k] ** 2
        gain = gain_early if t[k] < duration / 2 else gain_late
        torque = np.array([gain * np.sum(KF * u * pos[:, 1]), -gain * np.sum(KF * u * pos[:, 0]),
                           np.sum(KM * u * signs)])
        omega = omega + (torque - np.cross(omega, inertia * omega)) / inertia / rate
    thrust = KF * np.sum(speeds ** 2, axis=1) / MASS
    acc = np.column_stack([np.zeros(n), np.zeros(n), thrust + rng.normal(0, 0.2, n)])
    extra = {"acc_x": acc[:, 0], "acc_y": acc[:, 1], "acc_z": acc[:, 2]}
    return FlightLog(t=t, gyro=gyro + rng.normal(0, 0.002, (n, 3)), rotor_speed=speeds, extra=extra)


def test_window_gains_see_the_torque_gain_and_its_change():
    vehicle = parse_vehicle(VEHICLE)
    log = flight(0.6)
    mask = np.ones(len(log), dtype=bool)
    (gains,) = window_gains(log, vehicle, mask, lag=0, trapezoid=False)
    half = len(gains) // 2
    assert len(gains) == int(48.0 / WINDOW_S) - 1  # the first row has no step: 11 whole windows
    np.testing.assert_allclose(gains[: half - 1], 1.0, atol=0.05)  # (the window astride the change excluded)
    np.testing.assert_allclose(gains[half + 1:], 0.6, atol=0.05)


def test_rule_gives_a_walk_for_a_changing_gain_and_almost_none_for_a_constant_one():
    vehicle = parse_vehicle(VEHICLE)
    mask = np.ones(480 * 10, dtype=bool)
    constant = estimate_scale_walk(flight(1.0), vehicle, mask, lag=0, trapezoid=False)
    changing = estimate_scale_walk(flight(0.6), vehicle, mask, lag=0, trapezoid=False)
    # one step of 0.4 among 10 adjacent pairs: sqrt(0.16 / 10 / (8 / 3)) = 0.077
    assert 0.05 < changing["walk"] < 0.1
    assert constant["walk"] < 0.2 * changing["walk"]
    assert changing["pairs"] == 10 and constant["rule"].startswith("sqrt")
    short = estimate_scale_walk(flight(0.6, duration=12.0), vehicle, np.ones(1200, dtype=bool), 0, False)
    assert short["walk"] == 0.0 and "constant" in short["rule"]  # too few windows: a constant scale


def test_replay_uses_the_rule_or_a_given_walk_and_refuses_it_without_the_scale(cfilter_available):
    vehicle = parse_vehicle(VEHICLE)
    log = flight(0.6)
    auto = replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro+accel", torque_scale_walk="auto"))
    assert auto.summary["config"]["torque_scale_walk"] > 0.05
    assert auto.summary["config_notes"]["torque_scale_walk"]["pairs"] == 10
    # A collective swing tells the accelerometer's bias from kf (without it the kf scale at
    # constant thrust is the prior's: docs/math.md §9).
    swing = flight(0.6, collective=400.0)
    given = replay(swing, vehicle, ReplayOptions(progress=False, aiding="gyro+accel", torque_scale_walk=0.1))
    assert given.summary["config"]["torque_scale_walk"] == 0.1
    # with the walk the scale ends near the late gain (0.6); kf stays with the accelerometer
    assert abs(given.summary["torque_scale"] - 0.6) < 0.1
    assert np.allclose(given.summary["kf_mean"], KF, rtol=0.05)
    with pytest.raises(UserError, match="needs the thrust-torque scale"):
        replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", torque_scale_walk=0.1))
    with pytest.raises(UserError, match="between 0 and 10"):
        replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro+accel", torque_scale_walk=-1.0))


@pytest.mark.parametrize("seed", [3, 5])
def test_a_perfect_model_keeps_the_scale_at_one_within_its_claimed_std(cfilter_available, seed):
    """The scale direction (s up, every kf down, the accelerometer bias up) is unseen at constant
    collective thrust. A filter whose kf states enter the gyro row as s kf (bilinear) drifts along it
    under its linearisation while its std shrinks (seed 3 ended at 1.47 claiming 0.018); with the
    gyro row linear in its states (g = s kf, r = 1/s in the accelerometer row: docs/math.md §9) the
    scale stays where the data put it or its std says it does not know."""
    log = flight(1.0, seed=seed)
    result = replay(log, parse_vehicle(VEHICLE),
                    ReplayOptions(progress=False, aiding="gyro+accel", rotor_inertia="off", torque_scale="on"))
    summary = result.summary
    assert abs(summary["torque_scale"] - 1.0) < 3.0 * summary["torque_scale_std"]
    np.testing.assert_allclose(summary["kf_mean"], KF, rtol=0.10)
