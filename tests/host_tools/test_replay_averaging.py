"""The window kf_mean_window/km_mean_window average over (replay/averaging.py): by default from the first sample whose std
is under the convergence bar; with --mean-window at-least-half never later than the replay's midpoint, so a
bar crossed just before the log's end does not leave the mean of its last few samples. The replay reports
where each window starts (kf_mean_from_s, km_mean_from_s) beside the crossing (kf_converged_from_s)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import parse_vehicle, write_flightlog, write_vehicle
from propid.replay import ReplayOptions, replay
from propid.replay.averaging import window_means, window_start
from test_replay import KF_NOMINAL, VEHICLE, _run_cli, synthetic_log


def _flags(n: int, crossing: int | None) -> np.ndarray:
    flags = np.zeros(n, dtype=bool)
    if crossing is not None:
        flags[crossing:] = True
    return flags


def test_the_window_starts_at_the_crossing_or_with_at_least_half_no_later_than_the_midpoint():
    n = 1001
    for crossing, default, at_least_half in ((120, 120, 120), (990, 990, n // 2), (None, n // 2, n // 2),
                                             (n // 2 + 1, n // 2 + 1, n // 2)):
        assert window_start(_flags(n, crossing)) == default
        assert window_start(_flags(n, crossing), "at-least-half") == at_least_half
    flags = _flags(n, 300)
    flags[400:600] = False  # the std may rise over the bar again: the first crossing counts
    assert window_start(flags) == window_start(flags, "at-least-half") == 300


def test_a_late_crossing_averages_half_of_the_samples_with_at_least_half():
    n = 200
    t = np.arange(n) * 0.01
    values = np.column_stack([np.linspace(1.0, 2.0, n), np.linspace(1.0, 2.0, n)])
    converged = np.column_stack([_flags(n, n - 3), _flags(n, 10)])
    means, starts, crossings = window_means(values, converged, t, "at-least-half")
    assert means[0] == pytest.approx(np.mean(values[n // 2:, 0]))  # not the mean of the last 3 samples
    assert starts == [pytest.approx(t[n // 2]), pytest.approx(t[10])]
    assert crossings == [pytest.approx(t[n - 3]), pytest.approx(t[10])]
    default = window_means(values, converged, t)
    assert default[0][0] == pytest.approx(np.mean(values[n - 3:, 0])) and default[1][0] == pytest.approx(t[n - 3])
    never = window_means(values, np.zeros((n, 2), dtype=bool), t)
    assert np.isnan(never[2]).all() and never[1] == [pytest.approx(t[n // 2])] * 2


def test_replay_reports_the_window_when_a_rotor_crosses_the_bar_near_the_end(cfilter_available):
    """A bar set so that rotor 1's kf std crosses it at 90 % of the flight. Without the coefficient walk the
    std only falls, so the bar taken from a first replay's std at 90 % is crossed there in the second (the
    bar does not change the estimates)."""
    log = synthetic_log(duration=6.0)
    vehicle = parse_vehicle(VEHICLE)
    no_walk = {"thrust_coeff_rel_walk": 0.0}
    first = replay(log, vehicle, ReplayOptions(progress=False, overrides=no_walk))
    std = first.series["kf_std"][:, 0]
    n = std.size
    bar = float(std[int(0.9 * n)]) * (1.0 + 1e-6) / KF_NOMINAL
    late = {**no_walk, "converged_rel_std": bar}
    default = replay(log, vehicle, ReplayOptions(progress=False, overrides=late))
    half = replay(log, vehicle, ReplayOptions(progress=False, overrides=late, mean_window="at-least-half"))
    np.testing.assert_array_equal(default.series["kf"], first.series["kf"])
    t, kf = default.series["t"], default.series["kf"]
    s, h = default.summary, half.summary
    crossing = s["kf_converged_from_s"][0]
    assert t[n // 2] < crossing <= t[int(0.9 * n)]  # the late crossing this test is about
    assert h["kf_converged_from_s"] == s["kf_converged_from_s"]
    # default: from the crossing (the last ~10 % of the samples), and it says so
    start = int(np.searchsorted(t, crossing))
    assert s["kf_mean_window"][0] == pytest.approx(float(np.mean(kf[start:, 0])), rel=1e-12)
    assert s["kf_mean_from_s"][0] == crossing and s["mean_window"] == "from-crossing"
    # at-least-half: the second half's mean
    assert h["kf_mean_window"][0] == pytest.approx(float(np.mean(kf[n // 2:, 0])), rel=1e-12)
    assert h["kf_mean_from_s"][0] == pytest.approx(t[n // 2]) and h["mean_window"] == "at-least-half"
    for k in range(4):  # every window by the midpoint, at the crossing when that is earlier
        assert h["kf_mean_from_s"][k] <= t[n // 2] and h["km_mean_from_s"][k] <= t[n // 2]
        c = h["kf_converged_from_s"][k]
        if np.isfinite(c) and c < t[n // 2]:
            assert h["kf_mean_from_s"][k] == c == s["kf_mean_from_s"][k]
    with pytest.raises(UserError, match="mean window 'last'"):
        replay(log, vehicle, ReplayOptions(progress=False, mean_window="last"))


def test_cli_mean_window_reaches_the_json(cfilter_available, tmp_path):
    log_path = tmp_path / "synthetic.csv"
    write_flightlog(log_path, synthetic_log(duration=3.0))
    write_vehicle(tmp_path / "synthetic.vehicle.json", parse_vehicle(VEHICLE))
    out = tmp_path / "out.json"
    assert _run_cli(["--log", str(log_path), "--json", str(out), "--no-progress", "--mean-window",
                     "at-least-half"]) == 0
    summary = json.loads(out.read_text())
    assert summary["mean_window"] == "at-least-half" and len(summary["kf_mean_from_s"]) == 4
    assert max(summary["kf_mean_from_s"]) <= summary["duration_s"] / 2 + 0.01
