"""Is an effect there? A score test with an autocorrelation-consistent covariance and Holm's
step-down over the candidates of a selection step; the held-out fraction's interval from a
paired test over short held-out blocks.

Rules (docs/gap.md, "Scoring"):
- the evidence: a Wald test (effect_test, the joint fit's residual in its covariance) of "the effect's columns add nothing
  to the current model" on all whitened rows; one-sided (one_sided_p) for a one-parameter
  effect whose parameter physics keeps >= 0, the chi-bar-square test of the orthant
  (chi_bar_p) for an effect with several such parameters;
- replication: the held-out improvement must be confirmed by its own one-sided paired
  test (paired_test), Holm at REPLICATION_LEVEL = 5 % over the same candidates, each
  held-out block weighted per axis by the inverse of its 1 s block's held-out residual power
  (block_weights: a residual whose level changes in time, e.g. a start transient or a gust,
  would otherwise let one loud second set the test's variance; the reported explained fraction
  stays unweighted, the reported interval is the weighted statistic's, the decision's own): the Wald
  test on a whole flight also flags fits that soak up what the model gets wrong
  everywhere (the sensor chain's lag, a drifting gyro bias: on effect-free benchmark
  flights gyro_scale reached p ~ 1e-14 with a negative held-out fraction); they do not
  predict data they did not see. A held-out score pays for the fit's noise twice
  (estimated on the training folds, charged on the held-out ones), so this confirmation,
  not the Wald test, is what sets the detection limit (docs/gap.md);
- the test blocks are short (whitening.py: ten autocorrelation times of the whitened
  residual) and the covariance of their scores is Newey-West (Bartlett kernel) with
  Andrews' AR(1) plug-in bandwidth: structure the whitening left, or an improvement
  concentrated in a manoeuvre, widens the covariance by its own correlation instead of
  passing for independent evidence;
- a family of K candidates scored at one selection step: Holm's step-down at level
  FAMILY_LEVEL = 5 % (the chance of naming any effect when none adds anything is at most
  that, per step); forward selection (selection.py) then scores the rest conditionally on
  the effects already in;
- the held-out fraction: each held-out block b contributes
  c_b = mean over the effect's axes of (SSE_without[b, a] - SSE_with[b, a]) / SSE_without[all, a]
  (sum_b c_b is the fraction), the variance of its noise part Newey-West as above, Student's t
  on variance_dof degrees of freedom (a Bartlett window of M blocks over B blocks has about
  3 B / (2 M) of them);
- the reported interval is that of the statistic the p-value tests (the block-weighted sums,
  same variance and degrees of freedom), two-sided 95 %: it excludes 0 exactly when the
  two-sided p is below 5 % (its lower edge is above 0 exactly when the one-sided p is below
  2.5 %), so an interval never contradicts the p printed beside it.
"""

from __future__ import annotations

import math

import numpy as np

from propid.signals import bartlett_long_run_covariance

FAMILY_LEVEL = 0.05  # per selection step: chance of naming an effect that adds nothing
REPLICATION_LEVEL = 0.05  # held-out confirmation, family-wise over a step's candidates (Holm)
# the replication's statistic: "improvement" (the held-out SSE reduction, the default) or
# "prediction" (the held-out residual along the effect's training-fold prediction, mean 0 under
# "adds nothing"; evaluated, not the default: docs/gap.md, SITL accuracy "The score test again")
REPLICATION_STATISTICS = ("improvement", "prediction")


def block_contributions(sse_without: np.ndarray, sse_with: np.ndarray, axis_idx: list[int]) -> np.ndarray:
    """(B,) per-block share of the explained fraction (mean over axes with SSE > 0)."""
    a = sse_without[:, axis_idx]
    b = sse_with[:, axis_idx]
    total = a.sum(axis=0)
    ok = total > 0
    if not np.any(ok):
        return np.zeros(a.shape[0])
    return ((a[:, ok] - b[:, ok]) / total[ok]).sum(axis=1) / ok.sum()


def andrews_bandwidth(u: np.ndarray) -> float:
    """Bartlett-kernel bandwidth by Andrews' (1991) AR(1) plug-in: 1.1447 (alpha B)^(1/3),
    alpha = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2), rho the lag-1 autocorrelation of u
    (clipped below 1 so the rule stays finite)."""
    n = u.shape[0]
    if n < 3:
        return 0.0
    den = float(u[:-1] @ u[:-1])
    rho = float(u[1:] @ u[:-1]) / den if den > 0 else 0.0
    rho = min(max(rho, -0.97), 0.97)
    alpha = 4.0 * rho**2 / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return 1.1447 * (alpha * n) ** (1.0 / 3.0)


