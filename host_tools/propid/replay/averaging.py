"""The window kf_mean and km_mean average a coefficient's recorded estimate over.

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
