"""The firmware filter before/after: `propid replay` (the C filter, gyro only) on the
held-out logs with the given vehicle file and with the corrected one.

Both runs use the replay's recommended settings (`--segment flying`, or `all` when the
replay finds no flying rows; telemetry delay: each file's `esc_delay_s` when it has
one, else the replay's per-log rule), so the corrected run's filter holds the corrected delay. Every
other model key a file carries goes in the way `propid replay` takes it (replay/vehicle_terms.py,
replay/config.py): `gyro_scale` undone on the gyro at the boundary, `rotor_inertia` and
`aero_damping` into the filter's model, and `loop_bandwidth_hz` (the closed loop's bandwidth, from
`closed_loop_cancellation`) with the disturbance states on at that bandwidth, so they take the
torque the loop cancels and kf learns above it. Rows that repeat the previous row bit for bit (a
logger's copies of lost packets) are no samples for the filter (`--skip-repeats`, the replay's
recommended gyro-only chain on rows logs, docs/real-data.md "Repeated rows"). Fleet kf = mean over rotors of each run's
converged kf; run-to-run CV = std/mean over runs.
"""

from __future__ import annotations

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle


def _fleet(values: list[float]) -> dict:
    v = np.array(values, dtype=float)
    mean = float(np.mean(v)) if v.size else float("nan")
    return {"per_run": v.tolist(), "mean": mean,
            "cv": float(np.std(v) / mean) if v.size > 1 and mean else None}


def _replay_kf(log: FlightLog, vehicle: Vehicle, delay, skip_repeats: bool = False) -> float:
    from propid.replay import ReplayOptions, replay

    disturbance = "on" if vehicle.loop_bandwidth_hz is not None else "off"  # the file's bandwidth (replay/config.py)
    gyro_only = dict(esc_delay=delay, aiding="gyro", rotor_inertia="auto", aero_damping="auto", gyro_scale="auto",
                     torque_scale="off", disturbance=disturbance, skip_repeats=skip_repeats, progress=False)
    try:
        result = replay(log, vehicle, ReplayOptions(segment="flying", **gyro_only))
    except UserError:  # the replay's flying detector found nothing (e.g. a log that starts airborne)
        result = replay(log, vehicle, ReplayOptions(segment="all", **gyro_only))
    return float(np.mean(result.summary["kf_mean"]))


def filter_before_after(logs: list[FlightLog], vehicle: Vehicle, corrected: Vehicle, progress=None,
                        skip_repeats: bool = True) -> dict:
    before, after = [], []
    skip = skip_repeats
    for log in logs:
        # each file's esc_delay_s when it has one, else the replay's per-log rule
        before.append(_replay_kf(log, vehicle, "default", skip))
        after.append(_replay_kf(log, corrected, "default", skip))
        if progress:
            progress()
    return {"logs": [str(l.path) for l in logs], "kf_before": _fleet(before), "kf_after": _fleet(after),
            "skip_repeats": skip,
            "mode": "gyro only (no accelerometer aiding), --segment flying, the file's rotor_inertia, "
                    "aero_damping and gyro_scale carried as propid replay takes them"
                    + ("; rows repeating the previous row skipped (--skip-repeats)" if skip else "") + "".join(
                f"; {name}: disturbance states at its loop_bandwidth_hz {v.loop_bandwidth_hz:g} Hz"
                for name, v in (("vehicle file", vehicle), ("corrected vehicle", corrected))
                if v.loop_bandwidth_hz is not None)}
