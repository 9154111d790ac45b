"""Cross-validated scoring: least squares on training blocks, residual on held-out
blocks.

Rules (docs/gap.md, "Scoring"):
- folds: with 3 or more flights, one flight each (leave one flight out: no partition of the
  flights into groups, so neither the order of the logs nor a grouping decides which flights are
  held out together); otherwise (block_folds "first-row", the default) the fold blocks
  (Design.fold_group, 1 s on the whitened rows), block index mod 5, numbered across the flights in
  the canonical log order of log_order.py, so the logs' order and each log's first row pick which
  blocks are held out together; block_folds "phases" (an option, evaluated: docs/gap.md) numbers 1 s
  groups of the test blocks within each flight from its own first modelled row, index mod 5, in
  FOLD_PHASES partitions whose grids are offset by 1/FOLD_PHASES s, each log's first second whole,
  every held-out sum the mean over the partitions (repeated cross-fitting);
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
from dataclasses import dataclass, field

import numpy as np

from propid.gap.design import Design
from propid.gap.whitening import SCORE_BLOCK_S

MIN_SCALE_EFFECT_SIZE = 0.03  # effects seen as a torque-vs-accelerometer scale (zero-g offset ~2 % of g)
FOLDS = 5  # block folds with one or two flights (three or more: one fold per flight)
# the block folds with one or two flights: "first-row" (one partition numbered across the logs in
# canonical order, the default) or "phases" (FOLD_PHASES partitions, 1 s groups numbered within each
# log from its own start, grids offset by 1/FOLD_PHASES s, held-out sums averaged; an option,
# evaluated: docs/gap.md, Scoring "Folds")
BLOCK_FOLD_RULES = ("phases", "first-row")
BLOCK_FOLDS = "first-row"
FOLD_PHASES = 5
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
    fold: np.ndarray  # (B,) the first partition's folds
    partitions: np.ndarray | None = None  # (R, B) folds of each partition (held-out sums: mean over R)
    groups: np.ndarray | None = None  # (R, B) the 1 s group of each block per partition (block weights)

    cache: dict = field(init=False, repr=False, compare=False)  # held-out SSE stacks by model

    def __post_init__(self):
        if self.partitions is None:
            self.partitions = self.fold[None, :]
        self.cache = {}


def grams(design: Design, weight: np.ndarray | None = None, block_folds: str = BLOCK_FOLDS) -> Grams:
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
    w = np.ones(len(axes)) if weight is None else weight
    partitions, groups = fold_partitions(design, block_folds)
    return Grams(axes, g, h, s, m, count, w, partitions[0], partitions, groups)


def fold_partitions(design: Design, block_folds: str = BLOCK_FOLDS) -> tuple[np.ndarray, np.ndarray | None]:
    """(R, B) fold of every block in each of R partitions, and (R, B) the 1 s group each block
    belongs to in it (the block weights' groups; None where blocks are not pieces of groups).
    Three or more flights: one partition, a fold per flight. One or two flights: with "first-row"
    one partition, the fold groups (Design.fold_group) numbered across the flights, index mod
    FOLDS; with "phases" FOLD_PHASES partitions, partition m grouping the blocks by
    floor(t / SCORE_BLOCK_S + m / FOLD_PHASES), t the block's mean time from its flight's first
    modelled row, numbered within each flight (so the flights' order does not matter), a first
    group shorter than SCORE_BLOCK_S joined to the next (each log's first second held out whole in
    every partition, as with one grid), fold = group mod FOLDS (a log trimmed by d s gives, past its
    first 2 s, the partitions of phases shifted by d: within 1 / (2 FOLD_PHASES) s of the same set).
    Designs without fold groups (raw rows: prep's 2 s blocks) get one partition, each flight's
    blocks numbered from its own start."""
    if block_folds not in BLOCK_FOLD_RULES:
        raise ValueError(f"unknown block-fold rule {block_folds!r}")
    nb = design.n_blocks
    flights = design.block_flight
    n_flights = int(flights.max()) + 1 if flights.size else 1
    group = np.arange(nb) if design.fold_group is None else design.fold_group
    if n_flights >= 3:
        return flights.copy()[None, :], None if design.fold_group is None else group[None, :]
    if block_folds == "first-row":
        return (group % FOLDS)[None, :], None if design.fold_group is None else group[None, :]
    if design.fold_group is None or design.time is None or design.block.size == 0:
        # one partition: each flight's blocks numbered from its own first block
        within = np.zeros(nb, dtype=int)
        for f in np.unique(flights):
            members = np.flatnonzero(flights == f)
            within[members] = np.arange(members.size)
        return (within % FOLDS)[None, :], None
    rows = np.bincount(design.block, minlength=nb).astype(float)
    centre = np.bincount(design.block, weights=design.time, minlength=nb) / np.maximum(rows, 1.0)
    row_flight = design.flight
    start = np.array([design.time[row_flight == f].min() if np.any(row_flight == f) else 0.0
                      for f in range(n_flights)])
    rel = (centre - start[flights]) / SCORE_BLOCK_S
    partitions = np.empty((FOLD_PHASES, nb), dtype=int)
    groups = np.empty((FOLD_PHASES, nb), dtype=int)
    for m in range(FOLD_PHASES):
        local = np.floor(rel + m / FOLD_PHASES + 1e-9).astype(int)
        # a first group shorter than 1 s joins the next: each log's first second is held out whole in
        # every partition (a start transient's misfit is not confirmed by the rest of that transient)
        local = np.maximum(local, 1) if m else local
        partitions[m] = local % FOLDS
        groups[m] = local * n_flights + flights  # unique per flight
    return partitions, groups


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


def _axis_weighted(gr: Grams) -> tuple[np.ndarray, np.ndarray]:
    """(B, P, P) and (B, P): each block's normal matrix and right-hand side summed over the axes
    with the axis weights (cached per weight: every fit of every fold and partition reads them)."""
    key = ("axis_weighted", gr.weight.tobytes())
    if key not in gr.cache:
        gr.cache[key] = (np.einsum("a,bapq->bpq", gr.weight, gr.g), np.einsum("a,bap->bp", gr.weight, gr.h))
    return gr.cache[key]


def solve(gr: Grams, cols: list[int], blocks: np.ndarray) -> np.ndarray:
    """Weighted LS coefficients (scaled columns) on the given blocks."""
    if not len(blocks):
        return np.zeros(len(cols))
    g_w, h_w = _axis_weighted(gr)
    a = g_w[blocks].sum(axis=0)[np.ix_(cols, cols)]
    rhs = h_w[blocks].sum(axis=0)[cols]
    ridge = RIDGE * max(np.trace(a) / max(len(cols), 1), 1e-300)
    return np.linalg.solve(a + ridge * np.eye(len(cols)), rhs)


def block_sse(gr: Grams, cols: list[int], theta: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """(len(blocks), A) residual sum of squares of the model theta on those blocks."""
    g = gr.g[blocks][:, :, cols][:, :, :, cols]
    h = gr.h[blocks][:, :, cols]
    return gr.s[blocks] - 2.0 * h @ theta + np.einsum("bapq,p,q->ba", g, theta, theta)


def folds(gr: Grams, partition: int = 0):
    """(test, train) block indices per cross-validation fold of one partition (a single fold
    trains on itself)."""
    all_blocks = np.arange(gr.s.shape[0])
    fold = gr.partitions[partition]
    for k in np.unique(fold):
        test = all_blocks[fold == k]
        train = all_blocks[fold != k]
        yield test, (test if train.size == 0 else train)


def cv_sse_stack(gr: Grams, cols: list[int]) -> np.ndarray:
    """(R, B, A) held-out SSE per partition: each block predicted by the fit on the other folds."""
    key = (tuple(cols), gr.weight.tobytes())
    if key in gr.cache:
        return gr.cache[key]
    out = np.zeros((gr.partitions.shape[0],) + gr.s.shape)
    for r in range(gr.partitions.shape[0]):
        for test, train in folds(gr, r):
            theta = solve(gr, cols, train)
            out[r, test] = block_sse(gr, cols, theta, test)
    out.flags.writeable = False  # cached: shared by every caller of this model
    gr.cache[key] = out
    return out


def cv_sse(gr: Grams, cols: list[int]) -> np.ndarray:
    """(B, A) held-out SSE, the mean over the partitions (one partition: the plain CV)."""
    return cv_sse_stack(gr, cols).mean(axis=0)


def cv_cross_stack(gr: Grams, without: list[int], with_: list[int]) -> np.ndarray:
    """(R, B, A) held-out sum over each block's rows of r_with * (r_without - r_with) per
    partition: the with-model's held-out residual times what adding the columns changed in the
    prediction (each block predicted by the fits on the other folds). `without` must be a prefix
    of `with_`. The noise part of the held-out improvement is twice this (significance.py)."""
    out = np.zeros((gr.partitions.shape[0],) + gr.s.shape)
    for r in range(gr.partitions.shape[0]):
        for test, train in folds(gr, r):
            t1 = solve(gr, with_, train)
            t0 = np.zeros_like(t1)
            t0[:len(without)] = solve(gr, without, train)
            d = t1 - t0
            g = gr.g[test][:, :, with_][:, :, :, with_]
            h = gr.h[test][:, :, with_]
            out[r, test] = h @ d - np.einsum("bapq,p,q->ba", g, t1, d)
    return out


def cv_cross(gr: Grams, without: list[int], with_: list[int]) -> np.ndarray:
    """(B, A) cv_cross_stack's mean over the partitions."""
    return cv_cross_stack(gr, without, with_).mean(axis=0)


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
    """Held-out residual series per axis: each row predicted by its fold's fit (several
    partitions: the mean of its held-out predictions)."""
    all_blocks = np.arange(gr.s.shape[0])
    out = {a: np.zeros_like(design.y[a]) for a in design.axes}
    count = gr.partitions.shape[0]
    for fold in gr.partitions:
        fold_of_row = fold[design.block]
        for k in np.unique(fold):
            train = all_blocks[fold != k]
            theta = solve(gr, cols, train if train.size else all_blocks)
            rows = fold_of_row == k
            for a in design.axes:
                out[a][rows] += (design.y[a][rows] - design.x[a][rows][:, cols] @ theta) / count
    return out


def residuals(design: Design, cols: list[int], theta: np.ndarray) -> dict:
    return {a: design.y[a] - design.x[a][:, cols] @ theta for a in design.axes}
