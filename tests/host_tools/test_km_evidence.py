"""`propid real-data --km-evidence` (propid/km_evidence.py, docs/real-data.md "km: what the information allows"):
the km combinations of the input channels, the yaw regression on a synthetic closed-loop flight with known
per-rotor km, the filter model's bound against the least-squares std, and the colour correction."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from propid.flightlog import FlightLog, parse_vehicle
from propid.km_evidence import combination_std, combination_weights, km_evidence, model_bound
from synthetic_vehicles import x_quad

INERTIA = [3.0e-5, 3.0e-5, 5.0e-5]
KF, KM = 3.0e-8, 1.0e-10
KM_REL = np.array([0.8, 1.0, 1.1, 1.3])
VEHICLE = parse_vehicle(x_quad("km-x", 0.045, INERTIA, 0.035, KF, KM))


def _smooth(rng, n, dt, cutoff_hz):
    """Unit-rms white noise through a first-order low-pass."""
    alpha = np.exp(-2 * np.pi * cutoff_hz * dt)
    out, state = np.empty(n), 0.0
    for k, w in enumerate(rng.standard_normal(n)):
        state = alpha * state + (1 - alpha) * w
        out[k] = state
    return out / np.std(out)


def _flight(seed=0, seconds=60.0, yaw_noise_pole=0.0, q=0.3):
    """A closed-loop X-quad flight in the filter's own discretisation (trapezoid input, Euler step): rate
    feedback on the roll, pitch and yaw channels plus smooth excitation on all four; white angular-acceleration
    noise q on every axis, on yaw passed through an AR(1) with the given pole (0: white)."""
    rng = np.random.default_rng(seed)
    dt, u_hover = 0.01, 3.0e6
    n = int(seconds / dt)
    positions = np.asarray(VEHICLE.positions)
    signs = np.asarray(VEHICLE.yaw_signs, dtype=float)
    patterns = np.array([signs, np.ones(4), np.sign(positions[:, 1]), -np.sign(positions[:, 0])])
    excitation = np.array([0.04, 0.1, 0.04, 0.04])[:, None] * u_hover * np.vstack(
        [_smooth(rng, n, dt, 3.0) for _ in range(4)])
    gains = np.array([2.5e5, 0.0, 7e4, 7e4])  # rate feedback: yaw from w_z, roll from w_x, pitch from w_y
    inertia = np.diag(INERTIA)
    torque_rows = np.vstack([KF * positions[:, 1], -KF * positions[:, 0], KM * KM_REL * signs])
    w = np.zeros((n, 3))
    u = np.full((n, 4), u_hover)
    coloured = 0.0
    for k in range(1, n):
        feedback = gains * np.array([w[k - 1, 2], 0.0, w[k - 1, 0], w[k - 1, 1]])
        u[k] = np.maximum(u_hover + (excitation[:, k] - feedback) @ patterns, 0.1 * u_hover)
        ubar = 0.5 * (u[k] + u[k - 1])
        torque = torque_rows @ ubar - np.cross(w[k - 1], inertia @ w[k - 1])
        noise = q * np.sqrt(dt) * rng.standard_normal(3)
        coloured = yaw_noise_pole * coloured + np.sqrt(1 - yaw_noise_pole**2) * noise[2]
        noise[2] = coloured
        w[k] = w[k - 1] + dt * np.linalg.solve(inertia, torque) + noise
    gyro = w + 1e-4 * rng.standard_normal(w.shape)
    return FlightLog(t=np.arange(n) * dt, gyro=gyro, rotor_speed=np.sqrt(u), extra={})


def test_channel_combinations_of_an_x_quad():
    weights = combination_weights(VEHICLE)
    np.testing.assert_allclose(weights[0], np.full(4, 0.25))  # the yaw channel measures the mean km
    np.testing.assert_allclose(weights[1], np.asarray(VEHICLE.yaw_signs) / 4)  # collective: the sign-weighted sum
    np.testing.assert_allclose(np.abs(weights), 0.25)
    np.testing.assert_allclose(weights @ weights.T, np.eye(4) / 4, atol=1e-15)  # four independent combinations
    stds = combination_std(0.04 * np.eye(4), VEHICLE)  # 20 % per rotor, independent: 10 % for each combination
    assert set(stds) == {"yaw", "collective", "roll", "pitch"}
    assert all(v == pytest.approx(0.1) for v in stds.values())


def test_white_flight_recovers_km_and_its_std():
    entry = km_evidence(_flight(), VEHICLE)
    assert entry["rotor_lag_samples"] == 0  # the streams are aligned in the filter's convention
    fit = entry["fits"]["without_rotor_inertia"]  # the vehicle file has no rotor inertia
    assert "with_rotor_inertia" not in entry["fits"]
    white = np.array(fit["white"]["rotor"])
    assert np.all(np.abs(np.array(fit["km_rel"]) - KM_REL) < 4 * white)
    assert np.all(white < 0.1)
    # white residual: the colour correction changes little; the filter model with walk 0 is the least-squares std
    # at the noise the replay's rule measures (pooled over the axes, so not the yaw residual's own level)
    np.testing.assert_allclose(fit["as_is"]["rotor"], white, rtol=0.3)
    pooled_over_yaw = entry["rate_process_noise"] / fit["yaw_residual_density"]
    with_prior = 1.0 / np.sqrt(1.0 / (white * pooled_over_yaw) ** 2 + 1.0 / 0.3**2)  # the library prior, 30 %
    np.testing.assert_allclose(entry["filter_model"]["walk_0"]["rotor"], with_prior, rtol=0.1)
    # the library walk forgets: its bound is above the constant-km one
    assert np.all(np.array(entry["filter_model"]["walk_0.02"]["rotor"]) > np.array(entry["filter_model"]["walk_0"]["rotor"]))
    assert entry["yaw_drive_rms"]["yaw"] == pytest.approx(
        4 * KM / INERTIA[2] * entry["excitation_rel"]["yaw"] * 3.0e6, rel=0.1)
    worst = max(fit["as_is"]["rotor"])
    assert entry["seconds_for_every_rotor"]["one_std_5pct"] == pytest.approx(
        entry["duration_s"] * (worst / 0.05) ** 2)


def test_model_bound_is_the_least_squares_covariance_without_prior_and_walk():
    rng = np.random.default_rng(3)
    regressors = rng.standard_normal((2000, 4)) * np.array([1.0, 2.0, 0.5, 1.0])
    variance = np.full(2000, 0.04)
    bound = model_bound(regressors, variance, walk=0.0, dt=0.01, prior=1e4)
    np.testing.assert_allclose(bound, 0.04 * np.linalg.inv(regressors.T @ regressors), rtol=1e-5, atol=1e-10)
    forgetting = model_bound(regressors, variance, walk=0.02, dt=0.01, prior=1e4)
    assert np.all(np.diag(forgetting) > np.diag(bound))


def test_coloured_yaw_residual_widens_the_std_as_is():
    entry = km_evidence(_flight(yaw_noise_pole=0.9), VEHICLE)
    fit = entry["fits"]["without_rotor_inertia"]
    assert np.all(np.array(fit["as_is"]["rotor"]) > 1.5 * np.array(fit["white"]["rotor"]))
    assert fit["residual_autocorrelation"]["1"] > 0.8


def test_cli_refuses_both_evidence_flags(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "propid.cli", "real-data", "--data", str(tmp_path),
                           "--vehicle", str(tmp_path / "v.json"), "--reference-kf", "3.72e-8", "--thrust-evidence",
                           "--km-evidence", "--out", str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "choose one" in proc.stderr and "Traceback" not in proc.stderr


def test_cli_km_evidence_needs_no_reference_kf(tmp_path):
    """--km-evidence divides nothing by a reference kf: it runs without --reference-kf (the replays refuse)."""
    import json

    from propid.flightlog import write_flightlog

    data = tmp_path / "data"
    data.mkdir()
    write_flightlog(data / "flight.csv", _flight(seconds=20.0))
    (data / "km-x.vehicle.json").write_text(json.dumps(x_quad("km-x", 0.045, INERTIA, 0.035, KF, KM)))
    command = [sys.executable, "-m", "propid.cli", "real-data", "--data", str(data), "--out", str(tmp_path / "out"),
               "--no-progress"]
    proc = subprocess.run([*command, "--km-evidence"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "| flight |" in proc.stdout and (tmp_path / "out" / "km_evidence.json").is_file()
    proc = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "--reference-kf is needed" in proc.stderr and "Traceback" not in proc.stderr


def test_cli_data_that_is_a_file_is_named(tmp_path):
    log = tmp_path / "flight.csv"
    log.write_text("t\n")
    proc = subprocess.run([sys.executable, "-m", "propid.cli", "real-data", "--data", str(log), "--km-evidence",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1 and "a file, not a directory" in proc.stderr and "Traceback" not in proc.stderr


def _bartlett_by_definition(scores, bandwidth):
    """sum over every pair of rows of w(|t - s|) x_t x_s', w(l) = 1 - l / (bandwidth + 1) up to floor(bandwidth)."""
    rows = np.atleast_2d(np.asarray(scores, dtype=float).T).T
    n = rows.shape[0]
    lag = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
    weight = np.where(lag <= np.floor(bandwidth), 1.0 - lag / (bandwidth + 1.0), 0.0)
    return rows.T @ weight @ rows


