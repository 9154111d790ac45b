"""The torque scale of inertia_error with the motor commands (basefit.instrument_scales): a
least-squares scale against the accelerometer's kf also absorbs the attenuation of a noisy
rotor-speed regressor; the instrument takes that part out and leaves the true inertia error."""

import numpy as np
import pytest

from propid.gap import basefit
from propid.gap.prep import Band, Flight
from propid.realdata_checks import bandpass, difference_response

RATE = 100.0
KF = 2.0e-8
MASS = 0.05
POSITIONS = np.array([[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [-0.05, 0.0, 0.0], [0.0, -0.05, 0.0]])
SIGNS = np.array([1.0, -1.0, 1.0, -1.0])


def _flight(seed: int, inertia_scale: float, speed_noise: float, with_cmd: bool = True,
            seconds: float = 60.0) -> Flight:
    """Commands drive the rotors through a 20 ms lag and one sample of delay; the logged
    speeds carry white noise; J_true = inertia_scale x the file's J, so the torque measured
    with the file's inertia is the rotors' torque / inertia_scale."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    cmd = 0.5 + 0.08 * bandpass(rng.standard_normal((n, 4)), RATE, 0.5, 20.0) / 0.3
    a = np.exp(-1.0 / (RATE * 0.02))
    speed = np.zeros((n, 4))
    speed[0] = 4000.0 * cmd[0]
    for k in range(1, n):
        speed[k] = a * speed[k - 1] + (1 - a) * 4000.0 * cmd[k - 1]
    u = speed**2
    torque = np.zeros((n, 3))
    torque[:, 0] = difference_response(KF * (u @ POSITIONS[:, 1]), RATE) / inertia_scale
    torque[:, 1] = difference_response(-KF * (u @ POSITIONS[:, 0]), RATE) / inertia_scale
    torque[:, 2] = 1e-3 * rng.standard_normal(n) * 1e-6
    torque[:, :2] += 2e-6 * rng.standard_normal((n, 2))
    measured = speed + speed_noise * rng.standard_normal((n, 4))
    t = np.arange(n) / RATE
    blocks = [(s, min(s + 200, n)) for s in range(0, n, 200)]
    zeros3 = np.zeros((n, 3))
    return Flight(name=f"synthetic{seed}", path=None, rate_hz=RATE, t=t, gyro=zeros3, rate_dot=zeros3,
                  speed=measured, speed_dot=np.gradient(measured, t, axis=0), torque=torque,
                  specific_force_z=KF * u.sum(axis=1) / MASS, acc=None, body_velocity=None, height=None,
                  cmd=cmd if with_cmd else None, vbat=None, segs=[(0, n)], band=Band(1.0, 20.0), blocks=blocks)


def _least_squares_scale(f: Flight, axis: str) -> float:
    """What selection's fit gives: the accelerometer's kf over the least-squares torque kf."""
    thrust = basefit.fleet_fit([f], "thrust", POSITIONS, SIGNS, MASS, use_instrument=False)["value"]
    torque = basefit.fleet_fit([f], axis, POSITIONS, SIGNS, MASS, use_instrument=False)["value"]
    return thrust / torque


@pytest.mark.parametrize("seed,true_scale", [(1, 1.0), (2, 1.15)])
def test_the_instrument_leaves_the_true_inertia_scale(seed, true_scale):
    f = _flight(seed, true_scale, speed_noise=250.0)
    scales = {axis: _least_squares_scale(f, axis) for axis in ("roll", "pitch")}
    _, details = basefit.base_fit([f], POSITIONS, SIGNS, MASS, response_scales=scales)
    out = basefit.instrument_scales(scales, details)
    for axis in ("roll", "pitch"):
        assert scales[axis] > 1.06 * true_scale  # least squares: the attenuation is in the scale
        assert out[axis]["attenuation"] < 0.93
        # within 5 %: the thrust fit through the origin on noisy squared speeds reads ~1.6 % low
        assert out[axis]["scale"] == pytest.approx(true_scale, rel=0.05)
    # the after-fit with the instrument's scale reads the accelerometer's kf
    _, after = basefit.base_fit([f], POSITIONS, SIGNS, MASS,
                                response_scales={a: s["scale"] for a, s in out.items()})
    assert after["kf_roll"]["value"] == pytest.approx(after["kf_thrust"]["value"], rel=0.05)


def test_without_commands_there_is_nothing_to_correct():
    f = _flight(4, 1.1, speed_noise=250.0, with_cmd=False)
    scales = {"roll": _least_squares_scale(f, "roll")}
    _, details = basefit.base_fit([f], POSITIONS, SIGNS, MASS, response_scales=scales)
    assert basefit.instrument_scales(scales, details) == {}


def test_a_clean_regressor_keeps_the_least_squares_scale():
    f = _flight(5, 1.1, speed_noise=0.0)
    scales = {"roll": _least_squares_scale(f, "roll")}
    _, details = basefit.base_fit([f], POSITIONS, SIGNS, MASS, response_scales=scales)
    out = basefit.instrument_scales(scales, details)
    assert out["roll"]["scale"] == pytest.approx(scales["roll"], rel=0.02)
    assert out["roll"]["scale"] == pytest.approx(1.1, rel=0.03)
