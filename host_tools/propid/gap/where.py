"""Where the base model misses: residual per axis, per flight regime, per frequency
band and per rotor.

Regimes (rows may be in several; a regime needs the columns it is defined on):
- hover: |w| < 0.3 rad/s and (horizontal speed < 0.2 m/s when velocity is logged);
- fast_translation: horizontal speed > 1 m/s (velocity + attitude);
- aggressive_yaw: |w_z| > 1 rad/s;
- near_ground: height < 4 rotor radii (pz + rotor_radius), else < 0.2 m (pz);
- rapid_throttle: |d(sum Omega^2)/dt| > 2 /s relative to its median.
Per band: the base model's residual on the raw (not band-passed) torque, band-passed
to each band, RMS over the response's RMS in the same band (1 = the model explains
nothing there); bands up to 0.4 x the sample rate.
Per rotor: the base model's per-rotor kf and km relative to their fleet mean.
"""

from __future__ import annotations

import numpy as np

from propid.gap.design import Design, base_columns, responses, segment_rows
from propid.gap.prep import Flight, difference_response
from propid.realdata_checks import bandpass

BANDS = ((0.2, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0))


def regimes(design: Design, rotor_radius: float | None) -> dict:
    gyro = design.extra["gyro"]
    speed = design.extra["speed_h"]
    height = design.extra["height"]
    throttle = np.abs(design.extra["throttle_rate"])
    have_v = np.isfinite(speed).all()
    out = {"hover": (np.linalg.norm(gyro, axis=1) < 0.3) & ((speed < 0.2) if have_v else True),
           "aggressive_yaw": np.abs(gyro[:, 2]) > 1.0,
           "rapid_throttle": throttle > 2.0}
    if have_v:
        out["fast_translation"] = speed > 1.0
    if np.isfinite(height).all():
        out["near_ground"] = height < (4.0 * rotor_radius if rotor_radius else 0.2)
    return out


def per_axis_regime(design: Design, residual: dict, rotor_radius: float | None) -> tuple[dict, dict]:
    per_axis = {}
    for a in design.axes:
        y = design.y[a]
        r = residual[a]
        per_axis[a] = {"residual_rms": float(np.sqrt(np.mean(r**2))), "response_rms": float(np.sqrt(np.mean(y**2))),
                       "unexplained_fraction": float(np.sum(r**2) / np.sum(y**2)) if np.sum(y**2) > 0 else None}
    per_regime = {}
    for name, mask in regimes(design, rotor_radius).items():
        mask = np.asarray(mask, dtype=bool)
        entry = {"fraction_of_rows": float(mask.mean())}
        for a in design.axes:
            if mask.sum() >= 20:
                entry[a] = float(np.sqrt(np.mean(residual[a][mask] ** 2)))
            else:
                entry[a] = None
        per_regime[name] = entry
    return per_axis, per_regime


def per_band(flights: list[Flight], positions: np.ndarray, signs: np.ndarray, kf: np.ndarray, km: np.ndarray,
             mass: float | None) -> dict:
    theta = np.concatenate([kf, km])
    out = {}
    top = 0.4 * min(f.rate_hz for f in flights)
    for lo, hi in BANDS:
        if hi > top:
            continue
        key = f"{lo:g}-{hi:g}Hz"
        res = {"roll": [0.0, 0.0], "pitch": [0.0, 0.0], "yaw": [0.0, 0.0]}
        for f in flights:
            cols = base_columns(f, positions, signs)
            resp = responses(f, mass)
            for a in res:
                model = cols[a] @ theta
                for s, e in f.segs:
                    y = bandpass(resp[a][s:e, None], f.rate_hz, lo, hi)[:, 0]
                    m = difference_response(bandpass(model[s:e, None], f.rate_hz, lo, hi), f.rate_hz)[:, 0]
                    res[a][0] += float(np.sum((y - m) ** 2))
                    res[a][1] += float(np.sum(y**2))
        out[key] = {a: (float(np.sqrt(v[0] / v[1])) if v[1] > 0 else None) for a, v in res.items()}
    return out


