"""Metamorphic checks of `propid replay`: copies of one synthetic flight that mean the same thing
(the rotors relabelled with the vehicle file, the mirror image, another clock origin, the events
layout) give the same estimates (docs/real-data.md, "The same flight written differently")."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from propid.flightlog import FlightLog, parse_vehicle
from propid.replay import ReplayOptions, replay
from test_replay import KF_TRUE, VEHICLE, synthetic_log

GROUND_S = 0.5  # the synthetic flight's first half second is 'on the ground'


def flight(duration: float = 8.0, rate: float = 200.0) -> FlightLog:
    """synthetic_log's rate-loop flight with what a real log adds: is_flying, height, an accelerometer
    (collective thrust / mass + noise), an attitude and a velocity that nothing here needs."""
    log = synthetic_log(duration=duration, rate=rate, seed=11)
    n = len(log)
    rng = np.random.default_rng(12)
    on_ground = log.t < GROUND_S
    thrust = np.nansum(KF_TRUE * log.rotor_speed**2, axis=1)
    extra = {
        "acc_x": rng.normal(0, 0.2, n), "acc_y": rng.normal(0, 0.2, n),
        "acc_z": thrust / VEHICLE["mass"] + rng.normal(0, 0.3, n),
        "qw": np.ones(n), "qx": np.zeros(n), "qy": np.zeros(n), "qz": np.zeros(n),
        "vx": rng.normal(0, 0.1, n), "vy": rng.normal(0, 0.1, n), "vz": np.zeros(n),
        "px": np.zeros(n), "py": np.zeros(n), "pz": np.where(on_ground, 0.04, 1.0),
        "is_flying": np.where(on_ground, 0.0, 1.0),
    }
    return FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed, extra=extra)


def run(log: FlightLog, vehicle: dict) -> dict:
    # the Python API's defaults (streams as recorded: esc_delay 0) with the noise measured on the log
    return replay(log, parse_vehicle(vehicle), ReplayOptions(segment="flying", noise="auto", progress=False)).summary


@pytest.fixture(scope="module")
def original(cfilter_available):
    log = flight()
    return log, run(log, VEHICLE)


def events_layout(log: FlightLog) -> FlightLog:
    """Each row as two: its rotor speeds, then its gyro sample with every other column (a log that
    merges each sensor's own stream, as the ULog and tlog importers write)."""
    n = len(log)

    def spread(values, on_rotor_row):
        out = np.full((2 * n,) + values.shape[1:], np.nan)
        out[(0 if on_rotor_row else 1)::2] = values
        return out

    return FlightLog(t=np.repeat(log.t, 2), gyro=spread(log.gyro, False), rotor_speed=spread(log.rotor_speed, True),
                     extra={k: spread(v, False) for k, v in log.extra.items()})


def test_the_events_layout_replays_like_the_rows(original):
    # The flag, height and accelerometer sit on the gyro rows only: the rotor rows used to count as 'on the
    # ground' (no rotor speed replayed), and the noise and accelerometer-noise rules, which needed both
    # streams on one row, fell back to library values.
    log, rows = original
    events = run(events_layout(log), VEHICLE)
    assert events["streams"] == "events"
    for key in ("gyro_noise_density", "rate_process_noise", "gyro_sample_rate_hz", "accel_noise_std"):
        assert events["config"][key] == pytest.approx(rows["config"][key], rel=1e-12), key
    assert events["gyro_samples_accepted"] == rows["gyro_samples_accepted"]
    np.testing.assert_allclose(events["kf_mean"], rows["kf_mean"], rtol=1e-9)
    np.testing.assert_allclose(events["km_mean"], rows["km_mean"], rtol=1e-9)


def accelerometer_rows_apart(log: FlightLog) -> FlightLog:
    """events_layout with a third row per sample, after the gyro row, that carries the accelerometer alone."""
    n = len(log)
    acc = ("acc_x", "acc_y", "acc_z")
    t = np.repeat(log.t, 3)
    gyro = np.full((3 * n, 3), np.nan)
    gyro[1::3] = log.gyro
    speeds = np.full((3 * n, log.rotor_count), np.nan)
    speeds[0::3] = log.rotor_speed
    extra = {}
    for key, values in log.extra.items():
        out = np.full(3 * n, np.nan)
        out[(2 if key in acc else 1)::3] = values
        extra[key] = out
    return FlightLog(t=t, gyro=gyro, rotor_speed=speeds, extra=extra)


def test_an_accelerometer_on_rows_of_its_own_is_fused(original):
    # It was pushed only together with a gyro sample: on rows of its own it was never fused, though the
    # replay said gyro+accel.
    log, rows = original
    apart = run(accelerometer_rows_apart(log), VEHICLE)
    assert apart["config_notes"]["aiding"] == "gyro+accel"
    assert apart["config"]["accel_noise_std"] == pytest.approx(rows["config"]["accel_noise_std"], rel=1e-12)
    assert apart["counters"]["accel_accepted"] == rows["counters"]["accel_accepted"] > 0
    # the same pushes in the same order: the same final state; the series is recorded before each
    # accelerometer row instead of after, so the converged means differ by a sample's worth
    np.testing.assert_allclose(apart["kf"], rows["kf"], rtol=1e-9)
    np.testing.assert_allclose(apart["kf_mean"], rows["kf_mean"], rtol=2e-3)


@pytest.mark.parametrize("perm", [[3, 2, 1, 0], [1, 2, 3, 0], [0, 2, 1, 3]])
def test_relabelled_rotors_give_the_same_rotors_estimates(original, perm):
    # new rotor j is old rotor perm[j], in the log's columns and in the vehicle file alike
    log, rows = original
    vehicle = copy.deepcopy(VEHICLE)
    vehicle["rotors"] = [VEHICLE["rotors"][p] for p in perm]
    relabelled = FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed[:, perm], extra=log.extra)
    result = run(relabelled, vehicle)
    # the filter's float32 sums run in rotor order: rounding, far below the std
    np.testing.assert_allclose(result["kf_mean"], np.asarray(rows["kf_mean"])[perm], rtol=1e-4)
    np.testing.assert_allclose(result["km_mean"], np.asarray(rows["km_mean"])[perm], rtol=1e-4)


