"""Least-squares evidence for airspeed and attitude terms of the thrust on real logs (`propid real-data
--thrust-evidence`, docs/real-data.md "The square runs' offset with the accelerometer").

Per log, over its flying rows: m acc_z = kf sum_i Omega_i^2 + b + sum_k c_k x_k, with the accelerometer bias b
free, as the filter's accelerometer row has it. Reported per set of candidate terms: the run-to-run CV of that
slope kf and its mean over the square runs and the other runs (the split the filter shows), and per term its
median coefficient, how many runs have it positive, and its CV over runs; in the JSON also each run's
coefficient and its moving-block bootstrap std (blocks of BLOCK_S, the residual is coloured). A physical term
keeps one sign and a similar size on every run; a term whose sign follows the trajectory is not a property of
the rotor.
"""

from __future__ import annotations

import statistics

import numpy as np

from propid.flightlog import FlightLog, Vehicle
from propid.replay.thrust_aero import MIN_SEGMENT_S, cleaned_rotor_speeds, regressors
from propid.signals import segments

# Candidate terms: name -> (what it is, predicted sign or 0 when none is predicted)
CANDIDATES = {
    "climb": ("axial inflow: sum_i Omega_i v_z,b", -1),
    "translational": ("edgewise speed, blade-element form: N v_h^2", +1),
    "translational_u": ("edgewise speed, proportional form: sum_i Omega_i^2 v_h^2", +1),
    "drag_z": ("frame drag along z: v_z,b |v_z,b|", -1),
    "leak_x": ("horizontal specific force into z (misalignment): m acc_x", 0),
    "leak_y": ("horizontal specific force into z (misalignment): m acc_y", 0),
    "ground": ("ground effect: sum_i Omega_i^2 (R / 4 h)^2, h above the lowest logged height", +1),
}
BLOCK_S = 2.0  # bootstrap block [s]: longer than the slow (0.5-2 Hz) content the terms explain
BOOTSTRAP_DRAWS = 200
SETS = [(), ("climb",), ("translational",), ("translational_u",), ("drag_z",), ("leak_x", "leak_y"), ("ground",),
        ("climb", "translational"), ("climb", "translational_u"), ("climb", "translational", "drag_z")]


def candidate_columns(log: FlightLog, vehicle: Vehicle) -> tuple[np.ndarray, np.ndarray, dict, np.ndarray]:
    """(m acc_z, sum Omega^2, {candidate: column}, rows) of one log; rows = flying, everything finite."""
    from propid.realdata_checks import flying_mask

    speeds = cleaned_rotor_speeds(log)
    base = regressors(log, speeds)
    acc = log.acc
    if base is None or acc is None or vehicle.mass is None:
        raise ValueError("needs acc_*, vx..vz, qw..qz columns and the vehicle's mass")
    velocity_z = base["climb"] / np.where(speeds.sum(axis=1) != 0, speeds.sum(axis=1), np.nan)
    sum_u = (speeds**2).sum(axis=1)
    height = log.extra.get("pz")
    radius = vehicle.rotor_radius or 0.0
    columns = {
        "climb": base["climb"],
        "translational": base["translational"],
        "translational_u": sum_u * base["translational"] / speeds.shape[1],
        "drag_z": velocity_z * np.abs(velocity_z),
        "leak_x": vehicle.mass * acc[:, 0],
        "leak_y": vehicle.mass * acc[:, 1],
    }
    if height is not None and radius > 0:
        above = np.maximum(height - np.nanmin(height), 0.0) + radius  # hub a rotor radius above the skids
        columns["ground"] = sum_u * (radius / (4.0 * above)) ** 2
    rate = 1.0 / float(np.median(np.diff(log.t)))
    rows = np.zeros(len(log), dtype=bool)
    for a, b in segments(flying_mask(log), min_length=int(MIN_SEGMENT_S * rate)):
        rows[a:b] = True
    rows &= np.isfinite(acc[:, 2]) & np.isfinite(sum_u)
    for column in columns.values():
        rows &= np.isfinite(column)
    return vehicle.mass * acc[:, 2], sum_u, columns, rows


