"""Replay through the firmware filter (C library via propid.cfilter): a synthetic log with
known coefficients, one real Crazyflie log from ../shared, and the error paths."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog, parse_vehicle, read_flightlog, read_vehicle, write_flightlog, write_vehicle
from propid.replay import ReplayOptions, fleet_summary, replay

SHARED = Path(__file__).resolve().parents[2].parent / "shared"
CRAZYFLIE = SHARED / "data" / "real" / "crazyflie21b"
BETAFLIGHT = SHARED / "data" / "real" / "betaflight"

KF_NOMINAL = 2.3e-8
KM_NOMINAL = 7.8e-10
ARM = 0.043 / np.sqrt(2)
VEHICLE = {
    "name": "synthetic-x",
    "mass": 0.03,
    "inertia": [1.43e-5, 1.43e-5, 2.89e-5],
    "rotors": [
        {"position": [ARM, -ARM, 0.0], "yaw_sign": -1},
        {"position": [-ARM, -ARM, 0.0], "yaw_sign": 1},
        {"position": [-ARM, ARM, 0.0], "yaw_sign": -1},
        {"position": [ARM, ARM, 0.0], "yaw_sign": 1},
    ],
    "kf_nominal": KF_NOMINAL,
    "km_nominal": KM_NOMINAL,
}
KF_TRUE = KF_NOMINAL * np.array([1.10, 0.92, 1.05, 0.97])
KM_TRUE = KM_NOMINAL * np.array([0.95, 1.10, 1.00, 1.08])
BIAS_TRUE = np.array([0.02, -0.015, 0.01])


@pytest.fixture(scope="module")
def cfilter_available():
    from propid import cfilter

    try:
        cfilter.load_library()
    except Exception as exc:  # the C library is built by `make` before the Python tests
        pytest.fail(f"the firmware shared library is not built or does not load: {exc}")


def synthetic_log(duration: float = 20.0, rate: float = 500.0, seed: int = 7) -> FlightLog:
    """Rotational dynamics of an X quad with KF_TRUE/KM_TRUE exactly as the filter models
    them. A rate controller that knows the true coefficients turns multisine torque and
    thrust demands (plus rate feedback) into rotor speeds; gyro = rate + bias + white
    noise; rotor speeds get noise, a few NaN rows and eRPM spikes."""
    rng = np.random.default_rng(seed)
    vehicle = parse_vehicle(VEHICLE)
    inertia = np.diag(VEHICLE["inertia"])
    j_inv = np.linalg.inv(inertia)
    pos, signs = vehicle.positions, vehicle.yaw_signs
    # [thrust, tau_x, tau_y, tau_z] = allocation @ omega^2, with the true coefficients
    allocation = np.vstack([KF_TRUE, KF_TRUE * pos[:, 1], -KF_TRUE * pos[:, 0], KM_TRUE * signs])
    alloc_inv = np.linalg.inv(allocation)
    n = int(duration * rate)
    t = np.arange(n) / rate
    weight = VEHICLE["mass"] * 9.81
    thrust = weight * (1 + 0.15 * np.sin(2 * np.pi * 0.7 * t) + 0.1 * np.sin(2 * np.pi * 2.3 * t + 1.0))
    demand = np.zeros((n, 3))
    for axis, scale in enumerate((8e-5, 8e-5, 3e-5)):
        freqs, phases = rng.uniform(0.5, 5.0, 3), rng.uniform(0, 2 * np.pi, 3)
        demand[:, axis] = scale * np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None]).sum(axis=0)
    speeds = np.empty((n, 4))
    rate_true = np.zeros((n, 3))
    omega = np.zeros(3)
    substeps = 4
    for k in range(n):
        rate_true[k] = omega
        torque_cmd = demand[k] - inertia @ (4.0 * omega)  # rate feedback keeps the rates bounded
        u = np.clip(alloc_inv @ np.concatenate([[thrust[k]], torque_cmd]), 1.0, None)
        speeds[k] = np.sqrt(u)
        torque = (allocation @ u)[1:]
        for _ in range(substeps):
            omega = omega + j_inv @ (torque - np.cross(omega, inertia @ omega)) / (rate * substeps)
    gyro = rate_true + BIAS_TRUE + rng.normal(0, 0.005, size=(n, 3))
    measured = speeds + rng.normal(0, 1.0, size=speeds.shape)
    glitch_rows = rng.choice(n, 18, replace=False)
    measured[glitch_rows[:15], rng.integers(0, 4, 15)] = np.nan  # telemetry dropouts
    measured[glitch_rows[15:], 2] = 1.0e5  # eRPM spikes, on other rows
    return FlightLog(t=t, gyro=gyro, rotor_speed=measured, extra={})


def test_synthetic_replay_recovers_known_coefficients(cfilter_available, tmp_path):
    log = synthetic_log()
    vehicle = parse_vehicle(VEHICLE)
    result = replay(log, vehicle, ReplayOptions(progress=False))
    s = result.summary
    assert s["finite"]
    # per-rotor kf within 5 % of the truth, km within 15 %
    np.testing.assert_allclose(s["kf_mean"], KF_TRUE, rtol=0.05)
    np.testing.assert_allclose(s["km_mean"], KM_TRUE, rtol=0.15)
    assert all(s["converged"]["kf"])
    # A constant gyro bias and a constant body rate look alike to a gyro-only model (only
    # w x Jw tells them apart), so the bias must stay uncertain: its std may not collapse.
    assert all(0.5 * 0.05 < std < 0.06 for std in s["gyro_bias_std"])
    # every NaN row and every spike was pushed and rejected, by its own reason
    nan_rows = int(np.any(np.isnan(log.rotor_speed), axis=1).sum())
    spike_rows = int(np.any(log.rotor_speed > 1e4, axis=1).sum())
    assert s["rejected"].get("PROPID_ERR_NOT_FINITE") == nan_rows
    assert s["rejected"].get("PROPID_ERR_ROTOR_SPEED_RANGE") == spike_rows
    assert s["counters"]["rotor_accepted"] == len(log) - nan_rows - spike_rows
    assert s["counters"]["gyro_accepted"] == len(log)
    # series for the plot: one estimate per gyro sample
    assert result.series["kf"].shape == (len(log), 4)


def test_time_gap_is_bridged_with_resync(cfilter_available):
    log = synthetic_log(duration=6.0)
    keep = (log.t < 2.0) | (log.t > 3.0)  # a 1 s hole: longer than max_gyro_gap_us
    s = replay(log.select(keep), parse_vehicle(VEHICLE), ReplayOptions(progress=False)).summary
    assert s["resyncs_by_replay"] == 1 and s["counters"]["resyncs"] == 1 and s["finite"]


def test_events_log_pushes_each_stream_at_its_own_time(cfilter_available):
    full = synthetic_log(duration=8.0)
    # rotor speeds at 1/4 of the gyro rate, on their own rows (like the ULog/tlog importers)
    rotor_rows = np.arange(0, len(full), 4)
    n_g, n_r = len(full), rotor_rows.size
    t = np.concatenate([full.t[rotor_rows] - 1e-4, full.t])
    order = np.argsort(t, kind="stable")
    gyro = np.vstack([np.full((n_r, 3), np.nan), full.gyro])[order]
    speeds = np.vstack([full.rotor_speed[rotor_rows], np.full((n_g, 4), np.nan)])[order]
    events = FlightLog(t=np.clip(t[order], 0, None), gyro=gyro, rotor_speed=speeds, extra={})
    s = replay(events, parse_vehicle(VEHICLE), ReplayOptions(progress=False)).summary
    assert s["streams"] == "events"
    assert s["counters"]["gyro_accepted"] == n_g
    assert s["counters"]["rotor_accepted"] + sum(s["rejected"].values()) == n_r
    np.testing.assert_allclose(s["kf_mean"], KF_TRUE, rtol=0.08)
    # the flying gate holds the latest rotor row over the gyro rows: no gyro row is lost
    flying = replay(events, parse_vehicle(VEHICLE), ReplayOptions(segment="flying", progress=False)).summary
    assert flying["counters"]["gyro_accepted"] == n_g


def test_missing_inertia_is_explained(cfilter_available):
    vehicle = parse_vehicle({**VEHICLE, "inertia": None})
    with pytest.raises(UserError, match="inertia is null.*--unit-inertia"):
        replay(synthetic_log(duration=2.0), vehicle, ReplayOptions(progress=False))


def test_unit_inertia_mode_estimates_kf_over_j(cfilter_available):
    log = synthetic_log(duration=20.0)
    vehicle = parse_vehicle({**VEHICLE, "inertia": None, "kf_nominal": None, "km_nominal": None})
    s = replay(log, vehicle, ReplayOptions(unit_inertia=True, progress=False)).summary
    assert s["mode"] == "unit_inertia" and s["finite"]
    # Jxx = Jyy, so the roll/pitch "kf" is kf/Jxx
    np.testing.assert_allclose(s["kf_mean"], KF_TRUE / VEHICLE["inertia"][0], rtol=0.05)
    assert all(s["converged"]["kf"])
    # yaw "km" is km/Jzz; its prior comes from a weak least-squares fit here, and the
    # filter must not claim convergence on a value that is off
    km_true = KM_TRUE / VEHICLE["inertia"][2]
    for k in range(4):
        close = abs(s["km_mean"][k] / km_true[k] - 1) < 0.25
        assert close or not s["converged"]["km"][k]


def _run_cli(argv):
    from propid.commands import replay as command

    parser = argparse.ArgumentParser()
    command.add_arguments(parser)
    return command.run(parser.parse_args(argv))


def test_cli_writes_json_and_plot(cfilter_available, tmp_path):
    log_path = tmp_path / "synthetic.csv"
    write_flightlog(log_path, synthetic_log(duration=6.0))
    write_vehicle(tmp_path / "synthetic.vehicle.json", parse_vehicle(VEHICLE))
    out, png = tmp_path / "out.json", tmp_path / "out.png"
    assert _run_cli(["--log", str(log_path), "--json", str(out), "--plot", str(png), "--no-progress",
                     "--thrust-coeff-rel-std0", "0.4"]) == 0
    summary = json.loads(out.read_text())
    for key in ("kf", "kf_std", "km", "km_std", "kf_mean", "km_mean", "gyro_bias", "gyro_bias_std", "converged",
                "rejected", "counters", "config"):
        assert key in summary
    assert summary["config"]["thrust_coeff_rel_std0"] == 0.4
    assert png.stat().st_size > 5000 and png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.skipif(not CRAZYFLIE.is_dir(), reason="shared real data not present")
def test_real_crazyflie_replay_is_finite_and_converged(cfilter_available):
    """One real run with NaN rows and two eRPM spikes. Bounds (see docs/real-data.md):
    finite, every kf converged, every kf between 0.02x and 1.5x the thrust-stand value
    (the gyro-only filter reads far low on these logs), km within 0.2x..5x the nominal,
    each glitch rejected by its own reason."""
    vehicle = read_vehicle(CRAZYFLIE / "crazyflie21b.vehicle.json")
    log = read_flightlog(CRAZYFLIE / "multisine_20251017_run1.csv", vehicle)
    s = replay(log, vehicle, ReplayOptions(segment="flying", progress=False)).summary
    assert s["finite"] and all(s["converged"]["kf"])
    kf = np.array(s["kf_mean"])
    assert np.all((kf > 0.02 * 3.72e-8) & (kf < 1.5 * 3.72e-8))
    km = np.array(s["km_mean"])
    assert np.all((km > 0.2 * 1.2e-10) & (km < 5 * 1.2e-10))
    assert np.all(np.array(s["kf_std"]) > 0) and np.all(np.isfinite(s["gyro_bias"]))
    assert s["rejected"]["PROPID_ERR_NOT_FINITE"] == 28  # rows with an empty omega_i while flying
    assert s["rejected"]["PROPID_ERR_ROTOR_SPEED_RANGE"] == 2  # the two documented eRPM spikes
    assert fleet_summary([s], 3.72e-8)["kf_fleet_over_reference"] == pytest.approx(kf.mean() / 3.72e-8)


@pytest.mark.skipif(not (BETAFLIGHT / "btfl_004_log2.csv").is_file(), reason="shared real data not present")
def test_real_betaflight_needs_unit_inertia(cfilter_available):
    vehicle = read_vehicle(BETAFLIGHT / "betaflight_quadx.vehicle.json")
    log = read_flightlog(BETAFLIGHT / "btfl_004_log2.csv", vehicle)
    with pytest.raises(UserError, match="inertia is null"):
        replay(log, vehicle, ReplayOptions(progress=False))
    short = log.select(log.t < 8.0)
    s = replay(short, vehicle, ReplayOptions(segment="flying", unit_inertia=True, progress=False)).summary
    assert s["finite"] and s["mode"] == "unit_inertia"
    assert all(v > 0 for v in s["kf_mean"]) and all(v > 0 for v in s["km_mean"])


def _sitl_binary() -> Path | None:
    import os

    build = Path(os.environ.get("PROPID_BUILD_DIR", Path(__file__).resolve().parents[2] / "build" / "host"))
    binary = build / "sitl" / "propid_sitl"
    return binary if binary.is_file() else None


@pytest.mark.skipif(_sitl_binary() is None, reason="propid_sitl not built")
def test_replay_of_a_sitl_log_reproduces_the_in_loop_filter(cfilter_available, tmp_path):
    """The SITL runs the same C filter in the loop with the library defaults and logs its
    estimates; replaying its log with --noise default must land on the same numbers.
    --paper: sensors sampled at the control rate, so the log holds exactly what the filter
    received (with the default ESC telemetry model the rotor samples arrive at their own
    times, which one CSV row per control step cannot carry)."""
    import subprocess

    log_path = tmp_path / "sitl.csv"
    subprocess.run([str(_sitl_binary()), "--paper", "--duration", "3", "--log", str(log_path)],
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120, check=False)
    assert log_path.is_file(), "propid_sitl wrote no log"
    vehicle = read_vehicle(tmp_path / "sitl.vehicle.json")
    log = read_flightlog(log_path, vehicle)
    s = replay(log, vehicle, ReplayOptions(noise="default", progress=False)).summary
    in_loop_kf = [log.extra[f"est_kf_{i + 1}"][-1] for i in range(vehicle.rotor_count)]
    in_loop_km = [log.extra[f"est_km_{i + 1}"][-1] for i in range(vehicle.rotor_count)]
    np.testing.assert_allclose(s["kf"], in_loop_kf, rtol=0.005)
    np.testing.assert_allclose(s["km"], in_loop_km, rtol=0.005)
