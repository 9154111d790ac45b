"""The rotor report's timing error in replay (`--rotor-timing-error`, docs/math.md §14 "The report's timing",
docs/sitl.md "Log"): the interval rule, the option's checks, and the SITL flight whose untrimmed start locks the
thrust-torque scale without it."""

from __future__ import annotations

import numpy as np
import pytest

from propid.errors import UserError
from propid.flightlog import FlightLog
from propid.replay.report_timing import report_interval, resolve_rotor_timing_error


def rotor_log(t: np.ndarray, speeds: np.ndarray) -> FlightLog:
    return FlightLog(t=t, gyro=np.zeros((t.size, 3)), rotor_speed=speeds)


def test_interval_counts_new_samples_only():
    """Rows every 2 ms whose speeds change every other row (sample-and-hold at 250 Hz), one NaN row, the last
    rows outside the mask: the median interval between new samples is 4 ms."""
    t = np.arange(200) * 0.002
    speeds = np.repeat(np.arange(100, dtype=float) * 3.0 + 400.0, 2)[:, None] * np.ones((1, 4))
    speeds[50] = np.nan
    mask = np.ones(t.size, dtype=bool)
    mask[150:] = False
    assert report_interval(rotor_log(t, speeds), mask) == pytest.approx(0.004)
    config, notes = {}, {}
    resolve_rotor_timing_error(rotor_log(t, speeds), mask, "auto", config, notes)
    assert config["rotor_timing_error"] == pytest.approx(0.004)
    assert notes["rotor_timing_error"]["seconds"] == pytest.approx(0.004)


def test_interval_needs_two_new_samples_and_settings_are_checked():
    t = np.arange(10) * 0.002
    standing = np.full((10, 4), 500.0)
    config, notes = {}, {}
    resolve_rotor_timing_error(rotor_log(t, standing), np.ones(10, dtype=bool), "auto", config, notes)
    assert "rotor_timing_error" not in config and "off" in notes["rotor_timing_error"]
    for setting in (None, "off"):
        config = {}
        resolve_rotor_timing_error(rotor_log(t, standing), np.ones(10, dtype=bool), setting, config, {})
        assert config == {}
    resolve_rotor_timing_error(rotor_log(t, standing), np.ones(10, dtype=bool), 0.003, config, {})
    assert config["rotor_timing_error"] == 0.003
    with pytest.raises(UserError, match="rotor-timing-error"):
        resolve_rotor_timing_error(rotor_log(t, standing), np.ones(10, dtype=bool), 2.0, {}, {})


def test_timing_error_frees_the_scale_from_the_untrimmed_start(cfilter_available, untrimmed_start_flight,
                                                               replay_cli_json, tmp_path):
    """The untrimmed start's flight (conftest): the telemetry's age (1 ms latency, a 2 ms report hold) is
    then an input error larger than the process noise. Replayed with the accelerometer and the thrust-torque
    scale (the defaults) and exact timing, the scale locks far from 1 (measured 2.59, kf 0.40-0.47 x); with the
    report's timing error (the auto rule: 2 ms) every rotor's kf is within 5 % of the truth and the scale
    within 5 % of 1 (measured 0.980-0.994 x, 1.013)."""
    log_path, true_kf = untrimmed_start_flight
    exact = replay_cli_json(log_path, tmp_path, "exact")
    assert exact["aiding"] == "gyro+accel" and exact["config_notes"]["torque_scale"] == "estimated"
    assert exact["torque_scale"] > 1.5  # the flight has the trap
    timed = replay_cli_json(log_path, tmp_path, "timed", "--rotor-timing-error", "auto")
    assert timed["config"]["rotor_timing_error"] == pytest.approx(0.002)
    np.testing.assert_allclose(np.array(timed["kf"]) / true_kf, 1.0, atol=0.05)
    assert timed["torque_scale"] == pytest.approx(1.0, abs=0.05)
