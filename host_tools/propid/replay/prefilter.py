"""Pre-filters applied to a log before the replay (docs/real-data.md, "Matched pre-filter").

The matched pre-filter is a causal low-pass applied identically to the gyro and to the
rotor-speed-squared stream. The rate dynamics J dw/dt = B(kf, km) u are linear in
u = Omega^2 (up to the small gyroscopic term), so one LTI filter H on both sides keeps
J d(Hw)/dt = B(kf, km) (Hu) with the SAME coefficients, while removing the band in which
the torque model does not explain the measured angular acceleration. The filter is two
identical first-order sections in cascade (critically damped, 2nd order): its impulse
response is non-negative, so filtered Omega^2 stays >= 0 and can be pushed as the rotor
speed sqrt(H u). A high-pass part cannot be pushed (it makes u negative); removing slow
content needs a disturbance-torque state in the filter, which is why the high-pass here
(highpass_emulation_log) is a diagnostic only.
"""

from __future__ import annotations

import math

import numpy as np

from propid.errors import UserError
from propid.flightlog import FlightLog, Vehicle
from propid.realdata_checks import absurd_speed_limit, clean_rotor_speeds
from propid.signals import hold_gaps, measured_torque, median_dt, segment_starts, segments

CASCADE_3DB = math.sqrt(math.sqrt(2.0) - 1.0)  # -3 dB frequency of two equal 1st-order sections / their pole frequency
COHERENCE_THRESHOLD = 0.5
COHERENCE_WINDOW_S = 2.56


def lowpass_pole(cutoff_hz: float, rate_hz: float) -> float:
    """Pole a of each first-order section y[n] = a y[n-1] + (1 - a) x[n], chosen so that the
    cascade of two has its -3 dB point at cutoff_hz."""
    if not (cutoff_hz > 0 and rate_hz > 0):
        raise UserError(f"pre-filter cut-off {cutoff_hz} Hz at {rate_hz} Hz: both must be positive")
    pole_hz = cutoff_hz / CASCADE_3DB
    return math.exp(-2.0 * math.pi * pole_hz / rate_hz)


def matched_lowpass(x: np.ndarray, pole: float, starts: np.ndarray) -> np.ndarray:
    """Two first-order sections in cascade along axis 0, restarted (at the input value:
    no start-up transient) at every index in `starts`. Unit DC gain; the impulse response
    (1-a)^2 (n+1) a^n is non-negative."""
    out = np.empty_like(x, dtype=float)
    restart = np.zeros(x.shape[0], dtype=bool)
    restart[starts] = True
    restart[0] = True
    gain = 1.0 - pole
    s1 = s2 = x[0].astype(float)
    for n in range(x.shape[0]):
        if restart[n]:
            s1 = s2 = x[n].astype(float)
        s1 = pole * s1 + gain * x[n]
        s2 = pole * s2 + gain * s1
        out[n] = s2
    return out


def noise_gain(pole: float) -> float:
    """sum of h[n]^2 of the cascade: the variance ratio of white noise through it."""
    n = np.arange(int(20 / max(1e-9, 1.0 - pole)) + 50)
    h = (1.0 - pole) ** 2 * (n + 1) * pole**n
    return float(np.sum(h**2))


