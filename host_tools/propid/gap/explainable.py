"""How much of the base model's held-out residual is predictable from the logged signals at all.

A black-box upper bound for what any effect could add, scored exactly as the shrink is: a linear
FIR model of the base model's residual (per torque axis) from every logged non-gyro channel,
fitted on the fit logs' rows and scored on the hold-out logs (without hold-out logs: on the
cross-validation's held-out folds). Held out, so it does not flatter; generous in its model class
(any linear filter of all the channels over +-40 ms).

Channel sets (nested):
- `inputs`: Omega_i^2, dOmega_i/dt, cmd_i, accelerometer, body velocity and the gravity direction
  in body axes, whichever are logged, at every tap;
- `explainable`: `inputs` plus the body rate derived from the logged attitude at lag 0 only (a
  body-rate effect such as damping; one tap cannot differentiate it);
- `motion`: `inputs` plus that attitude rate at every tap. The taps can then differentiate an
  independent attitude sensor, which predicts the true angular acceleration itself: the share of
  the residual that is real body motion. What it leaves is the gyro's differentiated noise (and
  the attitude sensor's, and non-linear content).

The gyro and what derives from it are never a channel: its noise is in the response.

Noise floor (`gyro_noise_floor`): the gyro's white-noise level per axis read from its spectrum in
0.4-0.5 x the sample rate (above the analysed band), propagated through the same central
difference, inertia and band-pass on the logs' own segments: the share of the residual power that
gyro noise of that level makes. It is an over-estimate if the vehicle still moves that fast, an
under-estimate if the logger low-passed the gyro before decimating.
"""

from __future__ import annotations

import numpy as np

from propid.gap.design import segment_rows
from propid.gap.prep import Flight
from propid.realdata_checks import bandpass

TAPS_S = (-0.04, -0.02, -0.01, 0.0, 0.01, 0.02, 0.04)
RIDGE = 1e-6
AXES = ("roll", "pitch", "yaw")
SETS = ("inputs", "explainable", "motion")
BANDS = ((1.0, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0))
NOISE_BAND = (0.4, 0.5)  # x the sample rate


def _continuous(quat: np.ndarray) -> np.ndarray:
    """The quaternion with its sign chosen so consecutive rows lie in one hemisphere."""
    q = np.array(quat, dtype=float, copy=True)
    flip = np.cumsum(np.concatenate([[0], (np.sum(q[1:] * q[:-1], axis=1) < 0).astype(int)])) % 2 == 1
    q[flip] *= -1.0
    return q


def attitude_rate(t: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """Body rate from the attitude (w, x, y, z; body -> world): w = 2 conj(q) dq/dt, vector part."""
    q = _continuous(quat)
    dq = np.gradient(q, t, axis=0)
    w, v = q[:, 0], -q[:, 1:]  # conj(q)
    dw, dv = dq[:, 0], dq[:, 1:]
    vec = w[:, None] * dv + dw[:, None] * v + np.cross(v, dv)
    return 2.0 * vec


def gravity_in_body(quat: np.ndarray) -> np.ndarray:
    """The world z axis in body coordinates (R(q)^T e_z): the vehicle's tilt."""
    w, x, y, z = (quat[:, k] for k in range(4))
    return np.column_stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])


def raw_channels(f: Flight) -> dict[str, np.ndarray]:
    """The logged non-gyro channels of one flight by group (absent ones left out)."""
    out = {"rotor_speed_sq": f.speed**2, "rotor_accel": f.speed_dot}
    if f.cmd is not None and np.all(np.isfinite(f.cmd)):
        out["cmd"] = f.cmd
    if f.acc is not None and np.all(np.isfinite(f.acc)):
        out["acc"] = f.acc
    if f.body_velocity is not None and np.all(np.isfinite(f.body_velocity)):
        out["velocity"] = f.body_velocity
    if f.logged_quat is not None and np.all(np.isfinite(f.logged_quat)):
        out["tilt"] = gravity_in_body(f.logged_quat)
        out["attitude_rate"] = attitude_rate(f.t, f.logged_quat)
    return out


