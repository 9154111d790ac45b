"""Is a convergence miss the filter's or the flight's? (`propid bound-check`)

The Cramér-Rao bound (propid.crlb) gives a standard deviation; Table 1's convergence
time asks something else of an *error*: the last time it leaves a band of 0.1 prior
std. An efficient estimator whose std ends at 0.8 of the band still ends outside it on
a good share of flights. This module answers with the errors themselves: for each kept
log of a campaign it runs linear Kalman filters along the flight's TRUE trajectory
(the bound's model, noise and prior: crlb.flight_steps) and draws the Monte-Carlo
distribution of their errors (prior errors = this flight's true ones, the rate's drawn
from its prior; gyro and rate process noise drawn), then applies Table 1's criterion to
every realisation. Three covariance recursions ("loadings"):

- ``none``: the bound's own recursion. Its gain is optimal, its error covariance IS the
  bound: what an efficient estimator gives on this flight, under the table's criterion.
- ``filter``: the same plus the C filter's deterministic covariance loadings
  (docs/math.md §2: the rates by ``l m eps`` of their rounding scale, the kf and the
  biases by ``1 + eps`` per step, the kf in their roll/pitch-torque basis, the drag
  coefficients by ``1 + eps`` in their yaw basis every second step). The filter
  linearised at the truth, as implemented in float32.
- ``per-rotor-kf``: as ``filter`` but the kf loaded per rotor, as the filter did before
  it kept them in their torque basis: what that basis changed.

All three evolve the same errors with the TRUE process noise (the loadings are not
noise in the plant), so their differences are the gains' alone.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from propid import crlb, reference_filter, table1
from propid.errors import UserError
from propid.flightlog import Vehicle, read_vehicle

LOADINGS = ("none", "filter", "per-rotor-kf")
VAR_LOADING = float(np.finfo(np.float32).eps)  # C: PROPID_VAR_LOADING
RATE_LOADING_MIN = 8.0  # C: PROPID_RATE_LOADING / PROPID_VAR_LOADING


@dataclass(frozen=True)
class Bands:
    coeff: float  # |kf_rel, km_rel error| band
    bias: float  # |bias error| band [rad/s]


def drag_basis(vehicle: Vehicle) -> np.ndarray:
    """The km's kept basis (C: propid_drag_basis, docs/math.md §2): Householder
    reflection whose first row is the yaw-torque direction."""
    signs = np.asarray(vehicle.yaw_signs, dtype=float)
    v = np.zeros(signs.size)
    v[0] = 1.0
    v += signs[0] * signs / math.sqrt(signs.size)
    return np.eye(signs.size) - 2.0 * np.outer(v, v) / (v @ v)


def thrust_torque_basis(vehicle: Vehicle) -> np.ndarray:
    """The kf's kept basis (C: the filter's torque basis, docs/math.md §2): orthogonal
    rows, the roll- and pitch-torque directions per unit kf_rel first (the rows of
    J^-1 (r_i x z) kf_nominal_i; J diagonal 1 when the vehicle has none)."""
    pos = np.asarray(vehicle.positions, dtype=float)
    count = pos.shape[0]
    inertia = np.eye(3) if vehicle.inertia is None else np.asarray(vehicle.inertia, dtype=float)
    kf = np.ones(count) if vehicle.kf_nominal is None else np.asarray(vehicle.kf_nominal, dtype=float)
    arm = np.stack([pos[:, 1], -pos[:, 0], np.zeros(count)], axis=1)
    torque = (arm @ np.linalg.inv(inertia).T) * kf[:, None]
    return reference_filter.thrust_torque_basis(torque[:, 0], torque[:, 1])


def rate_row_terms(count: int) -> float:
    """m of the C prediction's rate loading (docs/math.md §2, "The rate block's
    loading"): 7 in the fixed quad layout, else two rates + N coefficients + 1."""
    return 7.0 if count == 4 else 3.0 + count


def criterion_times(t: np.ndarray, last_outside: np.ndarray, duration: float) -> tuple[float, float]:
    """(mean convergence time with never = duration, share that never converged) of
    realisations whose last outside sample index is ``last_outside`` (-1: never outside)."""
    final = t.size - 1
    never = last_outside == final
    times = np.where(last_outside < 0, t[0], t[np.minimum(last_outside + 1, final)])
    return float(np.mean(np.where(never, duration, times))), float(np.mean(never))