def test_the_mirror_image_gives_the_same_coefficients(original):
    # Reflected across the body x-z plane: rotor y and the spin (yaw_sign) flip; body rates are a pseudovector
    # (-M w: x and z flip, y stays); accelerations, velocities, positions are vectors (M v: y flips); the
    # attitude M R M is the quaternion (w, -x, y, -z). Torques: roll and yaw flip with their rates, so every kf
    # and km is unchanged.
    log, rows = original
    vehicle = copy.deepcopy(VEHICLE)
    for rotor in vehicle["rotors"]:
        rotor["position"][1] *= -1
        rotor["yaw_sign"] *= -1
    extra = dict(log.extra)
    for key in ("acc_y", "vy", "py", "qx", "qz"):
        extra[key] = -extra[key]
    mirrored = FlightLog(t=log.t, gyro=log.gyro * [-1.0, 1.0, -1.0], rotor_speed=log.rotor_speed, extra=extra)
    result = run(mirrored, vehicle)
    np.testing.assert_allclose(result["kf_mean"], rows["kf_mean"], rtol=1e-6)
    np.testing.assert_allclose(result["km_mean"], rows["km_mean"], rtol=1e-6)


@pytest.mark.parametrize("origin_s", [-5.0, 1.0e5, 1.0e6])
def test_the_clock_origin_changes_nothing(original, origin_s):
    log, rows = original
    shifted = FlightLog(t=log.t + origin_s, gyro=log.gyro, rotor_speed=log.rotor_speed, extra=log.extra)
    result = run(shifted, VEHICLE)
    assert result["kf_mean"] == rows["kf_mean"] and result["km_mean"] == rows["km_mean"]
    assert result["rows_replayed"] == rows["rows_replayed"]


@pytest.fixture(scope="module")
def long_flight(cfilter_available):
    """A 24 s flight (the walk rules need several 4 s windows) whose gyro repeats the previous sample on
    every fifth row (a logger's sample-and-hold copies of lost packets)."""
    log = flight(duration=24.0)
    gyro = log.gyro.copy()
    gyro[5::5] = gyro[4::5][: len(gyro[5::5])]
    return FlightLog(t=log.t, gyro=gyro, rotor_speed=log.rotor_speed, extra=log.extra)


