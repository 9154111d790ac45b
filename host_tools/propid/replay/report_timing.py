"""The rotor report's timing error for the filter (config.rotor_timing_error, docs/math.md §14, "The report's
timing"): how far the instant a rotor-speed report stands for may be from the instant the filter pairs it with.

Rule (`--rotor-timing-error auto`): the median interval between new rotor-speed samples over the replayed rows.
A report held until the next one is between 0 and one interval old when it is used, and an ESC's measurement
latency (the period measured over the last revolutions, the frame's turnaround) is of the same order; the
interval is what the stream itself tells about both. Only the log's time stamps and rotor-speed values enter
(no coefficient, no gyro)."""

from __future__ import annotations

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog

TIMING_ERROR_MAX = 1.0  # [s] the firmware's bound (PROPID_ROTOR_TIMING_ERROR_MAX)


def report_interval(log: FlightLog, mask: np.ndarray) -> float | None:
    """Median time between new rotor-speed samples (a finite row that differs from the previous finite one) among
    the rows of `mask`; None when fewer than two new samples."""
    rows = np.flatnonzero(mask)
    speeds = log.rotor_speed[rows]
    finite = np.all(np.isfinite(speeds), axis=1)
    rows, speeds = rows[finite], speeds[finite]
    if rows.size < 2:
        return None
    new = np.concatenate([[True], np.any(speeds[1:] != speeds[:-1], axis=1)])
    times = log.t[rows[new]]
    steps = np.diff(times)
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else None


def resolve_rotor_timing_error(log: FlightLog, mask: np.ndarray, setting: float | str | None, config_fields: dict,
                               notes: dict) -> None:
    """config_fields['rotor_timing_error'] from --rotor-timing-error: auto (the rule above), off/None, or seconds."""
    if setting is None or setting == "off":
        notes["rotor_timing_error"] = "off"
        return
    if setting == "auto":
        interval = report_interval(log, mask)
        if interval is None:
            notes["rotor_timing_error"] = "auto: fewer than two new rotor-speed samples, off"
            return
        value = min(interval, TIMING_ERROR_MAX)
        config_fields["rotor_timing_error"] = value
        notes["rotor_timing_error"] = {"rule": "median interval between new rotor-speed samples", "seconds": value}
        return
    value = float(setting)
    if not (0.0 <= value <= TIMING_ERROR_MAX):
        raise UserError(f"--rotor-timing-error {setting!r}: choose auto, off or a number between 0 and "
                        f"{TIMING_ERROR_MAX:g} [s]")
    config_fields["rotor_timing_error"] = value
    notes["rotor_timing_error"] = "given"
