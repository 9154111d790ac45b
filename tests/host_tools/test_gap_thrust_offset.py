"""propid gap's thrust-axis constant (`--thrust-offset segment`, docs/gap.md "Base model"): the
accelerometer's zero-g offset b_z against the SITL's own.

Two SITL flights (the default 12 s Lissajous, crazyflie-plus, seed 5) that differ only in the
accelerometer's offset (`--accel-bias-max 2` and 0: the offset is drawn from its own random stream, so
the noise and the flight are the same): the true offset is the mean difference of their acc_z columns.
Through the origin kf_thrust carries it as 1 + b_z/g; with a constant per segment kf_thrust does not
move and the fitted offset moves by b_z."""

from __future__ import annotations

import subprocess
from dataclasses import replace

import numpy as np
import pytest

from propid.flightlog import read_flightlog, read_vehicle
from propid.gap import analysis, basefit
from propid.gap.prep import Band, Flight, prepare_flight
from propid.gap.report import write_report

G = 9.80665


@pytest.fixture(scope="module")
def twins(tmp_path_factory, sitl_binary):
    root = tmp_path_factory.mktemp("thrust_offset")
    logs = {}
    for name, bias_max in (("biased", "2"), ("clean", "0")):
        path = root / f"{name}.csv"
        subprocess.run([str(sitl_binary), "--quiet", "--duration", "12", "--seed", "5", "--accel-bias-max", bias_max,
                        "--log", str(path)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120,
                       check=True)
        logs[name] = path
    vehicle = read_vehicle(logs["clean"].with_name("clean.vehicle.json"))
    read = {name: read_flightlog(path, vehicle) for name, path in logs.items()}
    difference = read["biased"].acc[:, 2] - read["clean"].acc[:, 2]
    true_offset = float(np.nanmean(difference))
    assert np.nanstd(difference) < 0.01  # the same flight: only the offset (and its slow walk) differs
    return vehicle, read, true_offset


def _thrust_fit(log, vehicle, offset: bool) -> dict:
    flight = prepare_flight(log, vehicle, Band(thrust_offset=offset))
    return basefit.fleet_fit([flight], "thrust", vehicle.positions, vehicle.yaw_signs, vehicle.mass)


def _offset(fit: dict) -> float:
    (entry,) = fit["thrust_offset"]["per_log"].values()
    return entry["m_s2"]


def test_the_sitl_offset_is_large_enough_to_matter(twins):
    _, _, true_offset = twins
    assert abs(true_offset) > 0.1  # > 1 % of g: the bias kf_thrust carries through the origin


def test_through_the_origin_kf_thrust_carries_the_offset(twins):
    vehicle, logs, true_offset = twins
    biased, clean = (_thrust_fit(logs[k], vehicle, offset=False) for k in ("biased", "clean"))
    assert "thrust_offset" not in biased
    assert biased["value"] / clean["value"] - 1.0 == pytest.approx(true_offset / G, rel=0.1)


def test_with_the_constant_kf_thrust_ignores_the_offset_and_the_fitted_offset_is_the_sitls(twins):
    vehicle, logs, true_offset = twins
    biased, clean = (_thrust_fit(logs[k], vehicle, offset=True) for k in ("biased", "clean"))
    assert biased["value"] / clean["value"] == pytest.approx(1.0, abs=1e-3)
    assert _offset(biased) - _offset(clean) == pytest.approx(true_offset, abs=0.005)
    # the clean flight's own constant is the model's thrust-axis mismatch: small against the offset
    assert abs(_offset(clean)) < 0.25 * abs(true_offset)
    (entry,) = biased["thrust_offset"]["per_log"].values()
    assert entry["ci"][0] < entry["m_s2"] < entry["ci"][1]
    assert biased["thrust_offset"]["determined"]
    true_kf = float(np.mean([np.nanmean(logs["clean"].extra[f"true_kf_{i}"]) for i in range(1, 5)]))
    assert biased["value"] == pytest.approx(true_kf, rel=0.01)


@pytest.mark.parametrize("added", [-0.3, 0.3])
def test_a_constant_added_to_acc_z_moves_the_offset_by_itself_and_nothing_else(twins, added):
    """Metamorphic: acc_z + c is fitted with kf_thrust unchanged and the offset moved by exactly c."""
    vehicle, logs, _ = twins
    log = logs["clean"]
    shifted = replace(log, extra={**log.extra, "acc_z": log.extra["acc_z"] + added})
    before, after = _thrust_fit(log, vehicle, offset=True), _thrust_fit(shifted, vehicle, offset=True)
    assert after["value"] == pytest.approx(before["value"], rel=1e-9)
    assert after["ci"] == pytest.approx(before["ci"], rel=1e-9)
    assert _offset(after) - _offset(before) == pytest.approx(added, abs=1e-6)


def test_the_answer_carries_the_offset_per_log(twins, tmp_path):
    vehicle, logs, _ = twins
    options = analysis.Options(Band(thrust_offset=True), progress=False, auto_highpass=True)
    result = analysis.run([logs["biased"]], vehicle, [], options)
    summary = result["base_fit_details"]["thrust_offset"]
    assert summary["mode"] == "segment"
    for when in ("before", "after"):
        part = summary[when]
        assert set(part) == {"per_log", "collective_variation", "kf_thrust_ci_relative_halfwidth", "determined"}
        (entry,) = part["per_log"].values()
        assert set(entry) == {"m_s2", "ci", "per_segment_m_s2"}
        assert all(np.isfinite(entry["ci"]))
    assert result["base_fit"]["kf_thrust"]["value"] > 0
    off = analysis._thrust_offset_summary(Band(), {}, {})
    assert off["mode"] == "none" and "before" not in off
    result.pop("_internal", None)
    page = write_report(result, tmp_path / "report").read_text()
    assert "zero-g offset" in page and "offset [m/s^2]" in page and "biased" in page


def test_a_constant_collective_thrust_leaves_kf_thrust_undetermined():
    """A hover without collective-thrust variation: the constant and sum kf Omega^2 are collinear, so
    kf_thrust's interval spans far more than +-10 % and `determined` says so."""
    rate, n, kf, mass = 100.0, 3000, 2.0e-8, 0.05
    rng = np.random.default_rng(3)
    speed = 1900.0 + 2.0 * rng.standard_normal((n, 4))  # telemetry noise only: no commanded variation
    t = np.arange(n) / rate
    u = speed**2
    acc_z = kf * u.sum(axis=1) / mass + 0.2 + 0.05 * rng.standard_normal(n)
    zeros3 = np.zeros((n, 3))
    positions = np.array([[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [-0.05, 0.0, 0.0], [0.0, -0.05, 0.0]])
    flight = Flight(name="hover", path=None, rate_hz=rate, t=t, gyro=zeros3, rate_dot=zeros3, speed=speed,
                    speed_dot=np.gradient(speed, t, axis=0), torque=zeros3, specific_force_z=acc_z, acc=None,
                    body_velocity=None, height=None, cmd=None, vbat=None, segs=[(0, n)],
                    band=Band(thrust_offset=True), blocks=[(s, min(s + 200, n)) for s in range(0, n, 200)])
    fit = basefit.fleet_fit([flight], "thrust", positions, np.array([1.0, -1.0, 1.0, -1.0]), mass)
    assert fit["thrust_offset"]["collective_variation"] < 0.01
    assert not fit["thrust_offset"]["determined"]
    assert fit["thrust_offset"]["kf_thrust_ci_relative_halfwidth"] > 0.10