@dataclass
class Run:
    """One recursion along a flight with its Monte-Carlo errors."""
    t: np.ndarray
    cov: np.ndarray  # final covariance
    errors: np.ndarray  # (realisations, n) final errors
    last_bias_outside: np.ndarray  # per realisation: last sample index outside the band (-1: never)
    last_coeff_outside: np.ndarray


def propagate(flight: crlb.FlightSteps, vehicle: Vehicle, config: crlb.BoundConfig, bands: Bands,
              loading: str, initial: np.ndarray | None, realisations: int, rng: np.random.Generator,
              record=None) -> Run:
    """The covariance recursion with ``loading`` and the errors of the linear filter with
    its gains, under the true noise. ``initial``: the (coefficient, bias) errors at the
    start, or None to draw them from the prior (Gaussian). ``record(k, errors, cov)`` sees the
    errors after every sample's update."""
    if loading not in LOADINGS:
        raise UserError(f"unknown loading {loading} (known: {', '.join(LOADINGS)})")
    t, dts, steps, count = flight.t, flight.dts, flight.steps, flight.count
    n = 6 + 2 * count
    coeff, bias = slice(3, 3 + 2 * count), slice(n - 3, n)
    basis = np.eye(n)
    basis[3 + count:3 + 2 * count, 3 + count:3 + 2 * count] = drag_basis(vehicle)
    if loading != "per-rotor-kf":
        basis[3:3 + count, 3:3 + count] = thrust_torque_basis(vehicle)
    terms = rate_row_terms(count)
    rate_factor = VAR_LOADING * terms * max(terms, RATE_LOADING_MIN)
    P = crlb.prior_covariance(config, count)
    err = rng.normal(0.0, 1.0, (realisations, n)) * np.sqrt(P.diagonal())
    if initial is not None:
        err[:, 3:] = initial
    last_bias = np.full(realisations, -1)
    last_coeff = np.full(realisations, -1)
    for k in range(t.size):
        dt = dts[k - 1] if k > 0 else dts[0]
        if k > 0:
            G = steps[k - 1]
            if loading != "none":
                rate_scale = P.diagonal()[:3] + (G ** 2) @ P.diagonal()
            P[0:3, :] += G @ P
            P[:, 0:3] += P @ G.T
            P = 0.5 * (P + P.T)
            P[0:3, 0:3] += np.eye(3) * config.rate_process_noise ** 2 * dt
            err[:, 0:3] += err @ G.T + rng.normal(0.0, config.rate_process_noise * math.sqrt(dt),
                                                  (realisations, 3))
            if loading != "none":
                P[np.diag_indices(3)] += rate_factor * rate_scale
                kept = basis @ P @ basis.T
                load = np.full(n, VAR_LOADING)
                load[:3] = 0.0
                if k % 2:  # the drag coefficients every second step
                    load[3 + count:3 + 2 * count] = 0.0
                kept[np.diag_indices(n)] += load * kept.diagonal()
                P = basis.T @ kept @ basis
        noise_var = config.gyro_noise_density ** 2 / dt
        for axis in range(3):
            h = P[:, axis] + P[:, n - 3 + axis]
            gain = h / (h[axis] + h[n - 3 + axis] + noise_var)
            P -= np.outer(h, gain)
            innovation = (rng.normal(0.0, math.sqrt(noise_var), realisations)
                          - (err[:, axis] + err[:, n - 3 + axis]))
            err += innovation[:, None] * gain[None, :]
        P = 0.5 * (P + P.T)
        if record is not None:
            record(k, err, P)
        last_bias[np.any(np.abs(err[:, bias]) > bands.bias, axis=1)] = k
        last_coeff[np.any(np.abs(err[:, coeff]) > bands.coeff, axis=1)] = k
    return Run(t=t, cov=P, errors=err, last_bias_outside=last_bias, last_coeff_outside=last_coeff)


def initial_errors(columns: dict[str, np.ndarray], vehicle: Vehicle, count: int) -> np.ndarray:
    """The flight's own initial errors: the filter starts at nominal (1) and zero bias."""
    first = int(np.flatnonzero(np.isfinite(columns["gyro_x"]))[0])
    kf_nom = np.asarray(vehicle.kf_nominal, dtype=float)
    km_nom = np.asarray(vehicle.km_nominal, dtype=float)
    true_rel = np.concatenate([[columns[f"true_kf_{i}"][first] for i in range(1, count + 1)] / kf_nom,
                               [columns[f"true_km_{i}"][first] for i in range(1, count + 1)] / km_nom])
    true_bias = np.array([columns[f"true_bg_{a}"][first] for a in "xyz"])
    return np.concatenate([1.0 - true_rel, -true_bias])


