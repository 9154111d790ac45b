"""How far the rotors' kf can differ from their run mean by the filter's own uncertainty alone
(docs/real-data.md, "Every rotor within 5 %: what the information allows").

With N identical rotors the estimates still differ by their errors. The deviation of rotor i from the run mean,
d_i = kf_i / mean(kf) - 1, has to first order the covariance J C J^T, C the covariance of the kf estimates and
J_ij = delta_ij / m - kf_i / (N m^2), m = mean(kf). The probability that every |d_i| stays within a tolerance
is then the Gaussian probability of a box, computed by drawing (fixed seed: the same log gives the same number).
Summed over runs it is how many runs a check "every rotor within 5 % of its run mean" should pass if the rotors
were equal and the filter's covariance honest: the ceiling the information sets for that check."""

from __future__ import annotations

import numpy as np

TOLERANCE = 0.05  # the per-rotor target of docs/real-data.md: every rotor within 5 % of its run mean
DRAWS = 20_000


def deviation_covariance(kf: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """Covariance of d_i = kf_i / mean(kf) - 1 (first order) from the covariance of the kf estimates."""
    kf = np.asarray(kf, dtype=float)
    n = kf.size
    mean = float(np.mean(kf))
    jac = np.eye(n) / mean - np.outer(kf, np.ones(n)) / (n * mean**2)
    return jac @ np.asarray(covariance, dtype=float) @ jac.T


def probability_all_within(covariance: np.ndarray, tolerance: float = TOLERANCE, draws: int = DRAWS,
                           seed: int = 0) -> float:
    """P(max_i |d_i| <= tolerance) for zero-mean Gaussian d with this (possibly singular) covariance."""
    cov = 0.5 * (covariance + covariance.T)
    values, vectors = np.linalg.eigh(cov)
    root = vectors * np.sqrt(np.clip(values, 0.0, None))
    samples = np.random.default_rng(seed).standard_normal((draws, cov.shape[0])) @ root.T
    return float(np.mean(np.max(np.abs(samples), axis=1) <= tolerance))


def spread_bound(kf: np.ndarray, covariance: np.ndarray, tolerance: float = TOLERANCE) -> dict:
    """The replay summary's entry: each rotor's deviation std, the probability that all are within tolerance, and
    the chi-squared of the observed deviations against their covariance (N - 1 degrees of freedom: the deviations
    sum to zero), which says whether the rotors differ by more than the filter's uncertainty."""
    kf = np.asarray(kf, dtype=float)
    deviation = deviation_covariance(kf, covariance)
    observed = kf / np.mean(kf) - 1.0
    return {"tolerance": tolerance,
            "deviation_std": [float(v) for v in np.sqrt(np.clip(np.diag(deviation), 0.0, None))],
            "p_every_rotor_within": probability_all_within(deviation, tolerance),
            "chi_squared": float(observed @ np.linalg.pinv(deviation) @ observed),
            "degrees_of_freedom": kf.size - 1}
