"""How kf_mean and km_mean summarise a coefficient's recorded estimate (one estimate per replayed gyro sample).

Three estimators, all always reported (docs/real-data.md "The mean of the estimate", "The smoothed mean"):
- "window": the plain mean over a window of the series, chosen by the window rule below.
- "inverse-variance": the mean of the whole series weighted by 1/std^2 of each estimate. No threshold:
  each estimate counts as much as the filter trusts it, so the prior-dominated start weighs little and
  the settled part most. Successive estimates are strongly correlated, so the weights are no likelihood
  and no std of the mean is claimed from them; it is a point estimate.
- "smoothed": the time mean over the replay of the smoothed estimate, each sample's estimate given every
  sample of the replay (a backward Rauch-Tung-Striebel pass on each coefficient alone, as the random walk
  the filter models it with: the walk's variance rate from the configuration). The target is the flight's
  average coefficient; under the walk that is the mean of the smoothed estimates. With the walk the filter's
  estimate lags a change (and the young fit's attenuation) by about the walk's memory, std^2 / walk
  variance rate; the backward pass takes the later samples' information back to the earlier ones.
  Evaluated, not the default: on SITL flights with known truth it is farther from the flight's average
  kf than the 1/std^2 mean, with and without the walk (the gyro-only estimate's own drift where the
  information is weak is no walk of the truth, and the smoother follows it back).

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
MEAN_ESTIMATORS = ("window", "inverse-variance", "smoothed")


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
    def weighted(k: int, usable: np.ndarray) -> float:
        value, std = values[usable, k], stds[usable, k]
        # weights relative to the smallest std: the same ratios as 1/std^2, without overflow for tiny stds
        weight = (np.min(std) / std) ** 2
        return float(np.sum(weight * value) / np.sum(weight))
    return _per_usable_column(values, stds, weighted)


def _per_usable_column(values: np.ndarray, stds: np.ndarray, summary) -> list[float]:
    """summary(k, usable) of each column k, usable the mask of its samples whose value is finite and whose std
    is finite and positive; nan for a column without such a sample."""
    means = []
    for k in range(values.shape[1]):
        value, std = values[:, k], stds[:, k]
        usable = np.isfinite(value) & np.isfinite(std) & (std > 0)
        means.append(summary(k, usable) if usable.any() else float("nan"))
    return means


def smoothed_series(value: np.ndarray, std: np.ndarray, t: np.ndarray, walk_var_rate: float) -> np.ndarray:
    """One coefficient's estimate at each sample given every sample (the backward pass of a scalar
    Rauch-Tung-Striebel smoother): the coefficient walks, its variance growing by walk_var_rate per second
    between samples, and the filter's estimate and std stand for the forward pass. Going backwards,
    smoothed_i = filtered_i + g (smoothed_(i+1) - filtered_i), g = std_i^2 / (std_i^2 + walk_var_rate dt):
    g near 1 where the walk adds little to the estimate's own variance (a young, uncertain estimate takes
    the later one), smaller where the estimate is settled and the walk lets the coefficient move. Without a
    walk every sample takes the final estimate."""
    variance = (std * std).tolist()  # Python floats: the loop runs once per sample
    step_var = (walk_var_rate * np.diff(t)).tolist()
    filtered = np.asarray(value, dtype=float).tolist()
    smoothed = list(filtered)
    for i in range(len(filtered) - 2, -1, -1):
        total = variance[i] + step_var[i]
        gain = variance[i] / total if total > 0 else 1.0
        smoothed[i] = filtered[i] + gain * (smoothed[i + 1] - filtered[i])
    return np.array(smoothed)


def time_mean(series: np.ndarray, t: np.ndarray) -> float:
    """Mean over time of samples at times t: each sample weighs half the span to its neighbours."""
    if series.shape[0] < 2 or not t[-1] > t[0]:
        return float(np.mean(series))
    span = np.empty_like(t, dtype=float)
    span[1:-1] = (t[2:] - t[:-2]) / 2
    span[0], span[-1] = (t[1] - t[0]) / 2, (t[-1] - t[-2]) / 2
    return float(np.sum(span * series) / np.sum(span))


def smoothed_means(values: np.ndarray, stds: np.ndarray, t: np.ndarray, walk_var_rates: list[float]) -> list[float]:
    """Per coefficient (column): the time mean of its smoothed series over the samples whose value is finite and
    whose std is finite and positive (nan if none). walk_var_rates: each column's walk variance per second,
    in the values' units squared ((relative walk x nominal)^2)."""
    def smoothed_mean(k: int, usable: np.ndarray) -> float:
        smoothed = smoothed_series(values[usable, k], stds[usable, k], t[usable], float(walk_var_rates[k]))
        return time_mean(smoothed, t[usable])
    return _per_usable_column(values, stds, smoothed_mean)


def coefficient_means(values: np.ndarray, stds: np.ndarray, converged: np.ndarray, t: np.ndarray,
                      walk_var_rates: list[float], estimator: str = "window",
                      window: str = "from-crossing") -> dict[str, list[float]]:
    """Every summary of one coefficient family (kf or km), per rotor: "mean" (the chosen estimator's),
    "window", "inverse_variance" and "smoothed" (every estimator), "from" (the window's start time) and
    "crossing" (the time the std first fell under the bar, nan if never)."""
    window_mean, window_from, crossing = window_means(values, converged, t, window)
    weighted = inverse_variance_means(values, stds)
    smoothed = smoothed_means(values, stds, t, walk_var_rates)
    chosen = {"window": window_mean, "inverse-variance": weighted, "smoothed": smoothed}[estimator]
    return {"mean": chosen, "window": window_mean, "inverse_variance": weighted, "smoothed": smoothed,
            "from": window_from, "crossing": crossing}
