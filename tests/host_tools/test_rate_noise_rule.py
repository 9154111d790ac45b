"""The rate process noise derived from a flight's log (tests/soak/rate_noise_rule.py,
docs/math.md §2 "What the prediction misses") against the truth residual of the same
flight: with exact speeds the two are independent reads of the same miss (the motor
model and the trapezoid from the log's speeds and commands; the simulator's own RK4
rates against the filter's step with the true coefficients)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

RULE = Path(__file__).resolve().parents[1] / "soak" / "rate_noise_rule.py"


@pytest.fixture(scope="module")
def step_log(sitl_binary, tmp_path_factory):
    """A Hummingbird X step flight with exact speeds (5 ms motors: the largest miss)."""
    log = tmp_path_factory.mktemp("rate_noise") / "step.csv"
    subprocess.run([str(sitl_binary), "--paper", "--vehicle", "hummingbird-x", "--trajectory", "step",
                    "--duration", "6", "--seed", "3", "--quiet", "--log", str(log)], check=True)
    return log


def test_derived_rate_noise_matches_the_truth_residual(step_log, soak_script):
    rule = soak_script("rate_noise_rule")
    derived = rule.derive(str(step_log), str(step_log)[:-4] + ".vehicle.json", "hummingbird-x", "paper", truth=True)
    print(derived)
    assert derived["truth_q_rate"] > 1e-5  # a miss the check can see (hovers are below it)
    assert 1 / 1.3 <= derived["q_rate"] / derived["truth_q_rate"] <= 1.3


def test_a_wrong_motor_model_is_seen(step_log, monkeypatch, soak_script):
    """The same log with the motor time constant doubled: the derivation no longer agrees."""
    rule = soak_script("rate_noise_rule")
    tau, top = rule.MOTORS["hummingbird"]
    monkeypatch.setitem(rule.MOTORS, "hummingbird", (2.0 * tau, top))
    derived = rule.derive(str(step_log), str(step_log)[:-4] + ".vehicle.json", "hummingbird-x", "paper", truth=True)
    ratio = derived["q_rate"] / derived["truth_q_rate"]
    assert not 1 / 1.3 <= ratio <= 1.3, ratio


def test_cli_refuses_an_unknown_vehicle(tmp_path):
    proc = subprocess.run([sys.executable, str(RULE), "--log", str(tmp_path / "x.csv"), "--vehicle", "quad-x",
                           "--sensors", "paper"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "no motor model for quad-x" in proc.stderr


def test_cli_refuses_an_output_that_is_a_directory(tmp_path):
    proc = subprocess.run([sys.executable, str(RULE), "--sitl", sys.executable, "--out", str(tmp_path)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "it is a directory" in proc.stderr


def test_default_args_reach_the_flight_of_a_default_sensor_case(tmp_path, soak_script):
    """The options `--default-args` gives (e.g. the input-noise hold as a floor) reach the
    simulator's command line of a default-sensor case: a stand-in simulator records its
    arguments (and fails, so only the first flight runs)."""
    rule = soak_script("rate_noise_rule")
    soak = rule.load_soak()
    record = tmp_path / "argv.txt"
    fake = tmp_path / "fake_sitl"
    fake.write_text(f"#!/bin/sh\necho \"$@\" >> {record}\nexit 1\n")
    fake.chmod(0o755)
    rng = rule.random.Random(5)
    cases = [soak.plan_case(rng, index) for index in range(200)]
    default = next(case for case in cases if case["clean"] and case["sensors"] == "default")
    result = rule.fly_case((None, str(fake), default, False, ["--filter-rotor-speed-noise-hold-floor"]))
    assert result["error"] == "no log"
    assert "--filter-rotor-speed-noise-hold-floor" in record.read_text()