def per_rotor(kf: np.ndarray, km: np.ndarray) -> dict:
    return {"kf_relative": (kf / np.mean(kf)).tolist(), "km_relative": (km / np.mean(km)).tolist(),
            "kf": kf.tolist(), "km": km.tolist()}


EIV_QUANTILES = 5
EIV_RISE = 1.5  # forward gain of the most excited fifth over the least excited fifth


def errors_in_variables(gr, cols: list[int], theta: np.ndarray, axis_idx: list[int]) -> dict:
    """Signature of noise on the rotor-speed regressor (docs/gap.md): per 2 s block, the
    forward least-squares gain of the measured on the modelled torque (sum Py / sum PP)
    and the reverse gain (sum yy / sum Py), blocks sorted by excitation (RMS of P) into
    fifths. An output disturbance leaves both gains flat; noise on the regressor makes the
    forward gain grow with excitation (the attenuation var(u)/(var(u)+var(noise)) shrinks)
    while the reverse gain stays flat. Flagged when the most excited fifth's forward gain
    is > EIV_RISE x the least excited fifth's."""
    g = gr.g[:, axis_idx][:, :, cols][:, :, :, cols].sum(axis=1)
    h = gr.h[:, axis_idx][:, :, cols].sum(axis=1)
    s = gr.s[:, axis_idx].sum(axis=1)
    pp = np.einsum("bpq,p,q->b", g, theta, theta)
    py = h @ theta
    n = np.maximum(gr.count, 1)
    ok = (pp > 0) & (py > 0)
    if ok.sum() < 2 * EIV_QUANTILES:
        return {"flag": False, "note": "too few blocks"}
    excitation = np.sqrt(pp[ok] / n[ok])
    order = np.argsort(excitation)
    groups = np.array_split(order, EIV_QUANTILES)
    fwd = [float(py[ok][gi].sum() / pp[ok][gi].sum()) for gi in groups]
    rev = [float(s[ok][gi].sum() / py[ok][gi].sum()) for gi in groups]
    flag = bool(fwd[0] > 0 and fwd[-1] / fwd[0] > EIV_RISE)
    return {"flag": flag, "forward_gain": fwd, "reverse_gain": rev,
            "excitation_rms": [float(np.median(excitation[gi])) for gi in groups],
            "rule": f"forward gain of the most excited fifth > {EIV_RISE} x the least excited fifth's"}


THRUST_BANDS = ((0.2, 0.5), (0.5, 2.0), (2.0, 5.0), (5.0, 10.0), (10.0, 20.0))
THRUST_COHERENT = 0.7  # coherence above which H1 and H2 agree to within 30 %: one gain, not noise


def _band_first_stage(f: Flight, u_band: np.ndarray, lo: float | None, hi: float | None) -> np.ndarray | None:
    """The collective sum Omega_i^2 that the motor commands alone predict in a band (zeros outside the
    segments), or None without commands: per rotor, least squares of the band-passed Omega_i^2 on the
    band-passed cmd_i and cmd_i^2 delayed by the base fit's INSTRUMENT_LAGS."""
    if f.cmd is None:
        return None
    from propid.gap.basefit import INSTRUMENT_LAGS, _delayed

    rows = segment_rows(f)
    out = np.zeros(len(f.t))
    for i in range(f.speed.shape[1]):
        feats = []
        for lag in INSTRUMENT_LAGS:
            c = _delayed(f.cmd[:, i], lag)
            feats += [c, c * c]
        feats = np.column_stack(feats)
        z = np.zeros_like(feats)
        for a, b in f.segs:
            z[a:b] = bandpass(np.nan_to_num(feats[a:b]), f.rate_hz, lo, hi)
        coef, *_ = np.linalg.lstsq(z[rows], u_band[rows, i], rcond=None)
        out += z @ coef
    return out


