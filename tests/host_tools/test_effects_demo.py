"""`propid effects-demo` (docs/math.md §13): flies, writes its JSON and table; on the
telemetry-delay case the held delay removes the bias the delay causes."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from propid import effects_demo

def test_esc_delay_case(tmp_path, sitl_binary):
    config = effects_demo.DemoConfig(sitl=sitl_binary, out_dir=tmp_path, seeds=1, duration_s=8.0, cases=("esc_delay",))
    result = effects_demo.run_demo(config, progress=False)
    rows = {row["mode"]: row for row in result["rows"]}
    assert set(rows) == {"oracle", "filter"}
    for row in rows.values():
        assert row["off"]["stable"] == row["on"]["stable"] == 1
        assert row["on"]["kf_worst"] < 0.5 * row["off"]["kf_worst"]
    assert json.loads((tmp_path / "effects_demo.json").read_text())["rows"][0]["effect"] == "esc_delay"
    table = effects_demo.render(result)
    assert "| esc_delay=0.02 | telemetry delay held (`--filter-esc-delay 0.021`) | oracle |" in table


def test_unknown_case_is_a_one_line_error():
    proc = subprocess.run([sys.executable, "-m", "propid.cli", "effects-demo", "--effects", "warp_drive"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "unknown warp_drive" in proc.stderr and "Traceback" not in proc.stderr
