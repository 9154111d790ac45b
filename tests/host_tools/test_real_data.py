"""`propid real-data` (docs/real-data.md): skips cleanly without the real logs; the summary
statistics; one real log in one mode when ../shared is present."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from propid import real_data

SHARED = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "real" / "crazyflie21b"


def test_missing_data_is_skipped_cleanly(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "propid.cli", "real-data", "--data", str(tmp_path / "none"),
                           "--reference-kf", "3.72e-8", "--skip-missing", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "skipped" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "propid.cli", "real-data", "--data", str(tmp_path / "none"),
                           "--reference-kf", "3.72e-8"], capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "no such directory" in proc.stderr and "Traceback" not in proc.stderr


def test_mode_summary_statistics():
    runs = {"square_a": dict(kf_over_reference=1.0, rotor_spread=0.02, km=1e-10, km_converged=True,
                             accel_bias=0.1, finite=True, p_every_rotor_within_5pct=0.9,
                             km_worst_rotor_rel_std=0.2, km_mean_rel_std=0.1),
            "random_b": dict(kf_over_reference=0.8, rotor_spread=0.10, km=2e-10, km_converged=False,
                             accel_bias=0.3, finite=True, p_every_rotor_within_5pct=0.5,
                             km_worst_rotor_rel_std=0.1, km_mean_rel_std=0.05),
            "random_c": dict(kf_over_reference=0.6, rotor_spread=0.04, km=3e-10, km_converged=False,
                             accel_bias=0.5, finite=True, p_every_rotor_within_5pct=0.25,
                             km_worst_rotor_rel_std=0.3, km_mean_rel_std=0.2)}
    s = real_data.mode_summary(runs)
    assert s["kf_fleet_over_reference"] == pytest.approx(0.8) and s["kf_run_cv"] == pytest.approx(0.25)
    assert s["square_kf"] == 1.0 and s["other_kf"] == pytest.approx(0.7) and s["other_runs"] == 2
    assert s["worst_rotor_spread"] == 0.10 and s["runs_every_rotor_within_5pct"] == 2
    assert s["runs_km_converged"] == 1 and s["accel_bias_median"] == 0.3
    assert s["runs_every_rotor_within_5pct_if_equal"] == pytest.approx(1.65)  # the sum of the runs' chances
    assert s["km_worst_rotor_rel_std_median"] == 0.2 and s["km_mean_rel_std_median"] == 0.1


def test_render_without_square_runs_and_one_run_per_group_shows_no_nan():
    """A directory of other logs (no name starts with "square", one "square" log) of a hexa: the groups' kf and CV
    read '-' where undefined, not 'nan'; the converged km count is out of the vehicle's rotors."""
    base = dict(rotor_spread=0.02, km=1e-10, km_converged=False, accel_bias=0.1, finite=True,
                p_every_rotor_within_5pct=0.9, km_worst_rotor_rel_std=0.2, km_mean_rel_std=0.1, esc_delay_s=0.0,
                km_converged_rotors=1, rotor_count=6)
    for runs in ({"hover_a": dict(base, kf_over_reference=1.0), "hover_b": dict(base, kf_over_reference=0.9)},
                 {"square_a": dict(base, kf_over_reference=1.0), "hover_b": dict(base, kf_over_reference=0.9)}):
        result = {"reference_kf": 3.72e-8,
                  "modes": [{"name": "gyro", "what": "gyro only", "runs": runs, "summary": real_data.mode_summary(runs)}]}
        text = real_data.render(result)
        assert "nan" not in text.lower()
        row = next(line for line in text.splitlines() if line.startswith("| gyro only |"))
        assert "| 0.950 | 7% |" in row
        assert "| hover_b | 0 | 0.90 (2%, 1/6) |" in text  # a hexa's rotors counted, not 4
    assert "| 1.00 (-) | 0.90 (-) |" in row  # one run per group: no CV


@pytest.mark.skipif(not SHARED.is_dir(), reason="real logs (../shared) not present")
def test_one_real_log(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "square_run1.csv").symlink_to(SHARED / "square_20251017_run1.csv")
    config = real_data.RealDataConfig(data_dir=data, vehicle=SHARED / "crazyflie21b.vehicle.json", out_dir=tmp_path,
                                      reference_kf=3.72e-8, modes=("gyro",))
    result = real_data.run_real_data(config, progress=False)
    run = result["modes"][0]["runs"]["square_run1"]
    assert run["finite"] and 0.0 < run["kf_over_reference"] < 5.0
    assert (tmp_path / "real_data.json").is_file()
    assert "| square_run1 |" in real_data.render(result)


