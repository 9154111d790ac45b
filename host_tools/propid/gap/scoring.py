"""Cross-validated scoring: least squares on training blocks, residual on held-out
blocks.

Rules (docs/gap.md, "Scoring"):
- folds: with 3 or more flights, one flight each (leave one flight out: no partition of the
  flights into groups, so neither the order of the logs nor a grouping decides which flights are
  held out together); otherwise the fold blocks (Design.fold_group, 1 s on the whitened rows),
  block index mod 5 (blocks numbered in the canonical log order of log_order.py);
- each axis is weighted by 1/sigma_a^2, sigma_a the base model's residual RMS on it
  (so torque [N m] and thrust [N] rows count alike);
- an effect's explained fraction = mean over its axes of 1 - SSE_with / SSE_without,
  both summed over held-out blocks (every block held out exactly once); the same mean over
  all modelled axes ranks effects against each other; `per_axis` gives it by axis;
- its interval and significance: significance.py (a paired test over short held-out
  blocks with a Newey-West variance for the interval; a Wald test on all whitened rows,
  Holm over the candidates of a selection step, for significance); the block-bootstrap
  interval below is kept for the stream alignment;
- effect size: RMS of what the effect adds to the fit (all data, beyond the current
  model) over the response's variation, largest over its axes;
- the rows are whitened first (whitening.py: generalised least squares for the residual's
  noise spectrum); folds keep 1 s blocks together, the test blocks are ten autocorrelation
  times of the whitened residual long; `excitation_folds` (option, not the default) splits a
  1 s block that holds more than a fold's share of an effect's regressor energy over the folds
  for that effect's replication;
- significant: physical sign (selection.physical_sign) AND fit inside its physical
  plausibility range (selection.implausible, effects.py bounds) AND held-out fraction > 0
  AND the Wald test rejected by Holm at 5 % family-wise AND, for the effects whose
  evidence is a torque scale against the accelerometer kf (inertia_error, gyro_scale,
  thrust_nonlinearity), effect size >= MIN_SCALE_EFFECT_SIZE (3 %): a MEMS
  accelerometer's zero-g offset (~20 mg) moves that reference by ~2 %, so a smaller
  scale is not evidence of the effect.
Everything runs on per-block Gram matrices, so a model (any column subset) costs a
few small solves, whatever the log length.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from propid.gap.design import Design

MIN_SCALE_EFFECT_SIZE = 0.03  # effects seen as a torque-vs-accelerometer scale (zero-g offset ~2 % of g)
FOLDS = 5  # block folds with one or two flights (three or more: one fold per flight)
BOOTSTRAP = 300
BOOTSTRAP_CI = 4000  # resamples for the held-out intervals (their tails are read at 0.05 / candidates)
RIDGE = 1e-9


@dataclass
class Grams:
    axes: list[str]
    g: np.ndarray  # (B, A, P, P)
    h: np.ndarray  # (B, A, P)
    s: np.ndarray  # (B, A)
    m: np.ndarray  # (B, A) sum of the response
    count: np.ndarray  # (B,) rows per block
    weight: np.ndarray  # (A,)
    fold: np.ndarray  # (B,)


def grams(design: Design, weight: np.ndarray | None = None) -> Grams:
    axes = design.axes
    nb = design.n_blocks
    p = len(design.names)
    g = np.zeros((nb, len(axes), p, p))
    h = np.zeros((nb, len(axes), p))
    s = np.zeros((nb, len(axes)))
    m = np.zeros((nb, len(axes)))
    order = np.argsort(design.block, kind="stable")
    bounds = np.searchsorted(design.block[order], np.arange(nb + 1))
    count = np.diff(bounds)
    for k, a in enumerate(axes):
        x = design.x[a][order]
        y = design.y[a][order]
        for b in range(nb):
            lo, hi = bounds[b], bounds[b + 1]
            if hi <= lo:
                continue
            xb = x[lo:hi]
            g[b, k] = xb.T @ xb
            h[b, k] = xb.T @ y[lo:hi]
            s[b, k] = y[lo:hi] @ y[lo:hi]
            m[b, k] = y[lo:hi].sum()
    flights = design.block_flight
    n_flights = int(flights.max()) + 1 if flights.size else 1
    group = np.arange(nb) if design.fold_group is None else design.fold_group
    fold = flights.copy() if n_flights >= 3 else group % FOLDS
    w = np.ones(len(axes)) if weight is None else weight
    return Grams(axes, g, h, s, m, count, w, fold)


# the held-out replication's folds: "time" (the 1 s blocks, index mod FOLDS: the default) or
# "excitation" (a 1 s block carrying more than a fold's share of the effect's excitation split over
# the folds; evaluated, not the default: docs/gap.md, SITL accuracy "Folds balanced by excitation")
REPLICATION_FOLDS = ("time", "excitation")


def excitation_share(gr: Grams, current: list[int], effect_cols: list[int], group: np.ndarray) -> np.ndarray:
    """(G,) share of the effect's excitation in each fold group: per column, its energy per block
    after the current model's columns are regressed out (the all-block fit with the axis weights,
    as `solve`), over its total; the mean over the columns, summed over each group's blocks.
    Regressors only: no response enters."""
    cur, eff = list(current), list(effect_cols)
    g_all = np.einsum("a,bapq->pq", gr.weight, gr.g)
    if cur:
        a = g_all[np.ix_(cur, cur)]
        ridge = RIDGE * max(np.trace(a) / len(cur), 1e-300)
        beta = np.linalg.solve(a + ridge * np.eye(len(cur)), g_all[np.ix_(cur, eff)])  # (C, E)
    else:
        beta = np.zeros((0, len(eff)))
    g_ee = np.einsum("bajj->baj", gr.g[:, :, eff][:, :, :, eff])
    g_ce = gr.g[:, :, cur][:, :, :, eff]  # (B, A, C, E)
    g_cc = gr.g[:, :, cur][:, :, :, cur]
    energy = (g_ee - 2.0 * np.einsum("bace,ce->bae", g_ce, beta)
              + np.einsum("ce,bacd,de->bae", beta, g_cc, beta))
    energy = np.einsum("a,bae->be", gr.weight, np.maximum(energy, 0.0))  # (B, E)
    total = energy.sum(axis=0)
    ok = total > 0
    if not np.any(ok):
        return np.zeros(int(group.max()) + 1 if group.size else 0)
    per_block = (energy[:, ok] / total[ok]).mean(axis=1)
    return np.bincount(group, weights=per_block, minlength=int(group.max()) + 1)


def excitation_folds(gr: Grams, current: list[int], effect_cols: list[int], group: np.ndarray | None) -> np.ndarray:
    """(B,) folds for an effect's held-out replication, balanced by its excitation: the time folds
    (group index mod FOLDS), except that a fold group carrying more than 1/FOLDS of the effect's
    excitation (excitation_share: e.g. the start transient) has its blocks (time order) dealt to the
    folds in turn, so no fold's fit loses more than about a fold's share of what determines the
    effect. For the block folds only (one or two flights; leave-one-flight-out folds stay)."""
    if group is None:
        group = np.arange(gr.s.shape[0])
    share = excitation_share(gr, current, effect_cols, group)
    fold = gr.fold.copy()
    for g in np.flatnonzero(share > 1.0 / FOLDS):
        members = np.flatnonzero(group == g)
        fold[members] = (g + np.arange(members.size)) % FOLDS
    return fold


def solve(gr: Grams, cols: list[int], blocks: np.ndarray) -> np.ndarray:
    """Weighted LS coefficients (scaled columns) on the given blocks."""
    idx = np.ix_(cols, cols)
    a = np.einsum("a,bapq->pq", gr.weight, gr.g[blocks][:, :, cols][:, :, :, cols]) if len(blocks) else None
    if a is None:
        return np.zeros(len(cols))
    rhs = np.einsum("a,bap->p", gr.weight, gr.h[blocks][:, :, cols])
    ridge = RIDGE * max(np.trace(a) / max(len(cols), 1), 1e-300)
    del idx
    return np.linalg.solve(a + ridge * np.eye(len(cols)), rhs)


def block_sse(gr: Grams, cols: list[int], theta: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """(len(blocks), A) residual sum of squares of the model theta on those blocks."""
    g = gr.g[blocks][:, :, cols][:, :, :, cols]
    h = gr.h[blocks][:, :, cols]
    return gr.s[blocks] - 2.0 * h @ theta + np.einsum("bapq,p,q->ba", g, theta, theta)


def folds(gr: Grams):
    """(test, train) block indices per cross-validation fold (a single fold trains on itself)."""
    all_blocks = np.arange(gr.s.shape[0])
    for k in np.unique(gr.fold):
        test = all_blocks[gr.fold == k]
        train = all_blocks[gr.fold != k]
        yield test, (test if train.size == 0 else train)


def cv_sse(gr: Grams, cols: list[int]) -> np.ndarray:
    """(B, A) held-out SSE: each block predicted by the fit on the other folds."""
    out = np.zeros_like(gr.s)
    for test, train in folds(gr):
        theta = solve(gr, cols, train)
        out[test] = block_sse(gr, cols, theta, test)
    return out


def cv_cross(gr: Grams, without: list[int], with_: list[int]) -> np.ndarray:
    """(B, A) held-out sum over each block's rows of r_with * (r_without - r_with): the
    with-model's held-out residual times what adding the columns changed in the prediction
    (each block predicted by the fits on the other folds). `without` must be a prefix of
    `with_`. The noise part of the held-out improvement is twice this (significance.py)."""
    out = np.zeros_like(gr.s)
    for test, train in folds(gr):
        t1 = solve(gr, with_, train)
        t0 = np.zeros_like(t1)
        t0[:len(without)] = solve(gr, without, train)
        d = t1 - t0
        g = gr.g[test][:, :, with_][:, :, :, with_]
        h = gr.h[test][:, :, with_]
        out[test] = h @ d - np.einsum("bapq,p,q->ba", g, t1, d)
    return out


def _fractions(without: np.ndarray, with_: np.ndarray) -> np.ndarray:
    """Rows of per-axis sums -> mean over axes of 1 - with/without (axes with 0 skipped)."""
    ok = without > 0
    ratio = np.where(ok, 1.0 - with_ / np.where(ok, without, 1.0), 0.0)
    return ratio.sum(axis=-1) / np.maximum(ok.sum(axis=-1), 1)


@functools.lru_cache(maxsize=4)
def _resample_counts(nb: int, seed: int) -> np.ndarray:
    """(BOOTSTRAP_CI, nb) how often each block is drawn in each resample."""
    rng = np.random.default_rng(seed)
    draws = rng.integers(0, nb, (BOOTSTRAP_CI, nb))
    counts = np.zeros((BOOTSTRAP_CI, nb))
    np.add.at(counts, (np.repeat(np.arange(BOOTSTRAP_CI), nb), draws.ravel()), 1.0)
    counts.flags.writeable = False  # cached: shared by every call with this block count and seed
    return counts


def explained(sse_without: np.ndarray, sse_with: np.ndarray, axis_idx: list[int],
              bootstrap: bool = True, seed: int = 12345, level: float = 0.05) -> tuple[float, list[float]]:
    """Explained fraction (mean over the given axes of 1 - SSE_with/SSE_without) and its
    two-sided (1 - level) block-bootstrap interval (None without bootstrap). `level` below
    0.05 for a family of candidates tested at once (Bonferroni: 0.05 / candidates)."""
    a = sse_without[:, axis_idx]
    b = sse_with[:, axis_idx]
    value = float(_fractions(a.sum(axis=0), b.sum(axis=0)))
    if not bootstrap:
        return value, None
    counts = _resample_counts(a.shape[0], seed)
    boot = _fractions(counts @ a, counts @ b)
    return value, [float(np.percentile(boot, 50.0 * level)), float(np.percentile(boot, 100.0 - 50.0 * level))]


def difference_ci(sse_base: np.ndarray, sse_a: np.ndarray, sse_b: np.ndarray, axis_idx: list[int],
                  seed: int = 54321) -> list[float]:
    """95 % bootstrap interval of explained(a) - explained(b) (same resamples)."""
    counts = _resample_counts(sse_base.shape[0], seed)
    base = counts @ sse_base[:, axis_idx]
    diff = _fractions(base, counts @ sse_a[:, axis_idx]) - _fractions(base, counts @ sse_b[:, axis_idx])
    return [float(np.percentile(diff, 2.5)), float(np.percentile(diff, 97.5))]


def axis_weights(design: Design, cols: list[int]) -> np.ndarray:
    """1/sigma^2 per axis from an unweighted all-data fit of `cols`."""
    gr = grams(design)
    theta = solve(gr, cols, np.arange(design.n_blocks))
    sse = block_sse(gr, cols, theta, np.arange(design.n_blocks)).sum(axis=0)
    n = gr.count.sum()
    sigma2 = np.maximum(sse / max(n, 1), 1e-300)
    return 1.0 / sigma2


def effect_size(gr: Grams, current: list[int], effect_cols: list[int], axis_idx: list[int]) -> float:
    """Largest over the effect's axes of sqrt(what the effect adds to the in-sample fit /
    variance of the response about its mean): the RMS of its own contribution relative to
    the signal's variation. Collinear columns add nothing, so they get no size."""
    blocks = np.arange(gr.s.shape[0])
    before = block_sse(gr, current, solve(gr, current, blocks), blocks).sum(axis=0)
    cols = current + effect_cols
    after = block_sse(gr, cols, solve(gr, cols, blocks), blocks).sum(axis=0)
    n = gr.count.sum()
    variation = gr.s.sum(axis=0) - gr.m.sum(axis=0) ** 2 / max(n, 1)
    ratios = [np.sqrt(max(before[a] - after[a], 0.0) / variation[a]) for a in axis_idx if variation[a] > 0]
    return float(max(ratios)) if ratios else 0.0


