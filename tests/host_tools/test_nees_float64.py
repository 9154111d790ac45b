"""tests/soak/nees_float64.py and the float64 reference without its loadings
(docs/reliability.md, "The loading's cost, measured in float64")."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from propid.cfilter import FilterConfig
from propid.reference_filter import VAR_LOADING, ReferenceFilter

TOOL = Path(__file__).resolve().parents[1] / "soak" / "nees_float64.py"


def quad_config() -> FilterConfig:
    """A quad whose gyro noise is so large that an update barely moves P: what the two filters
    differ by is then the prediction's loading alone."""
    return FilterConfig.symmetric(4, 0.17, math.pi / 4, 1.0, 5.57e-6, 1.36e-7, [3.65e-3, 3.68e-3, 7.03e-3],
                                  rate_process_noise=1e-4, thrust_coeff_rel_walk=0.0, drag_coeff_rel_walk=0.0,
                                  gyro_bias_walk=0.0, gyro_noise_density=5.0)


def step_both(steps: int) -> tuple[ReferenceFilter, ReferenceFilter]:
    """The same inputs into the reference with and without its loadings: an anchoring sample,
    then `steps` gyro samples at 500 Hz with unequal rotor speeds."""
    loaded, plain = ReferenceFilter(quad_config()), ReferenceFilter(quad_config(), loadings=False)
    speeds = [900.0, 950.0, 1000.0, 1050.0]
    for k in range(steps + 1):
        t_us = 2000 * k
        for filt in (loaded, plain):
            filt.push_rotor_speeds(t_us, speeds)
            filt.push_gyro(t_us, [0.01 * k, -0.02 * k, 0.005 * k])
    return loaded, plain


def test_without_loadings_only_the_loading_terms_are_gone():
    """Each prediction loads the kf and bias variances by a relative eps, the km variances on
    every second step, the rates by more (their rounding scale); without the loadings none of
    it; the estimates of the two filters agree to far below their std."""
    kf, km, bias = slice(3, 7), slice(7, 11), slice(11, 14)
    shares = []
    for steps in (1, 2, 3):
        loaded, plain = step_both(steps)
        relative = (np.diag(loaded.cov) / np.diag(plain.cov) - 1.0) / VAR_LOADING
        shares.append(relative)
        assert np.all(np.abs(loaded.state - plain.state) < 1e-3 * np.sqrt(np.diag(plain.cov)))
    for steps, relative in zip((1, 2, 3), shares):
        np.testing.assert_allclose(relative[kf], steps, rtol=0.02)
        np.testing.assert_allclose(relative[bias], steps, rtol=0.02)
        assert np.all(relative[:3] > 8.0)  # l eps of the rounding scale, l >= 8
    km_steps = [shares[0][km], shares[1][km] - shares[0][km], shares[2][km] - shares[1][km]]
    loaded_steps = [bool(np.all(np.abs(s - 1.0) < 0.02)) for s in km_steps]
    unloaded_steps = [bool(np.all(np.abs(s) < 0.02)) for s in km_steps]
    assert all(a != b for a, b in zip(loaded_steps, unloaded_steps))  # each step loads the block or not
    assert loaded_steps[0] != loaded_steps[1] and loaded_steps[1] != loaded_steps[2]  # every second step


def test_c_replay_of_a_sitl_log_reproduces_the_in_loop_nees(sitl_binary, tmp_path, soak_script):
    """A short exact-speed flight with the soak's matched tuning at a small rate noise: the C filter
    replayed from its log, configured by replay_config, gives the in-loop filter's NEES samples and
    mean (the config mirrors the SITL's); the float64 reference with its loadings follows it, and
    without them its NEES per dof is larger (the loadings hold the sigma open)."""
    tool = soak_script("nees_float64")
    soak = tool.rate_noise_rule.load_soak()
    case = {"case": 0, "seed": 7, "vehicle": "crazyflie-x", "trajectory": "circle", "duration_s": 6.0,
            "sensors": "paper", "tuning": "matched", "clean": True, "effects": [], "faults": [], "damage": None}
    log, summary = tmp_path / "flight.csv", tmp_path / "flight.json"
    q = 2.0e-5
    subprocess.run(soak.command(str(sitl_binary), case, "filter", str(summary))
                   + ["--filter-rate-noise", f"{q}", "--log", str(log)], check=True, capture_output=True)
    honesty = json.loads(summary.read_text())["honesty"]
    config = tool.replay_config(str(tmp_path / "flight.vehicle.json"), "crazyflie-x", q)
    replayed = {name: tool.replay_nees(str(log), config, name) for name in tool.FILTERS}
    c = replayed["c"]
    assert abs(c["samples"] - honesty["nees_samples"]) <= 3  # the blocks not positive definite: left out by both
    in_loop = honesty["nees_mean"] / honesty["nees_dof"]
    assert abs(c["nees_per_dof"] - in_loop) < 0.02 * in_loop
    assert abs(replayed["float64"]["nees_per_dof"] - c["nees_per_dof"]) < 0.1 * c["nees_per_dof"]
    assert replayed["float64_unloaded"]["nees_per_dof"] > 1.05 * replayed["float64"]["nees_per_dof"]


def test_cli_refuses_a_case_that_is_not_a_paper_sensor_clean_case(sitl_binary):
    proc = subprocess.run([sys.executable, str(TOOL), "--sitl", str(sitl_binary), "--case", "0"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "not a paper-sensor clean case of plan 1" in proc.stderr


def test_cli_refuses_a_rate_noise_that_is_not_positive(sitl_binary):
    proc = subprocess.run([sys.executable, str(TOOL), "--sitl", str(sitl_binary), "--rate-noise", "0"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "--rate-noise must be a positive number" in proc.stderr


def test_cli_refuses_an_unknown_filter(sitl_binary):
    proc = subprocess.run([sys.executable, str(TOOL), "--sitl", str(sitl_binary), "--filters", "float64,float32"],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "--filters: float32 is not one of c, float64, float64_unloaded, float64_gyro" in proc.stderr