def check_flight(columns: dict[str, np.ndarray], vehicle: Vehicle, config: crlb.BoundConfig,
                 bands: Bands, *, loadings: tuple[str, ...] = LOADINGS, realisations: int = 200,
                 seed: int = 0, duration: float | None = None) -> dict:
    """Each recursion's final bias std and Monte-Carlo criterion times on one flight
    (the flight's own initial coefficient and bias errors, the noise drawn)."""
    unknown = [name for name in loadings if name not in LOADINGS]
    if unknown:
        raise UserError(f"unknown loading(s) {', '.join(unknown)} (known: {', '.join(LOADINGS)})")
    if realisations < 1:
        raise UserError("realisations must be >= 1")
    flight = crlb.flight_steps(columns, vehicle)
    duration = float(flight.t[-1]) if duration is None else duration
    initial = initial_errors(columns, vehicle, flight.count)
    n = 6 + 2 * flight.count
    out: dict = {}
    for name in loadings:
        run = propagate(flight, vehicle, config, bands, name, initial, realisations,
                        np.random.default_rng(seed))
        bias_std = np.sqrt(np.maximum(run.cov.diagonal()[n - 3:], 0.0))
        t_bias, never_bias = criterion_times(run.t, run.last_bias_outside, duration)
        t_coeff, never_coeff = criterion_times(run.t, run.last_coeff_outside, duration)
        out[name] = {"final_bias_std_band": (bias_std / bands.bias).tolist(),
                     "t_bias_s": t_bias, "never_bias": never_bias,
                     "t_coeff_s": t_coeff, "never_coeff": never_coeff}
    return out


# The SE(3) controller's z loop (sitl/control/controller.c: natural frequency, damping).
Z_LOOP_NATURAL_FREQ = 4.0
Z_LOOP_DAMPING = 0.9
GRAVITY = 9.81


COLLECTIVE_TIMES_S = (0.05, 0.1, 0.2, 0.3, 0.5)  # where --z-excess reports the collective's std
Z_WINDOWS_S = ((0.0, 0.5), (0.5, 2.0), (2.0, 5.0), (5.0, math.inf))  # and the height RMSE


def z_loop_response(t: np.ndarray, thrust_error: np.ndarray) -> np.ndarray:
    """Height error of the closed z loop driven by a relative collective-thrust error
    (allocation with kf too large by eps: the rotors make (1 - eps) of the thrust
    asked): e'' = -wn^2 e - 2 zeta wn e' - g eps, from rest; columns are realisations."""
    out = np.zeros_like(thrust_error)
    height = np.zeros(thrust_error.shape[1:])
    rate = np.zeros(thrust_error.shape[1:])
    wn, zeta = Z_LOOP_NATURAL_FREQ, Z_LOOP_DAMPING
    for k in range(1, t.size):
        h = (t[k] - t[k - 1]) / 4.0
        for _ in range(4):  # semi-implicit Euler at a quarter of the sample period
            rate = rate + h * (-wn * wn * height - 2.0 * zeta * wn * rate - GRAVITY * thrust_error[k - 1])
            height = height + h * rate
        out[k] = height
    return out