def _cv(values: list[float]) -> float:
    mean = statistics.fmean(values) if values else 0.0
    return statistics.stdev(values) / abs(mean) if len(values) > 1 and mean != 0.0 else float("nan")


def _block_bootstrap_std(design: np.ndarray, response: np.ndarray, block: int) -> np.ndarray:
    """Std of the least-squares coefficients over moving-block resamples of the rows (fixed seed)."""
    rows = design.shape[0]
    block = max(1, min(block, rows))
    count = max(1, rows // block)
    rng = np.random.default_rng(0)
    draws = []
    for _ in range(BOOTSTRAP_DRAWS):
        starts = rng.integers(0, rows - block + 1, count)
        pick = (starts[:, None] + np.arange(block)[None, :]).ravel()
        draws.append(np.linalg.lstsq(design[pick], response[pick], rcond=None)[0])
    return np.std(np.array(draws), axis=0)


def thrust_evidence(logs: dict[str, FlightLog], vehicle: Vehicle, reference_kf: float) -> list[dict]:
    """One entry per candidate set in SETS that every log can carry (see the module text)."""
    data = {name: candidate_columns(log, vehicle) for name, log in logs.items()}
    out = []
    for terms in SETS:
        if any(t not in data[name][2] for name in data for t in terms):
            continue  # e.g. no height logged: no ground term
        slopes, coefficients, per_run = {}, {t: [] for t in terms}, {t: {} for t in terms}
        for name, (force, sum_u, columns, rows) in data.items():
            design = np.column_stack([sum_u[rows], np.ones(int(rows.sum()))] + [columns[t][rows] for t in terms])
            coeffs, *_ = np.linalg.lstsq(design, force[rows], rcond=None)
            spread = _block_bootstrap_std(design, force[rows], int(BLOCK_S / float(np.median(np.diff(
                logs[name].t))))) if terms else None
            slopes[name] = float(coeffs[0]) / reference_kf
            for j, t in enumerate(terms):
                coefficients[t].append(float(coeffs[2 + j]))
                per_run[t][name] = {"coefficient": float(coeffs[2 + j]), "bootstrap_std": float(spread[2 + j])}
        square = [v for n, v in slopes.items() if n.startswith("square")]
        other = [v for n, v in slopes.items() if not n.startswith("square")]
        out.append({
            "terms": list(terms), "slope_over_reference": slopes, "slope_cv": _cv(list(slopes.values())),
            "square": statistics.fmean(square) if square else float("nan"),
            "other": statistics.fmean(other) if other else float("nan"),
            "coefficients": {t: {"median": float(np.median(c)), "positive": int(np.sum(np.array(c) > 0)),
                                 "runs": len(c), "cv": _cv(c), "predicted_sign": CANDIDATES[t][1],
                                 "per_run": per_run[t]}
                             for t, c in coefficients.items()},
        })
    return out


def render_evidence(entries: list[dict]) -> str:
    lines = ["| terms (with a free bias) | slope CV | square | other | per term: median coefficient, runs positive "
             "(predicted sign), CV over runs |", "|---|---|---|---|---|"]
    for e in entries:
        cells = []
        for t, c in e["coefficients"].items():
            sign = {1: "+", -1: "-", 0: "none"}[c["predicted_sign"]]
            cells.append(f"{t} {c['median']:+.3g}, {c['positive']}/{c['runs']} positive ({sign}), "
                         f"CV {100 * c['cv']:.0f} %")
        lines.append(f"| {' + '.join(e['terms']) or 'none'} | {100 * e['slope_cv']:.1f} % | {e['square']:.3f} "
                     f"| {e['other']:.3f} | {'; '.join(cells)} |")
    return "\n".join(lines) + "\n"