def test_calibrated_mode_uses_the_other_half_of_the_runs():
    """gyro_walk_calibrated: odd positions (sorted) calibrate the even ones and vice versa (held out)."""
    from propid.flightlog import parse_vehicle
    from synthetic_vehicles import x_quad

    vehicle = parse_vehicle(x_quad("half-x", 0.045, [2.5e-5, 2.8e-5, 4.9e-5], 0.035, 3.0e-8, 1.0e-10))
    logs = [Path(f"run{k}.csv") for k in range(1, 6)]
    odd, even = real_data.halves(logs)
    assert [p.name for p in odd] == ["run1.csv", "run3.csv", "run5.csv"] and [p.name for p in even] == ["run2.csv", "run4.csv"]
    # gyro-only reads 0.5 x kf on the odd runs and 0.8 x on the even ones; the accelerometer 3e-8 on all
    raw = {}
    for k, p in enumerate(logs, start=1):
        raw[("gyro_walk", p)] = {"kf_mean": [(0.5 if k % 2 else 0.8) * 3.0e-8] * 4}
        raw[("accel_scale_walk", p)] = {"kf_mean": [3.0e-8] * 4}
    vehicles, infos = real_data._cross_calibrated("gyro_walk_calibrated", logs, vehicle, raw)
    assert set(vehicles) == {("gyro_walk_calibrated", p) for p in logs}
    for p in even:  # calibrated on the odd runs: gain 2
        assert vehicles[("gyro_walk_calibrated", p)].inertia[0, 0] == pytest.approx(2.5e-5 * 2.0)
    for p in odd:  # on the even runs: gain 1.25
        assert vehicles[("gyro_walk_calibrated", p)].inertia[1, 1] == pytest.approx(2.8e-5 * 1.25)
    assert len(infos) == 2
    with pytest.raises(Exception, match="two logs"):
        real_data._cross_calibrated("gyro_walk_calibrated", logs[:1], vehicle, raw)


def test_thrust_terms_are_fitted_on_the_other_half_of_the_runs():
    """accel_scale_walk_climb: the climb coefficient of the odd runs goes to the even ones and vice versa."""
    import numpy as np
    from propid.flightlog import parse_vehicle
    from test_thrust_aero import VEHICLE, table_log

    vehicle = parse_vehicle(VEHICLE)
    rng = np.random.default_rng(8)
    logs = [Path(f"run{k}.csv") for k in range(1, 5)]
    loaded = {}
    for k, p in enumerate(logs, start=1):
        n = 800
        velocity = rng.normal(0.0, 0.6, size=(n, 3))
        speeds = rng.uniform(1500.0, 2000.0, size=(n, 4))
        climb = -1e-6 if k % 2 else -3e-6  # odd runs -1e-6, even runs -3e-6
        force = 3.7e-8 * (speeds**2).sum(axis=1) + climb * speeds.sum(axis=1) * velocity[:, 2]
        loaded[p] = table_log(n, rng, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), velocity, force / vehicle.mass, speeds)
    vehicles, infos = real_data._cross_fitted_thrust("accel_scale_walk_climb", logs, vehicle, loaded)
    for k, p in enumerate(logs, start=1):
        fitted = vehicles[("accel_scale_walk_climb", p)]
        assert fitted.thrust_climb_coeff == pytest.approx(-3e-6 if k % 2 else -1e-6, rel=1e-6)
        assert fitted.thrust_translational_coeff is None  # the climb mode fits the climb term only
    assert len(infos) == 2
    # The per-run diagnostic fits each run on itself: the run's own coefficient, one fit per run.
    own, infos = real_data._cross_fitted_thrust("accel_scale_walk_skip_climb_own", logs, vehicle, loaded)
    for k, p in enumerate(logs, start=1):
        assert own[("accel_scale_walk_skip_climb_own", p)].thrust_climb_coeff == pytest.approx(
            -1e-6 if k % 2 else -3e-6, rel=1e-6)
    assert len(infos) == len(logs)


def test_a_gyro_only_mode_has_no_accelerometer_bias(cfilter_available):
    """No accelerometer fused: the replay reports no bias (JSON null), the mode's median is None and the table
    reads '-', not the bias state's unused 0.00; with the accelerometer the bias is a number."""
    import json

    from propid.flightlog import parse_vehicle
    from propid.replay import ReplayOptions, replay
    from test_scale_walk import VEHICLE, flight

    vehicle, log = parse_vehicle(VEHICLE), flight(1.0, duration=16.0)
    summaries = {aiding: replay(log, vehicle, ReplayOptions(progress=False, aiding=aiding, rotor_inertia="off"))
                 .summary for aiding in ("gyro", "gyro+accel")}
    assert summaries["gyro"]["accel_bias"] is None and summaries["gyro"]["accel_bias_std"] is None
    assert '"accel_bias": null' in json.dumps(summaries["gyro"])
    assert isinstance(summaries["gyro+accel"]["accel_bias"], float) and summaries["gyro+accel"]["accel_bias_std"] > 0
    modes = []
    for aiding, summary in summaries.items():
        runs = {"run1": real_data.run_summary(summary, 3.0e-8)}
        modes.append({"name": aiding, "what": aiding, "runs": runs, "summary": real_data.mode_summary(runs)})
    assert modes[0]["summary"]["accel_bias_median"] is None
    assert modes[1]["summary"]["accel_bias_median"] == pytest.approx(summaries["gyro+accel"]["accel_bias"])
    rows = real_data.render({"reference_kf": 3.0e-8, "modes": modes}).splitlines()
    assert next(r for r in rows if r.startswith("| gyro |")).endswith("| - |")
    assert next(r for r in rows if r.startswith("| gyro+accel |")).endswith(
        f"| {summaries['gyro+accel']['accel_bias']:.2f} |")