def z_excess(filter_columns: dict[str, np.ndarray], oracle_columns: dict[str, np.ndarray],
             vehicle: Vehicle, config: crlb.BoundConfig, bands: Bands, *, realisations: int = 200,
             seed: int = 0, horizon_s: float = 2.0) -> dict:
    """Height RMSE of the Oracle flight, of the Filter flight, of the Oracle's height error
    plus the z loop's response to the flown filter's collective-thrust error (the model's
    check), and the same with the efficient estimator's Monte-Carlo collective error (the
    bound's linear filter over the first ``horizon_s``, held after it)."""
    rows = np.flatnonzero(np.isfinite(filter_columns["gyro_x"]))
    orows = np.flatnonzero(np.isfinite(oracle_columns["gyro_x"]))
    if rows.size != orows.size:
        raise UserError("the Filter and Oracle logs have different gyro samples")
    count = table1.rotor_count(filter_columns)
    t = filter_columns["t"][rows]
    speed_sq = np.vstack([filter_columns[f"omega_{i}"][rows] for i in range(1, count + 1)]).T ** 2
    kf_true = np.vstack([filter_columns[f"true_kf_{i}"][rows] for i in range(1, count + 1)]).T
    kf_est = np.vstack([filter_columns[f"est_kf_{i}"][rows] for i in range(1, count + 1)]).T
    thrust = np.sum(kf_true * speed_sq, axis=1)
    flown_error = np.sum((kf_est - kf_true) * speed_sq, axis=1) / thrust
    oracle_z = (oracle_columns["pz"] - oracle_columns["ref_pz"])[orows]
    filter_z = (filter_columns["pz"] - filter_columns["ref_pz"])[rows]
    model_z = oracle_z + z_loop_response(t, flown_error[:, None])[:, 0]
    # efficient estimator's collective error: d(eps)/d(kf_rel_i) = kf_nominal_i u_i / thrust
    flight = crlb.flight_steps(filter_columns, vehicle)
    horizon = min(int(np.searchsorted(flight.t, horizon_s)) + 1, flight.t.size)
    short = crlb.FlightSteps(t=flight.t[:horizon], dts=flight.dts[:horizon - 1],
                             steps=flight.steps[:horizon - 1], count=count)
    weights = np.asarray(vehicle.kf_nominal, dtype=float)[None, :] * speed_sq / thrust[:, None]
    efficient = np.empty((t.size, realisations))
    initial = initial_errors(filter_columns, vehicle, count)
    bound_std = np.full(t.size, np.nan)  # the bound's std of the collective thrust error

    def record(k, err, cov):
        efficient[k] = err[:, 3:3 + count] @ weights[k]
        bound_std[k] = math.sqrt(max(float(weights[k] @ cov[3:3 + count, 3:3 + count] @ weights[k]), 0.0))
    propagate(short, vehicle, config, bands, "none", initial, realisations, np.random.default_rng(seed),
              record=record)
    efficient[horizon:] = efficient[horizon - 1]
    efficient_z = oracle_z[:, None] + z_loop_response(t, efficient)

    def rms(values, axis=None):
        return np.sqrt(np.mean(values ** 2, axis=axis))
    at = [int(np.searchsorted(t, when)) for when in COLLECTIVE_TIMES_S]
    windows = [(t >= start) & (t < end) for start, end in Z_WINDOWS_S]
    return {"oracle_rmse_z": float(rms(oracle_z)), "filter_rmse_z": float(rms(filter_z)),
            "model_rmse_z": float(rms(model_z)), "efficient_rmse_z": float(np.mean(rms(efficient_z, axis=0))),
            "collective_bound_std": [float(bound_std[k]) for k in at],
            "collective_filter_error": [float(flown_error[k]) for k in at],
            "oracle_rmse_z_windows": [float(rms(oracle_z[w])) if w.any() else None for w in windows],
            "filter_rmse_z_windows": [float(rms(filter_z[w])) if w.any() else None for w in windows]}


def filter_figures(columns: dict[str, np.ndarray], bands: Bands) -> dict:
    """The flown C filter's bias time, final error and std (band units) from its log."""
    err = np.vstack([columns[f"est_bg_{a}"] - columns[f"true_bg_{a}"] for a in "xyz"])
    std = np.array([columns[f"std_bg_{a}"][-1] for a in "xyz"])
    return {"t_bias_s": table1.convergence_time(columns["t"], np.any(~(np.abs(err) <= bands.bias), axis=0)),
            "final_bias_err_band": (err[:, -1] / bands.bias).tolist(),
            "final_bias_std_band": (std / bands.bias).tolist()}


def campaign_logs(directory: Path, trajectory: str, mode: str) -> tuple[dict, list[tuple[int, Path]]]:
    """(table1.json's _conditions, [(seed, log)]) of a `propid campaign --keep-logs` output."""
    table_path = directory / "table1.json"
    if not table_path.is_file():
        raise UserError(f"{directory}: no table1.json (run `propid campaign --keep-logs --out {directory}`)")
    conditions = table1.load_table(table_path).get("_conditions") or {}
    logs = sorted((directory / "logs").glob(f"{trajectory}_{mode}_*.csv"))
    if not logs:
        raise UserError(f"{directory}/logs: no {trajectory}_{mode}_NN.csv (was the campaign run with --keep-logs?)")
    base_seed = int(conditions.get("base_seed", 1))
    return conditions, [(base_seed + int(path.stem.rsplit("_", 1)[1]), path) for path in logs]


