"""What kf_mean/km_mean report (replay/averaging.py): the window's plain mean, the inverse-variance
(1/std^2) weighted mean of every recorded estimate or the time mean of the estimate smoothed backwards.
All are always in the summary under their own keys (kf_mean_window, kf_mean_inverse_variance,
kf_mean_smoothed; km_ the same) and mean_estimator says which kf_mean is."""

from __future__ import annotations

import json

import numpy as np
import pytest

from propid.cfilter import DEFAULT_TUNING
from propid.errors import UserError
from propid.flightlog import parse_vehicle, write_flightlog, write_vehicle
from propid.replay import ReplayOptions, replay
from propid.replay.averaging import coefficient_means, inverse_variance_means, smoothed_means, time_mean
from test_replay import KF_TRUE, KM_TRUE, VEHICLE, _run_cli, synthetic_log


def test_inverse_variance_mean_of_a_series_with_a_known_answer():
    n = 100
    # first half: value 2 with std 1; second half: value 1 with std 0.1 -> weights 1 and 100 per sample
    values = np.concatenate([np.full(n, 2.0), np.full(n, 1.0)])[:, None]
    stds = np.concatenate([np.full(n, 1.0), np.full(n, 0.1)])[:, None]
    expected = (2.0 * 1.0 + 1.0 * 100.0) / 101.0
    assert inverse_variance_means(values, stds) == [pytest.approx(expected, rel=1e-12)]
    # only the ratios of the stds matter, and tiny stds (kf ~ 1e-9) neither overflow nor underflow
    assert inverse_variance_means(values * 1e-8, stds * 1e-30) == [pytest.approx(expected * 1e-8, rel=1e-12)]
    # equal stds: the plain mean; a constant series: the constant, whatever the stds
    assert inverse_variance_means(values, np.ones_like(values)) == [pytest.approx(1.5, rel=1e-12)]
    assert inverse_variance_means(np.full((7, 1), 3.0), np.linspace(0.1, 5.0, 7)[:, None]) == [pytest.approx(3.0)]


def test_inverse_variance_mean_skips_unusable_samples():
    values = np.array([[1.0, 5.0], [np.nan, 5.0], [3.0, 5.0], [100.0, 5.0], [7.0, 5.0]])
    stds = np.array([[1.0, np.nan], [1.0, 0.0], [1.0, np.inf], [0.0, -1.0], [np.inf, np.nan]])
    means = inverse_variance_means(values, stds)
    assert means[0] == pytest.approx(2.0)  # rows 0 and 2 only: nan value, zero and infinite std dropped
    assert np.isnan(means[1])  # no usable sample


def test_coefficient_means_reports_both_estimators_and_picks_one():
    n = 10
    t = np.arange(n) * 0.1
    values = np.arange(1.0, n + 1.0)[:, None]
    stds = np.linspace(1.0, 0.1, n)[:, None]
    converged = (np.arange(n) >= 6)[:, None]
    window = coefficient_means(values, stds, converged, t, [0.0])
    weighted = coefficient_means(values, stds, converged, t, [0.0], "inverse-variance")
    smoothed = coefficient_means(values, stds, converged, t, [0.0], "smoothed")
    # without a walk every sample's smoothed estimate is the final one
    assert smoothed["mean"] == smoothed["smoothed"] == window["smoothed"] == [pytest.approx(float(n))]
    w = 1.0 / stds[:, 0] ** 2
    assert window["window"] == weighted["window"] == [pytest.approx(np.mean(values[6:, 0]))]
    assert window["inverse_variance"] == weighted["inverse_variance"] == [pytest.approx(np.sum(w * values[:, 0]) / w.sum())]
    assert window["mean"] == window["window"] and weighted["mean"] == weighted["inverse_variance"]
    assert window["from"] == weighted["from"] == [pytest.approx(0.6)] and window["crossing"] == [pytest.approx(0.6)]


def _scalar_walk_filter(truth: np.ndarray, dt: float, walk: float, noise_var: float) -> tuple[np.ndarray, np.ndarray]:
    """A scalar Kalman filter of a coefficient modelled as a random walk (variance walk^2 per second) measured
    directly with the given noise variance, started at 1 with std 0.3: its estimates and stds."""
    x, p = 1.0, 0.09
    xs, ps = np.empty_like(truth), np.empty_like(truth)
    for i, z in enumerate(truth):
        p += walk * walk * dt
        gain = p / (p + noise_var)
        x, p = x + gain * (z - x), p * (1.0 - gain)
        xs[i], ps[i] = x, p
    return xs, np.sqrt(ps)


@pytest.mark.parametrize("shape", ["step", "ramp"])
def test_smoothed_mean_recovers_the_flight_average_a_walking_filter_lags(shape):
    # The coefficient changes during the flight (a 20 % step at mid-flight, or a steady 20 % decline) and
    # the filter follows it with the walk's lag (memory about 2 s: std^2 / walk^2); noise-free measurements,
    # so only the lag separates the estimates from the truth. The user's number is the flight's average.
    dt, walk, noise_var = 0.01, 0.05, 1.0
    t = np.arange(0.0, 10.0, dt)
    truth = np.where(t < 5.0, 1.0, 0.8) if shape == "step" else 1.0 - 0.02 * t
    values, stds = _scalar_walk_filter(truth, dt, walk, noise_var)
    target = time_mean(truth, t)
    smoothed = smoothed_means(values[:, None], stds[:, None], t, [walk * walk])[0]
    weighted = inverse_variance_means(values[:, None], stds[:, None])[0]
    # 1/std^2 weighs the settled, lagging estimates uniformly: biased towards the early coefficient
    assert weighted / target - 1 > 0.02
    # the backward pass gives each sample the later samples' information: the lag is gone
    assert abs(smoothed / target - 1) < 0.002
    # in the estimate's units (kf ~ 1e-8): the same answer
    tiny = smoothed_means(values[:, None] * 1e-8, stds[:, None] * 1e-8, t, [(walk * 1e-8) ** 2])[0]
    assert tiny == pytest.approx(smoothed * 1e-8, rel=1e-9)


