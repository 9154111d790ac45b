#!/usr/bin/env python3
"""Add up the test counts of one `make test` run into a single closing line.

Reads the stage logs that the Makefile's `test` verb keeps (ctest and pytest
output) and prints `total: N passed, N failed` so a reader (or CI) sees the
whole run in one line. Exits 0: the Makefile decides success from the stages.
"""

import re
import sys
from pathlib import Path

CTEST = re.compile(r"(\d+)% tests passed, (\d+) tests failed out of (\d+)")
PYTEST_PASSED = re.compile(r"\b(\d+) passed\b")
PYTEST_FAILED = re.compile(r"\b(\d+) (?:failed|errors?)\b")


def count(log_dir: Path) -> tuple[int, int]:
    passed = failed = 0
    for log in sorted(log_dir.glob("*.log")):
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


def main() -> int:
    log_dir = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("build/test-logs")
    passed, failed = count(log_dir)
    print(f"total: {passed} passed, {failed} failed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
