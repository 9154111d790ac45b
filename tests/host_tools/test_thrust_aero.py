"""The airspeed terms of the rotor thrust in the accelerometer row (replay/thrust_aero.py, docs/real-data.md
"The square runs' offset with the accelerometer"), and the per-rotor ceiling of replay/rotor_spread.py.

The SITL flight has both terms in its physics (`rotor_drag`: per rotor -Omega k_z v_z along z;
`translational_lift`: +k_h v_h^2 per rotor), so the fit must find their sign and size, and the
accelerometer-aided kf must lose the bias they put into it once they are carried."""

from __future__ import annotations

import json
import math
import subprocess

import numpy as np
import pytest

from propid.cli import main
from propid.errors import UserError
from propid.flightlog import FlightLog, parse_vehicle, read_flightlog, read_vehicle
from propid.replay import ReplayOptions, replay
from propid.replay.rotor_spread import deviation_covariance, probability_all_within, spread_bound
from propid.replay.thrust_aero import carry_thrust_aero, fit_thrust_aero, regressors
from propid.signals import log_body_velocity

# The SITL's crazyflie preset (sitl/physics/vehicle_presets.c): RotorPy's k_z and k_h scaled by disc area.
SITL_INFLOW_COEFF = 7.553e-7  # N/(rad/s m/s) per rotor
SITL_TRANSLATIONAL_COEFF = 1.8e-4  # N/(m/s)^2 per rotor
STRENGTH = 3.0  # both effects 3x the preset: a bias well above the filter's spread in a 30 s flight

VEHICLE = {"name": "quad", "mass": 0.05,
           "rotors": [{"position": [0.04, -0.04, 0.0], "yaw_sign": -1}, {"position": [-0.04, -0.04, 0.0], "yaw_sign": 1},
                      {"position": [-0.04, 0.04, 0.0], "yaw_sign": -1}, {"position": [0.04, 0.04, 0.0], "yaw_sign": 1}],
           "inertia": [2.5e-5, 2.8e-5, 4.9e-5], "kf_nominal": 3.7e-8, "km_nominal": 1.2e-10}


def table_log(n: int, rng, quat: np.ndarray, velocity: np.ndarray, acc_z: np.ndarray | None = None,
              speeds: np.ndarray | None = None) -> FlightLog:
    t = np.arange(n) * 0.01
    speeds = rng.uniform(1500.0, 2000.0, size=(n, 4)) if speeds is None else speeds
    extra = {"qw": quat[:, 0], "qx": quat[:, 1], "qy": quat[:, 2], "qz": quat[:, 3],
             "vx": velocity[:, 0], "vy": velocity[:, 1], "vz": velocity[:, 2],
             "acc_x": np.zeros(n), "acc_y": np.zeros(n), "acc_z": np.full(n, 9.8) if acc_z is None else acc_z}
    return FlightLog(t=t, gyro=np.zeros((n, 3)), rotor_speed=speeds, extra=extra)


def test_body_velocity_is_the_world_velocity_in_the_body_frame():
    n = 3
    half = math.radians(90.0) / 2
    yaw90 = np.tile([math.cos(half), 0.0, 0.0, math.sin(half)], (n, 1))  # body x points world y
    log = table_log(n, np.random.default_rng(0), yaw90, np.tile([1.0, 0.0, 0.5], (n, 1)))
    np.testing.assert_allclose(log_body_velocity(log), np.tile([0.0, -1.0, 0.5], (n, 1)), atol=1e-12)
    pitch90 = np.tile([math.cos(half), 0.0, math.sin(half), 0.0], (n, 1))  # body z points world x
    log = table_log(n, np.random.default_rng(0), pitch90, np.tile([2.0, 0.0, 0.0], (n, 1)))
    x = regressors(log)
    np.testing.assert_allclose(x["climb"], log.rotor_speed.sum(axis=1) * 2.0, rtol=1e-12)
    np.testing.assert_allclose(x["translational"], 0.0, atol=1e-20)


