"""Where the filter starts on a log: `propid replay --start first|flying` (docs/sitl.md "Log").

`first` (the default): the segment's first row. `flying`: the first row from which the vehicle flies without a
break for HOLD_S (realdata_checks.flying_mask: every rotor above a third of the median spinning speed, clear of
the ground when the height is logged), or to the end of the log when it ends sooner. Rows before it (a
take-off, a simulator's untrimmed start that drives a rotor to 0 rad/s and back) are not given to the filter;
the per-log rules (noise, delay, walks) still measure on every row of the segment. Only the log's rotor
speeds, height and time stamps enter the rule. When no row qualifies the filter starts at the first row."""

from __future__ import annotations

import numpy as np

from propid.flightlog import FlightLog
from propid.realdata_checks import flying_mask

# [s] Uninterrupted flight that marks the start. Only decides which flying stretch counts: a start's short
# stretches before a rotor stops (a few ms in the simulator) do not; the rows cut are the rows before it.
HOLD_S = 0.5
STARTS = ("first", "flying")


def flying_start(log: FlightLog, hold_s: float = HOLD_S) -> int:
    """Index of the first flying row followed by hold_s of flight without a break (or by flight to the log's
    end); 0 when there is none."""
    flying = flying_mask(log)
    t = np.asarray(log.t, dtype=float)
    # For every row, the time of the first non-flying row at or after it (inf when none): a reversed running
    # minimum over the non-flying rows' times.
    breaks = np.where(flying, np.inf, t)
    next_break = np.minimum.accumulate(breaks[::-1])[::-1]
    held = flying & (next_break - t >= hold_s)
    first = np.flatnonzero(held)
    return int(first[0]) if first.size else 0
