"""Replay on logs with outliers (docs/reliability.md "Replay on logs with outliers"):
0.5 % rotor-speed spikes must not raise the automatic max-rotor-speed limit, nor the
process noise `--noise auto` measures; the JSON's `finite` covers the body rate."""

from __future__ import annotations

import numpy as np
import pytest

from propid.flightlog import FlightLog, parse_vehicle
from propid.realdata_checks import absurd_speed_limit
from propid.replay import ReplayOptions, replay
from propid.replay.config import build_config
from propid.replay.run import estimates_finite
from test_replay import VEHICLE, synthetic_log


def with_spikes(log: FlightLog, fraction: float, value_of, seed: int = 11) -> FlightLog:
    """A copy with `fraction` of the rotor-speed samples replaced by value_of(rng, n)."""
    rng = np.random.default_rng(seed)
    speeds = log.rotor_speed.copy()
    finite = np.argwhere(np.isfinite(speeds))
    pick = finite[rng.choice(len(finite), int(fraction * len(finite)), replace=False)]
    speeds[pick[:, 0], pick[:, 1]] = value_of(rng, len(pick))
    return FlightLog(t=log.t, gyro=log.gyro, rotor_speed=speeds, extra={})


SPIKES = {
    "huge": lambda rng, n: rng.uniform(5.0e4, 1.0e6, n),   # CRC-failed frames decoded as absurd speeds
    "large": lambda rng, n: rng.uniform(1.0e4, 5.0e4, n),  # 3-15x the real peak
}


@pytest.mark.parametrize("kind", sorted(SPIKES))
def test_spikes_do_not_raise_the_speed_limit(kind):
    clean = synthetic_log()
    spiky = with_spikes(clean, 0.005, SPIKES[kind])
    limit_clean = absurd_speed_limit(clean.rotor_speed)
    limit_spiky = absurd_speed_limit(spiky.rotor_speed)
    assert limit_spiky == pytest.approx(limit_clean, rel=0.02)
    # The rule the limit replaced (2x the 99.9th percentile of everything) moved with the spikes.
    finite = spiky.rotor_speed[np.isfinite(spiky.rotor_speed)]
    assert 2.0 * np.percentile(finite, 99.9) > 3.0 * limit_clean


def test_speed_limit_keeps_real_peaks_and_survives_a_constant_log():
    clean = synthetic_log()
    assert absurd_speed_limit(clean.rotor_speed) > 1.5 * np.nanmax(np.where(clean.rotor_speed < 1e4,
                                                                             clean.rotor_speed, np.nan))
    constant = np.full((100, 4), 1500.0)
    assert absurd_speed_limit(constant) == pytest.approx(3000.0)


@pytest.mark.parametrize("kind", sorted(SPIKES))
def test_noise_auto_ignores_spikes(kind):
    vehicle = parse_vehicle(VEHICLE)
    clean = synthetic_log()
    spiky = with_spikes(clean, 0.005, SPIKES[kind])
    options = ReplayOptions(noise="auto", progress=False)
    q_clean = build_config(vehicle, clean, options)[0]["rate_process_noise"]
    q_spiky = build_config(vehicle, spiky, options)[0]["rate_process_noise"]
    assert q_spiky == pytest.approx(q_clean, rel=0.5)


def test_replay_with_spikes_stays_finite_and_bounded(cfilter_available):
    vehicle = parse_vehicle(VEHICLE)
    spiky = with_spikes(synthetic_log(), 0.005, SPIKES["huge"])
    s = replay(spiky, vehicle, ReplayOptions(noise="auto", progress=False)).summary
    assert s["finite"]
    assert s["body_rate_max_abs"] < 10.0  # the synthetic flight's rates stay below 1 rad/s
    assert s["rejected"].get("PROPID_ERR_ROTOR_SPEED_RANGE", 0) > 0
    assert s.get("rejected", {}).get("PROPID_ERR_NUMERIC", 0) == 0


def test_finite_looks_at_the_body_rate():
    series = {"kf": np.ones((3, 4)), "kf_std": np.ones((3, 4)), "km": np.ones((3, 4)), "km_std": np.ones((3, 4)),
              "gyro_bias": np.zeros((3, 3)), "gyro_bias_std": np.ones((3, 3)), "body_rate": np.zeros((3, 3))}
    assert estimates_finite(series)
    series["body_rate"][1, 2] = np.inf
    assert not estimates_finite(series)


def test_disturbance_bandwidth_reaches_the_filter_and_is_checked():
    """--disturbance-bandwidth HZ sets the states' bandwidth (docs/math.md §7); it needs the states and a
    positive frequency, each refused with a one-line error."""
    from propid.errors import UserError

    vehicle = parse_vehicle(VEHICLE)
    log = synthetic_log()
    config = build_config(vehicle, log, ReplayOptions(disturbance="on", disturbance_bandwidth=5.0))[0]
    assert config["disturbance_torque"] == 1 and config["disturbance_bandwidth"] == 5.0
    assert "disturbance_bandwidth" not in build_config(vehicle, log, ReplayOptions(disturbance="on"))[0]
    with pytest.raises(UserError, match="needs --disturbance on"):
        build_config(vehicle, log, ReplayOptions(disturbance_bandwidth=5.0))
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(UserError, match="positive frequency"):
            build_config(vehicle, log, ReplayOptions(disturbance="on", disturbance_bandwidth=bad))


def test_the_vehicle_files_loop_bandwidth_sets_the_disturbance_states_bandwidth(tmp_path):
    """loop_bandwidth_hz (written by propid gap --vehicle-out, docs/flightlog.md) is the states'
    bandwidth when they are on and none is given; a given --disturbance-bandwidth wins; with the
    states off it is not used. The notes say where the value came from; the key survives a
    write/read and a non-positive value is refused naming it."""
    from propid.errors import UserError
    from propid.flightlog import read_vehicle, write_vehicle

    write_vehicle(tmp_path / "v.json", parse_vehicle({**VEHICLE, "loop_bandwidth_hz": 2.0}))
    vehicle = read_vehicle(tmp_path / "v.json")
    assert vehicle.loop_bandwidth_hz == 2.0
    log = synthetic_log(duration=4.0)
    config, notes = build_config(vehicle, log, ReplayOptions(disturbance="on"))
    assert config["disturbance_bandwidth"] == 2.0 and "loop_bandwidth_hz" in notes["disturbance"]
    config, notes = build_config(vehicle, log, ReplayOptions(disturbance="on", disturbance_bandwidth=5.0))
    assert config["disturbance_bandwidth"] == 5.0 and "given" in notes["disturbance"]
    config, notes = build_config(vehicle, log, ReplayOptions(disturbance="off"))
    assert "disturbance_bandwidth" not in config and "disturbance_torque" not in config
    assert notes["disturbance"].startswith("off") and "loop_bandwidth_hz" in notes["disturbance"]
    for bad in (0.0, -2.0, "2", True):
        with pytest.raises(UserError, match="loop_bandwidth_hz"):
            parse_vehicle({**VEHICLE, "loop_bandwidth_hz": bad})
