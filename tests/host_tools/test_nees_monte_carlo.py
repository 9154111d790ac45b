"""propid_sitl --nees-dump and tests/soak/nees_monte_carlo.py (docs/reliability.md, "The NEES
sample by sample")."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

TOOL = Path(__file__).resolve().parents[1] / "soak" / "nees_monte_carlo.py"


def test_dump_holds_each_nees_sample_of_the_flight(sitl_binary, tmp_path, soak_script):
    """Every row's error and covariance give back its NEES, the rows give back the summary's NEES
    counts, and the bases written in the head are orthonormal with the kf basis's first row the
    roll-torque direction (the rotors' y arms, signs as the filter's)."""
    tool = soak_script("nees_monte_carlo")
    dump, summary = tmp_path / "nees.csv", tmp_path / "flight.json"
    subprocess.run([str(sitl_binary), "--vehicle", "hexa-x", "--trajectory", "circle", "--duration", "4",
                    "--paper", "--quiet", "--summary-json", str(summary), "--nees-dump", str(dump)],
                   check=True, capture_output=True)
    rows = tool.read_dump(str(dump))
    assert rows["n"] == 15 and len(rows["t"]) > 150
    usable = rows["nees"] >= 0.0
    recomputed = tool.quadratic(rows["e"][usable], rows["P"][usable])
    np.testing.assert_allclose(recomputed, rows["nees"][usable], rtol=1e-5)
    honesty = json.loads(summary.read_text())["honesty"]
    lower, upper = tool.chi_square_quantile(15, -tool.Z95), tool.chi_square_quantile(15, tool.Z95)
    nees = rows["nees"][usable]
    assert honesty["nees_samples"] == int(usable.sum())
    assert honesty["nees_in_bounds"] == int(np.sum((nees >= lower) & (nees <= upper)))
    assert honesty["nees_below_bounds"] == int(np.sum(nees < lower))
    assert abs(honesty["nees_mean"] - float(nees.mean())) < 1e-6 * max(1.0, float(nees.mean()))
    for name in ("kf_basis", "km_basis"):
        np.testing.assert_allclose(rows[name] @ rows[name].T, np.eye(6), atol=1e-6)
    vehicle = tmp_path / "flight.vehicle.json"
    subprocess.run([str(sitl_binary), "--vehicle", "hexa-x", "--duration", "0.1", "--quiet",
                    "--log", str(tmp_path / "flight.csv")], check=True, capture_output=True)
    rotors = json.loads(vehicle.read_text())["rotors"]
    arms_y = np.array([r["position"][1] for r in rotors])
    roll = arms_y / np.linalg.norm(arms_y)
    assert abs(abs(float(rows["kf_basis"][0] @ roll)) - 1.0) < 1e-5


def test_monte_carlo_of_a_case_reproduces_its_runs_and_normalises_by_the_spread(sitl_binary, tmp_path):
    """A short clean case of make soak's plan, 16 runs: each run's share in band read from its dump
    is the share its flight summary counts; the consistent estimator's NEES (each run's error over
    the others' second moment) lies in its interval on average about as often as the interval
    says, whatever the filter's own sigma."""
    out = tmp_path / "mc.json"
    proc = subprocess.run([sys.executable, str(TOOL), "--sitl", str(sitl_binary), "--seed", "1", "--case", "51",
                           "--runs", "16", "--jobs", "1", "--out", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-500:]
    report = json.loads(out.read_text())
    case = report["cases"][0]
    assert case["case"] == 51 and case["runs"] == 16 and case["seeds"] == list(range(2001, 2017))
    assert len(case["own_in_band_pct"]) == 16 and all(0.0 <= s <= 100.0 for s in case["own_in_band_pct"])
    lo, hi = case["consistent_interval"]
    assert lo < case["dof"] < hi
    assert 70.0 <= float(np.mean(case["consistent_in_band_pct"])) <= 100.0
    last = case["at_times"][-1]
    assert set(last["block_nees_per_dof"]) == {"kf", "km", "bias"}
    assert "kf_roll" in last["second_moment_over_variance"] and "km_yaw" in last["second_moment_over_variance"]
    assert set(report["pooled"]) == {"own", "consistent"}


def test_cli_refuses_a_case_that_is_not_a_clean_case_of_the_plan(sitl_binary):
    proc = subprocess.run([sys.executable, str(TOOL), "--sitl", str(sitl_binary), "--case", "0", "--runs", "2"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "not a clean case of plan 1" in proc.stderr
