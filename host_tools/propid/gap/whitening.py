"""Frequency-domain whitening of the regression (generalised least squares).

The residual of the base model is far from white: the measured torque J dw/dt is a
differentiated gyro, so its noise grows with frequency and dominates the top of the
band, while the unmodelled effects live mostly where the vehicle moves (below a few
Hz). Ordinary least squares and a held-out score on such a residual weigh every
frequency alike: an effect that is many standard errors strong at 1 Hz explains a
fraction of a percent of a residual dominated by 20 Hz noise, and the residual's
correlation makes time blocks less independent than they look.

Rule (docs/gap.md, "Whitening"): per flight and axis, the power spectrum S(f) of the
base model's residual (Welch, WINDOW_S windows, smoothed over a third of an octave);
the response and every regressor column of that axis are filtered (zero phase, per
flying segment) by W(f) = 1/sqrt(S(f)), held constant outside the band's full-gain
region (where the band-pass, not the data, shaped the spectrum). The fit on the
whitened rows is the generalised least-squares fit for that noise spectrum; its
residual is close to white, so held-out sums of squares per short block are close to
independent and explained fractions measure signal over noise.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from propid.gap.design import Design

WINDOW_S = 2.0
SCORE_BLOCK_S = 1.0  # fold blocks on the whitened rows (each held out whole)
TEST_BLOCK_TAUS = 10.0  # test blocks: this many autocorrelation times of the whitened residual
SMOOTH_OCTAVES = 1.0 / 3.0


def segment_bounds(design: Design) -> list[tuple[int, int]]:
    """Contiguous runs of rows of one flying segment (flight change or a time gap)."""
    n = design.time.shape[0]
    if n == 0:
        return []
    dt = np.diff(design.time)
    new_flight = np.diff(design.flight) != 0
    step = np.median(dt[(dt > 0) & ~new_flight]) if np.any((dt > 0) & ~new_flight) else 1.0
    cut = new_flight | (dt <= 0) | (dt > 1.5 * step)
    starts = np.concatenate([[0], np.flatnonzero(cut) + 1])
    stops = np.concatenate([starts[1:], [n]])
    return list(zip(starts.tolist(), stops.tolist()))


def _welch(x: np.ndarray, nper: int) -> np.ndarray:
    """Mean periodogram of half-overlapping Hann windows (length nper) of x."""
    hop = max(nper // 2, 1)
    win = np.hanning(nper)
    acc = np.zeros(nper // 2 + 1)
    count = 0
    for s in range(0, x.shape[0] - nper + 1, hop):
        seg = x[s:s + nper] - x[s:s + nper].mean()
        acc += np.abs(np.fft.rfft(seg * win)) ** 2
        count += 1
    return acc / max(count, 1)


def _smooth_log(freqs: np.ndarray, psd: np.ndarray) -> np.ndarray:
    out = np.empty_like(psd)
    for k, f in enumerate(freqs):
        if f <= 0:
            out[k] = psd[k]
            continue
        lo, hi = f * 2 ** (-SMOOTH_OCTAVES / 2), f * 2 ** (SMOOTH_OCTAVES / 2)
        sel = (freqs >= lo) & (freqs <= hi)
        out[k] = psd[sel].mean()
    return out


def whitening_gain(residual_parts: list[np.ndarray], rate_hz: float, band: tuple[float | None, float]
                   ) -> tuple[np.ndarray, np.ndarray] | None:
    """(freqs, W) for one flight and axis from its residual segments, or None when the
    segments are too short for a spectrum."""
    nper = int(round(WINDOW_S * rate_hz))
    parts = [p for p in residual_parts if p.shape[0] >= nper]
    if not parts or nper < 8:
        return None
    weights = np.array([p.shape[0] for p in parts], dtype=float)
    psd = sum(w * _welch(p, nper) for w, p in zip(weights, parts)) / weights.sum()
    freqs = np.fft.rfftfreq(nper, d=1.0 / rate_hz)
    psd = _smooth_log(freqs, psd)
    lo_edge = 1.25 * band[0] if band[0] else freqs[1]
    hi_edge = 0.75 * band[1]
    # A bin on an edge (2.5 Hz = 1.25 x a 2 Hz high-pass, on the 0.5 Hz grid of 2 s windows) is inside
    # whatever the last bit of the log's rate: a median step of 0.0100000001 s (a clock origin at 1e6 s)
    # dropped it and moved every effect's held-out fraction by up to 0.008.
    tie = 1e-6 * freqs[1]
    inside = (freqs >= lo_edge - tie) & (freqs <= hi_edge + tie)
    if inside.sum() < 2 or not np.all(psd[inside] > 0):
        return None
    f_in, s_in = freqs[inside], psd[inside]
    s = np.interp(freqs, f_in, s_in)  # held constant outside the full-gain region
    return freqs, 1.0 / np.sqrt(s)


def _apply(x: np.ndarray, rate_hz: float, freqs: np.ndarray, gain: np.ndarray) -> np.ndarray:
    n = x.shape[0]
    xp = np.concatenate([x[::-1], x, x[::-1]], axis=0)  # mirror padding, as the band-pass
    f = np.fft.rfftfreq(xp.shape[0], d=1.0 / rate_hz)
    g = np.interp(f, freqs, gain)
    spec = np.fft.rfft(xp, axis=0) * (g[:, None] if xp.ndim == 2 else g)
    return np.fft.irfft(spec, n=xp.shape[0], axis=0)[n:2 * n]


def whiten(design: Design, residual: dict[str, np.ndarray], rates: list[float],
           bands: list[tuple[float | None, float]]) -> tuple[Design, dict]:
    """The design with every axis's response and columns whitened per flight by the
    spectrum of `residual` (the base model's residual on the same rows). `rates` and
    `bands` (high-pass, low-pass) per flight; the thrust axis is low-passed only. Axes or
    flights without a usable spectrum are left as they are."""
    filters = whitening_filters(design, residual, rates, bands)
    return apply_filters(design, filters, rates), filters["info"]


def whitening_filters(design: Design, residual: dict[str, np.ndarray], rates: list[float],
                      bands: list[tuple[float | None, float]]) -> dict:
    """The filters whiten() applies: per axis and flight (freqs, gain) from the spectrum of
    `residual`, scaled to a unit-variance whitened residual, and the test-block length. Several
    designs on the same rows (alignment.py: one per rotor-stream lag) share them."""
    bounds = segment_bounds(design)
    seg_flight = [int(design.flight[a]) for a, _ in bounds]
    gains, info, taus = {}, {}, []
    for a in design.axes:
        for fi in sorted(set(seg_flight)):
            segs = [(s, e) for (s, e), f in zip(bounds, seg_flight) if f == fi]
            band = (None, bands[fi][1]) if a == "thrust" else bands[fi]
            gain = whitening_gain([residual[a][s:e] for s, e in segs], rates[fi], band)
            if gain is None:
                continue
            freqs, w = gain
            # scaled to a unit-variance whitened residual: flights then weigh by their noise (GLS)
            white = np.concatenate([_apply(residual[a][s:e], rates[fi], freqs, w) for s, e in segs])
            w = w / max(float(np.sqrt(np.mean(white**2))), 1e-300)
            taus += [autocorrelation_time(_apply(residual[a][s:e], rates[fi], freqs, w)) for s, e in segs]
            gains[(a, fi)] = (freqs, w)
            info.setdefault(a, {})[fi] = {"freqs_hz": freqs.tolist(), "gain": w.tolist()}
    tau = max(taus) if taus else 1.0
    rows = max(int(math.ceil(TEST_BLOCK_TAUS * tau)), 2)
    info["test_block_rows"] = rows
    info["autocorrelation_time_rows"] = tau
    return {"gains": gains, "test_block_rows": rows, "info": info}


def apply_filters(design: Design, filters: dict, rates: list[float]) -> Design:
    """whiten() with given filters (whitening_filters): every axis's response and columns
    filtered per flying segment, the rows cut into 1 s fold blocks and short test blocks."""
    bounds = segment_bounds(design)
    seg_flight = [int(design.flight[a]) for a, _ in bounds]
    x = {a: np.array(v, copy=True) for a, v in design.x.items()}
    y = {a: np.array(v, copy=True) for a, v in design.y.items()}
    for (a, fi), (freqs, w) in filters["gains"].items():
        live = np.flatnonzero(np.any(design.x[a] != 0, axis=0))  # an all-zero column stays zero
        for (s, e), f in zip(bounds, seg_flight):
            if f != fi:
                continue
            y[a][s:e] = _apply(design.y[a][s:e], rates[fi], freqs, w)
            x[a][s:e] = 0.0
            if live.size:
                x[a][s:e, live] = _apply(design.x[a][s:e, live], rates[fi], freqs, w)
    block, block_flight = split_blocks(design, SCORE_BLOCK_S)
    test_block, test_flight, parent = split_rows(block, block_flight, filters["test_block_rows"])
    return replace(design, x=x, y=y, block=test_block, block_flight=test_flight, fold_group=parent)


def autocorrelation_time(r: np.ndarray) -> float:
    """Integrated autocorrelation time [rows] of r: 1 + 2 sum of its autocorrelations up to
    the first lag where it is no longer positive (the initial positive sequence)."""
    n = r.shape[0]
    if n < 4:
        return 1.0
    u = r - r.mean()
    spec = np.fft.rfft(u, n=2 * n)
    acf = np.fft.irfft(np.abs(spec) ** 2)[:n]
    if acf[0] <= 0:
        return 1.0
    rho = acf / acf[0]
    tau = 1.0
    for k in range(1, n // 2):
        if rho[k] <= 0:
            break
        tau += 2.0 * rho[k]
    return float(tau)


def split_rows(block: np.ndarray, block_flight: np.ndarray, rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut every block into consecutive pieces of about `rows` rows (test blocks); returns
    the piece of every row, the flight and the parent block of every piece."""
    new_block = np.empty_like(block)
    flights, parents = [], []
    nb = 0
    for b in range(block_flight.shape[0]):
        idx = np.flatnonzero(block == b)
        if idx.size == 0:
            continue
        pieces = max(int(round(idx.size / rows)), 1)
        for part in np.array_split(idx, pieces):
            new_block[part] = nb
            flights.append(int(block_flight[b]))
            parents.append(b)
            nb += 1
    return new_block, np.array(flights, dtype=int), np.array(parents, dtype=int)


def split_blocks(design: Design, length_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Cut every time block into pieces of about `length_s` (whitened residuals are close
    to independent beyond a few samples, so shorter blocks give the bootstrap more of them)."""
    new_block = np.empty_like(design.block)
    block_flight = []
    nb = 0
    for b in range(design.n_blocks):
        rows = np.flatnonzero(design.block == b)
        if rows.size == 0:
            continue
        duration = float(design.time[rows[-1]] - design.time[rows[0]])
        pieces = max(int(round(duration / length_s)), 1)
        for part in np.array_split(rows, pieces):
            new_block[part] = nb
            block_flight.append(int(design.block_flight[b]))
            nb += 1
    return new_block, np.array(block_flight, dtype=int)
