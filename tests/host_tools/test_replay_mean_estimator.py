"""What kf_mean/km_mean report (replay/averaging.py): the window's plain mean or the inverse-variance
(1/std^2) weighted mean of every recorded estimate. Both are always in the summary under their own keys
(kf_mean_window, kf_mean_inverse_variance; km_ the same) and mean_estimator says which kf_mean is."""

from __future__ import annotations

import json

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import parse_vehicle, write_flightlog, write_vehicle
from propid.replay import ReplayOptions, replay
from propid.replay.averaging import coefficient_means, inverse_variance_means
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
    window = coefficient_means(values, stds, converged, t)
    weighted = coefficient_means(values, stds, converged, t, "inverse-variance")
    w = 1.0 / stds[:, 0] ** 2
    assert window["window"] == weighted["window"] == [pytest.approx(np.mean(values[6:, 0]))]
    assert window["inverse_variance"] == weighted["inverse_variance"] == [pytest.approx(np.sum(w * values[:, 0]) / w.sum())]
    assert window["mean"] == window["window"] and weighted["mean"] == weighted["inverse_variance"]
    assert window["from"] == weighted["from"] == [pytest.approx(0.6)] and window["crossing"] == [pytest.approx(0.6)]


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
