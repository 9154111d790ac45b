"""A plain least-squares diagnosis, the bench's reference point for `propid gap`.

One ordinary least-squares fit of everything at once, on all of the flight's data
(no held-out scoring): the response of the nominal model (J dw/dt + w x Jw per
axis, m a_z) on the nominal regressors (per-rotor kf shared by roll, pitch and
thrust; per-rotor km on yaw) plus every testable effect's columns
(propid.gapbench.effect_regressors). Axes are weighted by the residual RMS of a
first nominal-only fit. Each effect is scored by its partial F statistic (what
removing its columns costs), flagged significant when F exceeds the chi-square
quantile of a 1 % test Bonferroni-corrected over the candidates; the verdict is
the significant effect that explains the most residual variance, or `none`.
It writes the same keys as `propid gap`'s OUT.json that the bench scores.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from propid.flightlog import read_flightlog, read_vehicle
from propid.gapbench.effect_regressors import effect_columns
from propid.gapbench.magnitudes import EFFECTS
from propid.gapbench.rigid_body import AXES, make_grid, nominal_regressors, response

FAMILY_ALPHA = 0.01


def chi2_quantile(p_upper: float, dof: int) -> float:
    """Upper quantile of chi-square (Wilson-Hilferty; ample for a threshold)."""
    z = _normal_upper_quantile(p_upper)
    c = 2.0 / (9.0 * dof)
    return dof * (1.0 - c + z * math.sqrt(c)) ** 3


def _normal_upper_quantile(p: float) -> float:
    lo, hi = 0.0, 40.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if 0.5 * math.erfc(mid / math.sqrt(2.0)) > p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _fit(design: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float]:
    return _GramFit(design, target).fit(np.arange(design.shape[1]))


class _GramFit:
    """Least squares of `target` on any subset of the columns of `design`, from one Gram
    matrix (columns scaled to unit norm; tall logs cost one product, not one SVD each)."""

    def __init__(self, design: np.ndarray, target: np.ndarray):
        self.scale = np.linalg.norm(design, axis=0)
        self.scale[self.scale == 0] = 1.0
        scaled = design / self.scale
        self.gram = scaled.T @ scaled
        self.cross = scaled.T @ target
        self.total = float(target @ target)

    def fit(self, cols: np.ndarray) -> tuple[np.ndarray, float]:
        g = self.gram[np.ix_(cols, cols)]
        h = self.cross[cols]
        coef, *_ = np.linalg.lstsq(g, h, rcond=1e-12)
        ssr = self.total - 2.0 * coef @ h + coef @ g @ coef
        return coef / self.scale[cols], float(max(ssr, 0.0))


def diagnose(csv_path: Path | list[Path], vehicle_path: Path) -> dict:
    """One fit over the log, or over several logs of one vehicle (rows stacked: one set of
    coefficients for all)."""
    vehicle = read_vehicle(vehicle_path)
    paths = list(csv_path) if isinstance(csv_path, (list, tuple)) else [csv_path]
    grids = [make_grid(read_flightlog(path, vehicle)) for path in paths]
    target = np.concatenate([response(grid, vehicle) for grid in grids], axis=1)
    nominal = np.concatenate([nominal_regressors(grid, vehicle) for grid in grids], axis=1)
    rows = target.shape[1]
    axes = [a for a in range(4) if np.all(np.isfinite(target[a]))]

    def flat(columns_4n: np.ndarray) -> np.ndarray:  # (4, n, k) -> (len(axes) n, k)
        return np.concatenate([columns_4n[a] for a in axes], axis=0)

    # Weights: per-axis residual RMS of the nominal-only fit (two passes).
    weights = np.array([1.0 / max(np.std(target[a]), 1e-12) for a in axes])
    for _ in range(2):
        w = np.repeat(weights, rows)
        coef, _ = _fit(flat(nominal) * w[:, None], flat(target[:, :, None])[:, 0] * w)
        resid = target - nominal @ coef
        weights = np.array([1.0 / max(np.sqrt(np.mean(resid[a] ** 2)), 1e-12) for a in axes])
    rms_before = {AXES[a]: float(np.sqrt(np.mean(resid[a] ** 2))) for a in axes}
    w = np.repeat(weights, rows)
    y = flat(target[:, :, None])[:, 0] * w

    groups: dict[str, np.ndarray] = {}
    untestable = []
    for effect in EFFECTS:
        per_log = [effect_columns(effect, grid, vehicle) for grid in grids]
        if any(cols is None for cols in per_log):
            untestable.append(effect)
            continue
        groups[effect] = np.concatenate([np.stack(cols, axis=-1) for cols in per_log],
                                        axis=1)  # (4, n, k)
    base = flat(nominal) * w[:, None]
    names = list(groups)
    blocks = [flat(groups[e]) * w[:, None] for e in names]
    full = np.concatenate([base] + blocks, axis=1)
    gram = _GramFit(full, y)
    starts = np.cumsum([base.shape[1]] + [b.shape[1] for b in blocks])
    _, ssr_nominal = gram.fit(np.arange(base.shape[1]))
    coef_full, ssr_full = gram.fit(np.arange(full.shape[1]))
    dof = max(y.size - full.shape[1], 1)
    sigma2 = ssr_full / dof
    threshold_p = FAMILY_ALPHA / max(len(names), 1)
    effects = []
    offset = base.shape[1]
    for k, effect in enumerate(names):
        width = blocks[k].shape[1]
        keep = np.ones(full.shape[1], dtype=bool)
        keep[starts[k]: starts[k] + width] = False
        _, ssr_reduced = gram.fit(np.flatnonzero(keep))
        gain = max(ssr_reduced - ssr_full, 0.0)
        f_stat = gain / width / sigma2
        explained = gain / ssr_nominal if ssr_nominal > 0 else 0.0
        touched = [AXES[a] for a in axes if np.any(groups[effect][a] != 0)]
        effects.append({
            "id": effect,
            "explained_fraction": explained,
            "ci": None,
            "axes": touched,
            "params": {"coefficients": coef_full[offset: offset + width].tolist(),
                       "f_statistic": f_stat},
            "significant": bool(f_stat * width > chi2_quantile(threshold_p, width)),
        })
        offset += width
    effects.sort(key=lambda e: e["explained_fraction"], reverse=True)
    significant = [e["id"] for e in effects if e["significant"]]
    # Residual after adding the significant effects (in sample), per axis.
    chosen = [groups[e] for e in significant]
    after_design = np.concatenate([nominal] + chosen, axis=2) if chosen else nominal
    coef_after, _ = _fit(flat(after_design) * w[:, None], y)
    resid_after = target - after_design @ coef_after
    shrink = {AXES[a]: {"rms_before": rms_before[AXES[a]],
                        "rms_after": float(np.sqrt(np.mean(resid_after[a] ** 2)))} for a in axes}
    return {
        "verdict": significant[0] if significant else "none",
        "effects": effects,
        "shrink": shrink,
        "untestable": untestable,
        "ambiguous": [],
        "method": "ordinary least squares on all data, partial F per effect (baseline)",
    }