def test_smoothed_mean_of_a_constant_and_unusable_samples():
    t = np.linspace(0.0, 2.0, 21)
    values = np.full((21, 2), 3.0)
    stds = np.column_stack([np.linspace(1.0, 0.1, 21), np.full(21, np.nan)])
    assert smoothed_means(values, stds, t, [0.5, 0.5])[0] == pytest.approx(3.0)
    assert np.isnan(smoothed_means(values, stds, t, [0.5, 0.5])[1])  # no usable sample
    # uneven sampling: the mean is over time, not over samples
    # spans 0.05, 5 and 4.95 s: (1 x 0.05 + 1 x 5 + 4 x 4.95) / 10, not the samples' plain mean 2
    assert time_mean(np.array([1.0, 1.0, 4.0]), np.array([0.0, 0.1, 10.0])) == pytest.approx(2.485)


def test_replay_reports_both_means_and_the_chosen_one(cfilter_available):
    log = synthetic_log(duration=6.0)
    vehicle = parse_vehicle(VEHICLE)
    window = replay(log, vehicle, ReplayOptions(progress=False, mean_estimator="window")).summary
    result = replay(log, vehicle, ReplayOptions(progress=False))  # the default: inverse-variance
    weighted, series = result.summary, result.series
    assert window["mean_estimator"] == "window" and weighted["mean_estimator"] == "inverse-variance"
    for name in ("kf", "km"):
        # the same filter run: both estimators agree between the two replays; kf_mean is the chosen one
        assert window[f"{name}_mean_window"] == weighted[f"{name}_mean_window"]
        assert window[f"{name}_mean_inverse_variance"] == weighted[f"{name}_mean_inverse_variance"]
        assert window[f"{name}_mean"] == window[f"{name}_mean_window"]
        assert weighted[f"{name}_mean"] == weighted[f"{name}_mean_inverse_variance"]
        w = 1.0 / series[f"{name}_std"] ** 2
        np.testing.assert_allclose(weighted[f"{name}_mean"], np.sum(w * series[name], axis=0) / w.sum(axis=0),
                                   rtol=1e-12)
    # the smoothed mean: the backward pass over the same series, with the walks the filter ran with
    smoothed = replay(log, vehicle, ReplayOptions(progress=False, mean_estimator="smoothed")).summary
    assert smoothed["mean_estimator"] == "smoothed"
    for name, walk_key, nominal_key in (("kf", "thrust_coeff_rel_walk", "thrust_coeff_nominal"),
                                        ("km", "drag_coeff_rel_walk", "drag_coeff_nominal")):
        rates = [(smoothed["config"].get(walk_key, DEFAULT_TUNING[walk_key]) * v) ** 2 for v in smoothed["config"][nominal_key]]
        expected = smoothed_means(series[name], series[f"{name}_std"], series["t"], rates)
        np.testing.assert_allclose(smoothed[f"{name}_mean"], expected, rtol=1e-12)
        assert smoothed[f"{name}_mean_smoothed"] == weighted[f"{name}_mean_smoothed"] == smoothed[f"{name}_mean"]
    np.testing.assert_allclose(smoothed["kf_mean"], KF_TRUE, rtol=0.05)
    # the weighted mean lands on the synthetic truth as the window mean does
    np.testing.assert_allclose(weighted["kf_mean"], KF_TRUE, rtol=0.05)
    np.testing.assert_allclose(weighted["km_mean"], KM_TRUE, rtol=0.15)
    # it is not the window's mean: the prior-dominated start enters with small weight
    assert weighted["kf_mean"] != window["kf_mean"]
    with pytest.raises(UserError, match="mean estimator 'median'"):
        replay(log, vehicle, ReplayOptions(progress=False, mean_estimator="median"))


def test_cli_mean_estimator_reaches_the_json(cfilter_available, tmp_path):
    log_path = tmp_path / "synthetic.csv"
    write_flightlog(log_path, synthetic_log(duration=3.0))
    write_vehicle(tmp_path / "synthetic.vehicle.json", parse_vehicle(VEHICLE))
    out = tmp_path / "out.json"
    assert _run_cli(["--log", str(log_path), "--json", str(out), "--no-progress"]) == 0
    summary = json.loads(out.read_text())
    assert summary["mean_estimator"] == "inverse-variance"  # the default
    assert summary["kf_mean"] == summary["kf_mean_inverse_variance"] != summary["kf_mean_window"]
    assert "1/std^2" in summary["definitions"]["kf_mean_inverse_variance"]
    assert _run_cli(["--log", str(log_path), "--json", str(out), "--no-progress", "--mean-estimator", "window"]) == 0
    summary = json.loads(out.read_text())
    assert summary["mean_estimator"] == "window" and summary["kf_mean"] == summary["kf_mean_window"]
    assert _run_cli(["--log", str(log_path), "--json", str(out), "--no-progress", "--mean-estimator", "smoothed"]) == 0
    summary = json.loads(out.read_text())
    assert summary["mean_estimator"] == "smoothed" and summary["kf_mean"] == summary["kf_mean_smoothed"]
    assert "smoothed" in summary["definitions"]["kf_mean_smoothed"]
