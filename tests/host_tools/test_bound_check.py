"""propid.bound_check: the Monte-Carlo errors of the linear filters along a flight
(their statistics against their own covariance), the loadings, the bases, the CLI."""

from __future__ import annotations

import math

import numpy as np
import pytest

from propid import bound_check, crlb
from propid.cli import main
from propid.flightlog import parse_vehicle

from test_crlb import CONFIG, N, columns, excited, vehicle

BANDS = bound_check.Bands(coeff=0.1 * CONFIG.coeff_rel_std0, bias=0.1 * CONFIG.bias_std0)


def with_truth(cols: dict, kf_rel: np.ndarray, km_rel: np.ndarray, bias: np.ndarray) -> dict:
    samples = cols["t"].size
    for i in range(N):
        cols[f"true_kf_{i + 1}"] = np.full(samples, 2.3e-8 * kf_rel[i])
        cols[f"true_km_{i + 1}"] = np.full(samples, 7.8e-10 * km_rel[i])
    for k, axis in enumerate("xyz"):
        cols[f"true_bg_{axis}"] = np.full(samples, bias[k])
    return cols


def flight(samples: int = 1500):
    cols = with_truth(columns(*excited(samples)), np.array([1.1, 0.9, 1.05, 0.85]),
                      np.array([0.95, 1.15, 0.9, 1.0]), np.array([0.01, -0.005, 0.012]))
    return cols, vehicle()


def test_monte_carlo_errors_have_the_bound_as_covariance():
    """The bound's recursion is the optimal linear filter's: its errors, drawn from the
    prior, have the recursion's final covariance (statistical, 600 realisations)."""
    cols, veh = flight()
    steps = crlb.flight_steps(cols, veh)
    run = bound_check.propagate(steps, veh, CONFIG, BANDS, "none", None, 600, np.random.default_rng(3))
    n = 6 + 2 * N
    for index in list(range(3, 3 + 2 * N)) + [n - 3, n - 2, n - 1]:
        empirical = np.std(run.errors[:, index])
        expected = math.sqrt(run.cov[index, index])
        assert 0.85 < empirical / expected < 1.15, (index, empirical, expected)
    # and it is crlb's bound
    bound = crlb.bound_along_log(cols, veh, CONFIG)
    assert np.allclose(np.sqrt(run.cov.diagonal()[n - 3:]), bound.bias_std[-1], rtol=1e-9)


def test_loadings_only_widen_and_the_torque_basis_widens_less():
    """The filter's loadings (kf in their torque basis) widen the bound, and widen the
    biases less than the same loadings with the kf per rotor."""
    cols, veh = flight(2500)
    steps = crlb.flight_steps(cols, veh)
    std = {}
    for name in bound_check.LOADINGS:
        run = bound_check.propagate(steps, veh, CONFIG, BANDS, name, None, 2, np.random.default_rng(0))
        std[name] = np.sqrt(run.cov.diagonal())
    assert np.all(std["filter"] >= std["none"] * (1 - 1e-12))
    assert np.all(std["per-rotor-kf"] >= std["none"] * (1 - 1e-12))
    n = 6 + 2 * N
    bias = slice(n - 3, n)
    assert np.all(std["filter"][bias] <= std["per-rotor-kf"][bias] * (1 + 1e-12))


def test_criterion_times_count_the_last_exit():
    t = np.array([0.0, 0.1, 0.2, 0.3])
    mean, never = bound_check.criterion_times(t, np.array([-1, 0, 2, 3]), 10.0)
    assert never == pytest.approx(0.25)
    assert mean == pytest.approx((0.0 + 0.1 + 0.3 + 10.0) / 4)


def test_band_decides_convergence():
    cols, veh = flight()
    wide = bound_check.Bands(coeff=10.0, bias=10.0)
    tight = bound_check.Bands(coeff=1e-9, bias=1e-12)
    first_gyro = float(cols["t"][1])  # the first row has no gyro sample
    for bands, never, time in ((wide, 0.0, first_gyro), (tight, 1.0, 10.0)):
        out = bound_check.check_flight(cols, veh, CONFIG, bands, loadings=("none",), realisations=20,
                                       duration=10.0)["none"]
        assert out["never_bias"] == never and out["never_coeff"] == never
        assert out["t_bias_s"] == pytest.approx(time)