def long_run_variance(c: np.ndarray) -> tuple[float, float]:
    """Newey-West variance of sum(c) and the bandwidth used."""
    u = c - c.mean()
    bw = andrews_bandwidth(u)
    return max(bartlett_long_run_covariance(u, bw), 0.0), bw


def _beta_fraction(a: float, b: float, x: float) -> float:
    """Continued fraction of the regularised incomplete beta function (the standard one,
    terms d_2m = m (b - m) x / ((a + 2m - 1)(a + 2m)), d_2m+1 = -(a + m)(a + b + m) x /
    ((a + 2m)(a + 2m + 1))), evaluated by the modified Lentz method; it converges fast for
    x < (a + 1) / (a + b + 2)."""
    tiny = 1e-300

    def guard(v: float) -> float:
        return v if abs(v) > tiny else tiny

    c = 1.0
    d = 1.0 / guard(1.0 - (a + b) * x / (a + 1.0))
    f = d
    for m in range(1, 2000):
        for term in (m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
                     -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1))):
            d = 1.0 / guard(1.0 + term * d)
            c = guard(1.0 + term / c)
            f *= c * d
        if abs(c * d - 1.0) < 1e-15:
            break
    return f


def beta_cdf(a: float, b: float, x: float) -> float:
    """Regularised incomplete beta I_x(a, b) (the continued fraction on the side where it
    converges, the symmetry I_x(a, b) = 1 - I_1-x(b, a) on the other)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (a * math.log(x) + b * math.log1p(-x)
                 - (math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)))
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_fraction(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_fraction(b, a, 1.0 - x) / b


def t_sf(t: float, dof: float) -> float:
    """P(T > t) for Student's t: half of I_{dof/(dof + t^2)}(dof/2, 1/2) in the upper tail.
    (Was a Simpson integral on x = t / s, which lost the mass near t = 0: it gave
    P(T > 1e-8) ~ 1e-5 instead of 0.5, so a held-out improvement of about nothing read as
    replicated.)"""
    if not math.isfinite(t):
        return 0.0 if t > 0 else 1.0
    tail = 0.5 * beta_cdf(dof / 2.0, 0.5, dof / (dof + t * t))
    return tail if t >= 0 else 1.0 - tail


def f_sf(x: float, d1: float, d2: float) -> float:
    """P(F > x) for Fisher's F(d1, d2) = I_{d2/(d2 + d1 x)}(d2/2, d1/2). (Was a Simpson
    integral that lost the mass near 0: P(F(2, 60) > 1e-6) came out 0.004 instead of ~1,
    so a statistic of about nothing read as a detection.)"""
    if x <= 0:
        return 1.0
    if not math.isfinite(x):
        return 0.0
    return float(min(max(beta_cdf(d2 / 2.0, d1 / 2.0, d2 / (d2 + d1 * x)), 0.0), 1.0))


def variance_dof(blocks: int, bandwidth: float) -> float:
    """Degrees of freedom of a Bartlett-window variance over `blocks` blocks: the
    Satterthwaite match to its relative variance 4 M / (3 B) (M = bandwidth + 1), at most
    B - 1 (independent blocks)."""
    return float(max(min(blocks - 1.0, 1.5 * blocks / (bandwidth + 1.0)), 1.0))


def t_quantile(p: float, dof: float) -> float:
    """Upper quantile t with P(T > t) = p, by bisection on t_sf."""
    lo, hi = 0.0, 1.0
    while t_sf(hi, dof) > p:
        hi *= 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if t_sf(mid, dof) > p else (lo, mid)
    return 0.5 * (lo + hi)


def block_weights(sse_with: np.ndarray, rows: np.ndarray, group: np.ndarray | None) -> np.ndarray:
    """(B, A) weight of each held-out block in the replication test: 1 / the with-model's
    held-out residual power per row over the block's group (the 1 s fold block it is a piece
    of), per axis; ones without groups. A residual whose level changes in time (a start
    transient, a gust) then does not let one loud second set the test's variance."""
    weights = np.ones_like(sse_with)
    if group is None:
        return weights
    for g in np.unique(group):
        members = group == g
        power = sse_with[members].sum(axis=0) / max(float(rows[members].sum()), 1.0)
        weights[members] = np.where(power > 0, 1.0 / np.where(power > 0, power, 1.0), 0.0)[None, :]
    return weights


