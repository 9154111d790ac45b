"""The generated firmware kernels are what their generator writes today
(firmware/codegen/): regenerating gives byte-identical files, and a stale or
hand-edited file is detected."""

from __future__ import annotations

import pathlib
import subprocess
import sys

REPO = pathlib.Path(__file__).resolve().parents[2]
GENERATOR = REPO / "firmware" / "codegen" / "quad_predict.py"
GENERATED = REPO / "firmware" / "src" / "propid_quad_predict.h"


def run_generator(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(GENERATOR), *args], capture_output=True, text=True)


def test_quad_predict_kernel_is_current():
    result = run_generator("--check")
    assert result.returncode == 0, result.stderr


def test_regenerating_gives_identical_file(tmp_path):
    out = tmp_path / "propid_quad_predict.h"
    assert run_generator("--out", str(out)).returncode == 0
    assert out.read_bytes() == GENERATED.read_bytes()


def test_edited_kernel_is_detected(tmp_path):
    edited = tmp_path / "propid_quad_predict.h"
    edited.write_text(GENERATED.read_text().replace("t0 * g1_2", "t1 * g1_2", 1))
    result = run_generator("--check", "--out", str(edited))
    assert result.returncode == 1
    assert "not current" in result.stderr
