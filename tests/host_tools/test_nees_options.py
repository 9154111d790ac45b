"""tests/soak/nees_options.py: a soak plan's clean flights flown with extra propid_sitl options
(docs/reliability.md, "The unbiased decode")."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

TOOL = Path(__file__).resolve().parents[1] / "soak" / "nees_options.py"


def fly(sitl_binary, tmp_path, *extra) -> dict:
    out = tmp_path / "nees.json"
    subprocess.run([sys.executable, str(TOOL), "--sitl", str(sitl_binary), "--seed", "1", "--sensors", "default",
                    "--limit", "1", "--jobs", "1", "--out", str(out), *extra], check=True, capture_output=True)
    return json.loads(out.read_text())


def test_the_options_reach_the_flight_and_change_it(sitl_binary, tmp_path):
    """The first default-sensor clean flight of make soak's plan, as the soak flies it and with the
    unbiased decode: the option is on that flight's command and its telemetry, so its NEES, differ."""
    plain = fly(sitl_binary, tmp_path)
    middle = fly(sitl_binary, tmp_path, "--default-args", "--esc-decode middle")
    assert plain["flights"][0]["case"] == middle["flights"][0]["case"]
    assert plain["flights"][0]["extra"] == [] and middle["flights"][0]["extra"] == ["--esc-decode", "middle"]
    for run in (plain, middle):
        figures = run["figures"]
        assert figures["errors"] == 0 and figures["default sensors"]["flights"] == 1
        assert run["flights"][0]["result"]["samples"] > 0
    assert plain["flights"][0]["result"]["nees_per_dof"] != middle["flights"][0]["result"]["nees_per_dof"]


def test_cli_refuses_an_unknown_option_for_the_flights(sitl_binary, tmp_path):
    """A misspelt SITL option is not a silent no-op: the flight fails and is counted as an error."""
    run = fly(sitl_binary, tmp_path, "--default-args", "--esc-decode nowhere")
    assert run["figures"]["errors"] == 1


def test_cli_refuses_an_output_that_is_a_directory(tmp_path):
    proc = subprocess.run([sys.executable, str(TOOL), "--sitl", sys.executable, "--out", str(tmp_path)],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    assert "it is a directory" in proc.stderr
