"""The per-log rule for the thrust-torque scale's random walk (`--torque-scale-walk auto`,
docs/real-data.md; the state: docs/math.md §9).

Rule (fixed before it was run on any log; it uses the vehicle file's geometry, inertia and
nominal kf as units, never a reference value):

- the roll and pitch torque the filter's step measures, J (w[k] - w[k-1]) / dt + w x Jw, and
  the model's roll and pitch torque at the nominal kf, sum_i y_i kf_nom_i u_i and
  -sum_i x_i kf_nom_i u_i (u = Omega^2, the input rule and the telemetry delay of the replay),
  both band-passed to 2-10 Hz per flying segment (the band where the torque model holds
  best; slow moments and high-frequency loss out);
- consecutive, non-overlapping windows of WINDOW_S inside each segment; in each window the
  torque gain g_w = sum(model . measured) / sum(model . model) over roll and pitch together:
  the product scale x kf_rel the gyro sees there, in the units of the scale state;
- for a random walk of rate q seen through window means, adjacent means differ with variance
  (2/3) q^2 W, so q = sqrt(mean((g_w+1 - g_w)^2) / (2 W / 3)) over the adjacent pairs of
  every segment. The windows' own estimation noise adds to the differences, so q errs high
  (the scale then follows more noise, not less of the change);
- fewer than MIN_PAIRS pairs: 0 (a constant scale).
"""

from __future__ import annotations

import numpy as np

from propid.flightlog import FlightLog, Vehicle
from propid.realdata_checks import absurd_speed_limit, bandpass, clean_rotor_speeds
from propid.signals import hold_gaps, measured_torque, median_dt, segments

WINDOW_S = 4.0
BAND_HZ = (2.0, 10.0)
MIN_PAIRS = 3
MAX_WALK = 10.0  # the firmware's bound on torque_scale_walk


def window_gains(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, lag: int, trapezoid: bool,
                 window_s: float = WINDOW_S) -> list[np.ndarray]:
    """Per flying segment, the torque gain of each window (model at the nominal kf = 1)."""
    dt = median_dt(log.t)
    rate = 1.0 / dt
    if BAND_HZ[1] >= 0.45 * rate or vehicle.inertia is None or vehicle.kf_nominal is None:
        return []
    steps = np.diff(log.t)
    uniform = np.ones(len(log), dtype=bool)
    uniform[1:] &= np.abs(steps - dt) < 0.5 * dt
    width = int(round(window_s * rate))
    segs = segments(mask & uniform, 2 * width)
    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    gyro = hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    step_rate = np.zeros_like(gyro)
    step_rate[1:] = (gyro[1:] - gyro[:-1]) / dt
    torque = measured_torque(gyro, step_rate, np.asarray(vehicle.inertia, dtype=float))[:, :2]
    u = speeds ** 2 * np.asarray(vehicle.kf_nominal, dtype=float)[None, :]
    if trapezoid:
        u = np.vstack([u[:1], 0.5 * (u[1:] + u[:-1])])
    pos = vehicle.positions
    model = np.column_stack([(u * pos[:, 1]).sum(axis=1), (-u * pos[:, 0]).sum(axis=1)])
    gains = []
    for a, b in segs:
        a = max(a, 1)  # the first row of a segment has no step
        measured = bandpass(torque[a:b], rate, *BAND_HZ)
        modelled = bandpass(model[a:b], rate, *BAND_HZ)
        n = measured.shape[0]
        lo, hi = max(0, -lag), min(n, n - lag)  # measured[k + lag] against modelled[k]
        if hi - lo < 2 * width:
            continue
        y, x = measured[lo + lag:hi + lag], modelled[lo:hi]
        count = (hi - lo) // width
        seg_gains = []
        for w in range(count):
            xs, ys = x[w * width:(w + 1) * width], y[w * width:(w + 1) * width]
            energy = float(np.sum(xs * xs))
            seg_gains.append(float(np.sum(xs * ys)) / energy if energy > 0 else np.nan)
        gains.append(np.asarray(seg_gains))
    return gains


def estimate_scale_walk(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, lag: int, trapezoid: bool) -> dict:
    """torque_scale_walk [1/sqrt(s)] by the rule above, with what it was measured on."""
    gains = window_gains(log, vehicle, mask, lag, trapezoid)
    diffs = np.concatenate([np.diff(g) for g in gains]) if gains else np.zeros(0)
    diffs = diffs[np.isfinite(diffs)]
    every = np.concatenate(gains) if gains else np.zeros(0)
    every = every[np.isfinite(every)]
    info = {"window_s": WINDOW_S, "band_hz": list(BAND_HZ), "windows": int(every.size), "pairs": int(diffs.size),
            "gain_mean": float(np.mean(every)) if every.size else float("nan"),
            "gain_std": float(np.std(every)) if every.size else float("nan")}
    if diffs.size < MIN_PAIRS:
        info["walk"] = 0.0
        info["rule"] = f"fewer than {MIN_PAIRS} adjacent windows: constant scale"
        return info
    walk = float(np.sqrt(np.mean(diffs ** 2) / (2.0 * WINDOW_S / 3.0)))
    info["walk"] = min(walk, MAX_WALK)
    info["rule"] = ("sqrt(mean squared change of the 2-10 Hz torque gain between adjacent "
                    f"{WINDOW_S:g} s windows / (2 W / 3))")
    return info