def effective_blocks(u: np.ndarray) -> float:
    """Kish's effective number of blocks of a sum of centred block terms u:
    (sum u^2)^2 / sum u^4 (B for equal terms, 1 when one block carries them all). A variance
    estimated from B blocks whose noise sits in a few of them has the few's degrees of freedom."""
    d = u - u.mean()
    q = float((d**4).sum())
    return float((d @ d) ** 2 / q) if q > 0 else float(u.shape[0])


def _improvement_p(sse_without: np.ndarray, sse_with: np.ndarray, axis_idx: list[int],
                   cross: np.ndarray | None, statistic: str = "improvement") -> dict:
    """The held-out replication test on (possibly weighted) block sums. `statistic`
    (REPLICATION_STATISTICS): "improvement" tests sum c_b (below); "prediction" tests
    sum_b r_without,b' delta_b, the current model's held-out residual along what the effect's
    training-fold fit adds (needs `cross`). Returns value (the improvement fraction of these
    sums), stat / se / dof (the tested statistic, its noise's standard error and degrees of
    freedom: p = P(T_dof > stat / se)), p and the Newey-West bandwidth."""
    c = block_contributions(sse_without, sse_with, axis_idx)
    value = float(c.sum())
    # c_b = |delta_b|^2 + 2 r_b' delta_b (delta: what the effect changed in the prediction,
    # r: the with-model's residual): only the second term is noise; with `cross` its
    # variance is the test's, so a strong effect's own smooth |delta|^2 does not widen it
    noise = c
    if cross is not None:
        total = sse_without[:, axis_idx].sum(axis=0)
        ok = total > 0
        noise = (2.0 * cross[:, axis_idx][:, ok] / total[ok]).sum(axis=1) / max(ok.sum(), 1)
    if statistic == "prediction" and cross is not None:
        # r_without' delta = |delta|^2 + r_with' delta = c_b - (its noise part) / 2: under "adds
        # nothing" the training-fold delta is independent of the held-out noise, so its mean is 0
        # (the improvement's is -E|delta|^2: conservative, about half the effect's t); noise part
        # r_with' delta; degrees of freedom at most the noise's effective number of blocks
        half = noise / 2.0
        stat = value - float(half.sum())
        var, bw = long_run_variance(half)
        dof = min(variance_dof(c.shape[0], bw), max(effective_blocks(half), 1.0))
    else:
        stat = value
        var, bw = long_run_variance(noise)
        dof = variance_dof(c.shape[0], bw)
    se = math.sqrt(var)
    p = t_sf(stat / se, dof) if se > 0 else (0.0 if stat > 0 else 1.0)
    return {"value": value, "stat": stat, "se": se, "dof": dof, "p": p, "bandwidth": bw}


def _interval(test: dict) -> list[float]:
    """Two-sided 95 % interval of a test's statistic (stat +- t_{0.975, dof} se): its lower edge is
    above 0 exactly when the test's one-sided p is below 0.025, i.e. it excludes 0 exactly when the
    two-sided p (2 min(p, 1 - p)) is below 0.05."""
    half = t_quantile(0.025, test["dof"]) * test["se"]
    return [test["stat"] - half, test["stat"] + half]


