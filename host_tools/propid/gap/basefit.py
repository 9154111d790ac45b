"""Base fit: the fleet thrust coefficient from the accelerometer and the fleet torque
coefficients from the gyro, each with a block-bootstrap 95 % interval.

    kf_thrust: m acc_z = kf sum_i Omega_i^2 [+ c_s]    (low-passed only; c_s a constant per flying
                                                        segment when the band fits the thrust offset)
    kf_roll:   tau_x   = kf sum_i y_i Omega_i^2        (band-passed)
    kf_pitch:  tau_y   = kf sum_i -x_i Omega_i^2       (band-passed)
    km_yaw:    tau_z   = km sum_i s_i Omega_i^2        (band-passed)

`after`: the same with the significant effects in: their columns on that axis as extra
regressors, the rotor stream shifted by the fitted delay, and the measured torque
recomputed with the fitted inertia / gyro scale.

Errors in variables: the rotor-speed regressor is noisy (telemetry quantisation,
jitter, sample-and-hold). When every log has motor commands, the coefficient is
estimated by instrumental variables: the instrument is the same regressor built from
the rotor speeds predicted by the commands alone (first stage: per flight and rotor,
least squares of the band-passed Omega_i^2 on band-passed cmd_i and cmd_i^2 delayed by
INSTRUMENT_LAGS samples; lags of 2 or more keep the controller's reaction to the
current gyro noise out). Command noise is independent of telemetry noise, so the
attenuation goes; the band-pass keeps the slow disturbance out as for least squares.
Without commands: least squares (an attenuated lower bound), said in `method`.

Thrust offset (`Band.thrust_offset`, docs/gap.md "Base model"): the accelerometer's zero-g offset
b_z adds m b_z to m acc_z. Through the origin, kf_thrust then reads kf (1 + b_z / g) in hover. With
a constant per segment (each segment's mean removed from both sides, prep.Flight.filtered) only
the collective thrust's variations set kf_thrust, and the fitted offset is reported per log
(`thrust_offset`): b_z = mean(acc_z - kf sum_i Omega_i^2 / m) over the segment, its interval from
the same bootstrap resamples as kf's. A hover or a level circle hardly varies its collective
thrust: kf_thrust's interval then widens, and `determined` says whether it lies within
OFFSET_DETERMINED_REL of the value.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from propid.gap import scoring
from propid.gap.design import responses, segment_rows
from propid.gap.prep import Flight

INSTRUMENT_LAGS = (2, 3, 5, 8, 13)
QUANTITIES = {"kf_thrust": "thrust", "kf_roll": "roll", "kf_pitch": "pitch", "km_yaw": "yaw"}
QUANTITY_OF = {axis: key for key, axis in QUANTITIES.items()}
OFFSET_DETERMINED_REL = 0.10  # kf_thrust's 95 % interval within +-10 %: the torque-vs-thrust agreement target


def main_regressor(axis: str, u: np.ndarray, positions: np.ndarray, signs: np.ndarray,
                   shape: dict | None = None) -> np.ndarray:
    """The fleet regressor; `shape` (kf, km: per-rotor value / fleet mean, from the joint
    base model) weights each rotor so a fleet value from any axis is the rotors' mean."""
    if shape is not None:
        u = u * np.asarray(shape["km" if axis == "yaw" else "kf"])[None, :]
    if axis == "roll":
        return u @ positions[:, 1]
    if axis == "pitch":
        return -(u @ positions[:, 0])
    if axis == "yaw":
        return u @ signs
    return u.sum(axis=1)


def _delayed(x: np.ndarray, lag: int) -> np.ndarray:
    out = np.empty_like(x)
    out[lag:] = x[:-lag] if lag else x
    out[:lag] = x[0]
    return out


def predicted_u(f: Flight, lowpass_only: bool) -> np.ndarray | None:
    """First-stage rotor speed squared from the commands (filtered domain), or None."""
    if f.cmd is None:
        return None
    rows = segment_rows(f)
    u_f = f.filtered(f.speed**2, lowpass_only, response=not lowpass_only)
    out = np.zeros_like(u_f)
    for i in range(f.speed.shape[1]):
        feats = []
        for lag in INSTRUMENT_LAGS:
            c = _delayed(f.cmd[:, i], lag)
            feats += [c, c * c]
        feats = f.filtered(np.column_stack(feats), lowpass_only, response=not lowpass_only)
        coef, *_ = np.linalg.lstsq(feats[rows], u_f[rows, i], rcond=None)
        out[:, i] = feats @ coef
    return out


