"""Fixtures shared by the host-tool tests: the built simulator, the C filter library, a free
UDP port, the soak's scripts as modules, a SITL log with an untrimmed start and the replay's
JSON through the command line.

The simulator binary comes from PROPID_BUILD_DIR (default <repo>/build/host). When
PROPID_BUILD_DIR is set (as `make test` does) a missing binary is a failure; in a plain dev
run without a build the tests that need it are skipped.
"""

from __future__ import annotations

import importlib.util
import json
import os
import socket
import subprocess
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
BUILD_DIR = Path(os.environ.get("PROPID_BUILD_DIR", REPO / "build" / "host"))
SITL = BUILD_DIR / "sitl" / "propid_sitl"
SOAK_DIR = REPO / "tests" / "soak"


@pytest.fixture(scope="session")
def sitl_binary() -> Path:
    """propid_sitl, built (or the test fails / is skipped, see the module text)."""
    if SITL.is_file() and os.access(SITL, os.X_OK):
        return SITL
    if "PROPID_BUILD_DIR" in os.environ:
        pytest.fail(f"{SITL} missing although PROPID_BUILD_DIR is set (build it: make host)")
    pytest.skip(f"{SITL} not built (run `make host`, or set PROPID_BUILD_DIR)")


@pytest.fixture(scope="session")
def free_udp_port() -> Callable[[], int]:
    """Returns a function giving a UDP port on 127.0.0.1 that nothing is bound to now."""

    def port() -> int:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    return port


@pytest.fixture(scope="session")
def cfilter_available() -> None:
    """The firmware filter's shared library loads (propid.cfilter); built by `make`."""
    from propid import cfilter

    try:
        cfilter.load_library()
    except Exception as exc:  # the C library is built by `make` before the Python tests
        pytest.fail(f"the firmware shared library is not built or does not load: {exc}")


@pytest.fixture(scope="session")
def soak_script() -> Callable[[str], ModuleType]:
    """Returns a function loading tests/soak/NAME.py as a module (the soak's scripts are not
    a package: they run as `python tests/soak/NAME.py`)."""

    def load(name: str) -> ModuleType:
        spec = importlib.util.spec_from_file_location(f"{name}_under_test", SOAK_DIR / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    return load


@pytest.fixture(scope="session")
def untrimmed_start_flight(sitl_binary, tmp_path_factory) -> tuple[Path, np.ndarray]:
    """hummingbird-x, Lissajous, seed 3, 4 s, default sensors: the flight starts level in the air and its
    first ~0.1 s drives rotors to 0 rad/s and back (docs/math.md §14, "The report's timing"). Returns the
    log's path and the true kf of each rotor on its last row."""
    log_path = tmp_path_factory.mktemp("untrimmed_start") / "h4.csv"
    subprocess.run([str(sitl_binary), "--vehicle", "hummingbird-x", "--duration", "4", "--seed", "3", "--log",
                    str(log_path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=True)
    with open(log_path) as handle:
        header = handle.readline().strip().split(",")
        last = handle.readlines()[-1].strip().split(",")
    return log_path, np.array([float(last[header.index(f"true_kf_{i + 1}")]) for i in range(4)])


@pytest.fixture(scope="session")
def replay_cli_json() -> Callable[..., dict]:
    """Returns a function running `propid replay --log LOG --json DIR/NAME.json --no-progress OPTIONS...`
    (exit status 0 asserted) and giving the JSON it wrote."""
    from propid.cli import main as cli_main

    def run(log_path: Path, out_dir: Path, name: str, *options: str) -> dict:
        out = out_dir / f"{name}.json"
        assert cli_main(["replay", "--log", str(log_path), "--json", str(out), "--no-progress", *options]) == 0
        return json.loads(out.read_text())

    return run
