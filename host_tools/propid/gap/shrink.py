"""How far: per axis, held-out residual RMS and open-loop prediction error before
(base model) and after (base + significant effects).

Held-out: with --holdout logs, the models fitted on the --log flights are evaluated
on the hold-out flights; otherwise the cross-validation's held-out predictions (each
block predicted by the fit on the other folds).

Open-loop prediction error at horizon h: the model's body rate propagated h seconds
from the measured rate, against the measured rate, i.e. the integral over [t, t+h] of
the (band-passed) torque residual divided by the axis inertia [rad/s]; for the thrust
axis the integral of the force residual over the mass [m/s, vertical speed]. RMS over
every start t whose horizon stays inside one flying segment.

What bounds the RMS shrink (`rms_library_in_sample`): the residual RMS left on the same
rows by the base model plus every testable candidate at once, fitted on those rows
(in-sample): no selection of the library predicts held-out rows better, so
1 - rms_library_in_sample / rms_before is the most the library could shrink the axis.
The band-passed torque is a differentiated gyro, whose noise fills the top of the band;
when this floor is close to rms_before the residual is sensor noise or outside the
library, and the prediction errors (an integral over the horizon, i.e. a low-pass) show
what the effects remove where they live.
"""

from __future__ import annotations

import numpy as np

from propid.gap.design import Design

HORIZONS = (0.1, 0.5)


def _runs(design: Design) -> list[tuple[int, int]]:
    """Contiguous row ranges (same flight, regular time steps)."""
    t = design.time
    fl = design.flight
    dt = np.diff(t)
    med = np.median(dt[dt > 0]) if np.any(dt > 0) else 1.0
    breaks = np.flatnonzero((np.abs(dt - med) > 0.5 * med) | (np.diff(fl) != 0)) + 1
    edges = np.concatenate([[0], breaks, [t.size]])
    return list(zip(edges[:-1], edges[1:]))


def prediction_error(design: Design, residual: np.ndarray, divisor: float, horizon: float) -> float:
    errs = []
    for a, b in _runs(design):
        if b - a < 3:
            continue
        dt = float(np.median(np.diff(design.time[a:b])))
        steps = int(round(horizon / dt))
        if steps < 1 or b - a <= steps:
            continue
        c = np.concatenate([[0.0], np.cumsum(residual[a:b]) * dt / divisor])
        errs.append(c[steps:] - c[:-steps])
    if not errs:
        return float("nan")
    e = np.concatenate(errs)
    return float(np.sqrt(np.mean(e**2)))


def shrink_table(design: Design, before: dict, after: dict, inertia: np.ndarray, mass: float | None,
                 library: dict | None = None) -> dict:
    """`library`: the in-sample residual of the base model plus every testable candidate on the
    same rows (the floor above), per axis; None leaves the key out."""
    out = {}
    for k, axis in enumerate(design.axes):
        divisor = float(inertia[k, k]) if axis != "thrust" else float(mass or 1.0)
        entry = {"rms_before": float(np.sqrt(np.mean(before[axis] ** 2))),
                 "rms_after": float(np.sqrt(np.mean(after[axis] ** 2)))}
        for h in HORIZONS:
            entry[f"pred_{h}s_before"] = prediction_error(design, before[axis], divisor, h)
            entry[f"pred_{h}s_after"] = prediction_error(design, after[axis], divisor, h)
        entry["reduction"] = 1.0 - entry["rms_after"] / entry["rms_before"] if entry["rms_before"] > 0 else 0.0
        if library is not None:
            entry["rms_library_in_sample"] = float(np.sqrt(np.mean(library[axis] ** 2)))
        entry["units"] = {"rms": "N" if axis == "thrust" else "N m",
                          "pred": "m/s (vertical speed)" if axis == "thrust" else "rad/s"}
        out[axis] = entry
    return out