def fleet_fit(flights: list[Flight], axis: str, positions: np.ndarray, signs: np.ndarray, mass: float | None,
              extra: list[np.ndarray] | None = None, response_scale: float = 1.0,
              use_instrument: bool = True, rng_seed: int = 7, shape: dict | None = None,
              keep_bootstrap: bool = False) -> dict | None:
    """One fleet coefficient on `axis` (+ extra nuisance/effect columns): value, CI, method."""
    lowpass_only = axis == "thrust"
    ys, xs, zs, blocks = [], [], [], []
    offset = 0
    instrumented = use_instrument and all(f.cmd is not None for f in flights)
    for fi, f in enumerate(flights):
        resp = responses(f, mass)
        if axis not in resp:
            return None
        rows = segment_rows(f)
        main = main_regressor(axis, f.speed**2, positions, signs, shape)
        cols = [main[:, None]] + ([extra[fi]] if extra is not None and extra[fi] is not None else [])
        x = f.filtered(np.column_stack(cols), lowpass_only, response=not lowpass_only)
        y = f.filtered(resp[axis] * response_scale, lowpass_only)
        z = x.copy()
        if instrumented:
            u_hat = predicted_u(f, lowpass_only)
            z[:, 0] = main_regressor(axis, u_hat, positions, signs, shape)
        b_of_row = np.full(len(f.t), -1)
        for k, (s, e) in enumerate(f.blocks):
            b_of_row[s:e] = offset + k
        offset += len(f.blocks)
        ys.append(y[rows])
        xs.append(x[rows])
        zs.append(z[rows])
        blocks.append(b_of_row[rows])
    y = np.concatenate(ys)
    x = np.concatenate(xs)
    z = np.concatenate(zs)
    block = np.concatenate(blocks)
    scale = np.sqrt(np.mean(x**2, axis=0))
    scale[scale == 0] = 1
    x = x / scale
    z = z / np.where(np.sqrt(np.mean(z**2, axis=0)) > 0, np.sqrt(np.mean(z**2, axis=0)), 1)
    nb = offset
    p = x.shape[1]
    zx = np.zeros((nb, p, p))
    zy = np.zeros((nb, p))
    xx = np.zeros((nb, p, p))
    xy = np.zeros((nb, p))
    order = np.argsort(block, kind="stable")
    bounds = np.searchsorted(block[order], np.arange(nb + 1))
    x, y, z = x[order], y[order], z[order]
    for b in range(nb):
        lo, hi = bounds[b], bounds[b + 1]
        zx[b] = z[lo:hi].T @ x[lo:hi]
        zy[b] = z[lo:hi].T @ y[lo:hi]
        xx[b] = x[lo:hi].T @ x[lo:hi]
        xy[b] = x[lo:hi].T @ y[lo:hi]

    def solve_all(rows, a, rhs):  # every coefficient, physical units
        m = a[rows].sum(axis=0)
        return np.linalg.lstsq(m, rhs[rows].sum(axis=0), rcond=None)[0] / scale

    all_rows = np.arange(nb)
    coef = solve_all(all_rows, zx, zy)
    value = coef[0]
    ls_value = solve_all(all_rows, xx, xy)[0]
    rng = np.random.default_rng(rng_seed)
    boot_all = np.array([solve_all(rng.integers(0, nb, nb), zx, zy) for _ in range(scoring.BOOTSTRAP)])
    boot = boot_all[:, 0]
    resid = y - x @ np.linalg.lstsq(x, y, rcond=None)[0]
    r2 = 1.0 - float(resid @ resid) / float(y @ y) if y @ y > 0 else float("nan")
    out = {"value": float(value), "ci": [float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))],
           "method": "instrumental variables (motor commands)" if instrumented else "least squares",
           "least_squares_value": float(ls_value), "r2": r2, "rows": int(y.size)}
    if keep_bootstrap:  # the resamples depend only on rng_seed and the block count: paired across calls
        out["bootstrap"] = np.asarray(boot)
    if lowpass_only and mass and any(f.band.thrust_offset for f in flights):
        out["thrust_offset"] = thrust_offsets(flights, positions, signs, mass, extra, shape, coef, boot_all)
    return out