def _lagged(x: np.ndarray, segs: list[tuple[int, int]], lag: int) -> np.ndarray:
    """x(t + lag rows) inside each segment, 0 past its ends."""
    out = np.zeros_like(x)
    for a, b in segs:
        n = b - a
        if abs(lag) >= n:
            continue
        if lag >= 0:
            out[a:b - lag] = x[a + lag:b]
        else:
            out[a - lag:b] = x[a:b + lag]
    return out


def channel_matrix(flights: list[Flight], groups: list[str]) -> dict[str, np.ndarray]:
    """Per channel set, the lagged, band-passed channel columns stacked over the flights' segment rows
    (the design's row order). `groups`: the groups every flight has (common to all)."""
    sets = {s: [] for s in SETS}
    for f in flights:
        raw = raw_channels(f)
        rows = segment_rows(f)
        lags = sorted({int(round(tap * f.rate_hz)) for tap in TAPS_S})
        per = {s: [] for s in SETS}
        for g in groups:
            filt = f.filtered(raw[g], response=True)
            for lag in lags:
                col = _lagged(filt, f.segs, lag)[rows]
                if g == "attitude_rate":
                    per["motion"].append(col)
                    if lag == 0:
                        per["explainable"].append(col)
                else:
                    for s in SETS:
                        per[s].append(col)
        for s in SETS:
            sets[s].append(np.column_stack(per[s]) if per[s] else np.zeros((rows.size, 0)))
    return {s: np.concatenate(v) for s, v in sets.items()}


def common_groups(flights: list[Flight]) -> list[str]:
    names = None
    for f in flights:
        present = list(raw_channels(f))
        names = present if names is None else [g for g in names if g in present]
    return names or []