def test_run_names_drop_any_date_token_not_one_date():
    from propid.flightlog import run_name

    assert run_name("logs/square_20251017_run1.csv") == "square_run1"
    assert run_name("hover_20240229_run2.csv") == "hover_run2"  # another campaign's date, not only the shared one
    assert run_name("flight_20240101.csv") == "flight"
    assert run_name("run_12345678_a.csv") == "run_12345678_a"  # not a date
    assert run_name("flight.csv") == "flight"


def test_the_window_and_smoothed_mean_figures_beside_the_chosen_estimator():
    """Each run keeps its replay's window and smoothed means (kf_mean_window, kf_mean_smoothed) beside kf_mean: the
    mode summary carries the fleet kf, CV, worst rotor and runs within 5 % of each, and render prints the others'
    when kf_mean is not them."""
    base = dict(km=1e-10, km_converged=False, accel_bias=None, finite=True, p_every_rotor_within_5pct=0.9,
                km_worst_rotor_rel_std=0.2, km_mean_rel_std=0.1, esc_delay_s=0.0, km_converged_rotors=0, rotor_count=4)
    runs = {"square_a": dict(base, kf_over_reference=1.0, rotor_spread=0.02, kf_window_over_reference=1.1,
                             rotor_spread_window=0.08, kf_smoothed_over_reference=0.8, rotor_spread_smoothed=0.01),
            "random_b": dict(base, kf_over_reference=0.9, rotor_spread=0.03, kf_window_over_reference=0.9,
                             rotor_spread_window=0.04, kf_smoothed_over_reference=1.0, rotor_spread_smoothed=0.06)}
    s = real_data.mode_summary(runs)
    assert s["kf_fleet_over_reference"] == pytest.approx(0.95) and s["runs_every_rotor_within_5pct"] == 2
    w = s["window_mean"]
    assert w["kf_fleet_over_reference"] == pytest.approx(1.0) and w["worst_rotor_spread"] == 0.08
    assert w["runs_every_rotor_within_5pct"] == 1 and w["kf_run_cv"] == pytest.approx(0.2 / 2 ** 0.5 / 1.0)
    result = {"reference_kf": 3.72e-8, "mean_estimator": "inverse-variance",
              "modes": [{"name": "gyro", "what": "gyro only", "runs": runs, "summary": s}]}
    assert "window mean (kf_mean_window) instead" in real_data.render(result)
    assert "gyro 1.000, 14%, 8%, 1/2" in real_data.render(result)
    assert "kf_mean_window" not in real_data.render(dict(result, mean_estimator="window"))
    # the smoothed mean's figures the same way (kf_mean_smoothed)
    m = s["smoothed_mean"]
    assert m["kf_fleet_over_reference"] == pytest.approx(0.9) and m["worst_rotor_spread"] == 0.06
    assert m["runs_every_rotor_within_5pct"] == 1
    assert "gyro 0.900, 16%, 6%, 1/2" in real_data.render(result)
    assert "kf_mean_smoothed" not in real_data.render(dict(result, mean_estimator="smoothed"))
    # a run summarised from a replay: both estimators' figures
    replayed = {"kf_mean": [1.0, 1.0, 1.0, 1.0], "kf_mean_window": [1.2, 1.0, 1.0, 0.8],
                "kf_mean_smoothed": [1.1, 1.1, 0.9, 0.9], "kf_mean_inverse_variance": [1.0] * 4, "km_mean": [1.0] * 4,
                "km_std": [0.1] * 4, "converged": {"kf": [True] * 4, "km": [False] * 4},
                "config": {"drag_coeff_nominal": [1.0] * 4}, "km_combination_std": {"yaw": 0.1},
                "model_mismatch": False, "accel_bias": None, "torque_scale": 1.0, "esc_delay_s": 0.0, "finite": True,
                "kf_rotor_spread_bound": {"p_every_rotor_within": 0.5, "chi_squared": 1.0}}
    r = real_data.run_summary(replayed, 2.0)
    assert r["kf_over_reference"] == 0.5 and r["rotor_spread"] == 0.0
    assert r["kf_window_over_reference"] == pytest.approx(0.5) and r["rotor_spread_window"] == pytest.approx(0.2)
    assert r["kf_smoothed_over_reference"] == pytest.approx(0.5) and r["rotor_spread_smoothed"] == pytest.approx(0.1)
    assert r["kf_inverse_variance_over_reference"] == 0.5 and r["rotor_spread_inverse_variance"] == 0.0
