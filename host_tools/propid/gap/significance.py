"""Is an effect there? A score test with an autocorrelation-consistent covariance and Holm's
step-down over the candidates of a selection step; the held-out fraction's interval from a
paired test over short held-out blocks.

Rules (docs/gap.md, "Scoring"):
- the evidence: a Wald test (effect_test, the joint fit's residual in its covariance) of "the effect's columns add nothing
  to the current model" on all whitened rows; one-sided (one_sided_p) for a one-parameter
  effect whose parameter physics keeps >= 0;
- replication: the held-out improvement must be confirmed by its own one-sided paired
  test (paired_test), Holm at REPLICATION_LEVEL = 5 % over the same candidates: the Wald
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
- the reported interval of the held-out fraction: each held-out block b contributes
  c_b = mean over the effect's axes of (SSE_without[b, a] - SSE_with[b, a]) / SSE_without[all, a]
  (sum_b c_b is the fraction), the variance of its noise part Newey-West as above,
  two-sided 95 % with Student's t on variance_dof degrees of freedom (a Bartlett window
  of M blocks over B blocks has about 3 B / (2 M) of them).
"""

from __future__ import annotations

import math

import numpy as np

FAMILY_LEVEL = 0.05  # per selection step: chance of naming an effect that adds nothing
REPLICATION_LEVEL = 0.05  # held-out confirmation, family-wise over a step's candidates (Holm)
_SIMPSON_POINTS = 2001


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
    n = c.shape[0]
    u = c - c.mean()
    bw = andrews_bandwidth(u)
    lags = min(int(math.floor(bw)), n - 1)
    s = float(u @ u) / n
    for k in range(1, lags + 1):
        s += 2.0 * (1.0 - k / (bw + 1.0)) * float(u[k:] @ u[:-k]) / n
    return max(s, 0.0) * n, bw


def t_sf(t: float, dof: float) -> float:
    """P(T > t) for Student's t (Simpson on the substitution x = t / s of the upper tail)."""
    if not math.isfinite(t):
        return 0.0 if t > 0 else 1.0
    if t < 0:
        return 1.0 - t_sf(-t, dof)
    if t == 0:
        return 0.5
    log_c = math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2) - 0.5 * math.log(dof * math.pi)
    s = np.linspace(0.0, 1.0, _SIMPSON_POINTS)[1:]
    x = t / s
    f = np.exp(log_c - (dof + 1) / 2 * np.log1p(x * x / dof)) * t / (s * s)
    f = np.concatenate([[0.0], f])  # the integrand vanishes at s -> 0 for dof > 1
    h = 1.0 / (_SIMPSON_POINTS - 1)
    return float(h / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum()))


def f_sf(x: float, d1: float, d2: float) -> float:
    """P(F > x) for Fisher's F(d1, d2) (Simpson on the substitution u = x / s)."""
    if x <= 0:
        return 1.0
    if not math.isfinite(x):
        return 0.0
    log_c = (0.5 * d1 * math.log(d1 / d2) + math.lgamma((d1 + d2) / 2) - math.lgamma(d1 / 2)
             - math.lgamma(d2 / 2))
    s = np.linspace(0.0, 1.0, _SIMPSON_POINTS)[1:]
    u = x / s
    f = np.exp(log_c + (d1 / 2 - 1) * np.log(u) - (d1 + d2) / 2 * np.log1p(d1 * u / d2)) * x / (s * s)
    f = np.concatenate([[0.0], f])
    h = 1.0 / (_SIMPSON_POINTS - 1)
    return float(min(h / 3 * (f[0] + f[-1] + 4 * f[1:-1:2].sum() + 2 * f[2:-1:2].sum()), 1.0))


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


def paired_test(sse_without: np.ndarray, sse_with: np.ndarray, axis_idx: list[int],
                cross: np.ndarray | None = None) -> dict:
    """Paired held-out test: c_b per block as in the module text, t = sum c_b / sqrt(Var) on
    B - 1 degrees of freedom (under "adds nothing" the held-out improvement has mean <= 0:
    extra columns only add estimation noise, so the test is conservative). Returns the
    explained fraction, its 95 % interval and that p-value. Blocks in time order."""
    c = block_contributions(sse_without, sse_with, axis_idx)
    value = float(c.sum())
    n = c.shape[0]
    if n < 3:
        return {"value": value, "ci": [float("-inf"), float("inf")], "p_value": 1.0, "blocks": n, "bandwidth": 0.0}
    # c_b = |delta_b|^2 + 2 r_b' delta_b (delta: what the effect changed in the prediction,
    # r: the with-model's residual): only the second term is noise; with `cross` its
    # variance is the test's, so a strong effect's own smooth |delta|^2 does not widen it
    noise = c
    if cross is not None:
        total = sse_without[:, axis_idx].sum(axis=0)
        ok = total > 0
        noise = (2.0 * cross[:, axis_idx][:, ok] / total[ok]).sum(axis=1) / max(ok.sum(), 1)
    var, bw = long_run_variance(noise)
    se = math.sqrt(var)
    dof = variance_dof(n, bw)
    p = t_sf(value / se, dof) if se > 0 else (0.0 if value > 0 else 1.0)
    half = t_quantile(0.025, dof) * se
    return {"value": value, "ci": [value - half, value + half], "p_value": float(p), "blocks": n, "bandwidth": bw}


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


def effect_test(gr, current: list[int], effect_cols: list[int], nonnegative: bool = False) -> dict:
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
    `nonnegative`: a one-parameter effect whose parameter physics keeps >= 0 (the physical
    sign rule names no negative fit): the alternative is one-sided, so the p-value is the
    one-sided t-test's (one_sided_p)."""
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
    lags = min(int(math.floor(bw)), n - 1)
    omega = omega0.copy()
    for lag in range(1, lags + 1):
        c = s_n[lag:].T @ s_n[:-lag]
        omega += (1.0 - lag / (bw + 1.0)) * (c + c.T)
    stat = float(b @ np.linalg.lstsq(omega, b, rcond=None)[0])
    rank = max(int(np.linalg.matrix_rank(omega, tol=1e-10 * max(np.abs(omega).max(), 1e-300))), 1)
    # Hotelling: W with a covariance estimated on nu degrees of freedom
    nu = variance_dof(n, bw)
    d2 = nu - rank + 1.0
    p = f_sf(stat * d2 / (nu * rank), rank, d2) if d2 >= 1.0 else 1.0
    if nonnegative and k == 1:
        p = one_sided_p(p, float(theta_e[0]))
    return {"statistic": stat, "dof": rank, "variance_dof": nu, "p_value": p, "bandwidth": bw}