def _fit(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    scale = np.sqrt(np.mean(x**2, axis=0))
    scale[scale == 0] = 1.0
    xs = x / scale
    gram = xs.T @ xs
    ridge = RIDGE * np.trace(gram) / max(gram.shape[0], 1)
    coef = np.linalg.solve(gram + ridge * np.eye(gram.shape[0]), xs.T @ y)
    return coef / scale


def _band_power(r: np.ndarray, flights_rows: list[tuple[Flight, np.ndarray, slice]], lo: float, hi: float) -> float:
    """Power of r (rows of the flights' segments) band-passed to lo-hi per segment."""
    total = 0.0
    for f, rows, where in flights_rows:
        full = np.zeros(len(f.t))
        full[rows] = r[where]
        for a, b in f.segs:
            if b - a > 12:
                total += float(np.sum(bandpass(full[a:b][:, None], f.rate_hz, lo, min(hi, 0.45 * f.rate_hz))[:, 0] ** 2))
    return total


def _row_map(flights: list[Flight]) -> list[tuple[Flight, np.ndarray, slice]]:
    out, start = [], 0
    for f in flights:
        rows = segment_rows(f)
        out.append((f, rows, slice(start, start + rows.size)))
        start += rows.size
    return out


def _score(res: np.ndarray, pred: np.ndarray) -> dict:
    sse_before = float(np.sum(res**2))
    sse_after = float(np.sum((res - pred) ** 2))
    if sse_before <= 0:
        return {"power": float("nan"), "rms_shrink": float("nan")}
    return {"power": 1.0 - sse_after / sse_before, "rms_shrink": 1.0 - float(np.sqrt(sse_after / sse_before))}


def out_of_fold(flights: list[Flight], test_folds: list[int], fold_of_row: np.ndarray, residual_for_fold,
                per_band: bool = True, per_group: bool = True) -> dict:
    """Fit the FIR per axis and channel set on every fold but k's rows of the residual the base model
    fitted without fold k leaves (`residual_for_fold(k)`: axis -> residual over all rows, the design's
    row order over `flights`), predict fold k's rows; score the out-of-fold predictions over the rows
    of `test_folds` exactly as the shrink is scored (sums over those rows)."""
    groups = common_groups(flights)
    if not groups:
        return {"computed": False, "why": "no non-gyro channel common to the logs"}
    x_all = channel_matrix(flights, groups)
    alone_x = {g: channel_matrix(flights, [g])["inputs"] for g in groups if g != "attitude_rate"} if per_group else {}
    test_rows = np.isin(fold_of_row, test_folds)
    axes = None
    res = {}
    pred = {}
    pred_alone = {}
    for k in test_folds:
        r = residual_for_fold(k)
        axes = [a for a in AXES if a in r] if axes is None else axes
        train = fold_of_row != k
        if len(test_folds) == 1:
            train = ~test_rows
        test = fold_of_row == k
        for axis in axes:
            res.setdefault(axis, np.zeros(fold_of_row.size))[test] = r[axis][test]
            for s in SETS:
                coef = _fit(x_all[s][train], r[axis][train])
                pred.setdefault((axis, s), np.zeros(fold_of_row.size))[test] = x_all[s][test] @ coef
            for g, xg in alone_x.items():
                coef = _fit(xg[train], r[axis][train])
                pred_alone.setdefault((axis, g), np.zeros(fold_of_row.size))[test] = xg[test] @ coef
    row_map = _row_map(flights)
    out = {"computed": True, "groups": groups, "taps_s": list(TAPS_S),
           "columns": {s: int(x_all[s].shape[1]) for s in SETS},
           "rows_scored": int(test_rows.sum())}
    for axis in axes or []:
        r = np.where(test_rows, res[axis], 0.0)
        entry = {s: _score(r[test_rows], pred[(axis, s)][test_rows]) for s in SETS}
        if per_band:
            p = np.where(test_rows, pred[(axis, "explainable")], 0.0)
            bands, total = {}, 0.0
            for lo, hi in BANDS:
                before = _band_power(r, row_map, lo, hi)
                after = _band_power(r - p, row_map, lo, hi)
                if before > 0:
                    bands[f"{lo:g}-{hi:g} Hz"] = {"residual_power_share": before, "explained_power": 1 - after / before}
                    total += before
            for v in bands.values():
                v["residual_power_share"] = v["residual_power_share"] / total
            entry["per_band"] = bands
        if per_group:
            entry["inputs_power_by_group_alone"] = {
                g: _score(r[test_rows], pred_alone[(axis, g)][test_rows])["power"] for g in alone_x}
        out[axis] = entry
    return out


def heldout_bound(fit_flights: list[Flight], fit_res: dict, held_flights: list[Flight], held_res: dict,
                  **kw) -> dict:
    """Hold-out logs: fitted on the fit logs' residual (base fitted on the fit logs), scored on the
    hold-out logs' residual of that base model."""
    n_fit = sum(segment_rows(f).size for f in fit_flights)
    n_held = sum(segment_rows(f).size for f in held_flights)
    fold = np.concatenate([np.zeros(n_fit, int), np.ones(n_held, int)])
    both = {a: np.concatenate([fit_res[a], held_res[a]]) for a in AXES if a in fit_res and a in held_res}
    return out_of_fold(fit_flights + held_flights, [1], fold, lambda k: both, **kw)


def _welch(x: np.ndarray, rate_hz: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD by Welch (Hann windows of n samples, half overlap, each window's mean removed):
    white noise of variance s^2 reads 2 s^2 / rate."""
    taper = np.hanning(n)
    acc, count = np.zeros(n // 2 + 1), 0
    for s in range(0, x.size - n + 1, max(n // 2, 1)):
        seg = x[s:s + n] - x[s:s + n].mean()
        acc += np.abs(np.fft.rfft(seg * taper)) ** 2
        count += 1
    psd = 2.0 * acc / max(count, 1) / (rate_hz * np.sum(taper**2))
    return np.fft.rfftfreq(n, 1.0 / rate_hz), psd


def gyro_noise_floor(flights: list[Flight], inertia: np.ndarray, res: dict, seed: int = 0) -> dict:
    """Per torque axis, the gyro white-noise level from its top band and the share of the residual
    power (`res`, design row order over `flights`) that noise of that level makes in the band."""
    rng = np.random.default_rng(seed)
    levels = {a: [] for a in AXES}
    noise_power = {a: 0.0 for a in AXES}
    for f in flights:
        rows = segment_rows(f)
        for k, axis in enumerate(AXES):
            psd_sum, count = 0.0, 0
            for a, b in f.segs:
                n = min(256, b - a)
                if n < 32:
                    continue
                freqs, p = _welch(f.gyro[a:b, k], f.rate_hz, n)
                sel = (freqs >= NOISE_BAND[0] * f.rate_hz) & (freqs <= NOISE_BAND[1] * f.rate_hz)
                if sel.any():
                    psd_sum += float(np.median(p[sel])) * (b - a)
                    count += b - a
            if count == 0:
                continue
            psd = psd_sum / count  # one-sided [rad^2/s^2/Hz]
            sigma = float(np.sqrt(psd * f.rate_hz / 2.0))  # white: PSD = 2 sigma^2 / fs
            levels[axis].append(sigma)
            noise = sigma * rng.standard_normal(len(f.t))
            torque_noise = inertia[k, k] * np.gradient(noise, f.t)
            noise_power[axis] += float(np.sum(f.filtered(torque_noise)[rows] ** 2))
    out = {"noise_band_x_rate": list(NOISE_BAND)}
    for axis in AXES:
        if not levels[axis] or axis not in res:
            continue
        power = float(np.sum(res[axis] ** 2))
        out[axis] = {"gyro_noise_rms": float(np.mean(levels[axis])),
                     "noise_power_share": noise_power[axis] / power if power > 0 else float("nan")}
    return out


def summary(bound: dict, noise: dict, shrink: dict) -> dict:
    """OUT.json `explainable`: per torque axis the held-out predictable share of the base model's
    residual (power and the RMS shrink it would give), the named effects' share of it, the gyro
    noise floor, and where the predictable part lies (bands, channel groups)."""
    out = {"computed": bool(bound.get("computed")),
           "how": "a linear FIR model (taps at " + ", ".join(f"{1000 * t:g}" for t in TAPS_S) + " ms) of the base "
                  "model's residual from every logged non-gyro channel, fitted on the fit rows and scored on the "
                  "same held-out rows as `shrink` (gap/explainable.py); explainable = the input channels plus the "
                  "attitude-derived body rate at lag 0; motion = that rate at every tap (real body motion: its "
                  "complement is sensor noise)"}
    if not bound.get("computed"):
        out["why"] = bound.get("why")
        return out
    out.update({k: bound[k] for k in ("groups", "columns", "rows_scored")})
    out["noise_band_x_rate"] = noise.get("noise_band_x_rate")
    for axis in AXES:
        if axis not in bound:
            continue
        b = bound[axis]
        entry = {"explainable_fraction": b["explainable"]["power"],
                 "explainable_rms_shrink": b["explainable"]["rms_shrink"],
                 "inputs_fraction": b["inputs"]["power"], "motion_fraction": b["motion"]["power"],
                 "per_band": b.get("per_band"), "inputs_fraction_by_group_alone": b.get("inputs_power_by_group_alone")}
        reduction = shrink.get(axis, {}).get("reduction")
        if reduction is not None and b["explainable"]["rms_shrink"] > 0:
            entry["named_effects_share"] = float(reduction / b["explainable"]["rms_shrink"])
        if axis in noise:
            entry["gyro_noise_rms"] = noise[axis]["gyro_noise_rms"]
            entry["gyro_noise_power_share"] = noise[axis]["noise_power_share"]
        out[axis] = entry
    return out


def report_line(axis: str, entry: dict, reduction: float | None) -> str:
    """"of the held-out residual, X % is predictable from the logged signals at all; the named effects take Y %
    of that" (RMS shrink terms, as the shrink itself)."""
    x = entry["explainable_rms_shrink"]
    text = f"{axis}: of the held-out residual RMS, {100 * x:.0f} % is predictable from the logged signals at all"
    if reduction is not None and x > 0:
        text += f"; the named effects take {100 * reduction:.0f} % ({100 * reduction / x:.0f} % of that)"
    return text