def check_campaign(directory: Path, trajectory: str, mode: str, *, loadings: tuple[str, ...] = LOADINGS,
                   realisations: int = 200, progress: bool = True) -> dict:
    from tqdm import tqdm

    from propid.campaign import bound_config, convergence_spec

    conditions, logs = campaign_logs(directory, trajectory, mode)
    config = campaign_config(conditions, directory)
    bound_cfg = bound_config(config)
    spec = convergence_spec(config)
    bands = Bands(coeff=spec.coeff_threshold_rel, bias=spec.bias_threshold)
    flights = []
    for seed, path in tqdm(logs, desc="bound-check", unit="flight", disable=not progress):
        columns = table1.read_log_columns(path)
        vehicle = read_vehicle(path.with_suffix(".vehicle.json"))
        bound = crlb.bound_along_log(columns, vehicle, bound_cfg)
        record = {"seed": seed, "log": path.name, "flown": filter_figures(columns, bands),
                  **bound.bound_times(bands.coeff, bands.bias)}
        record.update(check_flight(columns, vehicle, bound_cfg, bands, loadings=loadings,
                                   realisations=realisations, seed=seed,
                                   duration=float(config.duration_s)))
        flights.append(record)
    return {"directory": str(directory), "trajectory": trajectory, "mode": mode,
            "realisations": realisations, "loadings": list(loadings),
            "bias_band_rad_s": bands.bias, "coeff_band_rel": bands.coeff,
            "summary": summarise(flights, loadings, float(config.duration_s)), "flights": flights}


def campaign_config(conditions: dict, directory: Path):
    """The CampaignConfig a table1.json's _conditions describe (for the filter's bound config)."""
    from propid.campaign import CampaignConfig

    fields = set(CampaignConfig.__dataclass_fields__)
    config = CampaignConfig(**{key: value for key, value in conditions.items()
                               if key in fields and key not in ("out_dir", "sitl")},
                            out_dir=directory, sitl=Path(conditions.get("sitl", "propid_sitl")))
    config.extra_args = list(config.extra_args)
    return config


def z_excess_campaign(directory: Path, trajectory: str, *, realisations: int = 200,
                      progress: bool = True) -> dict:
    """z_excess for every seed with both a Filter and an Oracle log; the cell's ratios of
    mean height RMSE to the Oracle's (Table 1's Filter / Oracle ratio)."""
    from tqdm import tqdm

    from propid.campaign import bound_config, convergence_spec

    conditions, filter_logs = campaign_logs(directory, trajectory, "filter")
    _, oracle_logs = campaign_logs(directory, trajectory, "oracle")
    oracle_by_seed = dict(oracle_logs)
    config = campaign_config(conditions, directory)
    spec = convergence_spec(config)
    bands = Bands(coeff=spec.coeff_threshold_rel, bias=spec.bias_threshold)
    flights = []
    pairs = [(seed, path) for seed, path in filter_logs if seed in oracle_by_seed]
    for seed, path in tqdm(pairs, desc="z excess", unit="flight", disable=not progress):
        record = z_excess(table1.read_log_columns(path), table1.read_log_columns(oracle_by_seed[seed]),
                          read_vehicle(path.with_suffix(".vehicle.json")), bound_config(config), bands,
                          realisations=realisations, seed=seed)
        flights.append({"seed": seed, **record})
    if not flights:
        raise UserError(f"{directory}/logs: no seed with both a Filter and an Oracle {trajectory} log")
    means = {key: float(np.mean([f[key] for f in flights]))
             for key in ("oracle_rmse_z", "filter_rmse_z", "model_rmse_z", "efficient_rmse_z")}
    ratios = {key.replace("_rmse_z", "_ratio"): value / means["oracle_rmse_z"]
              for key, value in means.items() if key != "oracle_rmse_z"}
    bound_std = np.array([f["collective_bound_std"] for f in flights])
    error = np.array([f["collective_filter_error"] for f in flights])
    means["collective_times_s"] = list(COLLECTIVE_TIMES_S)
    means["collective_bound_std_rms"] = np.sqrt(np.mean(bound_std ** 2, axis=0)).tolist()
    means["collective_filter_error_rms"] = np.sqrt(np.mean(error ** 2, axis=0)).tolist()
    means["collective_error_over_bound_rms"] = np.sqrt(np.mean((error / bound_std) ** 2, axis=0)).tolist()
    for who in ("oracle", "filter"):
        per_window = zip(*[f[f"{who}_rmse_z_windows"] for f in flights])
        means[f"{who}_rmse_z_windows"] = [float(np.mean(values)) if None not in values else None
                                          for values in per_window]
    return {"trajectory": trajectory, "realisations": realisations, "flights": flights,
            "summary": {**means, **ratios}}