def test_one_newey_west_serves_the_km_evidence_and_the_gap():
    """km_evidence's coloured std and the gap's block-score variances are the same Bartlett long-run covariance
    (propid.signals): equal to its definition as a double sum, for a matrix and a scalar, an integer window
    and Andrews' fractional bandwidth, a window longer than the data."""
    from propid.gap.significance import andrews_bandwidth, long_run_variance
    from propid.km_evidence import newey_west
    from propid.signals import bartlett_long_run_covariance

    rng = np.random.default_rng(3)
    scores = np.cumsum(rng.standard_normal((60, 3)), axis=0) * 0.1 + rng.standard_normal((60, 3))
    for bandwidth in (0, 1, 4, 6.7, 200):
        np.testing.assert_allclose(bartlett_long_run_covariance(scores, bandwidth),
                                   _bartlett_by_definition(scores, bandwidth), rtol=1e-12)
        assert bartlett_long_run_covariance(scores[:, 0], bandwidth) == pytest.approx(
            _bartlett_by_definition(scores[:, 0], bandwidth)[0, 0], rel=1e-12)
    design, residual = rng.standard_normal((60, 3)), scores[:, 1]
    inverse = np.linalg.inv(design.T @ design)
    np.testing.assert_allclose(newey_west(design, residual, 5),
                               inverse @ _bartlett_by_definition(design * residual[:, None], 5) @ inverse, rtol=1e-12)
    c = scores[:, 2]
    variance, bandwidth = long_run_variance(c)
    assert bandwidth == andrews_bandwidth(c - c.mean()) and bandwidth > 1
    assert variance == pytest.approx(_bartlett_by_definition(c - c.mean(), bandwidth)[0, 0], rel=1e-12)


def test_filter_model_constants_are_the_libraries_defaults(cfilter_available):
    """The km bound's prior and walk and the 5 % target are propid_config_default()'s, read from the library."""
    from propid import km_evidence as ke
    from propid.cfilter import c_default_tuning

    c_defaults = c_default_tuning()
    assert ke.PRIOR_REL_STD == pytest.approx(c_defaults["drag_coeff_rel_std0"], rel=1e-6)
    assert ke.LIBRARY_WALK == pytest.approx(c_defaults["drag_coeff_rel_walk"], rel=1e-6)
    assert ke.TARGET_REL_STD == pytest.approx(c_defaults["converged_rel_std"], rel=1e-6)
