"""Stream alignment = the `esc_delay` effect: how much the logged rotor speeds lag
(positive) or lead (negative) the gyro.

Rule (docs/gap.md): the torque base model (per-rotor kf, km) is fitted with the rotor
stream shifted by d on a grid from -MAX_LEAD_S to +MAX_LAG_S (step: one sample, at
most 2 ms; sub-sample by a parabola through the best three). Held-out evidence
(whitened_evidence): on whitened rows, as the effects are scored, each fold picks its own d
on its training blocks and is scored on its held-out blocks against d = 0 (the vehicle
file's esc_delay_s, if any, is already applied), by the effects' replication test. The same
cross-validation on the raw rows' 2 s blocks is kept for reference; with a single such block
nothing is held out there, and its interval is undefined (NaN).
All three torque axes; yaw with per-rotor km and the rotor-acceleration term J_r sum s_i
dOmega_i/dt (both shifted with the stream: a lag and rotor inertia look alike on yaw, so
they are fitted together). Rate damping (-D w) and the roll/pitch columns of rotor_gyroscopic,
rotor_drag, com_offset and aero_damping are fitted with every lag: on a narrow-band signal
these torques and a lag look alike, and the lag must not absorb them. By default those columns
are built once, from the logged (unshifted) rotor stream; with `nuisance_at` (--lag-nuisance
shifted, evaluated, not the default: docs/gap.md) they are built at each lag from the stream
shifted by it, as every column is after the alignment (three of the four are functions of the
rotor speeds).
A shift commutes with the band-pass, so the band-passed rotor regressors are shifted,
not refiltered.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from propid.gap import scoring, significance, whitening
from propid.gap.design import Design, responses, segment_rows
from propid.gap.prep import Flight

MAX_LAG_S = 0.08
MAX_LEAD_S = 0.05


def _grid(flights: list[Flight]) -> np.ndarray:
    rate = max(f.rate_hz for f in flights)
    step = min(1.0 / rate, 0.002)
    return np.arange(-MAX_LEAD_S, MAX_LAG_S + 0.5 * step, step)


def _shift_rows(f: Flight, x: np.ndarray, delay: float) -> np.ndarray:
    out = np.empty_like(x)
    for a, b in f.segs:
        tt = f.t[a:b]
        for k in range(x.shape[1]):
            out[a:b, k] = np.interp(tt + delay, tt, x[a:b, k])
    return out


def _nuisance_columns(flights: list[Flight], nuisance: list[dict], rows: list[np.ndarray]) -> dict:
    return {a: np.concatenate([f.filtered(n[a], response=True)[r] for f, n, r in zip(flights, nuisance, rows)])
            for a in ("roll", "pitch")}


def delay_designs(flights: list[Flight], positions: np.ndarray, signs: np.ndarray, grid: np.ndarray,
                  nuisance: list[dict] | None = None,
                  nuisance_at: Callable[[float], list[dict]] | None = None) -> list[Design]:
    """Per lag: roll/pitch per-rotor kf, yaw per-rotor km and the rotor-acceleration term
    (shifted with the rotor stream), rate damping on all three axes, and the nuisance
    effect columns on roll/pitch: `nuisance` (per flight, the same at every lag) or, when
    given, `nuisance_at(d)` (per flight, built from the rotor stream shifted by d)."""
    rows = [segment_rows(f) for f in flights]
    filtered_u = [f.filtered(f.speed**2, response=True) for f in flights]
    filtered_spin = [f.filtered((f.speed_dot @ signs)[:, None]) for f in flights]
    damping = np.concatenate([f.filtered(-f.gyro, response=True)[r] for f, r in zip(flights, rows)])
    n_extra = 0
    extra = {}
    if nuisance_at is not None:
        n_extra = nuisance_at(0.0)[0]["roll"].shape[1]
    elif nuisance:
        extra = _nuisance_columns(flights, nuisance, rows)
        n_extra = extra["roll"].shape[1]
    resp = [responses(f, None) for f in flights]
    ys = {a: np.concatenate([f.filtered(rr[a])[r] for f, rr, r in zip(flights, resp, rows)])
          for a in ("roll", "pitch", "yaw")}
    blocks, block_flight, offset = [], [], 0
    for fi, f in enumerate(flights):
        b_of_row = np.full(len(f.t), -1)
        for k, (s0, e0) in enumerate(f.blocks):
            b_of_row[s0:e0] = offset + k
        blocks.append(b_of_row[rows[fi]])
        block_flight += [fi] * len(f.blocks)
        offset += len(f.blocks)
    block = np.concatenate(blocks)
    time = np.concatenate([f.t[r] - f.t[0] for f, r in zip(flights, rows)])
    flight = np.concatenate([np.full(r.shape[0], fi) for fi, r in enumerate(rows)])
    designs = []
    scale = None
    for d in grid:
        u = np.concatenate([(_shift_rows(f, fu, d) if d != 0 else fu)[r] for f, fu, r in zip(flights, filtered_u, rows)])
        spin = np.concatenate([(_shift_rows(f, fs, d) if d != 0 else fs)[r]
                               for f, fs, r in zip(flights, filtered_spin, rows)])
        n, count = u.shape
        zu = np.zeros((n, count))
        z1 = np.zeros((n, 1))
        zx = np.zeros((n, n_extra))
        dmp = [np.column_stack([damping[:, k] if j == k else np.zeros(n) for j in range(3)]) for k in range(3)]
        if nuisance_at is not None and n_extra:
            extra = _nuisance_columns(flights, nuisance_at(float(d)), rows)
        x = {"roll": np.column_stack([u * positions[:, 1][None, :], zu, z1, dmp[0]] + ([extra["roll"]] if n_extra else [])),
             "pitch": np.column_stack([-u * positions[:, 0][None, :], zu, z1, dmp[1]] + ([extra["pitch"]] if n_extra else [])),
             "yaw": np.column_stack([zu, u * signs[None, :], spin, dmp[2]] + ([zx] if n_extra else []))}
        if scale is None:
            scale = np.sqrt(sum(v**2 for v in x.values()).mean(axis=0) / 3)
            scale[scale == 0] = 1
        x = {a: v / scale for a, v in x.items()}
        p = x["roll"].shape[1]
        designs.append(Design(axes=["roll", "pitch", "yaw"], names=[f"c_{k}" for k in range(p)],
                              groups={"base": list(range(p))}, y=ys, x=x, scale=scale, block=block,
                              flight=flight, block_flight=np.array(block_flight), time=time))
    return designs


def search(flights: list[Flight], positions: np.ndarray, signs: np.ndarray, progress=None,
           nuisance: list[dict] | None = None, evidence: bool = True,
           nuisance_at: Callable[[float], list[dict]] | None = None,
           block_folds: str = scoring.BLOCK_FOLDS) -> dict:
    """The lag (all-data fit) and, with `evidence`, its held-out evidence on whitened rows
    (whitened_evidence, `whitened`); `explained_fraction` / `ci` are the raw rows' own
    cross-validation (kept for reference). `nuisance_at`: delay_designs."""
    grid = _grid(flights)
    designs = delay_designs(flights, positions, signs, grid, nuisance, nuisance_at)
    grs = []
    for d in designs:
        gr = scoring.grams(d, block_folds=block_folds)
        grs.append(gr)
        if progress:
            progress()
    cols = list(range(len(designs[0].names)))
    weight = None
    zero = int(np.argmin(np.abs(grid)))
    # axis weights from the d = 0 fit
    all_blocks = np.arange(grs[zero].s.shape[0])
    theta0 = scoring.solve(grs[zero], cols, all_blocks)
    sse0 = scoring.block_sse(grs[zero], cols, theta0, all_blocks).sum(axis=0)
    weight = 1.0 / np.maximum(sse0 / max(grs[zero].count.sum(), 1), 1e-300)
    for gr in grs:
        gr.weight = weight
    folds = np.unique(grs[zero].fold)
    held_best = np.zeros_like(grs[zero].s)
    fold_delay = {}
    for k in folds:
        test = all_blocks[grs[zero].fold == k]
        train = all_blocks[grs[zero].fold != k]
        if train.size == 0:
            train = test
        train_sse = []
        for gr in grs:
            th = scoring.solve(gr, cols, train)
            train_sse.append(float((scoring.block_sse(gr, cols, th, train) * weight).sum()))
        best = int(np.argmin(train_sse))
        fold_delay[int(k)] = float(grid[best])
        th = scoring.solve(grs[best], cols, train)
        held_best[test] = scoring.block_sse(grs[best], cols, th, test)
    held_zero = scoring.cv_sse(grs[zero], cols)
    total = []
    for gr in grs:
        th = scoring.solve(gr, cols, all_blocks)
        total.append(float((scoring.block_sse(gr, cols, th, all_blocks) * weight).sum()))
    total = np.array(total)
    best = int(np.argmin(total))
    delay = float(grid[best])
    if 0 < best < len(grid) - 1:  # parabola through the best three
        y0, y1, y2 = total[best - 1: best + 2]
        denom = y0 - 2 * y1 + y2
        if denom > 0:
            delay += 0.5 * (y0 - y2) / denom * (grid[1] - grid[0])
    frac, ci = scoring.explained(held_zero, held_best, [0, 1, 2])
    if folds.size < 2:  # one block: each fold's lag was chosen on the block it is scored on, nothing is held out
        ci = [float("nan"), float("nan")]
    out = {"delay_s": delay, "grid_s": [float(grid[0]), float(grid[-1]), float(grid[1] - grid[0])],
           "explained_fraction": frac, "ci": ci, "fold_delays_s": fold_delay,
           "sse_curve": {"delay_s": grid.tolist(), "weighted_sse": (total / total[zero]).tolist()},
           "held_zero": held_zero, "held_best": held_best}
    if evidence:
        theta = scoring.solve(grs[best], cols, all_blocks)
        residual = {a: designs[best].y[a] - designs[best].x[a] @ theta for a in designs[best].axes}
        out["whitened"] = whitened_evidence(flights, designs, grid, residual, block_folds)
    return out


EVIDENCE_LEVEL = 0.025  # one-sided: the level of the raw rule's two-sided 95 % interval above 0


def whitened_evidence(flights: list[Flight], designs: list[Design], grid: np.ndarray, residual: dict,
                      block_folds: str = scoring.BLOCK_FOLDS) -> dict:
    """The lag's held-out evidence on whitened rows (generalised least squares, whitening.py),
    as the effects are scored: every lag's design whitened by the same filter per flight and
    axis, from the spectrum of the residual at the all-data best lag (the model with the lag
    in, so the lag's own signature is not whitened away); 1 s fold blocks cut into short test
    blocks; each fold picks its lag on its training blocks; the held-out improvement over
    d = 0 is the effects' replication test (significance.paired_test, one-sided, block
    weights)."""
    rates = [f.rate_hz for f in flights]
    bands = [(f.band.highpass_hz, f.band.lowpass_hz) for f in flights]
    zero = int(np.argmin(np.abs(grid)))
    filters = whitening.whitening_filters(designs[zero], residual, rates, bands)
    wd = [whitening.apply_filters(d, filters, rates) for d in designs]
    grs = [scoring.grams(d, block_folds=block_folds) for d in wd]
    cols = list(range(len(wd[0].names)))
    all_blocks = np.arange(grs[zero].s.shape[0])
    weight = scoring.axis_weights(wd[zero], cols)
    for gr in grs:
        gr.weight = weight
    # per partition of the folds (scoring.fold_partitions), the test on their mean
    shape = grs[zero].partitions.shape[:1] + grs[zero].s.shape
    held_zero, held_best, cross = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    fold_delay = {}
    block = wd[zero].block
    n_blocks = all_blocks.shape[0]
    for r in range(shape[0]):
        for test, train in scoring.folds(grs[zero], r):
            sse = [float((scoring.block_sse(gr, cols, scoring.solve(gr, cols, train), train) * weight).sum())
                   for gr in grs]
            k = int(np.argmin(sse))
            if r == 0:  # reported: the first partition's folds
                fold_delay[int(grs[zero].fold[test[0]])] = float(grid[k])
            th0 = scoring.solve(grs[zero], cols, train)
            th1 = scoring.solve(grs[k], cols, train)
            held_zero[r, test] = scoring.block_sse(grs[zero], cols, th0, test)
            held_best[r, test] = scoring.block_sse(grs[k], cols, th1, test)
            rows = np.isin(block, test)
            for ai, a in enumerate(wd[zero].axes):
                r0 = wd[zero].y[a][rows] - wd[zero].x[a][rows] @ th0
                r1 = wd[k].y[a][rows] - wd[k].x[a][rows] @ th1
                cross[r, :, ai] += np.bincount(block[rows], weights=r1 * (r0 - r1), minlength=n_blocks)
    axes = [0, 1, 2]
    groups = grs[zero].groups if grs[zero].groups is not None else [wd[zero].fold_group] * shape[0]
    weights = np.stack([significance.block_weights(h, grs[zero].count, g) for h, g in zip(held_best, groups)])
    test = significance.paired_test(held_zero, held_best, axes, cross, weights)
    if len(fold_delay) < 2:
        test = {**test, "ci": [float("nan"), float("nan")], "p_value": 1.0}
    # ci: the interval of the weighted statistic p tests (centred on held_out_weighted_fraction):
    # its lower edge is above 0 exactly when p < EVIDENCE_LEVEL
    return {"explained_fraction": test["value"], "held_out_weighted_fraction": test["weighted_value"],
            "ci": test["ci"], "p_value": test["p_value"], "fold_delays_s": fold_delay}