@pytest.mark.parametrize("yaw_offset", [0.0, math.pi / 4])
def test_torque_basis_rows(yaw_offset):
    rotors = [{"position": [0.043 * math.cos(a), 0.043 * math.sin(a), 0.0], "yaw_sign": s}
              for a, s in zip(np.arange(N) * math.pi / 2 + yaw_offset, (1, -1, 1, -1))]
    veh = parse_vehicle({"name": "q", "mass": 0.03, "inertia": [1.43e-5, 1.43e-5, 2.89e-5],
                         "rotors": rotors, "kf_nominal": 2.3e-8, "km_nominal": 7.8e-10})
    basis = bound_check.thrust_torque_basis(veh)
    assert np.allclose(basis @ basis.T, np.eye(N))
    pos = np.asarray(veh.positions)
    for row, arm in ((0, pos[:, 1]), (1, pos[:, 0])):
        assert abs(abs(basis[row] @ arm) - np.linalg.norm(arm)) < 1e-12
    drag = bound_check.drag_basis(veh)
    signs = np.asarray(veh.yaw_signs, dtype=float)
    assert np.allclose(drag @ drag, np.eye(N)) and np.allclose(drag, drag.T)
    assert np.allclose(drag[0], -signs[0] * signs / math.sqrt(N))


def test_cli_errors(tmp_path, capsys):
    assert main(["bound-check", str(tmp_path / "none")]) == 1
    assert "no table1.json" in capsys.readouterr().err
    (tmp_path / "table1.json").write_text('{"circle": {}, "_conditions": {"base_seed": 1}}')
    assert main(["bound-check", str(tmp_path)]) == 1
    assert "--keep-logs" in capsys.readouterr().err
    assert main(["bound-check", str(tmp_path), "--realisations", "0"]) == 1


def test_z_loop_settles_at_the_thrust_shortfall_over_its_stiffness():
    """A constant relative thrust error eps leaves e = -g eps / wn^2 (no integral action),
    reached without overshoot beyond the damping's few percent."""
    t = np.arange(0, 5.0, 0.002)
    eps = np.full((t.size, 2), [0.01, -0.02])
    height = bound_check.z_loop_response(t, eps)
    expected = -bound_check.GRAVITY * np.array([0.01, -0.02]) / bound_check.Z_LOOP_NATURAL_FREQ ** 2
    assert np.allclose(height[-1], expected, rtol=1e-3)
    assert np.all(np.abs(height) <= np.abs(expected) * 1.01)
    assert np.all(height[0] == 0.0)


def test_cli_z_excess_needs_oracle_logs(tmp_path, capsys):
    (tmp_path / "logs").mkdir()
    (tmp_path / "table1.json").write_text('{"circle": {}, "_conditions": {"base_seed": 1}}')
    (tmp_path / "logs" / "circle_filter_00.csv").write_text("t\n0\n")
    assert main(["bound-check", str(tmp_path), "--z-excess"]) == 1
    assert "no circle_oracle_NN.csv" in capsys.readouterr().err


def test_z_excess_model_is_the_oracle_when_the_filter_knows_the_thrust():
    cols, veh = flight()
    samples = cols["t"].size
    oracle = dict(cols)
    oracle["pz"] = 1.0 + 1e-3 * np.sin(3.0 * cols["t"])
    oracle["ref_pz"] = np.ones(samples)
    filt = dict(oracle)
    for i in range(1, N + 1):
        filt[f"est_kf_{i}"] = cols[f"true_kf_{i}"].copy()  # no collective error at all
    filt["pz"] = oracle["pz"] + 2e-3
    out = bound_check.z_excess(filt, oracle, veh, CONFIG, BANDS, realisations=30, horizon_s=1.0)
    assert out["model_rmse_z"] == pytest.approx(out["oracle_rmse_z"], rel=1e-12)
    assert out["filter_rmse_z"] > out["oracle_rmse_z"]
    # the efficient estimator starts from the flight's (non-zero) coefficient errors
    assert out["efficient_rmse_z"] != pytest.approx(out["oracle_rmse_z"], rel=1e-3)
    assert out["oracle_rmse_z_windows"][-1] is None  # a 3 s flight has no 5 s- window
    std = out["collective_bound_std"]
    assert std[0] > std[-1] > 0.0
