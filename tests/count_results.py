#!/usr/bin/env python3
"""Add up the test counts of one `make test` run into a single closing line.

Reads the stage logs that the Makefile's `test` verb keeps (ctest and pytest
output) and prints `total: N passed, N failed` so a reader (or CI) sees the
whole run in one line. The stages the Makefile saw fail are given after the log
directory: a failed stage whose log holds no failed test (a build that broke
before its tests ran) counts as one failure and is named, so the line never
reads "0 failed" for a run that failed. Exits 0: the Makefile decides success
from the stages.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

CTEST = re.compile(r"(\d+)% tests passed, (\d+) tests failed out of (\d+)")
PYTEST_PASSED = re.compile(r"\b(\d+) passed\b")
PYTEST_FAILED = re.compile(r"\b(\d+) (?:failed|errors?)\b")


def count_log(log: Path) -> tuple[int, int]:
    """(passed, failed) of one stage's log."""
    passed = failed = 0
    text = log.read_text(errors="replace")
    for match in CTEST.finditer(text):
        bad, total = int(match.group(2)), int(match.group(3))
        passed += total - bad
        failed += bad
    if log.stem == "python-tests":
        # pytest's own summary is its last line with "passed"/"failed" in it.
        summary = [line for line in text.splitlines() if " in " in line and
                   (PYTEST_PASSED.search(line) or PYTEST_FAILED.search(line))]
        if summary:
            last = summary[-1]
            passed += sum(int(m) for m in PYTEST_PASSED.findall(last))
            failed += sum(int(m) for m in PYTEST_FAILED.findall(last))
        elif "error" in text.lower():
            failed += 1
    return passed, failed


def count(log_dir: Path, failed_stages: list[str] | None = None) -> tuple[int, int, list[str]]:
    """(passed, failed, the failed stages with no failed test in their log)."""
    per_stage = {log.stem: count_log(log) for log in sorted(log_dir.glob("*.log"))}
    passed = sum(p for p, _ in per_stage.values())
    failed = sum(f for _, f in per_stage.values())
    untested = [s for s in failed_stages or [] if per_stage.get(s, (0, 0))[1] == 0]
    return passed, failed + len(untested), untested


def main() -> int:
    log_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("build/test-logs")
    passed, failed, untested = count(log_dir, sys.argv[2:])
    line = f"total: {passed} passed, {failed} failed"
    if untested:
        line += f" ({len(untested)} of them a stage that failed without a test result: {', '.join(untested)})"
    print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
