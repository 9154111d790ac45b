"""The bench-only virtual environment with RotorPy (`make bench`, `make xsim`).

RotorPy and its dependencies are pinned with their hashes in
host_tools/setup/bench-requirements.txt and installed into BUILD/bench-venv, never into the
project's .venv; the venv is rebuilt when the pins change (a stamp holds their digest).
"""

from __future__ import annotations

import hashlib
import pathlib
import subprocess
import sys

ROTORPY_VERSION = "3.0.0"


def ensure_bench_venv(repo: pathlib.Path, build: pathlib.Path, say=print) -> pathlib.Path:
    """The bench venv's python, created or rebuilt when needed. Raises
    subprocess.CalledProcessError or OSError when it cannot be installed."""
    venv = build / "bench-venv"
    python = venv / "bin/python"
    pins = repo / "host_tools/setup/bench-requirements.txt"
    stamp = venv / "bench-requirements.sha256"
    wanted = hashlib.sha256(pins.read_bytes()).hexdigest()
    if not python.exists() or not stamp.exists() or stamp.read_text().strip() != wanted:
        say(f"installing rotorpy=={ROTORPY_VERSION} and its pinned dependencies into {venv} (bench only)...")
        for cmd in ([sys.executable, "-m", "venv", "--clear", str(venv)],
                    [str(python), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                     "--require-hashes", "--only-binary=:all:", "-r", str(pins)]):
            subprocess.run(cmd, check=True, text=True, capture_output=True)
        stamp.write_text(wanted + "\n")
    return python
