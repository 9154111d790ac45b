"""The excitation-grouped torque fit (realdata_checks.grouped_fit): an additive term on the
regressor side (rotor-speed noise, or the rotors' answer to a torque the controller cancels)
attenuates plain least squares but not the grouped slope; a gain error stays in both."""

import numpy as np
import pytest

from propid.realdata_checks import bandpass, grouped_fit

RATE = 100.0
BAND = (2.0, 10.0)
GAIN = 0.8


def excitation_and_signal(seed, seconds=120.0):
    """A band-limited manoeuvre whose size changes every 4 s (factor 10 between calm and hard)."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    size = np.repeat(rng.uniform(0.3, 3.0, int(seconds / 4) + 1), int(4 * RATE))[:n]
    shape = bandpass(rng.standard_normal((n, 1)), RATE, 1.0, 15.0)[:, 0]
    return rng, size, size * shape / shape.std()


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_an_additive_regressor_term_biases_the_plain_slope_and_not_the_grouped_one(seed):
    rng, size, x_true = excitation_and_signal(seed)
    n = x_true.size
    noise = bandpass(rng.standard_normal((n, 1)), RATE, 1.0, 15.0)[:, 0]
    noise *= 1.2 / noise.std()  # constant power, about the calm manoeuvres' size
    y = GAIN * x_true + 0.1 * rng.standard_normal(n)
    fit = grouped_fit(y, x_true + noise, size + 0.05 * rng.standard_normal(n), [(0, n)], RATE, BAND, 0)
    assert fit["plain"] < 0.9 * GAIN  # attenuated
    assert fit["kf"] == pytest.approx(GAIN, rel=0.06)
    in_band = bandpass(noise[:, None], RATE, *BAND)[:, 0].std()
    assert fit["additive_rms"] == pytest.approx(GAIN * in_band, rel=0.25)
    assert fit["group_slopes"] == sorted(fit["group_slopes"])  # calm groups are the most attenuated


@pytest.mark.parametrize("seed", [4, 5])
def test_a_cancelled_disturbance_is_read_as_an_additive_term(seed):
    """Closed loop: the rotors answer 80 % of a disturbance torque d; the gyro sees the rest."""
    rng, size, reference = excitation_and_signal(seed)
    n = reference.size
    d = bandpass(rng.standard_normal((n, 1)), RATE, 1.0, 15.0)[:, 0]
    d *= GAIN / d.std()
    rotor = reference - 0.8 * d / GAIN  # rotor torque in model units
    measured = GAIN * rotor + d
    fit = grouped_fit(measured, rotor, size, [(0, n)], RATE, BAND, 0)
    assert fit["plain"] < 0.9 * GAIN
    assert fit["kf"] == pytest.approx(GAIN, rel=0.06)


@pytest.mark.parametrize("seed", [6, 7])
def test_a_gain_error_alone_is_kept_by_both(seed):
    rng, size, x_true = excitation_and_signal(seed)
    y = GAIN * x_true + 0.05 * rng.standard_normal(x_true.size)
    fit = grouped_fit(y, x_true, size, [(0, x_true.size)], RATE, BAND, 0)
    assert fit["plain"] == pytest.approx(GAIN, rel=0.02)
    assert fit["kf"] == pytest.approx(GAIN, rel=0.03)


def test_no_spread_in_excitation_gives_no_grouped_slope():
    rng = np.random.default_rng(8)
    n = 6000
    x = bandpass(rng.standard_normal((n, 1)), RATE, 1.0, 15.0)[:, 0]
    fit = grouped_fit(GAIN * x, x, rng.standard_normal(n), [(0, n)], RATE, BAND, 0)
    assert np.isnan(fit["kf"]) and np.isnan(fit["additive_rms"])
    assert fit["plain"] == pytest.approx(GAIN, rel=0.01)
