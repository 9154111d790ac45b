"""make test's closing line (tests/count_results.py): a stage that fails before any test
runs (a build error) must not leave the line at '0 failed'."""

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[1] / "count_results.py"


def closing_line(log_dir: Path, *failed_stages: str) -> str:
    out = subprocess.run([sys.executable, str(SCRIPT), str(log_dir), *failed_stages],
                         capture_output=True, text=True, check=True).stdout
    return out.strip()


def write_logs(log_dir: Path) -> None:
    (log_dir / "host-tests.log").write_text("100% tests passed, 0 tests failed out of 48\n")
    (log_dir / "python-tests.log").write_text("....\n646 passed, 1 skipped in 1650.00s (0:27:30)\n")
    (log_dir / "sanitizers.log").write_text("sitl_sincos.c:40: error: AVX vector return without AVX enabled\n")


def test_counts_ctest_and_pytest(tmp_path):
    write_logs(tmp_path)
    assert closing_line(tmp_path) == "total: 694 passed, 0 failed"


def test_a_stage_failed_without_a_test_result_counts_and_is_named(tmp_path):
    write_logs(tmp_path)
    line = closing_line(tmp_path, "sanitizers")
    assert line.startswith("total: 694 passed, 1 failed")
    assert "sanitizers" in line


def test_a_stage_whose_tests_failed_is_not_counted_twice(tmp_path):
    write_logs(tmp_path)
    (tmp_path / "target-tests.log").write_text("95% tests passed, 2 tests failed out of 41\n")
    assert closing_line(tmp_path, "target-tests") == "total: 733 passed, 2 failed"
