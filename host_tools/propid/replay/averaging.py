"""How kf_mean and km_mean summarise a coefficient's recorded estimate (one estimate per replayed gyro sample).

Two estimators, both always reported (docs/real-data.md "The mean of the estimate"):
- "window": the plain mean over a window of the series, chosen by the window rule below.
- "inverse-variance": the mean of the whole series weighted by 1/std^2 of each estimate. No threshold:
  each estimate counts as much as the filter trusts it, so the prior-dominated start weighs little and
  the settled part most. Successive estimates are strongly correlated, so the weights are no likelihood
  and no std of the mean is claimed from them; it is a point estimate.

The window rules:

"from-crossing" (the default): from the first replayed gyro sample whose std falls below the
convergence bar (config.converged_rel_std of the nominal) to the end; a coefficient that never
crosses is averaged over the second half of the samples. A bar crossed just before the log's end
leaves the mean of the last few samples (one rotor of a 24 s log averaged over its last 0.07 s).
"at-least-half" (evaluated, not the default: docs/real-data.md "The averaging window"): from the
crossing or the midpoint, whichever is earlier, so every mean covers at least half of the samples
and the start is continuous in the crossing time.
"""

from __future__ import annotations

import numpy as np

MEAN_WINDOWS = ("from-crossing", "at-least-half")
MEAN_ESTIMATORS = ("window", "inverse-variance")


def window_start(converged: np.ndarray, rule: str = "from-crossing") -> int:
    """Index of the first sample averaged, from one coefficient's per-sample "std under the bar" flags."""
    half = converged.shape[0] // 2
    crossed = np.flatnonzero(converged)
    if not crossed.size:
        return half
    return min(int(crossed[0]), half) if rule == "at-least-half" else int(crossed[0])


def window_means(values: np.ndarray, converged: np.ndarray, t: np.ndarray,
                 rule: str = "from-crossing") -> tuple[list[float], list[float], list[float]]:
    """Per coefficient (column): the mean over its window, the window's start time and the time its std
    first fell under the bar (nan if never)."""
    means, starts, crossings = [], [], []
    for k in range(values.shape[1]):
        start = window_start(converged[:, k], rule)
        crossed = np.flatnonzero(converged[:, k])
        means.append(float(np.mean(values[start:, k])))
        starts.append(float(t[start]))
        crossings.append(float(t[crossed[0]]) if crossed.size else float("nan"))
    return means, starts, crossings


def inverse_variance_means(values: np.ndarray, stds: np.ndarray) -> list[float]:
    """Per coefficient (column): sum(value / std^2) / sum(1 / std^2) over the samples whose value is finite and
    whose std is finite and positive (nan if none)."""
    means = []
    for k in range(values.shape[1]):
        value, std = values[:, k], stds[:, k]
        usable = np.isfinite(value) & np.isfinite(std) & (std > 0)
        if not usable.any():
            means.append(float("nan"))
            continue
        # weights relative to the smallest std: the same ratios as 1/std^2, without overflow for tiny stds
        weight = (np.min(std[usable]) / std[usable]) ** 2
        means.append(float(np.sum(weight * value[usable]) / np.sum(weight)))
    return means


def coefficient_means(values: np.ndarray, stds: np.ndarray, converged: np.ndarray, t: np.ndarray,
                      estimator: str = "window", window: str = "from-crossing") -> dict[str, list[float]]:
    """Every summary of one coefficient family (kf or km), per rotor: "mean" (the chosen estimator's),
    "window" and "inverse_variance" (both estimators), "from" (the window's start time) and "crossing"
    (the time the std first fell under the bar, nan if never)."""
    window_mean, window_from, crossing = window_means(values, converged, t, window)
    weighted = inverse_variance_means(values, stds)
    return {"mean": weighted if estimator == "inverse-variance" else window_mean, "window": window_mean,
            "inverse_variance": weighted, "from": window_from, "crossing": crossing}