def torque_coherence(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Magnitude-squared coherence between the torque model's roll/pitch regressors
    (sum y_i Omega_i^2, sum -x_i Omega_i^2) and the measured torque J dw/dt + w x Jw, per
    frequency (Welch: Hann windows of COHERENCE_WINDOW_S, 50 % overlap, within the flying
    segments). Returns (frequencies, coherence averaged over roll and pitch). Lag-free and
    scale-free: it uses no coefficient value and no stream alignment."""
    dt = median_dt(log.t)
    nper = max(16, int(round(COHERENCE_WINDOW_S / dt)))
    speeds, _ = clean_rotor_speeds(log.rotor_speed, absurd_speed_limit(log.rotor_speed))
    u = speeds**2
    gyro = hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    rate_dot = np.gradient(gyro, log.t, axis=0)
    torque = measured_torque(gyro, rate_dot, inertia)
    pos = vehicle.positions
    regs = [(u * pos[:, 1]).sum(axis=1), (-u * pos[:, 0]).sum(axis=1)]
    window = np.hanning(nper)
    freqs = np.fft.rfftfreq(nper, dt)
    coherence = []
    for axis in range(2):
        sxx = syy = sxy = 0.0
        for a, b in segments(mask, nper):
            for s in range(a, b - nper + 1, nper // 2):
                x = regs[axis][s : s + nper]
                y = torque[s : s + nper, axis]
                fx = np.fft.rfft((x - x.mean()) * window)
                fy = np.fft.rfft((y - y.mean()) * window)
                sxx = sxx + np.abs(fx) ** 2
                syy = syy + np.abs(fy) ** 2
                sxy = sxy + np.conj(fx) * fy
        if np.isscalar(sxx):
            return freqs, np.full(freqs.shape, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            coherence.append(np.abs(sxy) ** 2 / (sxx * syy))
    return freqs, 0.5 * (coherence[0] + coherence[1])


COHERENCE_SMOOTH_HZ = 2.0


def coherence_cutoff(freqs: np.ndarray, coherence: np.ndarray, low_hz: float = 2.0,
                     threshold: float = COHERENCE_THRESHOLD) -> float | None:
    """The pre-filter cut-off rule: the coherence is smoothed by a moving average over
    COHERENCE_SMOOTH_HZ; from the best-explained frequency between low_hz and 4 x low_hz
    (robust to a dip at the low edge) upwards, the first frequency at which it falls below
    the threshold. None if it is below the threshold there (the torque model explains no
    band of this log)."""
    width = max(1, int(round(COHERENCE_SMOOTH_HZ / (freqs[1] - freqs[0]))) | 1)
    smooth = np.convolve(np.nan_to_num(coherence, nan=0.0), np.ones(width) / width, mode="same")
    lo, hi = int(np.searchsorted(freqs, low_hz)), int(np.searchsorted(freqs, 4.0 * low_hz))
    if lo >= freqs.size:
        return None
    start = lo + int(np.argmax(smooth[lo : max(hi, lo + 1)]))
    if smooth[start] < threshold:
        return None
    below = np.flatnonzero(smooth[start:] < threshold)
    return float(freqs[start + below[0]]) if below.size else float(freqs[-1])


def prefilter_log(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, cutoff: float | str,
                  inertia: np.ndarray) -> tuple[FlightLog, dict]:
    """The log as the filter sees it with the matched pre-filter: gyro -> H gyro, rotor speed ->
    sqrt(H Omega^2), same time stamps. Missing or absurd rotor speeds (and missing gyro
    samples) are held at the previous good value first: a recursive filter needs every
    sample, and holding is what the filter does with a rejected rotor sample anyway. The
    filter restarts at every contiguous replayed segment (no start-up transient)."""
    dt = median_dt(log.t)
    rate = 1.0 / dt
    info: dict = {"rule": "given"}
    if cutoff == "auto":
        freqs, coherence = torque_coherence(log, vehicle, mask, inertia)
        found = coherence_cutoff(freqs, coherence)
        info.update(rule=f"auto: from the best-explained frequency in 2-8 Hz upwards, the first frequency where the roll/pitch "
                         f"torque-model coherence (Welch, {COHERENCE_WINDOW_S} s windows, {COHERENCE_SMOOTH_HZ} Hz "
                         f"moving average) falls below {COHERENCE_THRESHOLD}",
                    coherence_hz=[float(f) for f in freqs[::4]], coherence=[float(c) for c in coherence[::4]])
        if found is None:
            info["note"] = "the torque model explains no band above 2 Hz of this log: no pre-filter applied"
            info["cutoff_hz"] = None
            return log, info
        cutoff = found
    cutoff = float(cutoff)
    if cutoff >= 0.45 * rate:
        info.update(cutoff_hz=cutoff, note="cut-off at or above 0.45 x the sample rate: no pre-filter applied")
        return log, info
    pole = lowpass_pole(cutoff, rate)
    limit = absurd_speed_limit(log.rotor_speed)
    bad_rotor = ~np.isfinite(log.rotor_speed) | (np.nan_to_num(log.rotor_speed, nan=0.0) > limit)
    bad_gyro = ~np.isfinite(log.gyro)
    speeds = hold_gaps(log.rotor_speed, bad_rotor)
    gyro = hold_gaps(log.gyro, bad_gyro)
    starts = segment_starts(mask, log.t, dt)  # a time gap restarts the filter too
    filtered_u = matched_lowpass(np.nan_to_num(speeds, nan=0.0) ** 2, pole, starts)
    filtered_gyro = matched_lowpass(np.nan_to_num(gyro, nan=0.0), pole, starts)
    out = FlightLog(t=log.t, gyro=filtered_gyro, rotor_speed=np.sqrt(np.maximum(filtered_u, 0.0)),
                    extra=log.extra, path=log.path)
    info.update(cutoff_hz=cutoff, pole=pole, noise_gain=noise_gain(pole),
                held_rotor_samples=int(np.sum(np.any(bad_rotor, axis=1) & mask)),
                held_gyro_samples=int(np.sum(np.any(bad_gyro, axis=1) & mask)),
                filter="two equal first-order low-pass sections in cascade (critically damped), "
                       "applied to gyro and to rotor speed squared")
    return out, info


def highpass_emulation_log(log: FlightLog, vehicle: Vehicle, mask: np.ndarray, cutoff_hz: float) -> tuple[FlightLog, dict]:
    """DIAGNOSTIC ONLY (not an estimator mode): what the filter would read if slow content,
    where unmodelled moments dominate, were removed, as a disturbance-torque state would.
    A high-pass of Omega^2 goes negative and cannot be pushed as a speed; instead every
    rotor gets u' = (u - L u) + U0 with the same offset U0 (large enough to keep u' > 0)
    and the gyro gets w - L w (L: the matched low-pass at cutoff_hz). For a vehicle whose
    rotor positions and yaw signs sum to zero, U0 adds no torque when the rotors' kf (and
    km) are equal, so the common kf is unchanged; unequal per-rotor kf would turn U0 into a
    large constant torque, so this mode pins the rotors to a common value: per-rotor numbers
    mean nothing here."""
    positions_sum = np.abs(vehicle.positions[:, :2].sum(axis=0)).max()
    arm = float(np.abs(vehicle.positions[:, :2]).max())
    if positions_sum > 1e-6 * max(arm, 1e-9) or abs(float(np.sum(vehicle.yaw_signs))) > 0:
        raise UserError("--diagnostic-highpass needs a symmetric vehicle (rotor x, y positions and yaw signs summing to 0)")
    dt = median_dt(log.t)
    pole = lowpass_pole(cutoff_hz, 1.0 / dt)
    limit = absurd_speed_limit(log.rotor_speed)
    bad_rotor = ~np.isfinite(log.rotor_speed) | (np.nan_to_num(log.rotor_speed, nan=0.0) > limit)
    speeds = hold_gaps(log.rotor_speed, bad_rotor)
    gyro = hold_gaps(log.gyro, ~np.isfinite(log.gyro))
    starts = segment_starts(mask, log.t, dt)
    u = np.nan_to_num(speeds, nan=0.0) ** 2
    u_high = u - matched_lowpass(u, pole, starts)
    gyro_high = np.nan_to_num(gyro, nan=0.0) - matched_lowpass(np.nan_to_num(gyro, nan=0.0), pole, starts)
    offset = max(float(np.mean(u[mask])), 1.05 * float(-u_high[mask].min()))
    out = FlightLog(t=log.t, gyro=gyro_high, rotor_speed=np.sqrt(np.maximum(u_high + offset, 0.0)),
                    extra=log.extra, path=log.path)
    return out, {"cutoff_hz": cutoff_hz, "offset_rotor_speed_sq": offset,
                 "held_rotor_samples": int(np.sum(np.any(bad_rotor, axis=1) & mask)),
                 "note": "diagnostic only: slow content removed by emulation; rotors pinned to a common kf"}