def thrust_offsets(flights: list[Flight], positions: np.ndarray, signs: np.ndarray, mass: float,
                   extra: list[np.ndarray] | None, shape: dict | None, coef: np.ndarray,
                   boot_coef: np.ndarray) -> dict:
    """The thrust axis's fitted constant per log as the accelerometer's z offset [m/s^2]: each
    segment's mean of acc_z - (kf sum_i Omega_i^2 + extra columns) / m, low-passed as the fit and
    with its mean kept (module text); the interval from the bootstrap's coefficients."""
    per_log, variation = {}, []
    for fi, f in enumerate(flights):
        raw = replace(f, band=replace(f.band, thrust_offset=False))
        main = main_regressor("thrust", f.speed**2, positions, signs, shape)
        cols = [main[:, None]] + ([extra[fi]] if extra is not None and extra[fi] is not None else [])
        x = raw.filtered(np.column_stack(cols), True)
        y = raw.filtered(responses(f, mass)["thrust"], True)
        seg_values, seg_boot, weights = [], [], []
        for a, b in f.segs:
            mx, my = x[a:b].mean(axis=0), float(y[a:b].mean())
            seg_values.append((my - float(mx @ coef)) / mass)
            seg_boot.append((my - boot_coef @ mx) / mass)
            weights.append(b - a)
            total = x[a:b, 0]
            if total.mean() > 0:
                variation.append((float(np.std(total) / total.mean()), b - a))
        w = np.asarray(weights, dtype=float) / sum(weights)
        boot = np.asarray(seg_boot).T @ w
        per_log[f.name] = {"m_s2": float(np.dot(w, seg_values)), "ci": [float(np.percentile(boot, 2.5)),
                                                                         float(np.percentile(boot, 97.5))],
                           "per_segment_m_s2": [float(v) for v in seg_values]}
    value = float(coef[0])
    lo, hi = float(np.percentile(boot_coef[:, 0], 2.5)), float(np.percentile(boot_coef[:, 0], 97.5))
    half = max(value - lo, hi - value) / abs(value) if value else float("inf")
    rows = sum(n for _, n in variation)
    return {"per_log": per_log,
            "collective_variation": float(sum(v * n for v, n in variation) / rows) if rows else None,
            "kf_thrust_ci_relative_halfwidth": float(half),
            "determined": bool(value > 0 and half <= OFFSET_DETERMINED_REL)}


def instrument_scales(scales: dict, after_details: dict) -> dict:
    """The torque scales (axis -> response scale of a significant inertia_error / gyro_scale)
    without the rotor-speed noise's attenuation. Selection fits such a scale by least squares
    against the accelerometer's kf, so it also absorbs the attenuation of the torque regressor
    (errors in variables: a noisy regressor reads low under least squares, not under
    instrumental variables; a true inertia error reads low under both). With motor commands
    that attenuation is measured on the same axis, band and extra columns as the after-fit:
    least-squares / instrumental-variables value of the fleet coefficient (both are linear in
    the response, so the ratio does not depend on the scale applied). The scale the
    instrument gives is the least-squares one times that ratio. Empty without commands."""
    out = {}
    for axis, scale in scales.items():
        fit = after_details.get(QUANTITY_OF.get(axis, ""))
        if not fit or not fit["method"].startswith("instrumental") or not fit["value"] > 0:
            continue
        attenuation = fit["least_squares_value"] / fit["value"]
        if not attenuation > 0:  # a least-squares fit of the other sign: no attenuation to read
            continue
        out[axis] = {"least_squares_scale": float(scale), "attenuation": float(attenuation),
                     "scale": float(scale * attenuation)}
    return out


def base_fit(flights: list[Flight], positions: np.ndarray, signs: np.ndarray, mass: float | None,
             extras: dict | None = None, response_scales: dict | None = None,
             shape: dict | None = None) -> tuple[dict, dict]:
    """(base_fit in the issue's shape, details). extras: axis -> per-flight columns."""
    extras = extras or {}
    response_scales = response_scales or {}
    out, details = {}, {}
    for key, axis in QUANTITIES.items():
        fit = fleet_fit(flights, axis, positions, signs, mass, extras.get(axis), response_scales.get(axis, 1.0),
                        shape=shape)
        out[key] = None if fit is None else {"value": fit["value"], "ci": fit["ci"]}
        details[key] = fit
    return out, details


GAIN_WINDOW_S = 4.0  # Hann windows, no overlap: 0.25 Hz resolution, a few bins in the lowest band
GAIN_BAND_OCTAVES = 0.5
GAIN_MIN_WINDOWS = 8