def coefficients_with_se(gr: Grams, cols: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """All-data weighted LS coefficients (scaled columns) and their standard errors
    (residual variance times the inverse normal matrix: valid on whitened rows)."""
    blocks = np.arange(gr.s.shape[0])
    theta = solve(gr, cols, blocks)
    a = np.einsum("a,bapq->pq", gr.weight, gr.g[:, :, cols][:, :, :, cols])
    sse = float((block_sse(gr, cols, theta, blocks) * gr.weight).sum())
    n = float(gr.count.sum()) * len(gr.axes)
    dof = max(n - len(cols), 1.0)
    ridge = RIDGE * max(np.trace(a) / max(len(cols), 1), 1e-300)
    cov = np.linalg.inv(a + ridge * np.eye(len(cols))) * sse / dof
    return theta, np.sqrt(np.maximum(np.diag(cov), 0.0))


def cv_residuals(design: Design, gr: Grams, cols: list[int]) -> dict:
    """Held-out residual series per axis: each row predicted by its fold's fit."""
    all_blocks = np.arange(gr.s.shape[0])
    fold_of_row = gr.fold[design.block]
    out = {a: np.zeros_like(design.y[a]) for a in design.axes}
    for k in np.unique(gr.fold):
        train = all_blocks[gr.fold != k]
        theta = solve(gr, cols, train if train.size else all_blocks)
        rows = fold_of_row == k
        for a in design.axes:
            out[a][rows] = design.y[a][rows] - design.x[a][rows][:, cols] @ theta
    return out


def residuals(design: Design, cols: list[int], theta: np.ndarray) -> dict:
    return {a: design.y[a] - design.x[a][:, cols] @ theta for a in design.axes}
