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
                             accel_bias=0.1, finite=True),
            "random_b": dict(kf_over_reference=0.8, rotor_spread=0.10, km=2e-10, km_converged=False,
                             accel_bias=0.3, finite=True),
            "random_c": dict(kf_over_reference=0.6, rotor_spread=0.04, km=3e-10, km_converged=False,
                             accel_bias=0.5, finite=True)}
    s = real_data.mode_summary(runs)
    assert s["kf_fleet_over_reference"] == pytest.approx(0.8) and s["kf_run_cv"] == pytest.approx(0.25)
    assert s["square_kf"] == 1.0 and s["other_kf"] == pytest.approx(0.7) and s["other_runs"] == 2
    assert s["worst_rotor_spread"] == 0.10 and s["runs_every_rotor_within_5pct"] == 2
    assert s["runs_km_converged"] == 1 and s["accel_bias_median"] == 0.3


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
