"""The per-log rule for the rotor-speed input error (propid/replay/input_noise.py) and the
replay's --rotor-speed-noise option (docs/math.md §14)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog
from propid.replay import ReplayOptions, replay
from propid.replay.input_noise import estimate_rotor_speed_noise

from test_scale_walk import VEHICLE, flight  # a multisine flight around hover at 100 Hz

RATE = 100.0


def smooth_speeds(n: int, seed: int = 5, amplitude: float = 60.0) -> np.ndarray:
    """Four smooth motor speeds around 2000 rad/s (slow sines, far below the sample rate)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    speeds = np.empty((n, 4))
    for i in range(4):
        f, phase = rng.uniform(0.2, 1.0, 3), rng.uniform(0, 2 * np.pi, 3)
        speeds[:, i] = 2000.0 + amplitude * np.sin(2 * np.pi * f[:, None] * t + phase[:, None]).sum(axis=0)
    return speeds


def log_of(speeds: np.ndarray) -> FlightLog:
    n = len(speeds)
    return FlightLog(t=np.arange(n) / RATE, gyro=np.zeros((n, 3)), rotor_speed=speeds)


def test_white_error_is_measured_with_one_sample_interval():
    n = 6000
    rng = np.random.default_rng(1)
    log = log_of(smooth_speeds(n) + rng.normal(0.0, 8.0, (n, 4)))
    info = estimate_rotor_speed_noise(log, np.ones(n, dtype=bool))
    assert 7.0 < info["sigma"] < 9.0  # 8 rad/s, the smooth motion nearly cancels in the second difference
    assert info["time"] == pytest.approx(1.0 / RATE, rel=0.05)


def test_quantisation_and_held_samples_are_seen():
    n = 6000
    step = 4.0
    # slow enough to sit on a step for several samples, on a 4 rad/s grid: std 4 / sqrt(12) = 1.15
    speeds = np.round(smooth_speeds(n, amplitude=10.0) / step) * step
    held = speeds.copy()
    held[1::3] = held[0:-1:3]  # every third row repeats the previous sample
    info = estimate_rotor_speed_noise(log_of(held), np.ones(n, dtype=bool))
    assert info["per_rotor"][0]["step"] == pytest.approx(step)
    assert 1.0 < info["sigma"] < 1.6
    # one step takes much longer than a sample to cross at these slews: a long correlation time
    assert info["time"] > 3.0 / RATE
    # crossing several steps per sample, the grid is white noise: measured once, not twice
    fast = np.round(smooth_speeds(n, amplitude=300.0) / step) * step
    white = estimate_rotor_speed_noise(log_of(fast), np.ones(n, dtype=bool))
    assert white["sigma"] < 1.6
    exact = estimate_rotor_speed_noise(log_of(smooth_speeds(n)), np.ones(n, dtype=bool))
    assert exact["sigma"] < 0.1  # neither noise nor a grid: (almost) nothing


def test_too_few_samples_switch_it_off():
    info = estimate_rotor_speed_noise(log_of(smooth_speeds(30)), np.ones(30, dtype=bool))
    assert info["sigma"] == 0.0 and info["rotors"] == 0


def test_replay_sets_the_filter_fields(cfilter_available):
    from propid.flightlog import parse_vehicle

    vehicle = parse_vehicle(VEHICLE)
    log = flight(1.0, duration=12.0)
    auto = replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise="auto"))
    assert auto.summary["config"]["rotor_speed_noise"] == auto.summary["config_notes"]["rotor_speed_noise"]["sigma"]
    given = replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise=50.0,
                                               rotor_speed_noise_time=0.05))
    plain = replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro"))
    assert given.summary["config"]["rotor_speed_noise"] == 50.0
    assert given.summary["config"]["rotor_speed_noise_time"] == 0.05
    # a large input error: the coefficients are less certain than with exact inputs
    assert np.mean(given.summary["kf_std"]) > 1.2 * np.mean(plain.summary["kf_std"])
    with pytest.raises(UserError, match="needs --rotor-speed-noise"):
        replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise_time=0.01))
    with pytest.raises(UserError, match="between 0 and 1"):
        replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise=1.0,
                                           rotor_speed_noise_time=2.0))


def test_replay_sets_the_compensation(cfilter_available):
    """--input-error-compensation on: the filter field is set with an error size, refused without one, and
    switched off (with a note) when the rule finds no error."""
    from propid.flightlog import parse_vehicle

    vehicle = parse_vehicle(VEHICLE)
    log = flight(1.0, duration=12.0)
    noisy = ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise=20.0)
    on = replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise=20.0,
                                            input_error_compensation=True))
    off = replay(log, vehicle, noisy)
    assert on.summary["config"]["input_error_compensation"] == 1
    assert "input_error_compensation" not in off.summary["config"]
    assert on.summary["kf_mean"] != off.summary["kf_mean"]
    with pytest.raises(UserError, match="needs --rotor-speed-noise"):
        replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", input_error_compensation=True))
    zero = replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro", rotor_speed_noise=0.0,
                                              input_error_compensation=True))
    assert zero.summary["config"]["input_error_compensation"] == 0
    assert "error is 0" in zero.summary["config_notes"]["input_error_compensation"]


def test_cli_refuses_a_bad_value_in_one_line():
    proc = subprocess.run([sys.executable, "-m", "propid.cli", "replay", "--log", "x.csv", "--rotor-speed-noise", "-3"],
                          capture_output=True, text=True)
    assert proc.returncode != 0
    assert "between 0 and 10000" in proc.stderr and "Traceback" not in proc.stderr


@pytest.fixture(scope="module")
def cfilter_available():
    from propid.cfilter import load_library

    try:
        load_library()
    except UserError as exc:
        pytest.skip(str(exc))