@pytest.mark.parametrize("rule, options, measured", [
    ("rotor-speed noise", dict(rotor_speed_noise="auto"), ("rotor_speed_noise", "rotor_speed_noise_time")),
    ("kf walk", dict(aiding="gyro", thrust_coeff_walk="auto"), ("thrust_coeff_rel_walk",)),
    ("scale walk", dict(aiding="gyro+accel", torque_scale_walk="auto"), ("torque_scale_walk",)),
])
def test_the_per_log_rules_measure_the_events_layout_like_the_rows(long_flight, rule, options, measured):
    # They read the rows log's rows as samples: on the events layout the other stream's rows lay between two
    # samples (the walks found no window with both streams and fell back to the library's value; the
    # rotor-speed noise read the interpolated fill of the gyro rows as samples, 80x too small on a real run;
    # the repeated-gyro check compared a gyro row with a rotor row and never warned).
    def summary(log):
        return replay(log, parse_vehicle(VEHICLE), ReplayOptions(segment="flying", noise="auto", esc_delay=0.0,
                                                                 progress=False, **options)).summary

    rows, events = summary(long_flight), summary(events_layout(long_flight))
    assert events["streams"] == "events" and rows["streams"] == "rows"
    for key in measured:
        assert rows["config"][key] > 0.0, (rule, key)
        assert events["config"][key] == pytest.approx(rows["config"][key], rel=1e-9), (rule, key)
    repeated = [w for w in rows["warnings"] if "repeat the previous gyro sample" in w]
    assert repeated and [w for w in events["warnings"] if "repeat the previous gyro sample" in w] == repeated


def test_the_delay_rule_reads_the_events_layout_like_the_rows(cfilter_available):
    # The rule gave 0 on any events log, where the rows copy of the same samples finds the stream's lag
    # (a real run: -20 ms against 0, kf 4 % apart). Rotor speeds logged 3 samples (15 ms) late:
    log = flight(duration=12.0)
    late = np.vstack([np.repeat(log.rotor_speed[:1], 3, axis=0), log.rotor_speed[:-3]])
    lagging = FlightLog(t=log.t, gyro=log.gyro, rotor_speed=late, extra=log.extra)

    def summary(log):
        return replay(log, parse_vehicle(VEHICLE), ReplayOptions(segment="flying", noise="auto", esc_delay="auto",
                                                                 progress=False)).summary

    rows, events = summary(lagging), summary(events_layout(lagging))
    assert events["streams"] == "events"
    assert rows["esc_delay_s"] == pytest.approx(0.015, abs=0.0051)  # found on the rows, within a sample
    assert events["esc_delay_s"] == rows["esc_delay_s"]
    np.testing.assert_allclose(events["kf_mean"], rows["kf_mean"], rtol=1e-9)


def with_commands(log: FlightLog) -> FlightLog:
    """The flight with motor commands cmd_1..cmd_N in 0..1: each rotor's speed 30 ms later, normalised (the
    speed follows its command with a lag); the rows that lost a rotor sample keep their command."""
    lead = int(round(0.03 / float(np.median(np.diff(log.t)))))
    speeds = np.nan_to_num(np.clip(log.rotor_speed, 0.0, None), nan=0.0)
    ahead = np.vstack([speeds[lead:], np.repeat(speeds[-1:], lead, axis=0)])
    commands = np.clip(ahead / (1.2 * np.percentile(speeds, 99.0)), 0.0, 1.0)
    extra = dict(log.extra)
    extra.update({f"cmd_{i + 1}": commands[:, i] for i in range(log.rotor_count)})
    return FlightLog(t=log.t, gyro=log.gyro, rotor_speed=log.rotor_speed, extra=extra)


def commands_on_rotor_rows(events: FlightLog, rotor_count: int) -> FlightLog:
    """An events log with its cmd_* moved from each gyro row to the rotor row before it (the same stamp)."""
    extra = dict(events.extra)
    for i in range(rotor_count):
        values = extra[f"cmd_{i + 1}"]
        moved = np.full_like(values, np.nan)
        moved[0::2] = values[1::2]
        extra[f"cmd_{i + 1}"] = moved
    return FlightLog(t=events.t, gyro=events.gyro, rotor_speed=events.rotor_speed, extra=extra)


