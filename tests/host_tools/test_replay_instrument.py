"""propid replay --instrument commands (docs/math.md §16): the log's cmd_i columns reach the filter's
first stage (propid_push_motor_command), its lag rule, and the one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog, parse_vehicle
from propid.replay import ReplayOptions, replay
from propid.replay.instrument import LAG_CANDIDATES_S, choose_lag, command_columns
from test_replay import BIAS_TRUE, KF_TRUE, KM_TRUE, VEHICLE, rate_loop_flight

TOP_SPEED = 4000.0  # the commands' full scale [rad/s]
MOTOR_LAG = 0.03  # [s]


def commanded_log(telemetry_rel_noise: float, duration: float = 20.0, rate: float = 250.0,
                  seed: int = 5) -> FlightLog:
    """An X quad whose rate loop (on the true rates) commands rotor speeds; the motors follow their
    commands with a first-order lag; the telemetry is the true speed with white noise of
    telemetry_rel_noise of it; cmd_i = command / TOP_SPEED."""
    rng = np.random.default_rng(seed)
    f = rate_loop_flight(duration, rate, rng)
    inertia, j_inv, allocation, alloc_inv = f.inertia, f.inertia_inv, f.allocation, f.allocation_inv
    t, thrust, demand = f.t, f.thrust, f.demand
    n = len(t)
    speeds = np.empty((n, 4))
    commands = np.empty((n, 4))
    rate_true = np.zeros((n, 3))
    omega = np.zeros(3)
    speed = None
    substeps = 4
    h = 1.0 / (rate * substeps)
    for k in range(n):
        rate_true[k] = omega
        speeds[k] = speed if speed is not None else 0.0
        torque_cmd = demand[k] - inertia @ (4.0 * omega)
        command = np.sqrt(np.clip(alloc_inv @ np.concatenate([[thrust[k]], torque_cmd]), 1.0, None))
        speed = command.copy() if speed is None else speed
        if k == 0:
            speeds[k] = speed
        commands[k] = command
        for _ in range(substeps):
            speed = command + (speed - command) * np.exp(-h / MOTOR_LAG)
            torque = (allocation @ speed ** 2)[1:]
            omega = omega + j_inv @ (torque - np.cross(omega, inertia @ omega)) * h
    gyro = rate_true + BIAS_TRUE + rng.normal(0, 0.005, size=(n, 3))
    measured = speeds * (1.0 + telemetry_rel_noise * rng.standard_normal(speeds.shape))
    extra = {f"cmd_{i + 1}": np.clip(commands[:, i] / TOP_SPEED, 0.0, 1.0) for i in range(4)}
    return FlightLog(t=t, gyro=gyro, rotor_speed=measured, extra=extra)


def kf_ratio(log: FlightLog, instrument: str) -> tuple[float, dict]:
    options = ReplayOptions(progress=False, aiding="gyro", instrument=instrument, max_rotor_speed=TOP_SPEED)
    summary = replay(log, parse_vehicle(VEHICLE), options).summary
    return float(np.mean(np.array(summary["kf_mean"]) / KF_TRUE)), summary


def test_the_commands_remove_the_telemetry_noise_attenuation(cfilter_available):
    # 0.5 % telemetry noise: telemetry 0.771, first stage 0.982 (1 %: 0.584 / 0.967; 2 %: 0.294 / 0.920, the
    # first stage's own estimation noise growing: docs/math.md §16).
    log = commanded_log(0.005)
    plain, _ = kf_ratio(log, "off")
    instrumented, summary = kf_ratio(log, "commands")
    print(f"kf / truth, 0.5 % telemetry noise: telemetry {plain:.3f}, commands' first stage {instrumented:.3f}")
    assert plain < 0.85
    assert abs(instrumented - 1.0) < 0.04
    notes = summary["config_notes"]["instrument"]
    assert notes["lag_s"] in LAG_CANDIDATES_S and notes["memory_s"] == 10.0
    assert summary["config"]["motor_command_instrument"] == 1
    assert summary["counters"]["command_accepted"] == len(log)
    assert summary["counters"]["instrument_inputs"] > 0.9 * len(log)


def test_the_lag_rule_finds_the_motor_lag():
    log = commanded_log(0.0, duration=10.0)
    rows = np.ones(len(log), dtype=bool)
    assert choose_lag(log, command_columns(log), rows)["lag_s"] == MOTOR_LAG


def test_missing_or_unscaled_commands_are_one_line_errors():
    log = commanded_log(0.0, duration=2.0)
    bare = FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed, extra={})
    with pytest.raises(UserError, match="needs the columns cmd_1"):
        command_columns(bare)
    unscaled = FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed,
                         extra={k: v * 65535.0 for k, v in log.extra.items()})
    with pytest.raises(UserError, match="normalised"):
        command_columns(unscaled)
    with pytest.raises(UserError, match="give off or commands"):
        replay(log, parse_vehicle(VEHICLE), ReplayOptions(progress=False, instrument="yes"))
    with pytest.raises(UserError, match="command-lag"):
        replay(log, parse_vehicle(VEHICLE), ReplayOptions(progress=False, instrument="commands", command_lag=5.0))


def test_the_guard_reaches_the_filter_and_refuses_a_bad_threshold(cfilter_available):
    """--command-min-f: into the configuration and the notes; on this log every rotor's command follows its
    speed, so the guard (F >= 10) holds the telemetry only while the fit is young (measured: the samples of
    its first 1.3 s, 925 rotor inputs), then the first stage throughout."""
    log = commanded_log(0.005, duration=10.0)
    options = ReplayOptions(progress=False, aiding="gyro", instrument="commands", max_rotor_speed=TOP_SPEED,
                            command_min_f=10.0)
    summary = replay(log, parse_vehicle(VEHICLE), options).summary
    assert summary["config"]["motor_command_min_f"] == 10.0
    assert summary["config_notes"]["instrument"]["min_f"] == 10.0
    assert 0 < summary["counters"]["instrument_guarded"] < 4 * len(log) // 5
    assert summary["counters"]["instrument_inputs"] > 0.8 * len(log)
    # (The window mean's kf / truth 0.958 with the guard, 0.980 without: the young fit's samples keep the
    # telemetry's attenuation. The default kf_mean, every estimate weighted by 1/std^2, reads 0.950 with the
    # guard: it gives those early samples more weight than the window does. The bound is the window mean's.)
    guarded = float(np.mean(np.array(summary["kf_mean_window"]) / KF_TRUE))
    assert abs(guarded - 1.0) < 0.05
    with pytest.raises(UserError, match="command-min-f"):
        replay(log, parse_vehicle(VEHICLE), ReplayOptions(progress=False, instrument="commands", command_min_f=-1.0))
