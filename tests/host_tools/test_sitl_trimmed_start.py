"""propid_sitl --start-trimmed: the flight starts on the trajectory's trim (attitude, body
rate and thrust of the controller's feed-forward at t = 0), not level (docs/sitl.md)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from propid.flightlog import read_table

# oracle mode: the mixer uses the true coefficients, so the only start transient is the start's
CIRCLE = ["--quiet", "--mode", "oracle", "--vehicle", "crazyflie-x", "--seed", "3", "--duration", "4",
          "--trajectory", "circle", "--trajectory-period", "8", "--yaw-amplitude", "0.3"]


def _fly(sitl_binary, tmp_path, extra):
    log = tmp_path / ("trimmed.csv" if extra else "level.csv")
    subprocess.run([str(sitl_binary), *CIRCLE, *extra, "--log", str(log)], check=True, timeout=120,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    c = read_table(log)
    t = c["t"] - c["t"][0]
    tilt = np.degrees(np.arccos(np.clip(1.0 - 2.0 * (c["qx"] ** 2 + c["qy"] ** 2), -1.0, 1.0)))
    rate = np.hypot(c["true_wx"], c["true_wy"])
    return t, tilt, rate


def test_trimmed_start_is_on_the_circles_tilt_and_has_no_start_transient(sitl_binary, tmp_path):
    """On a circle the thrust must tilt by atan(a_c / g) from the start: level, the first
    0.5 s carry a roll/pitch rate burst well above the steady circle's (measured 7x);
    trimmed, the first row is already at the steady tilt and the burst is gone (1.0x)."""
    t0, tilt0, rate0 = _fly(sitl_binary, tmp_path, [])
    t1, tilt1, rate1 = _fly(sitl_binary, tmp_path, ["--start-trimmed"])
    steady = np.median(tilt1[t1 > 2.0])
    assert steady > 3.0  # the circle needs a visible tilt
    assert tilt0[0] < 0.5  # default: level
    assert tilt1[0] == pytest.approx(steady, rel=0.3)
    burst0 = rate0[t0 < 0.5].max() / rate0[t0 > 2.0].max()
    burst1 = rate1[t1 < 0.5].max() / rate1[t1 > 2.0].max()
    assert burst0 > 2.0
    assert burst1 < 1.2


def test_trimmed_start_on_the_ground_is_a_usage_error(sitl_binary, tmp_path):
    proc = subprocess.run([str(sitl_binary), *CIRCLE, "--start-trimmed", "--start-on-ground"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode != 0 and "--start-trimmed" in proc.stderr
