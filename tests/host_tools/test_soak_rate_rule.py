"""The soak's rate-noise rule for its NEES flights (tests/soak/rate_noise_rule.py, the
previous-flight rule; soak.py --nees-rate-rule; docs/reliability.md "The rate process noise
from a previous flight"): which flights it takes, that the value comes from another flight
than the one it is used on, and that it reaches the simulator's command line."""

from __future__ import annotations

import random
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

NEES_OPTIONS = Path(__file__).resolve().parents[1] / "soak" / "nees_options.py"


def plan(soak, seed: int = 5, count: int = 200) -> list[dict]:
    rng = random.Random(seed)
    return [soak.plan_case(rng, index) for index in range(count)]


def test_the_rule_takes_only_clean_flights_with_exact_speeds(soak_script):
    rule = soak_script("rate_noise_rule")
    cases = plan(rule.load_soak())
    taken = [case for case in cases if rule.rule_applies("previous-flight", case)]
    assert taken and all(case["clean"] and case["sensors"] == "paper" for case in taken)
    assert any(case["clean"] and case["sensors"] == "default" for case in cases)  # left at the matched tuning
    assert not any(rule.rule_applies("none", case) for case in cases)


def test_the_value_reaches_the_command_and_only_when_set(soak_script):
    soak = soak_script("soak")
    case = next(case for case in plan(soak) if case["clean"])
    assert "--filter-rate-noise" not in soak.command("sitl", case, "filter", "x.json")
    cmd = soak.command("sitl", {**case, "rate_noise": 3.25e-5}, "filter", "x.json")
    assert cmd[cmd.index("--filter-rate-noise") + 1] == "3.25e-05"


def test_calibration_flies_another_seed_and_derives_from_it(sitl_binary, soak_script):
    """The calibration flight is the case with another seed (a previous flight of the same vehicle
    and mission), never the flight the value is used on; its q_rate is a miss the derivation sees."""
    rule = soak_script("rate_noise_rule")
    soak = rule.load_soak()
    case = {**next(case for case in plan(soak) if rule.rule_applies("previous-flight", case)),
            "vehicle": "crazyflie-x", "trajectory": "circle", "duration_s": 4.0}
    seen: list[dict] = []

    def command_of(flight: dict, summary: str) -> list[str]:
        seen.append(flight)
        return soak.command(str(sitl_binary), flight, "filter", summary)

    found = rule.calibrate(case, command_of)
    assert [flight["seed"] for flight in seen] == [case["seed"] + rule.CALIBRATION_SEED_OFFSET]
    assert found["seed"] == seen[0]["seed"]
    assert 1e-7 < found["q_rate"] < 1e-2  # the exact-speed range (docs/math.md §2), far below 0.2


def test_a_failed_calibration_flight_keeps_the_matched_tuning(tmp_path, soak_script, capsys):
    """A simulator that fails: the error is said and the case keeps no rate noise of the rule."""
    soak = soak_script("soak")
    fake = tmp_path / "fake_sitl"
    fake.write_text("#!/bin/sh\necho broken >&2\nexit 1\n")
    fake.chmod(0o755)
    cases = plan(soak)
    args = SimpleNamespace(sitl=str(fake), no_detect_damage=False, inertia_std=None, gyro_stuck=0, jobs=1,
                           nees_rate_rule="previous-flight")
    assert any(case["clean"] and case["sensors"] == "paper" for case in cases[:40])
    soak.calibrate_cases(cases[:40], args)
    assert not any("rate_noise" in case for case in cases)
    assert "calibration flight exit 1" in capsys.readouterr().err


def test_the_default_sensor_rate_noise_takes_only_their_clean_flights(soak_script):
    soak = soak_script("soak")
    cases = plan(soak)
    soak.set_default_sensor_rate_noise(cases, 2.0)
    taken = [case for case in cases if "rate_noise" in case]
    assert taken and all(case["clean"] and case["sensors"] == "default" for case in taken)
    assert any(case["clean"] and case["sensors"] == "paper" for case in cases)
    cmd = soak.command("sitl", taken[0], "oracle", "x.json")
    assert cmd[cmd.index("--filter-rate-noise") + 1] == "2"


def test_cli_refuses_a_negative_default_sensor_rate_noise(tmp_path, soak_script):
    soak = soak_script("soak")
    fake = tmp_path / "fake_sitl"
    fake.write_text("#!/bin/sh\nexit 1\n")
    fake.chmod(0o755)
    assert soak.main(["--sitl", str(fake), "--nees-default-rate-noise", "-1", "--out", str(tmp_path / "s.json")]) == 2


def test_nees_options_refuses_a_window_that_is_not_positive():
    proc = subprocess.run([sys.executable, str(NEES_OPTIONS), "--sitl", sys.executable, "--rate-rule", "previous-flight",
                           "--rate-rule-window", "0"], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "--rate-rule-window > 0" in proc.stderr
