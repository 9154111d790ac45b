"""Oracle detectability index of an effect in one flight.

Three SITL flights with the same seed, trajectory and rates (only the bench sees
them; the true coefficients come from their truth columns):

- clean twin  C: ideal sensors (no noise, bias, quantisation, dropouts), no effect;
- clean probe B: ideal sensors, the effect at the flight's strength;
- noisy twin  N: the flight's real sensors and nuisances, no effect.

The controller flies on the true state, so C and N fly the same path. With r(X)
the nominal-model residual of flight X (propid.gapbench.rigid_body, true kf/km):

    signature  e = r(B) - r(C)      what the effect adds (sensor effects included)
    noise      n = r(N) - r(C)      what the measurements add

Axes are weighted by 1/std(n), and the part of e that re-fitted per-rotor kf, km
and a thrust offset (the accelerometer's bias) could absorb is projected out (those
are unknown to any diagnosis). The index is
the weighted norm of what remains:

    D = || P_perp W e ||       (P_perp: residual of least squares on W X_nominal)

which is the t-statistic of a matched filter that knows the effect's exact
signature, on samples that are nearly independent (the grid's decimation). D = 5
is a 5-sigma detection for that oracle; a diagnosis that must also find the
signature among many candidates needs more.

Free flight only: the nominal model does not hold while the vehicle rests on the
ground (the SITL clamps its height at pz = 0 and holds the body there, rotors still
spinning), so grid rows within CONTACT_MARGIN_S of a contact row of any of the three
flights are left out. Otherwise r(B) - r(C) would be the difference of two crashes'
contact wrenches, not the effect. A flight with fewer than MIN_FREE_ROWS rows left
has nothing to detect in (D = 0); one without contact keeps every row.
"""

from __future__ import annotations

import numpy as np

from propid.flightlog import FlightLog, Vehicle
from propid.gapbench.rigid_body import AXES, Grid, make_grid, nominal_regressors, response


# A contact's jump, low-passed at 10 Hz and differentiated, reaches about two cycles either side.
CONTACT_MARGIN_S = 0.25
MIN_FREE_ROWS = 20  # make_grid's own minimum of rows for an analysis


def contact_times(log: FlightLog) -> np.ndarray:
    """Times of the SITL log's rows where the vehicle rests on the ground (pz <= 0)."""
    pz = log.extra.get("pz")
    if pz is None:
        return np.empty(0)
    pz = np.asarray(pz, dtype=float)
    return np.asarray(log.t, dtype=float)[np.isfinite(pz) & (pz <= 0.0)]


def free_flight_rows(t: np.ndarray, logs: list[FlightLog], margin_s: float = CONTACT_MARGIN_S
                     ) -> np.ndarray:
    """Grid times farther than margin_s from every contact row of every log."""
    t = np.asarray(t, dtype=float)
    keep = np.ones(t.size, dtype=bool)
    for log in logs:
        times = np.sort(contact_times(log))
        if times.size == 0:
            continue
        after = np.clip(np.searchsorted(times, t), 0, times.size - 1)
        before = np.clip(after - 1, 0, times.size - 1)
        nearest = np.minimum(np.abs(t - times[before]), np.abs(times[after] - t))
        keep &= nearest > margin_s
    return keep


def true_coefficients(log: FlightLog) -> tuple[np.ndarray, np.ndarray]:
    count = log.rotor_count
    kf = np.array([np.nanmedian(log.extra[f"true_kf_{i}"]) for i in range(1, count + 1)])
    km = np.array([np.nanmedian(log.extra[f"true_km_{i}"]) for i in range(1, count + 1)])
    return kf, km


def residual(grid: Grid, vehicle: Vehicle, kf: np.ndarray, km: np.ndarray) -> np.ndarray:
    """(4, n) response minus the nominal model with the given coefficients."""
    theta = np.concatenate([kf, km])
    return response(grid, vehicle) - nominal_regressors(grid, vehicle) @ theta


def _common(*arrays: np.ndarray) -> list[np.ndarray]:
    n = min(a.shape[-1] for a in arrays)
    return [a[..., :n] for a in arrays]


