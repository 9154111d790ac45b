"""What bounds the shrink: the share of the measured torque that no linear time-invariant model
of the logged input channels can predict (1 - multiple coherence), per torque axis, in the band.

The measured torque J dw/dt + w x Jw is a differentiated gyro. Any model the library could add
that is driven by the logs' other channels (rotor speeds squared, rotor accelerations, motor
commands, accelerometer, body velocity, whichever are present; the gyro and anything derived from
it are left out, as they are the response) is, at best, a linear filter of those channels. The
multiple coherence gamma^2(f) of the torque with the channels is the share of its power at f such
a filter can explain; sum_f S_tau (1 - gamma^2) over the band is what is left by the best one.
Spectra by Welch (Hann windows of WINDOW_S rounded up to a power of two samples, half overlap,
inside the flying segments), pooled over the logs and solved per frequency on the same data: an
optimistic (in-sample) bound; the estimate's own upward bias is about channels / windows, which is
reported. `max_shrink` = 1 - that floor over the base model's held-out residual: no model of these
channels can shrink the residual RMS more.
"""

from __future__ import annotations

import numpy as np

from propid.gap.design import segment_rows
from propid.gap.prep import Flight

WINDOW_S = 1.28
AXES = ("roll", "pitch", "yaw")


def input_channels(f: Flight) -> np.ndarray:
    """The logs' non-gyro channels (n, p): Omega_i^2, dOmega_i/dt, and cmd_i, acc, body velocity when logged."""
    cols = [f.speed**2, f.speed_dot]
    for extra in (f.cmd, f.acc, f.body_velocity):
        if extra is not None and np.all(np.isfinite(extra)):
            cols.append(extra)
    return np.column_stack(cols)


def _window(rate_hz: float) -> int:
    return int(2 ** np.ceil(np.log2(max(WINDOW_S * rate_hz, 16))))


def unpredictable_share(flights: list[Flight], rotor_only: bool = False) -> dict | None:
    """Per axis, sqrt(sum over the band of S_tau (1 - gamma^2) / sum of S_tau): the RMS share of the
    band's torque that no LTI model of the channels predicts. None when there are too few windows
    (fewer than 5 per channel) or the logs differ in rate."""
    rates = {round(f.rate_hz, 6) for f in flights}
    if len(rates) != 1:
        return None
    rate = flights[0].rate_hz
    n = _window(rate)
    taper = np.hanning(n)
    freqs = np.fft.rfftfreq(n, 1.0 / rate)
    lo = max(f.band.highpass_hz for f in flights)
    hi = min(f.band.lowpass_hz for f in flights)
    in_band = (freqs >= lo) & (freqs <= hi)
    p = None
    sxx = sxy = syy = None
    windows = 0
    for f in flights:
        x_all = input_channels(f)
        if rotor_only:
            x_all = x_all[:, :f.speed.shape[1]]
        if p is None:
            p = x_all.shape[1]
            sxx = np.zeros((in_band.sum(), p, p), complex)
            sxy = np.zeros((3, in_band.sum(), p), complex)
            syy = np.zeros((3, in_band.sum()))
        elif x_all.shape[1] != p:
            return None
        for a, b in f.segs:
            for s in range(a, b - n + 1, n // 2):
                x = x_all[s:s + n] - x_all[s:s + n].mean(axis=0)
                xf = np.fft.rfft(x * taper[:, None], axis=0)[in_band]
                y = f.torque[s:s + n] - f.torque[s:s + n].mean(axis=0)
                yf = np.fft.rfft(y * taper[:, None], axis=0)[in_band]
                sxx += np.einsum("fi,fj->fij", np.conj(xf), xf)
                sxy += np.conj(xf)[None, :, :] * yf.T[:, :, None]
                syy += (np.abs(yf) ** 2).T
                windows += 1
    if p is None or windows < 5 * p or not in_band.any():
        return None
    out = {}
    ridge = 1e-12 * np.eye(p)
    for k, axis in enumerate(AXES):
        left = 0.0
        for j in range(in_band.sum()):
            a = sxx[j] + ridge * np.trace(sxx[j]).real / p
            explained = float(np.real(np.conj(sxy[k, j]) @ np.linalg.solve(a, sxy[k, j])))
            left += max(syy[k, j] - explained, 0.0)
        out[axis] = float(np.sqrt(left / syy[k].sum())) if syy[k].sum() > 0 else float("nan")
    out["channels"] = int(p)
    out["windows"] = int(windows)
    return out


def shrink_bound(flights: list[Flight], shrink: dict) -> dict:
    """The floor any LTI model of the channels leaves and the most it could shrink each axis's
    held-out residual (`shrink[axis]["rms_before"]`, the base model's on the same logs)."""
    every = unpredictable_share(flights)
    rotors = unpredictable_share(flights, rotor_only=True)
    if every is None:
        return {"computed": False, "why": "too few spectral windows for the channels, or logs of different rates"}
    out = {"computed": True, "channels": every["channels"], "windows": every["windows"],
           "coherence_bias": every["channels"] / every["windows"],
           "rule": "1 - multiple coherence of the measured torque with the non-gyro channels (Welch, pooled, "
                   "in-sample per frequency: optimistic), RMS share of the band's torque; max_shrink = 1 - "
                   "floor / the base model's held-out residual (gap/coherence.py)"}
    for k, axis in enumerate(AXES):
        response = np.sqrt(np.mean(np.concatenate([f.filtered(f.torque[:, k])[segment_rows(f)] for f in flights]) ** 2))
        entry = {"unpredictable_share": every[axis], "rotor_streams_only_share": rotors[axis] if rotors else None,
                 "response_rms": float(response)}
        before = shrink.get(axis, {}).get("rms_before")
        if before and response > 0:
            entry["base_residual_share"] = float(before / response)
            entry["max_shrink"] = float(1.0 - every[axis] * response / before)
        out[axis] = entry
    return out
