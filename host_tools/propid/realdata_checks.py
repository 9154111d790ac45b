"""Independent checks of a real flight log: least-squares fits per frequency band.

These are not the filter: they are plain regressions that tell what the data can
support, so the filter's real-data numbers can be judged against something.

- Thrust (needs acc_z and mass): m * acc_z = kf * sum(omega_i^2), through the origin.
  The accelerometer sees every rotor's thrust directly, so this is the independent
  kf measurement the gyro-only filter is compared with.
- Torques (needs inertia, positions, yaw signs): with tau = J dw/dt + w x (J w)
  (dw/dt by central differences of the gyro),
    roll:  tau_x = kf * sum(y_i omega_i^2)
    pitch: tau_y = kf * sum(-x_i omega_i^2)
    yaw:   tau_z = km * sum(s_i omega_i^2) [+ J_rotor * sum(s_i d omega_i/dt)]
  i.e. the same torque model the filter uses (plus the rotor-acceleration term in yaw
  as a separate fit, since the filter does not model it).

"Band" fits band-pass both sides (zero phase, FFT, per contiguous flying segment)
and search a lag of the response behind the rotor speeds. Steady trim torques and
slow drifts are removed by the band-pass; sensor noise still attenuates the slope
towards zero (least squares with a noisy regressor), so band numbers are lower bounds
more than unbiased values. The roll/pitch fits are repeated with the samples grouped by
excitation (grouped_fit), which an additive regressor-side term does not attenuate, and
with the logged motor commands as instruments (instrument_fit), which share neither the
telemetry's errors nor, as far as it decorrelates within their lags, a torque the
controller cancels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.outputs import save_figure
from propid.signals import log_body_velocity, measured_torque, repeats_previous_row, segments

GRAVITY = 9.80665


GROUND_CLEARANCE_M = 0.05  # airborne = this far above the lowest logged height (ground contact, ground effect)
# ... when that height can be the ground: a landed multirotor's centre of mass sits lower than this (0.03-0.05 m
# on the Crazyflie logs, landing gear of larger vehicles ~0.1-0.3 m); a log whose lowest height is above it never
# touched the ground (a SITL flight hovering at 1 m), and its height says nothing about ground contact
LANDED_HEIGHT_MAX_M = 0.3


def flying_mask(log: FlightLog, min_fraction: float = 0.33, clearance: float = GROUND_CLEARANCE_M) -> np.ndarray:
    """Rows in free flight (docs/real-data.md): the log's is_flying flag if present, else
    every rotor above `min_fraction` of the median spinning rotor speed; and, when the
    height pz is logged and its lowest value can be the ground (LANDED_HEIGHT_MAX_M), at
    least `clearance` above it, so that rows on the ground (take-off, landing: contact
    torques the model does not have) are left out."""
    speeds = _hold_rotor_rows(log.rotor_speed)
    if "is_flying" in log.extra:
        mask = np.nan_to_num(_hold_missing(log.t, log.extra["is_flying"]), nan=0.0) > 0.5
    else:
        spinning = speeds[np.isfinite(speeds) & (speeds > 0)]
        if spinning.size == 0:
            return np.zeros(len(log), dtype=bool)
        threshold = min_fraction * float(np.median(spinning))
        mask = np.all(np.nan_to_num(speeds, nan=threshold + 1.0) > threshold, axis=1) & np.any(
            np.isfinite(speeds), axis=1
        )
    height = log.extra.get("pz")
    if height is not None and np.isfinite(height).any():
        height = _hold_missing(log.t, height)
        ground = float(np.nanmin(height))
        if ground <= LANDED_HEIGHT_MAX_M:
            mask &= np.nan_to_num(height, nan=ground) > ground + clearance
    return mask


def _hold_missing(t: np.ndarray, values: np.ndarray) -> np.ndarray:
    """A flag or height column with, in the rows that miss it (the rows of another stream in an events
    log, a dropped sample), the value in force at their time: the latest logged at or before it (rows
    before the first value take that one). Missing was read as 'on the ground', so an events log that
    wrote pz or is_flying on its gyro rows only had no flying rotor row at all."""
    logged = np.isfinite(values)
    if logged.all() or not logged.any():
        return values
    index = np.searchsorted(t[logged], t, side="right") - 1
    return values[logged][np.maximum(index, 0)]


def _hold_rotor_rows(speeds: np.ndarray, values: np.ndarray | None = None, before=np.nan) -> np.ndarray:
    """Rows without any rotor speed (gyro rows of an event-style log) take the latest
    rotor row before them, as the filter does: its speeds, or `values` (a per-row quantity
    of the rotor stream), `before` the first rotor row."""
    values = speeds if values is None else values
    empty = ~np.any(np.isfinite(speeds), axis=1)
    if not empty.any() or empty.all():
        return values
    index = np.where(~empty, np.arange(len(speeds)), 0)
    np.maximum.accumulate(index, out=index)
    held = values[index]
    held[empty & (np.cumsum(~empty) == 0)] = before  # nothing to hold before the first rotor row
    return held


# Speeds further than this many robust standard deviations (1.4826 MAD) from the
# median are outliers for the limit below: a spike of a corrupt frame, not a peak.
SPEED_FENCE_SIGMAS = 10.0


def absurd_speed_limit(speeds: np.ndarray) -> float:
    """A rotor speed above this is a telemetry glitch: 2x the 99.9th percentile of the
    finite speeds inside a robust fence (median + SPEED_FENCE_SIGMAS x 1.4826 MAD), so
    eRPM spikes do not raise the limit however many there are (up to half the samples),
    and real peaks keep a factor 2 of headroom."""
    finite = speeds[np.isfinite(speeds)]
    if finite.size == 0:
        raise UserError("the log has no finite rotor speed")
    median = float(np.median(finite))
    spread = 1.4826 * float(np.median(np.abs(finite - median)))
    spread = max(spread, 0.01 * abs(median), 1.0)  # a constant-speed log: 1 % of it, at least 1 rad/s
    inside = finite[np.abs(finite - median) <= SPEED_FENCE_SIGMAS * spread]
    return 2.0 * float(np.percentile(inside, 99.9))


def clean_rotor_speeds(speeds: np.ndarray, limit: float) -> tuple[np.ndarray, int]:
    """Replace NaN and absurd values by linear interpolation along time (for fits only)."""
    out = speeds.copy()
    bad_total = 0
    idx = np.arange(out.shape[0])
    for k in range(out.shape[1]):
        col = out[:, k]
        bad = ~np.isfinite(col) | (col > limit)
        bad_total += int(bad.sum())
        if bad.any() and (~bad).sum() >= 2:
            col[bad] = np.interp(idx[bad], idx[~bad], col[~bad])
    return out, bad_total


def bandpass(x: np.ndarray, rate_hz: float, low_hz: float | None, high_hz: float | None) -> np.ndarray:
    """Zero-phase FFT band-pass of each column with raised-cosine edges (+-25 %)."""
    if low_hz is None and high_hz is None:
        return x - x.mean(axis=0)
    n = x.shape[0]
    pad = n  # mirror padding keeps the segment ends from ringing
    xp = np.concatenate([x[::-1], x, x[::-1]], axis=0)
    freqs = np.fft.rfftfreq(xp.shape[0], d=1.0 / rate_hz)
    gain = np.ones_like(freqs)

    def ramp(f, edge):  # 0 below edge*0.75, 1 above edge*1.25
        lo, hi = 0.75 * edge, 1.25 * edge
        r = np.clip((f - lo) / (hi - lo), 0.0, 1.0)
        return 0.5 - 0.5 * np.cos(np.pi * r)

    if low_hz:
        gain *= ramp(freqs, low_hz)
    if high_hz:
        gain *= 1.0 - ramp(freqs, high_hz)
    spec = np.fft.rfft(xp, axis=0) * gain[:, None]
    return np.fft.irfft(spec, n=xp.shape[0], axis=0)[pad : pad + n]


@dataclass
class Fit:
    coeffs: list[float]
    r2: float
    lag: int  # samples the response lags the regressors
    rows: int

    def as_dict(self, names: list[str], rate_hz: float) -> dict:
        out = {name: value for name, value in zip(names, self.coeffs)}
        out.update({"r2": self.r2, "lag_samples": self.lag, "lag_ms": 1e3 * self.lag / rate_hz, "rows": self.rows})
        return out


def _lstsq(y_parts: list[np.ndarray], x_parts: list[np.ndarray]) -> Fit:
    y = np.concatenate(y_parts)
    x = np.concatenate(x_parts)
    if y.size < x.shape[1] + 2:
        return Fit([float("nan")] * x.shape[1], float("nan"), 0, int(y.size))
    coeffs, *_ = np.linalg.lstsq(x, y, rcond=None)
    resid = y - x @ coeffs
    total = float(np.sum(y**2))  # R^2 about zero: the fits go through the origin
    r2 = 1.0 - float(np.sum(resid**2)) / total if total > 0 else float("nan")
    return Fit([float(c) for c in coeffs], r2, 0, int(y.size))


def lagged_fit(
    response: np.ndarray,
    regressors: np.ndarray,
    segs: list[tuple[int, int]],
    rate_hz: float,
    band: tuple[float | None, float | None],
    lags: range,
) -> Fit:
    """Through-origin LS of response[n + lag] on regressors[n] over the segments, each
    band-passed separately; the lag with the best R^2 wins (R^2 about zero, not the mean)."""
    filtered = []
    for a, b in segs:
        yy = bandpass(response[a:b, None], rate_hz, *band)[:, 0] if band != (None, None) else response[a:b]
        xx = bandpass(regressors[a:b], rate_hz, *band) if band != (None, None) else regressors[a:b]
        filtered.append((yy, xx))
    best = None
    for lag in lags:
        ys, xs = [], []
        for yy, xx in filtered:
            n = yy.shape[0]
            lo, hi = max(0, -lag), min(n, n - lag)
            if hi - lo < 10:
                continue
            ys.append(yy[lo + lag : hi + lag])
            xs.append(xx[lo:hi])
        if not ys:
            continue
        fit = _lstsq(ys, xs)
        fit.lag = lag
        if best is None or (np.isfinite(fit.r2) and (not np.isfinite(best.r2) or fit.r2 > best.r2)):
            best = fit
    return best if best is not None else Fit([float("nan")] * regressors.shape[1], float("nan"), 0, 0)


# Excitation groups for grouped_fit: quintiles of the slow (EXCITATION_WINDOW_S mean) body-rate magnitude.
EXCITATION_GROUPS = 5
EXCITATION_WINDOW_S = 1.0
# Below this ratio of the largest to the smallest group's regressor power the groups do not differ
# enough in excitation for the slope to mean anything (grouped_fit returns NaN).
MIN_EXCITATION_RATIO = 2.0


def _band_aligned(response, regressor, segs, rate_hz, band, lag, history=0, regressor_response=None):
    """Per flying segment (a, b): response and regressor band-passed (the regressor first given
    `regressor_response`, if any) and paired as response[n + lag] with regressor[n], over the rows n
    of the segment where response[n + lag] and response[n + lag - history] both exist. Yields
    ((a, b), rows, paired response, paired regressor); segments with fewer than 10 rows are skipped."""
    for a, b in segs:
        yy = bandpass(response[a:b, None], rate_hz, *band)[:, 0]
        x_seg = regressor[a:b] if regressor_response is None else regressor_response(regressor[a:b])
        xx = bandpass(x_seg[:, None], rate_hz, *band)[:, 0]
        n = yy.shape[0]
        lo, hi = max(0, -lag, history - lag), min(n, n - lag)
        if hi - lo < 10:
            continue
        rows = np.arange(lo, hi)
        yield (a, b), rows, yy[rows + lag], xx[rows]


def grouped_fit(
    response: np.ndarray,
    regressor: np.ndarray,
    excitation: np.ndarray,
    segs: list[tuple[int, int]],
    rate_hz: float,
    band: tuple[float, float],
    lag: int,
    groups: int = EXCITATION_GROUPS,
) -> dict:
    """Through-origin slope that an ADDITIVE term on the regressor side does not attenuate
    (Wald's grouping estimator; docs/real-data.md "What the torque gain is").

    Model: regressor x = x_true + n, response y = k x_true + e, with n's power the same in every
    group (rotor-speed noise, or the rotors' answer to a torque the controller cancels and the
    gyro therefore does not see) and e independent. The samples are grouped by `excitation`
    (one value per row, e.g. the slow body-rate magnitude: it sets the size of x_true, not of n);
    per group the mean products are c_g = <y x>/N = k v_g - k s2 and v_g = <x x>/N, so k is the
    slope of the straight line through (v_g, c_g) and s2 = -intercept / k. Plain least squares
    gives sum c_g / sum v_g instead, attenuated by the share of n in x. A gain error of the
    model itself (inertia, arm, gyro scale) multiplies every group alike and stays in k.

    Returns k, the additive term's rms in the response's units (k sqrt(s2)), the plain slope,
    and the per-group slopes c_g / v_g; k is NaN when the groups' v_g span less than
    MIN_EXCITATION_RATIO."""
    ys, xs, ss = [], [], []
    for (a, _), rows, y_seg, x_seg in _band_aligned(response, regressor, segs, rate_hz, band, lag):
        ys.append(y_seg)
        xs.append(x_seg)
        ss.append(excitation[a + rows])
    nan = {"kf": float("nan"), "additive_rms": float("nan"), "plain": float("nan"), "group_slopes": []}
    if not ys:
        return nan
    y, x, s = np.concatenate(ys), np.concatenate(xs), np.concatenate(ss)
    if y.size < 10 * groups:
        return nan
    order = np.argsort(s, kind="stable")
    c, v = [], []
    for part in np.array_split(order, groups):  # equal-count groups by excitation
        c.append(float(y[part] @ x[part]) / part.size)
        v.append(float(x[part] @ x[part]) / part.size)
    c, v = np.array(c), np.array(v)
    plain = float(c.sum() / v.sum()) if v.sum() > 0 else float("nan")
    out = dict(nan, plain=plain, group_slopes=[float(cg / vg) if vg > 0 else float("nan") for cg, vg in zip(c, v)])
    if v.min() <= 0 or v.max() < MIN_EXCITATION_RATIO * v.min():
        return out
    slope, intercept = np.polyfit(v, c, 1)
    out["kf"] = float(slope)
    if slope > 0:
        out["additive_rms"] = float(slope * np.sqrt(max(-intercept / slope, 0.0)))
    return out


# Instrument lags [samples] for instrument_fit: the commands this many samples before the response.
INSTRUMENT_LAGS = (2, 3, 5, 8, 13)


def difference_response(x: np.ndarray, rate_hz: float) -> np.ndarray:
    """x given the response of the central difference against d/dt, sin(wT)/(wT) with T the sample
    interval (0.94 at 10 Hz, 0.76 at 20 Hz at 100 Hz): the measured angular acceleration is a central
    difference of the gyro, so a regressor with the same response is compared like with like."""
    n = x.shape[0]
    xp = np.concatenate([x[::-1], x, x[::-1]])
    w = 2.0 * np.pi * np.fft.rfftfreq(xp.shape[0], d=1.0 / rate_hz) / rate_hz
    gain = np.ones_like(w)
    gain[1:] = np.sin(w[1:]) / w[1:]
    return np.fft.irfft(np.fft.rfft(xp) * gain, n=xp.shape[0])[n : 2 * n]


def instrument_fit(
    response: np.ndarray,
    regressor: np.ndarray,
    instruments: np.ndarray,
    segs: list[tuple[int, int]],
    rate_hz: float,
    band: tuple[float, float],
    lag: int,
) -> dict:
    """Two-stage least squares of response[n + lag] on regressor[n] with `instruments` (columns, same
    rows and clock as the response; each used at INSTRUMENT_LAGS samples before the response's row), all
    band-passed per segment, the regressor given the central difference's response (difference_response).
    Instruments that do
    not share the regressor's errors (the motor commands: not the rotor-speed telemetry's noise, and,
    for a cancelled torque that decorrelates within the lags, not the rotors' answer to it) remove the
    attenuation those errors cause. Returns the slope, the plain slope with the same response, and the
    first stage's R^2 (instrument strength; a weak first stage, below ~0.1, makes the slope noisy)."""
    nan = {"kf": float("nan"), "plain": float("nan"), "first_stage_r2": float("nan")}
    ys, xs, zs = [], [], []
    max_lag = max(INSTRUMENT_LAGS)
    long_segs = [(a, b) for a, b in segs if b - a >= 4 * max_lag]
    aligned = _band_aligned(response, regressor, long_segs, rate_hz, band, lag, history=max_lag,
                            regressor_response=lambda x: difference_response(x, rate_hz))
    for (a, b), rows, y_seg, x_seg in aligned:
        zz = bandpass(instruments[a:b], rate_hz, *band)
        ys.append(y_seg)
        xs.append(x_seg)
        # the commands are on the response's (the gyro's) clock: k samples before the response
        zs.append(np.column_stack([zz[rows + lag - k] for k in INSTRUMENT_LAGS]))
    if not ys:
        return nan
    y, x, z = np.concatenate(ys), np.concatenate(xs), np.concatenate(zs)
    if y.size < 10 * z.shape[1] or not np.any(x):
        return nan
    coeffs, *_ = np.linalg.lstsq(z, x, rcond=None)
    fitted = z @ coeffs
    first = 1.0 - float(np.sum((x - fitted) ** 2)) / float(np.sum(x**2))
    denominator = float(fitted @ x)
    return {"kf": float(fitted @ y) / denominator if denominator != 0 else float("nan"),
            "plain": float(x @ y) / float(x @ x), "first_stage_r2": first}


def slow_rate_magnitude(gyro: np.ndarray, rate_hz: float, window_s: float = EXCITATION_WINDOW_S) -> np.ndarray:
    """Running mean of the roll/pitch rate magnitude over window_s: how hard the vehicle is manoeuvring."""
    width = max(1, int(round(window_s * rate_hz)))
    magnitude = np.hypot(gyro[:, 0], gyro[:, 1])
    return np.convolve(magnitude, np.ones(width) / width, mode="same")


DEFAULT_BANDS = {
    "raw": (None, None),
    "0.5-2Hz": (0.5, 2.0),
    "2-5Hz": (2.0, 5.0),
    "5-10Hz": (5.0, 10.0),
    "10-20Hz": (10.0, 20.0),
    "2-10Hz": (2.0, 10.0),
    "5-20Hz": (5.0, 20.0),
}
EVIDENCE_BANDS = ("0.5-2Hz", "2-5Hz", "5-10Hz", "10-20Hz")  # the per-band evidence table (docs/real-data.md)


def _commands(log: FlightLog, rotors: int) -> np.ndarray | None:
    """The logged motor commands cmd_1..cmd_N (flight-log v1 optional columns), gaps held; None
    when any is missing or never finite."""
    columns = []
    for i in range(rotors):
        col = log.extra.get(f"cmd_{i + 1}")
        if col is None or not np.isfinite(col).any():
            return None
        col = np.asarray(col, dtype=float).copy()
        bad = ~np.isfinite(col)
        if bad.any():
            idx = np.arange(col.size)
            col[bad] = np.interp(idx[bad], idx[~bad], col[~bad])
        columns.append(col)
    return np.column_stack(columns)


def repeated_row_shares(log: FlightLog, rows: np.ndarray) -> dict:
    """Share of `rows` (a mask) whose gyro triple, or rotor-speed set, equals the previous row's bit for bit:
    a logger's sample-and-hold copy of a lost packet, not a new sample (docs/real-data.md "Repeated rows")."""
    same_gyro, same_rotor = repeats_previous_row(log.gyro), repeats_previous_row(log.rotor_speed)
    count = int(rows.sum())
    if count == 0:
        return {"gyro": float("nan"), "rotor": float("nan")}
    return {"gyro": float(same_gyro[rows].sum()) / count, "rotor": float(same_rotor[rows].sum()) / count}


def thrust_fit_with_bias(force: np.ndarray, sum_u: np.ndarray, rows: np.ndarray,
                         climb: np.ndarray | None = None) -> dict:
    """m acc_z = kf sum(Omega^2) [+ d sum(Omega) v_z,body] + m b over `rows`, unfiltered.

    With the intercept b free, kf is the slope of the thrust against the collective, which is what a
    filter with an accelerometer-bias state reads; through the origin (the `thrust_kf` fit) it is the
    hover ratio. The optional climb term is a force linear in the body-z velocity at the rotor speed
    (a rotor in axial climb makes less thrust at the same speed; frame drag in climb): d < 0 when present.
    Returns kf, the intercept as a force (bias x mass) [N], d, R^2 and the rows used."""
    ok = rows & np.isfinite(force) & np.isfinite(sum_u)
    if climb is not None:
        ok &= np.isfinite(climb)
    nan = {"kf": float("nan"), "bias_force": float("nan"), "climb": float("nan"), "r2": float("nan"),
           "rows": int(ok.sum())}
    if ok.sum() < 10:
        return nan
    columns = [sum_u[ok], np.ones(int(ok.sum()))] + ([climb[ok]] if climb is not None else [])
    x = np.column_stack(columns)
    y = force[ok]
    coeffs, *_ = np.linalg.lstsq(x, y, rcond=None)
    resid = y - x @ coeffs
    total = float(np.sum((y - y.mean()) ** 2))
    return {"kf": float(coeffs[0]), "bias_force": float(coeffs[1]),
            "climb": float(coeffs[2]) if climb is not None else float("nan"),
            "r2": 1.0 - float(np.sum(resid**2)) / total if total > 0 else float("nan"), "rows": int(ok.sum())}


def check_log(
    log: FlightLog,
    vehicle: Vehicle,
    bands: dict[str, tuple[float | None, float | None]] | None = None,
    max_lag_s: float = 0.05,
    unit_inertia: bool = False,
) -> dict:
    """Per-band thrust and torque fits on the flying rows of one log. All SI."""
    bands = dict(DEFAULT_BANDS if bands is None else bands)
    dt = np.diff(log.t)
    dt_med = float(np.median(dt[dt > 0])) if np.any(dt > 0) else float("nan")
    if not np.isfinite(dt_med):
        raise UserError("the log's time never advances")
    rate = 1.0 / dt_med
    max_lag = max(1, int(round(max_lag_s * rate)))  # lag search +-max_lag_s, in samples
    nyquist = 0.5 * rate
    for name, (lo, hi) in list(bands.items()):
        if hi is not None and hi >= 0.9 * nyquist:
            del bands[name]  # band beyond what this sample rate can show
    limit = absurd_speed_limit(log.rotor_speed)
    speeds, repaired = clean_rotor_speeds(log.rotor_speed, limit)
    gyro = log.gyro.copy()
    for k in range(3):  # isolated missing gyro samples: interpolate for the fits
        bad = ~np.isfinite(gyro[:, k])
        if bad.any() and (~bad).sum() >= 2:
            idx = np.arange(len(gyro))
            gyro[bad, k] = np.interp(idx[bad], idx[~bad], gyro[~bad, k])
    fly = flying_mask(log)
    # central differences need both neighbours; keep segments with uniform timing
    uniform = np.ones(len(log), dtype=bool)
    uniform[1:] &= np.abs(dt - dt_med) < 0.5 * dt_med
    uniform[:-1] &= np.abs(dt - dt_med) < 0.5 * dt_med
    segs = segments(fly & uniform, min_length=int(max(2.0 * rate, 50)))
    rows = sum(b - a for a, b in segs)
    result = {
        "log": str(log.path) if log.path else None,
        "rate_hz": rate,
        "flying_rows": int(fly.sum()),
        "fit_rows": rows,
        "segments": len(segs),
        "repaired_rotor_samples": repaired,
        "repeated_rows": repeated_row_shares(log, fly),
        "absurd_speed_limit": limit,
        "bands": {},
    }
    if rows == 0:
        result["note"] = "no flying segment long enough for the fits"
        return result

    u = speeds**2
    pos = vehicle.positions
    signs = vehicle.yaw_signs
    use_unit = unit_inertia or vehicle.inertia is None
    inertia = np.eye(3) if use_unit else np.asarray(vehicle.inertia)
    result["inertia_used"] = "unit" if use_unit else "vehicle"
    rate_dot = np.gradient(gyro, log.t, axis=0)
    torque = measured_torque(gyro, rate_dot, inertia)
    reg_roll = (u * pos[:, 1]).sum(axis=1, keepdims=True)
    reg_pitch = (-u * pos[:, 0]).sum(axis=1, keepdims=True)
    reg_yaw = (u * signs).sum(axis=1, keepdims=True)
    speed_dot = np.gradient(speeds, log.t, axis=0)
    reg_yaw_rotor = np.column_stack([reg_yaw[:, 0], (speed_dot * signs).sum(axis=1)])
    sum_u = u.sum(axis=1, keepdims=True)
    body_velocity = log_body_velocity(log, missing=0.0)
    acc = log.acc
    thrust_ok = acc is not None and vehicle.mass is not None and np.isfinite(acc[:, 2]).any()
    lags = range(-max_lag, max_lag + 1)
    excitation = slow_rate_magnitude(gyro, rate)
    commands = _commands(log, speeds.shape[1])
    for name, band in bands.items():
        entry = {}
        if thrust_ok:
            force = vehicle.mass * np.nan_to_num(acc[:, 2], nan=float(np.nanmedian(acc[:, 2])))
            thrust_lags = range(0, 1) if band == (None, None) else lags
            entry["thrust_kf"] = lagged_fit(force, sum_u, segs, rate, band, thrust_lags).as_dict(["kf"], rate)
            if band == (None, None):
                seg_rows = np.zeros(len(log), dtype=bool)
                for a, b in segs:
                    seg_rows[a:b] = True
                entry["thrust_kf_with_bias"] = thrust_fit_with_bias(force, sum_u[:, 0], seg_rows)
                if body_velocity is not None:
                    climb = speeds.sum(axis=1) * body_velocity[:, 2]
                    entry["thrust_kf_climb"] = thrust_fit_with_bias(force, sum_u[:, 0], seg_rows, climb)
        band_lags = range(0, 1) if band == (None, None) else lags
        entry["roll_kf"] = lagged_fit(torque[:, 0], reg_roll, segs, rate, band, band_lags).as_dict(["kf"], rate)
        entry["pitch_kf"] = lagged_fit(torque[:, 1], reg_pitch, segs, rate, band, band_lags).as_dict(["kf"], rate)
        entry["yaw_km"] = lagged_fit(torque[:, 2], reg_yaw, segs, rate, band, band_lags).as_dict(["km"], rate)
        entry["yaw_km_rotor_inertia"] = lagged_fit(torque[:, 2], reg_yaw_rotor, segs, rate, band, band_lags).as_dict(
            ["km", "rotor_inertia"], rate
        )
        if band != (None, None):
            # the same torque fits with the samples grouped by excitation (grouped_fit), at the plain fits' lags
            for key, axis, reg, fit_key in (("roll_kf_grouped", 0, reg_roll, "roll_kf"),
                                            ("pitch_kf_grouped", 1, reg_pitch, "pitch_kf")):
                entry[key] = grouped_fit(torque[:, axis], reg[:, 0], excitation, segs, rate, band,
                                         entry[fit_key]["lag_samples"])
            if commands is not None:
                # the motor commands, in the same per-axis combination and squared, as instruments
                for key, axis, reg, weights, fit_key in (
                        ("roll_kf_instrumented", 0, reg_roll, pos[:, 1], "roll_kf"),
                        ("pitch_kf_instrumented", 1, reg_pitch, -pos[:, 0], "pitch_kf")):
                    instruments = np.column_stack([commands @ weights, commands**2 @ weights])
                    entry[key] = instrument_fit(torque[:, axis], reg[:, 0], instruments, segs, rate, band,
                                                entry[fit_key]["lag_samples"])
        if body_velocity is not None:
            # same torque fits with a moment linear in body velocity (rotor drag / blade flapping)
            for key, axis, reg in (("roll_kf_with_velocity", 0, reg_roll), ("pitch_kf_with_velocity", 1, reg_pitch)):
                fit = lagged_fit(torque[:, axis], np.column_stack([reg, body_velocity]), segs, rate, band, band_lags)
                entry[key] = fit.as_dict(["kf", "moment_per_vx", "moment_per_vy", "moment_per_vz"], rate)
        result["bands"][name] = entry
    return result


def format_checks(result: dict) -> str:
    """Human-readable table of one log's checks."""
    lines = [
        f"log {result.get('log')}: {result['rate_hz']:.1f} Hz, {result['fit_rows']} flying rows in "
        f"{result['segments']} segment(s), {result['repaired_rotor_samples']} rotor samples interpolated"
    ]
    unit = " (unit inertia: torque coefficients are kf/J-like ratios)" if result.get("inertia_used") == "unit" else ""
    lines.append(f"{'band':>9} {'thrust kf (R2)':>20} {'roll kf (R2,lag)':>24} {'pitch kf (R2,lag)':>24} "
                 f"{'yaw km (R2,lag)':>24} {'yaw km, J_rotor (R2)':>30}{unit}")
    for band, entry in result.get("bands", {}).items():
        def cell(fit, key):
            return f"{fit[key]:.3e} ({fit['r2']:.2f},{fit['lag_samples']:+d})"

        thrust = f"{entry['thrust_kf']['kf']:.3e} ({entry['thrust_kf']['r2']:.2f})" if "thrust_kf" in entry else "n/a"
        yr = entry["yaw_km_rotor_inertia"]
        lines.append(
            f"{band:>9} {thrust:>20} {cell(entry['roll_kf'], 'kf'):>24} {cell(entry['pitch_kf'], 'kf'):>24} "
            f"{cell(entry['yaw_km'], 'km'):>24} {yr['km']:.2e}, {yr['rotor_inertia']:.2e} ({yr['r2']:.2f})"
        )
    repeated = result.get("repeated_rows")
    if repeated:
        lines.append(f"rows repeating the previous row's sample (sample-and-hold copies; --skip-repeats): "
                     f"gyro {100 * repeated['gyro']:.1f} %, rotor speeds {100 * repeated['rotor']:.1f} %")
    raw = result.get("bands", {}).get("raw", {})
    if "thrust_kf_with_bias" in raw:
        fit = raw["thrust_kf_with_bias"]
        line = f"thrust kf with a free bias (the slope a filter with an accelerometer bias reads): {fit['kf']:.3e}"
        if "thrust_kf_climb" in raw:
            climb = raw["thrust_kf_climb"]
            line += f"; with a climb term d sum(Omega) v_z: {climb['kf']:.3e}, d {climb['climb']:.2e} N/(rad/s m/s)"
        lines.append(line)
    velocity_lines = []
    for band, entry in result.get("bands", {}).items():
        if "roll_kf_with_velocity" in entry:
            r, p = entry["roll_kf_with_velocity"], entry["pitch_kf_with_velocity"]
            velocity_lines.append(f"{band:>9} roll kf {r['kf']:.3e} (R2 {r['r2']:.2f}), pitch kf {p['kf']:.3e} (R2 {p['r2']:.2f})")
    grouped_lines = []
    for band, entry in result.get("bands", {}).items():
        if "roll_kf_grouped" in entry:
            r, p = entry["roll_kf_grouped"], entry["pitch_kf_grouped"]
            grouped_lines.append(f"{band:>9} roll kf {r['kf']:.3e} (additive {r['additive_rms']:.1e} N m), "
                                  f"pitch kf {p['kf']:.3e} (additive {p['additive_rms']:.1e} N m)")
    for band, entry in result.get("bands", {}).items():
        if "roll_kf_instrumented" in entry:
            r, p = entry["roll_kf_instrumented"], entry["pitch_kf_instrumented"]
            grouped_lines.append(f"{band:>9} commands as instruments: roll kf {r['kf']:.3e} (first stage R2 "
                                 f"{r['first_stage_r2']:.2f}), pitch kf {p['kf']:.3e} ({p['first_stage_r2']:.2f})")
    if velocity_lines:
        lines.append("torque fits with a body-velocity moment term (rotor drag / flapping):")
        lines.extend(velocity_lines)
    if grouped_lines:
        lines.append("torque fits grouped by excitation (not attenuated by an additive regressor-side term) "
                     "and with the motor commands as instruments:")
        lines.extend(grouped_lines)
    return "\n".join(lines)


def band_evidence_table(checks: list[dict], names: list[str], reference_kf: float | None = None) -> str:
    """Markdown: per run and band, the gyro-torque roll/pitch kf (ratio to the reference, or
    to the run's own accelerometer thrust kf without one) with R^2, and the yaw km without
    and with the rotor-acceleration term, beside the accelerometer thrust kf (raw); last
    columns the 2-10 Hz torque kf divided by R^2 (the reverse regression: an upper bound if
    all the unexplained variance were noise on the rotor-speed regressor) and the 2-10 Hz torque
    kf grouped by excitation (grouped_fit: not attenuated by an additive regressor-side term)
    with that term's rms, and the 5-20 Hz torque kf with the motor commands as instruments
    (instrument_fit; needs cmd_* columns) with the first stage's R^2."""
    head = "| run | acc thrust kf (raw) |" + "".join(
        f" {b.replace('Hz', ' Hz')} roll / pitch kf (R^2) | {b.replace('Hz', ' Hz')} km / km+J_r [1e-10] |"
        for b in EVIDENCE_BANDS) + " 2-10 Hz roll / pitch kf / R^2 (errors-in-variables bound) |" \
        " 2-10 Hz roll / pitch kf grouped by excitation (additive torque rms [1e-5 N m]) |" \
        " 5-20 Hz roll / pitch kf, motor commands as instruments (first-stage R^2) |"
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    pooled = {b: [] for b in EVIDENCE_BANDS}
    eiv, grouped, instrumented = [], [], []
    for name, c in zip(names, checks):
        bands = c.get("bands", {})
        thrust = bands.get("raw", {}).get("thrust_kf", {}).get("kf", float("nan"))
        ref = reference_kf or thrust
        cells = [f"{thrust / reference_kf:.2f}" if reference_kf else f"{thrust:.3g}"]
        for b in EVIDENCE_BANDS:
            e = bands.get(b)
            if not e:
                cells += ["n/a", "n/a"]
                continue
            r, p = e["roll_kf"], e["pitch_kf"]
            pooled[b].append(0.5 * (r["kf"] + p["kf"]) / ref)
            cells.append(f"{r['kf'] / ref:.2f} / {p['kf'] / ref:.2f} ({r['r2']:.2f}/{p['r2']:.2f})")
            cells.append(f"{e['yaw_km']['km'] * 1e10:.2f} / {e['yaw_km_rotor_inertia']['km'] * 1e10:.2f}")
        # Through-origin LS of y on x gives Sxy/Sxx; of x on y (all error in the regressor) Syy/Sxy =
        # (Sxy/Sxx)/R^2 with R^2 about zero: the truth lies between them if only noise separates the two.
        e = bands.get("2-10Hz")
        if e and e["roll_kf"]["r2"] > 0 and e["pitch_kf"]["r2"] > 0:
            eiv.append(0.5 * (e["roll_kf"]["kf"] / e["roll_kf"]["r2"] + e["pitch_kf"]["kf"] / e["pitch_kf"]["r2"]) / ref)
        cells.append(f"{e['roll_kf']['kf'] / e['roll_kf']['r2'] / ref:.2f} / {e['pitch_kf']['kf'] / e['pitch_kf']['r2'] / ref:.2f}"
                     if e and e["roll_kf"]["r2"] > 0 and e["pitch_kf"]["r2"] > 0 else "n/a")
        g = (e or {}).get("roll_kf_grouped"), (e or {}).get("pitch_kf_grouped")
        if g[0] and g[1] and np.isfinite(g[0]["kf"]) and np.isfinite(g[1]["kf"]):
            grouped.append(0.5 * (g[0]["kf"] + g[1]["kf"]) / ref)
            cells.append(f"{g[0]['kf'] / ref:.2f} / {g[1]['kf'] / ref:.2f} "
                         f"({g[0]['additive_rms'] * 1e5:.1f} / {g[1]['additive_rms'] * 1e5:.1f})")
        else:
            cells.append("n/a")
        e = bands.get("5-20Hz") or {}
        iv = e.get("roll_kf_instrumented"), e.get("pitch_kf_instrumented")
        if iv[0] and iv[1] and np.isfinite(iv[0]["kf"]) and np.isfinite(iv[1]["kf"]):
            instrumented.append(0.5 * (iv[0]["kf"] + iv[1]["kf"]) / ref)
            cells.append(f"{iv[0]['kf'] / ref:.2f} / {iv[1]['kf'] / ref:.2f} "
                         f"({iv[0]['first_stage_r2']:.2f} / {iv[1]['first_stage_r2']:.2f})")
        else:
            cells.append("n/a")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    mean_cells = ["**mean (roll+pitch)/2**", ""]
    for b in EVIDENCE_BANDS:
        mean_cells += [f"**{np.mean(pooled[b]):.2f}**" if pooled[b] else "n/a", ""]
    mean_cells.append(f"**{np.mean(eiv):.2f}**" if eiv else "n/a")
    mean_cells.append(f"**{np.mean(grouped):.2f}**" if grouped else "n/a")
    mean_cells.append(f"**{np.mean(instrumented):.2f}**" if instrumented else "n/a")
    lines.append("| " + " | ".join(mean_cells) + " |")
    return "\n".join(lines)


def plot_band_evidence(checks: list[dict], names: list[str], path: str, reference_kf: float, dpi: int = 80) -> None:
    """PNG: torque-derived kf (roll+pitch)/2 and the band-passed accelerometer thrust kf per
    band, relative to the reference, one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bands = ["raw", *EVIDENCE_BANDS]
    x = np.arange(len(bands))
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.6), dpi=dpi, sharey=True)
    colors = {"square": "C0", "random1": "C1", "random2": "C2", "multisine": "C3"}
    for name, c in zip(names, checks):
        color = next((v for k, v in colors.items() if name.startswith(k)), "C4")
        torque, thrust = [], []
        for b in bands:
            e = c.get("bands", {}).get(b, {})
            torque.append(0.5 * (e["roll_kf"]["kf"] + e["pitch_kf"]["kf"]) / reference_kf if e else np.nan)
            thrust.append(e["thrust_kf"]["kf"] / reference_kf if e and "thrust_kf" in e else np.nan)
        axes[0].plot(x, torque, "-o", color=color, ms=3, lw=1, alpha=0.8)
        axes[1].plot(x, thrust, "-o", color=color, ms=3, lw=1, alpha=0.8)
    for ax, title in zip(axes, ("gyro torque fit: (roll + pitch)/2", "accelerometer thrust fit (same band)")):
        ax.axhline(1.0, color="k", ls="--", lw=1)
        ax.set_xticks(x)
        ax.set_xticklabels([b.replace("Hz", " Hz") for b in bands], fontsize=8)
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
        ax.set_ylim(-0.1, 1.3)
    axes[0].set_ylabel("kf / independent kf")
    for k, v in colors.items():
        axes[1].plot([], [], color=v, label=k)
    axes[1].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    try:
        save_figure(fig, path)
    finally:
        plt.close(fig)
