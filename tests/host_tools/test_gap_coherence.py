"""gap's shrink bound (gap/coherence.py): the share of the measured torque no linear time-invariant model
of the logged input channels predicts. A torque made of a lagged, filtered function of the rotor speeds
plus independent noise: the bound is the noise's share, whatever the lag and filter."""

import numpy as np
import pytest

from propid.gap import coherence
from propid.gap.prep import Band, Flight
from propid.realdata_checks import bandpass

RATE = 100.0
POSITIONS = np.array([[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [-0.05, 0.0, 0.0], [0.0, -0.05, 0.0]])


def _flight(seed: int, noise_rms: float, seconds: float = 120.0) -> Flight:
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    speed = 2000.0 + 200.0 * bandpass(rng.standard_normal((n, 4)), RATE, 0.5, 30.0) / 0.5
    u = speed**2
    drive = 1e-8 * (u @ POSITIONS[:, 1])
    lagged = np.concatenate([np.full(3, drive[0]), drive[:-3]])  # a 30 ms lag and a low-pass: still LTI
    roll = bandpass((lagged - lagged.mean())[:, None], RATE, None, 20.0)[:, 0]
    torque = np.zeros((n, 3))
    torque[:, 0] = roll + noise_rms * rng.standard_normal(n)
    torque[:, 1] = noise_rms * rng.standard_normal(n)  # nothing but noise
    torque[:, 2] = 1e-8 * (u @ np.array([1.0, -1.0, 1.0, -1.0])) * 1e-2
    t = np.arange(n) / RATE
    zeros3 = np.zeros((n, 3))
    return Flight(name=f"synthetic{seed}", path=None, rate_hz=RATE, t=t, gyro=zeros3, rate_dot=zeros3, speed=speed,
                  speed_dot=np.gradient(speed, t, axis=0), torque=torque, specific_force_z=None, acc=None,
                  body_velocity=None, height=None, cmd=None, vbat=None, segs=[(0, n)], band=Band(2.0, 25.0))


def _band_rms(f: Flight, x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(f.filtered(x) ** 2)))


@pytest.mark.parametrize("noise_rms", [2e-4, 5e-4])
def test_the_floor_is_the_noise_share(noise_rms):
    f = _flight(1, noise_rms)
    rng = np.random.default_rng(1)
    share = coherence.unpredictable_share([f])
    # the truth: the noise's band RMS over the torque's band RMS (white noise of the same level, same filter)
    truth = _band_rms(f, noise_rms * rng.standard_normal(len(f.t))) / _band_rms(f, f.torque[:, 0])
    print(f"noise {noise_rms:g}: floor {share['roll']:.3f}, truth {truth:.3f}")
    assert share["roll"] == pytest.approx(truth, abs=0.04)
    assert share["pitch"] > 0.95  # pure noise: nothing predicts it
    assert share["yaw"] < 0.1  # an instantaneous function of the rotor speeds, no noise
    assert share["channels"] == 8 and share["windows"] >= 40


def test_the_bound_on_the_shrink():
    f = _flight(2, 3e-4)
    share = coherence.unpredictable_share([f])
    response = _band_rms(f, f.torque[:, 0])
    before = 0.9 * response  # a base model that explains little
    out = coherence.shrink_bound([f], {"roll": {"rms_before": before}})
    assert out["computed"] and out["coherence_bias"] < 0.2
    assert out["roll"]["base_residual_share"] == pytest.approx(0.9, rel=1e-6)
    assert out["roll"]["max_shrink"] == pytest.approx(1.0 - share["roll"] / 0.9, rel=1e-6)
    assert out["roll"]["rotor_streams_only_share"] == pytest.approx(share["roll"], abs=0.02)  # only rotors here


def test_too_short_a_log_is_not_bounded():
    f = _flight(3, 1e-4, seconds=10.0)
    assert coherence.unpredictable_share([f]) is None
    assert coherence.shrink_bound([f], {})["computed"] is False