def test_the_pooled_fit_recovers_known_terms_with_one_intercept_per_log():
    vehicle = parse_vehicle(VEHICLE)
    kf, climb, translational = 3.7e-8, -2.0e-6, 5.0e-4
    rng = np.random.default_rng(4)
    logs = []
    for bias in (0.3, -0.4):  # a different accelerometer bias per flight
        n = 2000
        quat = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        velocity = rng.normal(0.0, 0.8, size=(n, 3))
        speeds = rng.uniform(1500.0, 2000.0, size=(n, 4))
        force = (kf * (speeds**2).sum(axis=1) + climb * speeds.sum(axis=1) * velocity[:, 2]
                 + translational * 4 * (velocity[:, 0] ** 2 + velocity[:, 1] ** 2))
        logs.append(table_log(n, rng, quat, velocity, force / vehicle.mass + bias, speeds))
    fit = fit_thrust_aero(logs, vehicle)
    assert fit["logs"] == 2 and fit["rows"] == 4000
    assert fit["kf"] == pytest.approx(kf, rel=1e-6)
    assert fit["coefficients"]["climb"] == pytest.approx(climb, rel=1e-6)
    assert fit["coefficients"]["translational"] == pytest.approx(translational, rel=1e-6)
    only = fit_thrust_aero(logs, vehicle, ("climb",))
    assert set(only["coefficients"]) == {"climb"}
    with pytest.raises(UserError, match="thrust terms must be among"):
        fit_thrust_aero(logs, vehicle, ("ground",))


def test_carrying_the_terms_subtracts_them_from_acc_z_and_off_leaves_the_log():
    rng = np.random.default_rng(5)
    n = 50
    log = table_log(n, rng, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), rng.normal(0.0, 1.0, size=(n, 3)))
    plain = parse_vehicle(VEHICLE)
    same, note = carry_thrust_aero(log, plain, "off")
    assert same is log and note == "not modelled"
    with pytest.raises(UserError, match="needs thrust_climb_coeff"):
        carry_thrust_aero(log, plain, "on")
    with pytest.raises(UserError, match="choose on or off"):
        carry_thrust_aero(log, plain, "auto")
    vehicle = parse_vehicle(dict(VEHICLE, thrust_climb_coeff=-2e-6, thrust_translational_coeff=4e-4))
    out, note = carry_thrust_aero(log, vehicle, "on")
    x = regressors(log)
    expected = log.extra["acc_z"] - (-2e-6 * x["climb"] + 4e-4 * x["translational"]) / vehicle.mass
    np.testing.assert_allclose(out.extra["acc_z"], expected, rtol=1e-12)
    np.testing.assert_array_equal(log.extra["acc_z"], 9.8)  # the input log is not touched
    assert "thrust_climb_coeff -2e-06" in note
    with pytest.raises(UserError, match="needs --aiding gyro\\+accel"):
        replay(log, vehicle, ReplayOptions(aiding="gyro", thrust_aero="on", progress=False))
    # the keys are written back only when set
    assert vehicle.to_json_dict()["thrust_translational_coeff"] == 4e-4
    assert "thrust_climb_coeff" not in plain.to_json_dict()


def test_deviation_probability_matches_the_two_rotor_closed_form():
    # two equal rotors, independent errors sigma: d_1 = (k_1 - k_2) / (2 m) has std sigma / sqrt(2) (relative),
    # so P(|d_1| <= t) = erf(t / sigma)
    sigma = 0.04
    cov = deviation_covariance(np.array([1.0, 1.0]), np.diag([sigma**2, sigma**2]))
    np.testing.assert_allclose(np.sqrt(np.diag(cov)), sigma / math.sqrt(2.0), rtol=1e-12)
    assert probability_all_within(cov, 0.05) == pytest.approx(math.erf(0.05 / sigma), abs=0.01)
    assert probability_all_within(cov * 1e-4, 0.05) == 1.0
    # a common error of all rotors (the scale) does not move their deviation from the mean
    common = deviation_covariance(np.ones(4), np.full((4, 4), 0.01))
    np.testing.assert_allclose(common, 0.0, atol=1e-15)
    # the chi-squared of an observed spread, rotors 1.0 and 1.1 with std 0.04 each: d_1 = 1 / 1.05 - 1, whose
    # variance is (a^2 + b^2) 0.04^2 with a = dd_1/dk_1 = 1/m - k_1/(2 m^2), b = dd_1/dk_2 = -k_1/(2 m^2)
    bound = spread_bound(np.array([1.0, 1.1]), np.diag([0.04**2, 0.04**2]))
    m = 1.05
    a, b = 1 / m - 1 / (2 * m * m), -1 / (2 * m * m)
    assert bound["degrees_of_freedom"] == 1
    assert bound["chi_squared"] == pytest.approx((1 / m - 1) ** 2 / ((a * a + b * b) * 0.04**2), rel=1e-9)