def render_z_excess(result: dict) -> str:
    s = result["summary"]
    return (f"{result['trajectory']} height RMSE, mean of {len(result['flights'])} seeds "
            f"(ratio to the Oracle's):\n\n"
            "| Oracle | Filter flown | model: Oracle + z loop x filter's collective error | "
            "model: Oracle + z loop x efficient estimator's |\n|---|---|---|---|\n"
            f"| {s['oracle_rmse_z'] * 1e3:.3f} mm | {s['filter_rmse_z'] * 1e3:.3f} mm ({s['filter_ratio']:.3f}) | "
            f"{s['model_rmse_z'] * 1e3:.3f} mm ({s['model_ratio']:.3f}) | "
            f"{s['efficient_rmse_z'] * 1e3:.3f} mm ({s['efficient_ratio']:.3f}) |\n\n"
            "Height RMSE per window (mean of the seeds), Oracle / Filter [mm]: "
            + ", ".join(f"{start:g}-{end:g} s {o * 1e3:.2f} / {f * 1e3:.2f}" for (start, end), o, f in
                        zip(Z_WINDOWS_S, s["oracle_rmse_z_windows"], s["filter_rmse_z_windows"])
                        if o is not None and f is not None) + "\n"
            "Collective thrust at " + " / ".join(f"{x:g}" for x in s["collective_times_s"]) + " s, RMS over the seeds: "
            "bound std " + " / ".join(f"{100 * x:.2f}" for x in s["collective_bound_std_rms"]) + " %, "
            "filter error " + " / ".join(f"{100 * x:.2f}" for x in s["collective_filter_error_rms"]) + " %, "
            "error / bound std " + " / ".join(f"{x:.2f}" for x in s["collective_error_over_bound_rms"]) + "\n")


def summarise(flights: list[dict], loadings: tuple[str, ...], duration: float) -> dict:
    def mean(values):
        return float(np.mean(values)) if values else None
    filt = [f["flown"]["t_bias_s"] for f in flights]
    out = {"flights": len(flights),
           "flown_t_bias_s": mean([duration if v is None else v for v in filt]),
           "flown_never_bias": sum(1 for v in filt if v is None),
           "bound_t_bias_s": mean([duration if f["t_bound_bias_s"] is None else f["t_bound_bias_s"]
                                   for f in flights]),
           "bound_never_bias": sum(1 for f in flights if f["t_bound_bias_s"] is None)}
    for name in loadings:
        out[name] = {"t_bias_s": mean([f[name]["t_bias_s"] for f in flights]),
                     "expected_never_bias": float(sum(f[name]["never_bias"] for f in flights)),
                     "t_coeff_s": mean([f[name]["t_coeff_s"] for f in flights]),
                     "expected_never_coeff": float(sum(f[name]["never_coeff"] for f in flights)),
                     "final_bias_std_band_max": mean([max(f[name]["final_bias_std_band"]) for f in flights])}
    return out


def render(result: dict) -> str:
    s = result["summary"]
    lines = [f"{result['trajectory']} / {result['mode']}: {s['flights']} flights, "
             f"{result['realisations']} Monte-Carlo realisations each",
             "",
             "| estimator | b_g time (s) | never (of flights) | kf & km time (s) | final b_g std / band (largest axis) |",
             "|---|---|---|---|---|",
             f"| flown C filter | {s['flown_t_bias_s']:.2f} | {s['flown_never_bias']} | | |",
             f"| bound 1-sigma time | {s['bound_t_bias_s']:.2f} | {s['bound_never_bias']} | | |"]
    label = {"none": "efficient (the bound's recursion)", "filter": "filter's loadings",
             "per-rotor-kf": "filter's loadings, kf per rotor (before)"}
    for name in result["loadings"]:
        r = s[name]
        lines.append(f"| {label[name]} | {r['t_bias_s']:.2f} | {r['expected_never_bias']:.1f} expected | "
                     f"{r['t_coeff_s']:.3f} | {r['final_bias_std_band_max']:.2f} |")
    return "\n".join(lines) + "\n"


def write_json(result: dict, path: Path) -> None:
    from propid import outputs

    outputs.write_text(path, json.dumps(result, indent=1) + "\n")
