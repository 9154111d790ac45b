"""propid gap's result does not depend on the order its logs are given in (docs/gap.md, "Log
order"): the same fitted and held-out logs in two orders give the same OUT.json (up to the listing
of the inputs) and the same corrected vehicle file; the canonical order follows the logs' content,
not their names; the default vehicle file does not depend on which log comes first."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog

DURATION = "8"


def _sitl_log(sitl_binary, path, seed, effect):
    subprocess.run([str(sitl_binary), "--quiet", "--duration", DURATION, "--seed", str(seed), "--log", str(path),
                    "--effect", effect], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120,
                   check=True)
    return path


def _without_input_listing(result: dict) -> dict:
    result = json.loads(json.dumps(result))
    for key in ("logs", "holdout"):
        result["inputs"].pop(key)
    result["calibration"].pop("logs", None)
    return result


def test_gap_result_does_not_depend_on_the_order_of_its_logs(tmp_path, sitl_binary):
    """Three fitted logs (so the folds are whole logs) and two held out, each list given in two
    orders: OUT.json identical but for the listing of the inputs, the corrected file (calibrated
    with the filter on the fit logs) identical byte for byte. Before the canonical order the folds,
    block bootstraps and sums followed the command line, and the intervals moved with it."""
    from propid.cli import main

    fit = [_sitl_log(sitl_binary, tmp_path / f"fit_{seed}.csv", seed, "rotor_inertia=2") for seed in (5, 6, 7)]
    held = [_sitl_log(sitl_binary, tmp_path / f"held_{seed}.csv", seed, "rotor_inertia=2") for seed in (8, 9)]
    vehicle = fit[0].with_name(fit[0].stem + ".vehicle.json")
    outputs = []
    for tag, fit_order, held_order in (("a", fit, held), ("b", [fit[2], fit[0], fit[1]], held[::-1])):
        out, corrected = tmp_path / f"{tag}.json", tmp_path / f"{tag}.vehicle.json"
        assert main(["gap", "--log", *map(str, fit_order), "--holdout", *map(str, held_order), "--vehicle",
                     str(vehicle), "--json", str(out), "--vehicle-out", str(corrected), "--no-filter",
                     "--quiet"]) == 0
        outputs.append((json.loads(out.read_text()), corrected.read_bytes()))
    (first, first_file), (second, second_file) = outputs
    assert first["verdict"] == second["verdict"]
    assert _without_input_listing(first) == _without_input_listing(second)
    assert first_file == second_file


def _log(seed: int, name: str) -> FlightLog:
    rng = np.random.default_rng(seed)
    t = np.arange(200) * 0.01
    return FlightLog(t=t, gyro=rng.normal(size=(200, 3)), rotor_speed=2000 + rng.normal(size=(200, 4)),
                     extra={"acc_z": rng.normal(size=200)}, path=name)


def test_canonical_order_follows_the_content_not_the_names_or_the_command_line():
    from propid.gap.log_order import canonical_order, content_digest

    logs = [_log(seed, f"run{seed}.csv") for seed in range(5)]
    order = [content_digest(log) for log in canonical_order(logs)]
    assert [content_digest(log) for log in canonical_order(logs[::-1])] == order
    assert [content_digest(log) for log in canonical_order(logs[2:] + logs[:2])] == order
    renamed = [_log(seed, f"z{9 - seed}.csv") for seed in range(5)]
    assert [content_digest(log) for log in canonical_order(renamed)] == order
    # one value changed is another log
    changed = _log(0, "run0.csv")
    changed.gyro[17, 1] += 1e-9
    assert content_digest(changed) != content_digest(logs[0])
    # identical content twice: the path breaks the tie
    twins = [_log(3, "b.csv"), _log(3, "a.csv")]
    assert [str(log.path) for log in canonical_order(twins)] == ["a.csv", "b.csv"]


def test_default_vehicle_is_the_one_beside_the_logs_whatever_their_order(tmp_path):
    from propid.commands.gap import default_vehicle_path

    for name in ("a", "b"):  # the same vehicle; the notes may differ (the SITL names its seed there)
        (tmp_path / f"{name}.csv").write_text("t\n")
        (tmp_path / f"{name}.vehicle.json").write_text(f'{{"name": "q", "mass": 0.03, "notes": "log {name}"}}\n')
    logs = [str(tmp_path / "a.csv"), str(tmp_path / "b.csv")]
    assert default_vehicle_path(logs) == default_vehicle_path(logs[::-1]) == tmp_path / "a.vehicle.json"
    (tmp_path / "b.vehicle.json").write_text('{"name": "q", "mass": 0.04}\n')
    with pytest.raises(UserError, match="give --vehicle"):
        default_vehicle_path(logs[::-1])