def thrust_gain_per_band(flights: list[Flight], mass: float | None) -> dict | None:
    """The thrust axis's dynamic gain against its static one (docs/gap.md "Thrust gain per band"):
    m acc_z against the collective sum Omega_i^2, pooled over the flights' segments.
    static: through the origin on the low-passed rows (the mean's gain, what the base fit's kf_thrust reads);
    per band (both sides band-passed per segment), as ratios over static:
    h1 = Sxy / Sxx (least squares: attenuated by noise on the rotor-speed side),
    h2 = Syy / Sxy (the reverse regression: inflated by noise on the accelerometer side),
    coherence = Sxy^2 / (Sxx Syy) = h1 / h2, and instrument = Szy / Szx with z the collective the motor
    commands predict (their noise is not the telemetry's). Noise on the regressor: h1 low, h2 and the
    instrument near 1, low coherence; a real gain: h1 ~ h2 ~ instrument, coherence near 1.
    segment_demeaned: h1 of the low-passed rows with each segment's mean removed (the slope
    `--thrust-offset segment` fits). None without accelerometer or mass."""
    if not mass or any(f.specific_force_z is None for f in flights):
        return None
    sxx = sxy = 0.0
    demeaned = np.zeros(3)
    for f in flights:
        rows = segment_rows(f)
        x = f.filtered(np.sum(f.speed**2, axis=1), lowpass_only=True)
        y = f.filtered(mass * f.specific_force_z, lowpass_only=True)
        sxx += float(x[rows] @ x[rows])
        sxy += float(x[rows] @ y[rows])
        for a, b in f.segs:
            xs, ys = x[a:b] - x[a:b].mean(), y[a:b] - y[a:b].mean()
            demeaned += [xs @ xs, xs @ ys, ys @ ys]
    if not sxx > 0:
        return None
    static = sxy / sxx
    top = 0.4 * min(f.rate_hz for f in flights)
    bands = {}
    for lo, hi in THRUST_BANDS:
        if hi > top:
            continue
        s = np.zeros(5)  # xx, xy, yy, zx, zy
        instrumented = all(f.cmd is not None for f in flights)
        for f in flights:
            rows = segment_rows(f)
            u = np.zeros_like(f.speed)
            y = np.zeros(len(f.t))
            for a, b in f.segs:
                u[a:b] = bandpass(np.nan_to_num(f.speed[a:b] ** 2), f.rate_hz, lo, hi)
                y[a:b] = bandpass(mass * np.nan_to_num(f.specific_force_z[a:b, None]), f.rate_hz, lo, hi)[:, 0]
            x = u.sum(axis=1)
            z = _band_first_stage(f, u, lo, hi) if instrumented else None
            s[:3] += [x[rows] @ x[rows], x[rows] @ y[rows], y[rows] @ y[rows]]
            if z is not None:
                s[3:] += [z[rows] @ x[rows], z[rows] @ y[rows]]
        xx, xy, yy, zx, zy = s
        ok = xx > 0 and xy != 0 and yy > 0
        bands[f"{lo:g}-{hi:g}Hz"] = {
            "h1": float(xy / xx / static) if ok else None,
            "h2": float(yy / xy / static) if ok else None,
            "coherence": float(xy * xy / (xx * yy)) if ok else None,
            "instrument": float(zy / zx / static) if instrumented and zx != 0 else None}
    xx, xy, yy = demeaned
    return {"static_kf": float(static),
            "segment_demeaned": {"h1": float(xy / xx / static) if xx > 0 else None,
                                 "h2": float(yy / xy / static) if xy != 0 else None,
                                 "coherence": float(xy * xy / (xx * yy)) if xx > 0 and yy > 0 else None},
            "per_band": bands,
            "coherent_above": THRUST_COHERENT}
