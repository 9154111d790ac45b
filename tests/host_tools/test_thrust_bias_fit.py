"""realdata_checks: the thrust fit with a free bias and a climb term, and the repeated-row shares
(docs/real-data.md "Repeated rows" and "The square runs' offset with the accelerometer")."""

from __future__ import annotations

import numpy as np
import pytest

from propid.flightlog import FlightLog
from propid.realdata_checks import repeated_row_shares, thrust_fit_with_bias

KF, BIAS_FORCE, CLIMB = 3.7e-8, 0.02, -2.0e-6


def climbing_flight(seed: int = 1, n: int = 6000):
    """Collective and body-z velocity of a flight that climbs when it pushes harder (correlated)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    speed = 1750.0 + 120.0 * np.sin(2 * np.pi * 0.4 * t) + 40.0 * rng.standard_normal(n)
    sum_u = 4.0 * speed**2
    v_z = 0.8 * np.sin(2 * np.pi * 0.4 * t - 0.6)  # the climb follows the thrust with a lag
    climb = 4.0 * speed * v_z
    force = KF * sum_u + CLIMB * climb + BIAS_FORCE + 0.002 * rng.standard_normal(n)
    return force, sum_u, climb


def test_thrust_fit_with_bias_recovers_the_slope_bias_and_climb_term():
    force, sum_u, climb = climbing_flight()
    rows = np.ones(force.size, dtype=bool)
    fit = thrust_fit_with_bias(force, sum_u, rows, climb)
    assert fit["kf"] == pytest.approx(KF, rel=0.005)
    assert fit["climb"] == pytest.approx(CLIMB, rel=0.02)
    assert fit["bias_force"] == pytest.approx(BIAS_FORCE, abs=0.005)
    # without the climb term the slope takes part of it (the climb correlates with the collective)
    plain = thrust_fit_with_bias(force, sum_u, rows)
    assert abs(plain["kf"] / KF - 1.0) > 0.01 and np.isnan(plain["climb"])
    # too few rows: NaN, not a number from noise
    few = np.zeros(force.size, dtype=bool)
    few[:5] = True
    assert np.isnan(thrust_fit_with_bias(force, sum_u, few)["kf"])


def test_repeated_row_shares_count_exact_copies_of_the_previous_row():
    rng = np.random.default_rng(3)
    n = 200
    gyro = rng.normal(0.0, 0.3, size=(n, 3))
    speeds = 1700.0 + rng.normal(0.0, 20.0, size=(n, 4))
    copies = np.arange(10, n, 10)  # 19 rows copy the previous gyro sample
    gyro[copies] = gyro[copies - 1]
    speeds[copies[:5]] = speeds[copies[:5] - 1]  # 5 of them the rotor speeds too
    speeds[55, 2] = speeds[54, 2]  # one rotor alone repeating is a new set of speeds
    log = FlightLog(t=np.arange(n) * 0.01, gyro=gyro, rotor_speed=speeds, extra={})
    every = np.ones(n, dtype=bool)
    shares = repeated_row_shares(log, every)
    assert shares == {"gyro": pytest.approx(19 / n), "rotor": pytest.approx(5 / n)}
    half = every.copy()
    half[100:] = False  # only the first 100 rows: 9 gyro copies (10..90), 5 rotor copies
    assert repeated_row_shares(log, half) == {"gyro": pytest.approx(9 / 100), "rotor": pytest.approx(5 / 100)}
    assert np.isnan(repeated_row_shares(log, np.zeros(n, dtype=bool))["gyro"])
