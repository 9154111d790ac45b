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
recommended gyro-only chain on rows logs, docs/real-data.md "Repeated rows"). When the corrected file
was calibrated with the filter (gap/calibration.py) both runs use the chain it was calibrated in, which
adds the coefficient walk by the per-log rule (`--thrust-coeff-rel-walk auto`). Fleet kf = mean over
rotors of each run's converged kf; run-to-run CV = std/mean over runs.
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


def chain_options(vehicle: Vehicle, delay="default", skip_repeats: bool = True, walk: bool = False,
                  segment: str = "flying") -> "ReplayOptions":
    """The gyro-only replay gap's files are checked (and calibrated) with: every model key the file carries
    taken as `propid replay` takes it, the disturbance states at its loop_bandwidth_hz when it has one;
    `walk`: the coefficient walk by the per-log torque-gain rule (`--thrust-coeff-rel-walk auto`)."""
    from propid.replay import ReplayOptions

    disturbance = "on" if vehicle.loop_bandwidth_hz is not None else "off"  # the file's bandwidth (replay/config.py)
    return ReplayOptions(segment=segment, esc_delay=delay, aiding="gyro", rotor_inertia="auto", aero_damping="auto",
                         gyro_scale="auto", torque_scale="off", disturbance=disturbance, skip_repeats=skip_repeats,
                         thrust_coeff_walk="auto" if walk else None, progress=False)


def replay_summary(log: FlightLog, vehicle: Vehicle, options: "ReplayOptions") -> dict:
    """The replay's summary of the flying rows, or of every row when its flying detector finds none
    (e.g. a log that starts airborne)."""
    from dataclasses import replace

    from propid.replay import replay

    try:
        return replay(log, vehicle, options).summary
    except UserError:
        if options.segment != "flying":
            raise
        return replay(log, vehicle, replace(options, segment="all")).summary


def _replay_kf(log: FlightLog, vehicle: Vehicle, delay, skip_repeats: bool = False, walk: bool = False) -> float:
    summary = replay_summary(log, vehicle, chain_options(vehicle, delay, skip_repeats, walk))
    return float(np.mean(summary["kf_mean"]))


def filter_before_after(logs: list[FlightLog], vehicle: Vehicle, corrected: Vehicle, progress=None,
                        skip_repeats: bool = True, walk: bool = False) -> dict:
    before, after = [], []
    skip = skip_repeats
    for log in logs:
        # each file's esc_delay_s when it has one, else the replay's per-log rule
        before.append(_replay_kf(log, vehicle, "default", skip, walk))
        after.append(_replay_kf(log, corrected, "default", skip, walk))
        if progress:
            progress()
    return {"logs": [str(l.path) for l in logs], "kf_before": _fleet(before), "kf_after": _fleet(after),
            "skip_repeats": skip, "walk_rule": walk,
            "mode": "gyro only (no accelerometer aiding), --segment flying, the file's rotor_inertia, "
                    "aero_damping and gyro_scale carried as propid replay takes them"
                    + ("; rows repeating the previous row skipped (--skip-repeats)" if skip else "")
                    + ("; coefficient walk by the per-log rule (--thrust-coeff-rel-walk auto), the chain the "
                       "calibrated file is meant for" if walk else "") + "".join(
                f"; {name}: disturbance states at its loop_bandwidth_hz {v.loop_bandwidth_hz:g} Hz"
                for name, v in (("vehicle file", vehicle), ("corrected vehicle", corrected))
                if v.loop_bandwidth_hz is not None)}
