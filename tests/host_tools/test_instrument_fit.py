"""Torque fits with the motor commands as instruments (realdata_checks.instrument_fit) and the
central difference's response (difference_response)."""

import numpy as np
import pytest

from propid.realdata_checks import bandpass, difference_response, instrument_fit

RATE = 100.0
BAND = (5.0, 20.0)
GAIN = 0.9


def test_the_difference_response_is_what_a_central_difference_does_to_a_sine():
    t = np.arange(2000) / RATE
    for f in (5.0, 12.0, 20.0):
        w = 2 * np.pi * f
        measured = np.gradient(np.sin(w * t), t)
        modelled = difference_response(w * np.cos(w * t), RATE)
        inner = slice(200, -200)
        assert measured[inner] == pytest.approx(modelled[inner], abs=1e-6 * w)
        assert np.std(measured[inner]) / np.std(w * np.cos(w * t)[inner]) < 1.0 - 0.01 * (f > 10)


def flight(seed, seconds=90.0, noise=1.5):
    """Commands drive the rotor torque through a 20 ms lag; the telemetry of it is noisy."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    command = bandpass(rng.standard_normal((n, 1)), RATE, 1.0, 30.0)[:, 0]
    command /= command.std()
    true = np.zeros(n)
    a = np.exp(-1.0 / (RATE * 0.02))
    for k in range(1, n):  # first-order motor, one sample of transport delay
        true[k] = a * true[k - 1] + (1 - a) * command[k - 1]
    true /= true.std()
    measured = true + noise * rng.standard_normal(n)
    response = GAIN * difference_response(true, RATE) + 0.2 * rng.standard_normal(n)
    return command, measured, response


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_commands_as_instruments_undo_the_telemetry_noise(seed):
    command, measured, response = flight(seed)
    n = command.size
    fit = instrument_fit(response, measured, command[:, None], [(0, n)], RATE, BAND, 0)
    assert fit["plain"] < 0.8 * GAIN  # least squares with a noisy regressor
    assert fit["kf"] == pytest.approx(GAIN, rel=0.06)
    assert 0.05 < fit["first_stage_r2"] < 1.0


def test_an_instrument_that_shares_the_noise_does_not_help():
    command, measured, response = flight(4)
    n = command.size
    shared = np.roll(measured, -3)[:, None]  # the telemetry itself, 3 samples later, on the response's clock
    fit = instrument_fit(response, measured, shared, [(0, n)], RATE, BAND, 0)
    assert fit["kf"] < 0.8 * GAIN


def test_too_short_segments_give_no_fit():
    command, measured, response = flight(5, seconds=0.4)
    fit = instrument_fit(response, measured, command[:, None], [(0, command.size)], RATE, BAND, 0)
    assert np.isnan(fit["kf"]) and np.isnan(fit["first_stage_r2"])
