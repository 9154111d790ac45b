"""The gyro-only coefficient walk rule (--thrust-coeff-rel-walk auto) and the torque-gain calibration
with the accelerometer (propid/replay/calibration.py, propid replay --vehicle-out; docs/real-data.md)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import parse_vehicle, read_vehicle, write_flightlog
from propid.replay import ReplayOptions, replay
from propid.replay.calibration import accelerometer_options, check_calibration_inputs, torque_gain_correction
from propid.replay.scale_walk import estimate_scale_walk
from test_scale_walk import KF, VEHICLE, flight

GYRO = dict(progress=False, aiding="gyro", torque_scale="off", rotor_inertia="off")


def test_walk_rule_adds_the_torque_gain_walk_in_quadrature(cfilter_available):
    vehicle = parse_vehicle(VEHICLE)
    log = flight(0.6)
    q = estimate_scale_walk(log, vehicle, np.ones(len(log), dtype=bool), lag=0, trapezoid=True)["walk"]
    auto = replay(log, vehicle, ReplayOptions(thrust_coeff_walk="auto", **GYRO)).summary
    assert q > 0.05
    assert auto["config"]["thrust_coeff_rel_walk"] == pytest.approx(np.hypot(0.02, q), rel=1e-6)
    assert auto["config_notes"]["thrust_coeff_rel_walk"]["torque_gain_walk"] == pytest.approx(q, rel=1e-6)
    # the faster memory follows the gain's drop to 0.6 sooner (measured: 2.9 s against 5.7 s with the library walk)
    def settle(result) -> float:
        kf, t = result.series["kf"].mean(axis=1) / KF, result.series["t"]
        return float(t[np.flatnonzero((t > 24.0) & (np.abs(kf - 0.6) < 0.03))[0]] - 24.0)

    default = replay(log, vehicle, ReplayOptions(**GYRO))
    walking = replay(log, vehicle, ReplayOptions(thrust_coeff_walk="auto", **GYRO))
    assert settle(walking) < 0.7 * settle(default)
    assert np.mean(walking.summary["kf_std"]) > 2.0 * np.mean(default.summary["kf_std"])


def test_walk_rule_refuses_the_scale_state_and_a_second_walk(cfilter_available):
    vehicle = parse_vehicle(VEHICLE)
    log = flight(1.0, duration=16.0)
    with pytest.raises(UserError, match="without the thrust-torque scale"):
        replay(log, vehicle, ReplayOptions(progress=False, aiding="gyro+accel", thrust_coeff_walk="auto"))
    with pytest.raises(UserError, match="not both"):
        replay(log, vehicle, ReplayOptions(thrust_coeff_walk="auto", overrides={"thrust_coeff_rel_walk": 0.1}, **GYRO))


def test_calibration_from_one_flight_corrects_another(cfilter_available):
    """The gyro sees every roll/pitch torque at 0.7 of the thrust's (a constant gain, like a wrong inertia):
    gyro only reads ~0.7 kf, the accelerometer the true kf; the file calibrated on one flight makes
    gyro only read the true kf on another flight (other excitation and noise)."""
    vehicle = parse_vehicle(VEHICLE)
    fit, held_out = (flight(0.7, gain_early=0.7, seed=seed, collective=400.0) for seed in (3, 11))
    options = ReplayOptions(thrust_coeff_walk="auto", **GYRO)
    gyro = [replay(fit, vehicle, options).summary]
    accel = [replay(fit, vehicle, accelerometer_options(options)).summary]
    assert np.mean(gyro[0]["kf_mean"]) / KF == pytest.approx(0.7, abs=0.07)
    assert np.mean(accel[0]["kf_mean"]) / KF == pytest.approx(1.0, abs=0.05)
    corrected, info = torque_gain_correction(vehicle, gyro, accel)
    assert info["torque_gain"] == pytest.approx(1 / 0.7, rel=0.1)
    j0, j1 = np.diag(vehicle.inertia), np.diag(corrected.inertia)
    np.testing.assert_allclose(j1[:2], j0[:2] * info["torque_gain"])
    assert j1[2] == j0[2]  # the scale does not act on yaw
    assert np.mean(corrected.kf_nominal) == pytest.approx(info["kf_with_accelerometer"])
    before = np.mean(replay(held_out, vehicle, options).summary["kf_mean"]) / KF
    after = np.mean(replay(held_out, corrected, options).summary["kf_mean"]) / KF
    assert before == pytest.approx(0.7, abs=0.07)
    assert after == pytest.approx(1.0, abs=0.05)


def test_calibration_inputs_are_judged_first():
    vehicle = parse_vehicle(VEHICLE)
    log = flight(1.0, duration=8.0)
    check_calibration_inputs(vehicle, [log], ReplayOptions(**GYRO))
    with pytest.raises(UserError, match="--aiding gyro"):
        check_calibration_inputs(vehicle, [log], ReplayOptions(progress=False, aiding="gyro+accel"))
    with pytest.raises(UserError, match="mass"):
        check_calibration_inputs(parse_vehicle(dict(VEHICLE, mass=None)), [log], ReplayOptions(**GYRO))
    log.extra.clear()
    with pytest.raises(UserError, match="no accelerometer"):
        check_calibration_inputs(vehicle, [log], ReplayOptions(**GYRO))
    with pytest.raises(UserError, match="one gyro-only and one accelerometer"):
        torque_gain_correction(vehicle, [], [])


def test_cli_vehicle_out_writes_the_calibrated_file(cfilter_available, tmp_path):
    vehicle_path = tmp_path / "v.json"
    vehicle_path.write_text(json.dumps(VEHICLE))
    log_path = tmp_path / "fit.csv"
    write_flightlog(log_path, flight(0.7, gain_early=0.7, duration=24.0, collective=400.0))
    out = tmp_path / "corrected.json"
    base = [sys.executable, "-m", "propid.cli", "replay", "--log", str(log_path), "--vehicle", str(vehicle_path),
            "--no-progress", "--aiding", "gyro", "--thrust-coeff-rel-walk", "auto"]
    proc = subprocess.run(base + ["--vehicle-out", str(out), "--json", str(tmp_path / "r.json")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    corrected = read_vehicle(out)
    gain = json.loads((tmp_path / "r.json").read_text())["calibration"]["torque_gain"]
    assert gain > 1.2
    assert corrected.inertia[0, 0] == pytest.approx(VEHICLE["inertia"][0] * gain)
    assert "calibrated by propid replay --vehicle-out" in corrected.notes
    proc = subprocess.run(base[:-2] + ["--aiding", "gyro+accel", "--vehicle-out", str(tmp_path / "x.json")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "--aiding gyro" in proc.stderr and "Traceback" not in proc.stderr
    assert not (tmp_path / "x.json").exists()
    proc = subprocess.run(base + ["--vehicle-out", str(vehicle_path)], capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0 and "must not overwrite" in proc.stderr