def test_the_command_instrument_runs_on_the_events_layout_like_the_rows(original):
    # The commands were pushed only from rows that carry rotor speeds: an events log with its commands on the
    # gyro rows (the layout events_layout writes) fed the filter no command at all, silently (the first stage
    # never ran; square_20251017_run2's events copy: 0 of 2,267 commands, kf 0.7-5.6 % apart); and the lag
    # rule's first stage started from 0 where the log's first row is another stream's.
    log = with_commands(original[0])

    def summary(flight):
        return replay(flight, parse_vehicle(VEHICLE), ReplayOptions(
            segment="flying", noise="auto", esc_delay=0.0, aiding="gyro", instrument="commands", command_lag="auto",
            progress=False)).summary

    rows = summary(log)
    assert rows["counters"]["command_accepted"] > 0.9 * len(log)
    events = events_layout(log)
    for copy in (events, commands_on_rotor_rows(events, log.rotor_count)):
        result = summary(copy)
        assert result["streams"] == "events"
        assert result["config_notes"]["instrument"] == rows["config_notes"]["instrument"]
        assert result["counters"]["command_accepted"] == rows["counters"]["command_accepted"]
        assert result["counters"]["instrument_inputs"] == rows["counters"]["instrument_inputs"]
        np.testing.assert_allclose(result["kf_mean"], rows["kf_mean"], rtol=1e-9)
        np.testing.assert_allclose(result["km_mean"], rows["km_mean"], rtol=1e-9)


def test_the_lag_rule_starts_at_the_first_logged_command():
    # The firmware's first stage starts at its first command's steady state; the rule's copy started at 0
    # when the log's first row carried no command (an events log's rotor or gyro row).
    from propid.replay.instrument import lagged

    t = np.arange(6) * 0.01
    commands = np.array([[np.nan, np.nan], [0.4, 0.6], [0.5, 0.6], [np.nan, np.nan], [0.5, 0.7], [0.5, 0.7]])
    out = lagged(commands, t, 0.03)
    np.testing.assert_allclose(out[:3], [[0.4, 0.6]] * 3)  # held at the first command until it changes
    decay = np.exp(-0.01 / 0.03)
    np.testing.assert_allclose(out[3], [0.5 + (0.4 - 0.5) * decay, 0.6])


def test_skipping_repeats_skips_the_accelerometers_copies_and_keeps_its_fresh_samples(original):
    # A logger that samples separately streamed blocks by sample-and-hold copies each lost packet: on some
    # rows both the gyro and the accelerometer repeat the row before, on others only the gyro does and the
    # accelerometer's sample is new. --skip-repeats drops every stream's copies and nothing else.
    log, _ = original
    rng = np.random.default_rng(13)
    flying = np.flatnonzero(log.t >= GROUND_S + 0.1)
    rows = np.sort(rng.choice(flying[1:], 2 * (len(flying) // 10), replace=False))
    both, gyro_only = rows[0::2], rows[1::2]
    gyro = log.gyro.copy()
    extra = {k: v.copy() for k, v in log.extra.items()}
    for k in rows:  # in time order: a copy of a copy stays a copy
        gyro[k] = gyro[k - 1]
        if k in set(both.tolist()):
            for axis in ("acc_x", "acc_y", "acc_z"):
                extra[axis][k] = extra[axis][k - 1]
    lossy = FlightLog(t=log.t, gyro=gyro, rotor_speed=log.rotor_speed, extra=extra)
    vehicle = parse_vehicle(VEHICLE)

    def summary(skip):
        options = ReplayOptions(segment="flying", noise="auto", progress=False, skip_repeats=skip)
        return replay(lossy, vehicle, options).summary

    fused, skipped = summary(False), summary(True)
    assert skipped["repeated_rows_skipped"]["gyro"] == rows.size
    assert skipped["repeated_rows_skipped"]["accel"] == both.size

    def accel_pushes(s):
        counters = s["counters"]
        return counters["accel_accepted"] + sum(n for name, n in counters["rejected"].items() if "ACCEL" in name)

    assert accel_pushes(fused) > 0
    assert accel_pushes(skipped) == accel_pushes(fused) - both.size