def paired_test(sse_without: np.ndarray, sse_with: np.ndarray, axis_idx: list[int],
                cross: np.ndarray | None = None, weights: np.ndarray | None = None,
                statistic: str = "improvement") -> dict:
    """Paired held-out test: c_b per block as in the module text, t = sum c_b / sqrt(Var) on
    B - 1 degrees of freedom (under "adds nothing" the held-out improvement has mean <= 0:
    extra columns only add estimation noise, so the test is conservative). With `weights`
    (block_weights) the test is on the weighted block sums. Returns `value` (the unweighted
    explained fraction), `p_value` (the test's one-sided p), `weighted_value` (the tested
    statistic: the weighted fraction, or with statistic "prediction" the weighted fraction along
    the prediction) and `ci` its two-sided 95 % interval (_interval: the decision's own statistic,
    so ci[0] > 0 exactly when p < 0.025). Blocks in time order. Arrays (B, A), or (R, B, A) for R
    partitions of the folds: the sums are then the means over the partitions."""
    if statistic not in REPLICATION_STATISTICS:
        raise ValueError(f"unknown replication statistic {statistic!r}")
    # (R, B, A) arrays: R partitions of the folds (repeated cross-fitting, scoring.fold_partitions);
    # the tested sums are the means over the partitions of each block's (weighted) held-out sums:
    # every block is held out once in each partition, so the mean is itself a held-out statistic,
    # tested once (no combination of R p-values), its noise variance Newey-West on the same means
    if sse_without.ndim == 2:
        sse_without, sse_with = sse_without[None], sse_with[None]
        cross = None if cross is None else cross[None]
        weights = None if weights is None else weights[None]
    n = sse_without.shape[1]
    plain_without, plain_with = sse_without.mean(axis=0), sse_with.mean(axis=0)
    plain_cross = None if cross is None else cross.mean(axis=0)
    if n < 3:
        value = float(block_contributions(plain_without, plain_with, axis_idx).sum())
        return {"value": value, "weighted_value": value, "ci": [float("-inf"), float("inf")], "p_value": 1.0,
                "blocks": n, "bandwidth": 0.0}
    plain = _improvement_p(plain_without, plain_with, axis_idx, plain_cross)
    test = plain
    if weights is None and statistic != "improvement":
        test = _improvement_p(plain_without, plain_with, axis_idx, plain_cross, statistic)
    if weights is not None:
        test = _improvement_p((sse_without * weights).mean(axis=0), (sse_with * weights).mean(axis=0), axis_idx,
                              None if cross is None else (cross * weights).mean(axis=0), statistic)
    return {"value": plain["value"], "weighted_value": test["stat"], "ci": _interval(test),
            "p_value": float(test["p"]), "blocks": n, "bandwidth": plain["bandwidth"]}


def difference_interval(sse_base: np.ndarray, sse_a: np.ndarray, sse_b: np.ndarray, axis_idx: list[int]) -> list[float]:
    """95 % interval of explained(a) - explained(b) over the same held-out blocks."""
    c = block_contributions(sse_base, sse_a, axis_idx) - block_contributions(sse_base, sse_b, axis_idx)
    n = c.shape[0]
    if n < 3:
        return [float("-inf"), float("inf")]
    var, _ = long_run_variance(c)
    half = t_quantile(0.025, n - 1) * math.sqrt(var)
    return [float(c.sum() - half), float(c.sum() + half)]


def holm(p_values: list[float], level: float = FAMILY_LEVEL) -> list[bool]:
    """Holm's step-down: which hypotheses are rejected at family-wise `level`."""
    order = np.argsort(p_values, kind="stable")
    m = len(p_values)
    out = [False] * m
    for rank, k in enumerate(order):
        if p_values[k] > level / (m - rank):
            break
        out[k] = True
    return out


def chi2_sf(x: float, dof: int) -> float:
    """P(X > x) for a chi-square with `dof` degrees of freedom (regularised lower gamma by
    its power series; exact enough for the family levels read here)."""
    if x <= 0:
        return 1.0
    a, z = dof / 2.0, x / 2.0
    if z > a + 40.0 * math.sqrt(a) + 60.0:
        return 0.0
    term = 1.0 / a
    total = term
    n = 0
    while term > 1e-17 * total and n < 100000:
        n += 1
        term *= z / (a + n)
        total += term
    lower = math.exp(a * math.log(z) - z - math.lgamma(a) + math.log(total))
    return float(min(max(1.0 - lower, 0.0), 1.0))


def one_sided_p(p_two_sided: float, estimate: float) -> float:
    """One-sided p-value of "the parameter is > 0" from a two-sided test of one parameter
    (F(1, d) = t^2 with a symmetric t): p/2 when the estimate is above 0, 1 - p/2 otherwise.
    Under "the parameter is 0" it is uniform like the two-sided one, so Holm's level holds;
    the power is that of a two-sided test at twice the level, in the physical direction."""
    return p_two_sided / 2.0 if estimate > 0 else 1.0 - p_two_sided / 2.0


CHI_BAR_DRAWS = 20000  # Monte-Carlo draws for the chi-bar-square weights (fixed seed: deterministic)