def test_sitl_flight_with_climb_and_translational_thrust(cfilter_available, sitl_binary, tmp_path):
    """Fitted sign and size of both terms recovered; the accelerometer-aided kf biased without them and not with."""
    log_path = tmp_path / "climb.csv"
    subprocess.run([str(sitl_binary), "--paper", "--quiet", "--duration", "30", "--seed", "3", "--log-rate", "100",
                    "--lissajous-climb", "0.1", "--effect", f"rotor_drag={STRENGTH}",
                    "--effect", f"translational_lift={STRENGTH}", "--log", str(log_path)],
                   stdout=subprocess.DEVNULL, timeout=120, check=True)
    fitted_path = tmp_path / "fitted.vehicle.json"
    assert main(["replay", "--log", str(log_path), "--thrust-aero-out", str(fitted_path), "--aiding", "gyro+accel",
                 "--no-progress", "--json", str(tmp_path / "plain.json")]) == 0
    fitted = read_vehicle(fitted_path)
    climb_only = tmp_path / "climb_only.vehicle.json"
    assert main(["replay", "--log", str(log_path), "--thrust-aero-out", str(climb_only), "--thrust-aero-terms",
                 "climb", "--aiding", "gyro+accel", "--no-progress", "--json", str(tmp_path / "again.json")]) == 0
    assert read_vehicle(climb_only).thrust_translational_coeff is None
    assert read_vehicle(climb_only).thrust_climb_coeff < 0
    assert fitted.thrust_climb_coeff == pytest.approx(-STRENGTH * SITL_INFLOW_COEFF, rel=0.10)
    assert fitted.thrust_translational_coeff == pytest.approx(STRENGTH * SITL_TRANSLATIONAL_COEFF, rel=0.20)

    vehicle = read_vehicle(tmp_path / "climb.vehicle.json")
    log = read_flightlog(log_path, vehicle)
    truth = np.array([log.extra[f"true_kf_{i + 1}"][-1] for i in range(4)])
    options = ReplayOptions(aiding="gyro+accel", torque_scale="on", rotor_inertia="off", progress=False)
    plain = replay(log, vehicle, options).summary
    carried = replay(log, fitted, ReplayOptions(**{**options.__dict__, "thrust_aero": "on"})).summary
    assert plain["config_notes"]["thrust_aero"] == "not modelled"
    assert "thrust_climb_coeff" in carried["config_notes"]["thrust_aero"]
    bias_plain = float(np.mean(np.array(plain["kf"]) / truth)) - 1.0
    bias_carried = float(np.mean(np.array(carried["kf"]) / truth)) - 1.0
    assert bias_plain < -0.02  # the terms read as a lower thrust slope (measured -3.5 %)
    assert abs(bias_carried) < 0.01 and abs(bias_carried) < 0.3 * abs(bias_plain)  # measured -0.2 %
    # the replay's JSON carries the per-rotor ceiling, a probability
    bound = json.loads((tmp_path / "plain.json").read_text())["kf_rotor_spread_bound"]
    assert 0.0 <= bound["p_every_rotor_within"] <= 1.0 and all(s > 0 for s in bound["deviation_std"])


def test_thrust_evidence_finds_the_term_the_logs_carry():
    from propid.thrust_evidence import render_evidence, thrust_evidence

    vehicle = parse_vehicle(dict(VEHICLE, rotor_radius=0.03))
    kf, climb = 3.7e-8, -2.0e-6
    rng = np.random.default_rng(6)
    logs = {}
    for name in ("square_run1", "random_run1", "random_run2"):
        n = 1500
        velocity = rng.normal(0.0, 0.6, size=(n, 3))
        speeds = rng.uniform(1500.0, 2000.0, size=(n, 4))
        force = kf * (speeds**2).sum(axis=1) + climb * speeds.sum(axis=1) * velocity[:, 2]
        log = table_log(n, rng, np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), velocity, force / vehicle.mass + 0.2, speeds)
        log.extra["pz"] = np.linspace(1.0, 1.5, n)
        logs[name] = log
    entries = {tuple(e["terms"]): e for e in thrust_evidence(logs, vehicle, kf)}
    with_climb = entries[("climb",)]
    assert with_climb["slope_cv"] < 1e-9 and with_climb["square"] == pytest.approx(1.0, rel=1e-9)
    assert with_climb["coefficients"]["climb"]["positive"] == 0
    assert with_climb["coefficients"]["climb"]["median"] == pytest.approx(climb, rel=1e-6)
    assert entries[()]["slope_cv"] > with_climb["slope_cv"]  # without the term the slope scatters
    run = with_climb["coefficients"]["climb"]["per_run"]["square_run1"]
    # white noise-free data: the resampled fits agree to rounding, far inside the coefficient
    assert run["coefficient"] == pytest.approx(climb, rel=1e-6) and 0.0 <= run["bootstrap_std"] < 1e-3 * abs(climb)
    assert ("ground",) in entries and "| climb |" in render_evidence(list(entries.values()))
