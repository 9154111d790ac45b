"""The vehicle file's aero_damping and gyro_scale carried by propid replay (replay/vehicle_terms.py):
a synthetic rate-loop flight of an airframe that damps its rates (-D omega) and whose gyro reads
s_a x the true rate; the replay with the file's keys recovers the coefficients the replay without
them misreads, and the JSON says where each value came from."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog, parse_vehicle
from propid.replay import ReplayOptions, replay
from test_replay import BIAS_TRUE, KF_TRUE, KM_TRUE, VEHICLE, fly_rate_loop, rate_loop_flight

DAMPING = [8.6e-5, 8.6e-5, 1.7e-4]  # [N m s/rad]: a decay rate of 6 1/s on every axis of this airframe
GYRO_SCALE = [1.06, 1.06, 0.97]


def damped_log(damping, gyro_scale, duration: float = 20.0, rate: float = 500.0, seed: int = 11) -> FlightLog:
    """test_replay's rate-loop flight with the body torque -damping omega and the gyro reading
    gyro_scale x the true rate (+ bias + white noise); clean rotor speeds (1 rad/s noise)."""
    rng = np.random.default_rng(seed)
    f = rate_loop_flight(duration, rate, rng)
    n = len(f.t)
    speeds, rate_true = fly_rate_loop(f, rate, damping=np.asarray(damping, dtype=float))
    gyro = rate_true * np.asarray(gyro_scale)[None, :] + BIAS_TRUE + rng.normal(0, 0.005, size=(n, 3))
    return FlightLog(t=f.t, gyro=gyro, rotor_speed=speeds + rng.normal(0, 1.0, size=speeds.shape), extra={})


def _errors(summary):
    kf = np.asarray(summary["kf_mean"]) / KF_TRUE
    km = np.asarray(summary["km_mean"]) / KM_TRUE
    return float(np.mean(kf)), float(np.max(np.abs(kf - 1.0))), float(np.mean(km))


@pytest.fixture(scope="module")
def damped_flight():
    return damped_log(DAMPING, [1.0, 1.0, 1.0])


def test_file_damping_removes_the_damping_bias(cfilter_available, damped_flight):
    vehicle = parse_vehicle({**VEHICLE, "aero_damping": DAMPING})
    off = replay(damped_flight, vehicle, ReplayOptions(progress=False, aero_damping="off")).summary
    on = replay(damped_flight, vehicle, ReplayOptions(progress=False, aero_damping="auto")).summary
    kf_off, _, km_off = _errors(off)
    kf_on, worst_on, km_on = _errors(on)
    print(f"kf/true off {kf_off:.4f} on {kf_on:.4f} (worst rotor {worst_on:.3f}); km off {km_off:.4f} on {km_on:.4f}")
    assert kf_off < 0.93 and km_off < 0.93  # the damping torque read as missing rotor torque
    assert abs(kf_on - 1.0) < 0.03 and worst_on < 0.06
    assert abs(km_on - 1.0) < 0.06
    assert on["config"]["aero_damping"] == pytest.approx(DAMPING)
    assert on["aero_damping"].startswith("vehicle file")
    assert "aero_damping" not in off["config"] and "--aero-damping off" in off["aero_damping"]


def test_file_gyro_scale_is_undone_at_the_boundary(cfilter_available):
    log = damped_log([0.0, 0.0, 0.0], GYRO_SCALE, seed=12)
    vehicle = parse_vehicle({**VEHICLE, "gyro_scale": GYRO_SCALE})
    off = replay(log, vehicle, ReplayOptions(progress=False, gyro_scale="off")).summary
    on = replay(log, vehicle, ReplayOptions(progress=False, gyro_scale="auto")).summary
    kf_off, _, km_off = _errors(off)
    kf_on, worst_on, km_on = _errors(on)
    print(f"kf/true: gyro scale kept {kf_off:.4f}, undone {kf_on:.4f} (worst rotor {worst_on:.3f}); "
          f"km {km_off:.4f} / {km_on:.4f}")
    assert kf_off > 1.04  # the gyro's 6 % larger roll and pitch rates read as 6 % more rotor torque
    assert abs(kf_on - 1.0) < 0.02 and worst_on < 0.05
    assert on["gyro_scale"].startswith("vehicle file: the gyro divided by")
    assert "--gyro-scale off" in off["gyro_scale"]


def test_vehicle_terms_refuse_what_they_cannot_carry(cfilter_available, damped_flight):
    short = replace(damped_flight)
    with pytest.raises(UserError, match="--aero-damping on needs 'aero_damping'"):
        replay(short, parse_vehicle(VEHICLE), ReplayOptions(progress=False, aero_damping="on"))
    negative = parse_vehicle({**VEHICLE, "aero_damping": [1e-5, -1e-5, 0.0]})
    with pytest.raises(UserError, match="negative component"):
        replay(short, negative, ReplayOptions(progress=False, aero_damping="auto"))
    none = replay(short, parse_vehicle(VEHICLE), ReplayOptions(progress=False, aero_damping="auto",
                                                               gyro_scale="auto")).summary
    assert none["aero_damping"] == "not modelled" and none["gyro_scale"].startswith("none")