def _orthant_projection(theta: np.ndarray, precision: np.ndarray, constrained: tuple[int, ...]):
    """Projection of each row of theta (n, k) onto {c: c_i >= 0 for i in constrained} in the
    metric `precision`: (distance^2, free components) per row. Every active set S (the
    constrained components held at 0) is tried: the rest then follows in closed form,
    d_f = -Q_ff^-1 Q_fS theta_S, distance^2 = theta_S' (Q_SS - Q_Sf Q_ff^-1 Q_fS) theta_S;
    the least distance among the feasible sets is the convex problem's minimum (k <= 3: at
    most 8 sets)."""
    n, k = theta.shape
    best = np.full(n, np.inf)
    free_count = np.zeros(n, dtype=int)
    for mask in range(1 << len(constrained)):
        active = [constrained[j] for j in range(len(constrained)) if mask >> j & 1]
        free = [i for i in range(k) if i not in active]
        if free:
            q_ff = precision[np.ix_(free, free)]
            q_fa = precision[np.ix_(free, active)]
            shift = -np.linalg.solve(q_ff, q_fa @ theta[:, active].T).T if active else np.zeros((n, len(free)))
            c_free = theta[:, free] - shift
            ok = np.ones(n, dtype=bool)
            for j, i in enumerate(free):
                if i in constrained:
                    ok &= c_free[:, j] >= 0.0
            d = np.zeros_like(theta)
            d[:, active] = theta[:, active]
            d[:, free] = shift
        else:
            ok = np.ones(n, dtype=bool)
            d = theta.copy()
        dist = np.einsum("np,pq,nq->n", d, precision, d)
        take = ok & (dist < best)
        best[take] = dist[take]
        free_count[take] = len(free)
    return best, free_count


def chi_bar_weights(precision: np.ndarray, constrained: tuple[int, ...]) -> np.ndarray:
    """Weights w_i (i = 0..k) of the chi-bar-square law of the orthant-constrained Wald
    statistic under the null: the chance that the projection of a N(0, precision^-1) draw
    has i free components (Monte Carlo, fixed seed)."""
    k = precision.shape[0]
    # draws of N(0, precision^-1) by its eigenvectors; a precision that is not positive
    # definite in floating point (a near-singular Newey-West covariance) has no such law:
    # LinAlgError, and the caller keeps the two-sided test
    vals, vecs = np.linalg.eigh(0.5 * (precision + precision.T))
    if not vals.min() > 1e-12 * max(vals.max(), 0.0):
        raise np.linalg.LinAlgError("precision not positive definite")
    root = vecs / np.sqrt(vals)
    z = np.random.default_rng(20240).normal(size=(CHI_BAR_DRAWS, k)) @ root.T
    _, free = _orthant_projection(z, precision, constrained)
    return np.bincount(free, minlength=k + 1) / CHI_BAR_DRAWS


def chi_bar_p(theta: np.ndarray, precision: np.ndarray, constrained: tuple[int, ...], nu: float) -> tuple[float, float]:
    """One-sided Wald test of "theta = 0" against "theta != 0 with theta_i >= 0 for i in
    constrained" (Kudo; Shapiro): T = theta' Q theta - min over the constrained set of
    (theta - c)' Q (theta - c), null law sum_i w_i chi2_i (chi2_0 = 0); with Q estimated on
    nu degrees of freedom each chi2_i is read as Hotelling's T^2 (F(i, nu - i + 1)), as the
    two-sided test. Returns (p, T)."""
    t0 = float(theta @ precision @ theta)
    dist, _ = _orthant_projection(theta[None, :], precision, constrained)
    stat = max(t0 - float(dist[0]), 0.0)
    if stat <= 0.0:
        return 1.0, 0.0
    w = chi_bar_weights(precision, constrained)
    p = 0.0
    for i in range(1, len(w)):
        d2 = nu - i + 1.0
        p += w[i] * (f_sf(stat * d2 / (nu * i), i, d2) if d2 >= 1.0 else 1.0)
    return float(min(p, 1.0)), stat


