"""Where the filter starts on a log (`propid replay --start first|flying`, replay/start.py, docs/sitl.md "Log"):
the rule on made-up rotor speeds, the option's check, and the SITL flight whose untrimmed start locks the
thrust-torque scale when the filter is given it."""

from __future__ import annotations

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog
from propid.replay import ReplayOptions, replay
from propid.replay.start import HOLD_S, flying_start

DT = 0.002


def rotor_log(speeds: np.ndarray) -> FlightLog:
    t = np.arange(speeds.shape[0]) * DT
    return FlightLog(t=t, gyro=np.zeros((t.size, 3)), rotor_speed=speeds)


def hover(seconds: float) -> np.ndarray:
    speeds = np.full((int(round(seconds / DT)), 4), 500.0)
    speeds[0] = np.nan  # the first row before the first rotor sample, as the simulator writes it
    return speeds


def test_start_skips_the_short_stretch_before_a_rotor_stops():
    """Rows 1-4 fly, rotor 4 is stopped from row 5 to row 45, the flight goes on from row 46: the start is row
    46, not row 1 (its stretch lasts 8 ms, far below HOLD_S)."""
    speeds = hover(2.0)
    speeds[5:46, 3] = 0.0
    assert flying_start(rotor_log(speeds)) == 46


def test_start_is_the_first_rotor_row_when_the_flight_has_no_break():
    assert flying_start(rotor_log(hover(2.0))) == 1


def test_flight_to_the_end_counts_and_no_hold_means_the_first_row():
    # The last break ends 0.2 s before the log does: flight to the end counts as held.
    speeds = hover(2.0)
    end_break = speeds.shape[0] - int(0.2 / DT)
    speeds[10:end_break, 0] = np.where(np.arange(10, end_break) % 100 < 50, 0.0, 500.0)
    speeds[end_break - 10:end_break, 0] = 0.0
    assert flying_start(rotor_log(speeds)) == end_break
    # Flight never lasts HOLD_S without a break before the last one, and the log ends in a break: row 0.
    speeds = hover(2.0)
    gap = int(HOLD_S / DT) // 2
    for k in range(1, speeds.shape[0], 2 * gap):
        speeds[k + gap:k + 2 * gap, 2] = 0.0
    speeds[-1, 2] = 0.0
    assert flying_start(rotor_log(speeds)) == 0


def test_start_setting_is_checked():
    with pytest.raises(UserError, match="--start 'late'"):  # checked before the log or the vehicle is read
        replay(rotor_log(hover(1.0)), None, ReplayOptions(start="late", progress=False))  # type: ignore[arg-type]


def test_flying_start_frees_the_scale_from_the_untrimmed_start(cfilter_available, untrimmed_start_flight,
                                                               replay_cli_json, tmp_path):
    """The untrimmed start's flight (conftest): the default replay (from the first row, the accelerometer and
    the thrust-torque scale on) ends with the scale far from 1 (measured 2.59, kf 0.40-0.47 x); with
    `--start flying` the filter starts at 0.096 s and every rotor's kf is within 5 % of the truth and the scale
    within 5 % of 1 (measured 0.999-1.010 x, 0.991). The per-log rules measure on the same rows either way
    (the same noise and delay)."""
    log_path, true_kf = untrimmed_start_flight
    first = replay_cli_json(log_path, tmp_path, "first")
    assert first["start"] == {"rule": "first", "from_s": 0.0, "rows_left_out": 0}
    assert first["aiding"] == "gyro+accel" and first["config_notes"]["torque_scale"] == "estimated"
    flying = replay_cli_json(log_path, tmp_path, "flying", "--start", "flying")
    assert flying["start"]["rule"] == "flying" and 0.05 < flying["start"]["from_s"] < 0.2
    assert flying["rows_replayed"] == first["rows_replayed"] - flying["start"]["rows_left_out"]
    for key in ("rate_process_noise", "gyro_noise_density", "rotor_delay_us"):
        assert flying["config"][key] == first["config"][key]
    np.testing.assert_allclose(np.array(flying["kf"]) / true_kf, 1.0, atol=0.05)
    assert flying["torque_scale"] == pytest.approx(1.0, abs=0.05)
    assert flying["counters"]["accel_reanchored"] == 0