def _band_edges(lo_hz: float, hi_hz: float) -> list[tuple[float, float]]:
    out, lo = [], lo_hz
    while lo * 2.0**GAIN_BAND_OCTAVES <= hi_hz * (1 + 1e-9):
        out.append((lo, lo * 2.0**GAIN_BAND_OCTAVES))
        lo *= 2.0**GAIN_BAND_OCTAVES
    return out


def torque_gain_per_band(flights: list[Flight], positions: np.ndarray, signs: np.ndarray, mass: float | None,
                         shape: dict | None = None, thrust_kf: float | None = None,
                         rng_seed: int = 7) -> dict | None:
    """The roll/pitch torque coefficient per half-octave band (the flights' band), from pooled cross-spectra:
    kf(band) = Re(sum S_z,tau / sum S_z,x) over the band's bins, z the instrument (the commands' first stage)
    or the regressor itself without commands; its phase; a 95 % interval by resampling the Welch windows.

    Open loop, or in closed loop where the rotors answer a reference (not a disturbance), kf(band) is the same
    in every band and its phase is near 0. Where the controller answers an unmodelled torque d, the rotor
    torque is correlated with d: below the loop's crossover with the opposite sign (the gain reads low),
    above it, where a lagged loop amplifies d (|sensitivity| > 1), with the same sign (the gain reads high).
    A gain that rises through the band is that signature, and no lower band edge then reads the truth: the
    band fit's value is set by the band's composition (docs/gap.md, "The torque gain per band")."""
    if not flights:
        return None
    instrumented = all(f.cmd is not None for f in flights)
    bands = _band_edges(min(f.band.highpass_hz for f in flights), min(f.band.lowpass_hz for f in flights))
    if not bands:
        return None
    per_window = {axis: [] for axis in ("roll", "pitch")}  # each window: (n_bands, 2) complex [S_zy, S_zx]
    for f in flights:
        n = int(round(GAIN_WINDOW_S * f.rate_hz))
        if n < 8:
            continue
        hann = np.hanning(n)
        freq = np.fft.rfftfreq(n, 1.0 / f.rate_hz)
        masks = [(freq >= lo) & (freq < hi) for lo, hi in bands]
        resp = responses(f, mass)
        u_hat = predicted_u(f, False) if instrumented else None
        for axis in ("roll", "pitch"):
            if axis not in resp:
                return None
            y = f.filtered(resp[axis])
            x = f.filtered(main_regressor(axis, f.speed**2, positions, signs, shape), response=True)
            z = main_regressor(axis, u_hat, positions, signs, shape) if instrumented else x
            for a, b in f.segs:
                for s in range(a, b - n + 1, n):  # no overlap: the windows resample independently
                    fy, fx, fz = (np.fft.rfft((v[s:s + n] - v[s:s + n].mean()) * hann) for v in (y, x, z))
                    szy, szx = np.conj(fz) * fy, np.conj(fz) * fx
                    per_window[axis].append(np.array([[szy[m].sum(), szx[m].sum()] for m in masks]))
    if len(per_window["roll"]) < GAIN_MIN_WINDOWS:
        return None
    rng = np.random.default_rng(rng_seed)
    out = {"method": "instrumental variables (motor commands)" if instrumented else "least squares",
           "window_s": GAIN_WINDOW_S, "windows": len(per_window["roll"])}
    for axis, wins in per_window.items():
        w = np.array(wins)  # (windows, bands, 2)
        total = w.sum(axis=0)
        boot = np.array([w[rng.integers(0, len(w), len(w))].sum(axis=0) for _ in range(scoring.BOOTSTRAP)])
        rows = []
        for k, (lo, hi) in enumerate(bands):
            h = total[k, 0] / total[k, 1] if total[k, 1] != 0 else complex("nan")
            hb = boot[:, k, 0] / np.where(boot[:, k, 1] != 0, boot[:, k, 1], np.nan)
            hb = hb.real[np.isfinite(hb.real)]
            row = {"band_hz": [float(lo), float(hi)], "value": float(h.real),
                   "ci": [float(np.percentile(hb, 2.5)), float(np.percentile(hb, 97.5))] if hb.size else None,
                   "phase_deg": float(np.degrees(np.angle(h)))}
            if thrust_kf:
                row["over_thrust"] = float(h.real / thrust_kf)
            rows.append(row)
        out[axis] = rows
    return out