def effect_test(gr, current: list[int], effect_cols: list[int], nonnegative: bool | tuple[int, ...] = False) -> dict:
    """Wald test of "the effect's columns add nothing to the current model" on all whitened
    rows, with a covariance that does not assume independent rows:
        theta_e = the effect's coefficients in the joint all-data fit,
        s_b = sum_a w_a (X_e - X_c Pi)_b' r_b  (r the joint fit's residual, Pi the
              regression of the effect's columns on the current ones),
        Var(theta_e) = A^-1 Omega A^-1,  A = sum_b sum_a w_a (X_e - X_c Pi)_b' (X_e - X_c Pi)_b,
        Omega = Newey-West covariance of the s_b (Andrews' bandwidth on their projection
                onto the test direction),
        W = theta_e' A Omega^-1 A theta_e, Hotelling's T^2 with k (the effect's parameter
            count) and nu = variance_dof(B, bandwidth) degrees of freedom:
            W (nu - k + 1) / (nu k) ~ F(k, nu - k + 1) under the null.
    The residual is the joint fit's (with the effect in): a strong effect does not inflate
    the covariance that judges it (a score test on the current model's residual would:
    its block scores then carry the smooth effect itself, and a Newey-West window over them
    loses power exactly when the effect is large).
    `nonnegative`: the effect's parameters that physics keeps >= 0 (indices into
    effect_cols; True = all of a one-parameter effect). The physical sign rule names no fit
    with all of them below 0, so the alternative is one-sided: with one parameter the
    one-sided t-test's p-value (one_sided_p); with several, all of them constrained, the
    chi-bar-square test of the orthant (chi_bar_p)."""
    from propid.gap import scoring

    blocks = np.arange(gr.s.shape[0])
    cur, eff = list(current), list(effect_cols)
    cols = cur + eff
    w = gr.weight
    theta = scoring.solve(gr, cols, blocks)
    theta_e = theta[len(cur):]
    g_cc = np.einsum("a,bapq->pq", w, gr.g[:, :, cur][:, :, :, cur])
    g_ce = np.einsum("a,bapq->pq", w, gr.g[:, :, cur][:, :, :, eff])
    g_ee = np.einsum("a,bapq->pq", w, gr.g[:, :, eff][:, :, :, eff])
    ridge = scoring.RIDGE * max(np.trace(g_cc) / max(len(cur), 1), 1e-300)
    pi = np.linalg.solve(g_cc + ridge * np.eye(len(cur)), g_ce)  # (c, e)
    a_mat = g_ee - g_ce.T @ pi
    # per block and axis: X_e' r and X_c' r for the joint fit's residual r
    xe_r = gr.h[:, :, eff] - np.einsum("bapq,q->bap", gr.g[:, :, eff][:, :, :, cols], theta)
    xc_r = gr.h[:, :, cur] - np.einsum("bapq,q->bap", gr.g[:, :, cur][:, :, :, cols], theta)
    s = np.einsum("a,bap->bp", w, xe_r) - np.einsum("a,bac,ce->be", w, xc_r, pi)  # (B, e)
    n, k = s.shape
    if n < 3 or k == 0:
        return {"statistic": 0.0, "dof": k, "p_value": 1.0, "bandwidth": 0.0}
    scale = np.sqrt(np.maximum(np.diag(a_mat), 1e-300))
    a_n = a_mat / np.outer(scale, scale)
    s_n = s / scale
    b = a_n @ (theta_e * scale)  # A theta in the normalised coordinates
    omega0 = s_n.T @ s_n
    direction = np.linalg.lstsq(omega0, b, rcond=None)[0]
    bw = andrews_bandwidth(s_n @ direction)
    omega = bartlett_long_run_covariance(s_n, bw)
    stat = float(b @ np.linalg.lstsq(omega, b, rcond=None)[0])
    # the coefficients' sandwich standard errors (scaled columns): A^-1 Omega A^-1
    a_inv = np.linalg.pinv(a_n)
    se = np.sqrt(np.maximum(np.diag(a_inv @ omega @ a_inv), 0.0)) / scale
    rank = max(int(np.linalg.matrix_rank(omega, tol=1e-10 * max(np.abs(omega).max(), 1e-300))), 1)
    # Hotelling: W with a covariance estimated on nu degrees of freedom
    nu = variance_dof(n, bw)
    d2 = nu - rank + 1.0
    p = f_sf(stat * d2 / (nu * rank), rank, d2) if d2 >= 1.0 else 1.0
    constrained = (0,) if nonnegative is True else tuple(nonnegative or ())
    if constrained == (0,) and k == 1:
        p = one_sided_p(p, float(theta_e[0]))
    elif len(constrained) == k and k > 1 and rank == k:
        # precision of the normalised coefficients: A Omega^-1 A (W = theta' A Omega^-1 A theta)
        try:
            precision = a_n @ np.linalg.solve(omega, a_n)
            p, stat = chi_bar_p(theta_e * scale, 0.5 * (precision + precision.T), constrained, nu)
        except np.linalg.LinAlgError:
            pass  # a singular covariance: the two-sided test stands
    return {"statistic": stat, "dof": rank, "variance_dof": nu, "p_value": p, "bandwidth": bw, "se": se}