def _weighted_parts(clean_effect: FlightLog, clean_twin: FlightLog, noisy_twin: FlightLog,
                    vehicle: Vehicle) -> dict:
    """One flight's noise-weighted signature, nominal columns and accelerometer-offset column."""
    kf, km = true_coefficients(clean_twin)
    logs = [clean_effect, clean_twin, noisy_twin]
    grids = [make_grid(log) for log in logs]
    r_b, r_c, r_n = _common(*(residual(g, vehicle, kf, km) for g in grids))
    x_nominal = nominal_regressors(grids[0], vehicle)[:, : r_b.shape[1], :]
    free = free_flight_rows(grids[0].t[: r_b.shape[1]], logs)
    free_share = float(np.mean(free))
    if np.count_nonzero(free) < MIN_FREE_ROWS:
        return {"free": False, "free_share": free_share}
    signature = (r_b - r_c)[:, free]
    noise = (r_n - r_c)[:, free]
    x_nominal = x_nominal[:, free, :]
    axes = [a for a in range(4) if np.all(np.isfinite(signature[a])) and np.all(np.isfinite(noise[a]))]
    # The noise is what varies: a constant (the accelerometer's bias on the thrust
    # axis) is a sensor offset any diagnosis fits, so it is projected out below too.
    sigma = np.array([np.std(noise[a]) for a in axes])
    sigma = np.maximum(sigma, 1e-12 * max(float(np.max(sigma)), 1e-30))
    weighted_e = np.concatenate([signature[a] / s for a, s in zip(axes, sigma)])
    weighted_x = np.concatenate([x_nominal[a] / s for a, s in zip(axes, sigma)], axis=0)
    offset_column = None
    if 3 in axes:  # accelerometer bias: a constant on the thrust axis
        offset_column = np.concatenate([np.full(signature.shape[1], 1.0 / s if a == 3 else 0.0)
                                        for a, s in zip(axes, sigma)])
    return {"free": True, "free_share": free_share, "signature": signature, "axes": axes,
            "sigma": sigma, "e": weighted_e, "x": weighted_x, "offset": offset_column}


def _project_out(weighted_e: np.ndarray, weighted_x: np.ndarray) -> np.ndarray:
    """What of the signature least squares on the nuisance columns cannot absorb."""
    scale = np.linalg.norm(weighted_x, axis=0)
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(weighted_x / scale, weighted_e, rcond=None)
    return weighted_e - (weighted_x / scale) @ coef


def detectability(clean_effect: FlightLog, clean_twin: FlightLog, noisy_twin: FlightLog,
                  vehicle: Vehicle) -> dict:
    """D of the effect present in `clean_effect`, plus per-axis signature/noise RMS and the
    share of the grid's rows in free flight (`free_flight_share`)."""
    parts = _weighted_parts(clean_effect, clean_twin, noisy_twin, vehicle)
    if not parts["free"]:
        return {"index": 0.0, "axes": {}, "free_flight_share": parts["free_share"]}
    signature, axes, sigma = parts["signature"], parts["axes"], parts["sigma"]
    weighted_e, weighted_x = parts["e"], parts["x"]
    if parts["offset"] is not None:
        weighted_x = np.column_stack([weighted_x, parts["offset"]])
    remaining = _project_out(weighted_e, weighted_x)
    per_axis = {}
    offset = 0
    for a, s in zip(axes, sigma):
        n = signature.shape[1]
        part = remaining[offset: offset + n]
        offset += n
        per_axis[AXES[a]] = {
            "signature_rms": float(np.sqrt(np.mean(signature[a] ** 2))),
            "noise_rms": float(s),
            "index": float(np.linalg.norm(part)),
        }
    return {"index": float(np.linalg.norm(remaining)), "axes": per_axis,
            "free_flight_share": parts["free_share"]}


def pooled_detectability(flights: list[tuple[FlightLog, FlightLog, FlightLog]],
                         vehicle: Vehicle) -> float:
    """D over several flights of one vehicle: each flight's (clean probe, clean twin, noisy twin)
    weighted by its own noise as in `detectability`, stacked, and the part that one set of
    per-rotor kf/km (the same vehicle: shared by every flight) and one accelerometer offset per
    flight could absorb projected out (a flight without free flight adds nothing). The matched
    filter's t-statistic over all the flights;
    with one flight it is `detectability`'s index; with independent nuisances per flight it
    would be sqrt(sum D_k^2), and the shared kf/km make it at least that."""
    parts = [p for p in (_weighted_parts(*flight, vehicle) for flight in flights) if p["free"]]
    if not parts:
        return 0.0
    if len({p["x"].shape[1] for p in parts}) != 1:
        raise ValueError("pooled detectability: the flights have different nominal columns")
    weighted_e = np.concatenate([p["e"] for p in parts])
    columns = [np.concatenate([p["x"] for p in parts], axis=0)]
    row = 0
    for p in parts:
        if p["offset"] is not None:
            column = np.zeros(weighted_e.size)
            column[row: row + p["offset"].size] = p["offset"]
            columns.append(column[:, None])
        row += p["e"].size
    return float(np.linalg.norm(_project_out(weighted_e, np.column_stack(columns))))
