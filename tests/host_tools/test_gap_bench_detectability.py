"""gap-bench's detectability index D counts free flight only: rows where the SITL's vehicle
rests on the ground (its contact holds the body while the rotors spin) are left out of all
three flights, so a crash is not taken for a strong effect (docs/gap-bench.md, "Magnitudes
and the detection limit"). Needs propid_sitl (the sitl_binary fixture, conftest.py)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from propid.flightlog import FlightLog, read_vehicle
from propid.gapbench import detectability as det
from propid.gapbench.flights import CLEAN_SENSORS
from propid.gapbench.sitl_log import read_sitl_log

# A blind-benchmark flight of seed 1 (f024): a crazyflie circle started 0.14 m above the
# ground; the level start's transient puts it on the ground at 0.5 s, where it lies tilted.
CRASH = ("--mode incorrect --vehicle crazyflie-plus --seed 283851901 --duration 6 --log-rate 100 "
         "--esc-rate 100 --esc-latency 0 --esc-phase 0 --trajectory circle --trajectory-period 4.558 "
         "--yaw-amplitude 1.204 --yaw-cycles 1.176 --start-height 0.1356")
AIRBORNE = "--duration 6 --seed 5"


def _twins(sitl: Path, tmp: Path, base: str, effect: str) -> tuple:
    """Clean probe B, clean twin C, noisy twin N as the bench flies them, and the vehicle."""
    runs = {"B": CLEAN_SENSORS + ["--effect", effect], "C": CLEAN_SENSORS, "N": []}
    for name, extra in runs.items():
        subprocess.run([str(sitl), "--quiet", *base.split(), *extra, "--log", str(tmp / f"{name}.csv")],
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=True)
    logs = tuple(read_sitl_log(tmp / f"{name}.csv") for name in runs)
    return logs, read_vehicle(tmp / "C.vehicle.json")


def _every_row(t, logs, margin_s=det.CONTACT_MARGIN_S):
    return np.ones(np.asarray(t).size, dtype=bool)


def test_a_crashed_flight_has_no_free_flight_to_detect_an_effect_in(tmp_path, sitl_binary, monkeypatch):
    logs, vehicle = _twins(sitl_binary, tmp_path, CRASH, "aero_damping=0.0378493")
    assert all(det.contact_times(log).size > 0 for log in logs)
    result = det.detectability(*logs, vehicle)
    assert result["index"] == 0.0 and result["free_flight_share"] == 0.0
    assert det.pooled_detectability([logs], vehicle) == 0.0
    # counting the contact rows (the index before): the two crashes' difference reads as a
    # strong effect, mostly on the thrust axis, which aero_damping does not act on
    monkeypatch.setattr(det, "free_flight_rows", _every_row)
    contact = det.detectability(*logs, vehicle)
    assert contact["index"] > 20.0
    assert contact["axes"]["thrust"]["index"] > contact["axes"]["roll"]["index"]


def test_a_flight_that_stays_airborne_keeps_every_row_and_its_index(tmp_path, sitl_binary, monkeypatch):
    logs, vehicle = _twins(sitl_binary, tmp_path, AIRBORNE, "aero_damping=1")
    assert all(det.contact_times(log).size == 0 for log in logs)
    result = det.detectability(*logs, vehicle)
    assert result["free_flight_share"] == 1.0 and result["index"] > 5.0
    monkeypatch.setattr(det, "free_flight_rows", _every_row)
    assert det.detectability(*logs, vehicle)["index"] == result["index"]


def _log(t, pz):
    t = np.asarray(t, dtype=float)
    return FlightLog(t=t, gyro=np.zeros((t.size, 3)), rotor_speed=np.ones((t.size, 4)),
                     extra={"pz": np.asarray(pz, dtype=float)})


def test_rows_within_the_margin_of_a_contact_in_any_flight_are_left_out():
    t = np.arange(0.0, 4.0, 0.01)
    touch = _log(t, np.where((t >= 2.0) & (t < 2.1), 0.0, 0.3))  # on the ground 2.0-2.1 s
    airborne = _log(t, np.full(t.size, 0.3))
    grid = np.arange(1.0, 3.5, 0.04)
    keep = det.free_flight_rows(grid, [airborne, touch])
    near = (grid >= 2.0 - det.CONTACT_MARGIN_S) & (grid <= 2.09 + det.CONTACT_MARGIN_S)
    assert np.array_equal(keep, ~near)
    assert det.free_flight_rows(grid, [airborne]).all()
    no_height = FlightLog(t=t, gyro=np.zeros((t.size, 3)), rotor_speed=np.ones((t.size, 4)), extra={})
    assert det.contact_times(no_height).size == 0


@pytest.mark.parametrize("height", [0.0, -1e-9])
def test_contact_is_a_height_at_or_below_the_ground(height):
    t = np.arange(0.0, 1.0, 0.1)
    pz = np.full(t.size, 0.05)
    pz[4] = height
    assert np.array_equal(det.contact_times(_log(t, pz)), t[[4]])
