"""The float64 reference with the rate kept in the gyro's coordinate s = omega + b
(ReferenceFilter(..., rate_coordinate="gyro"); docs/math.md, "What it costs where the bias is
not learnt"): its loadings are those of an explicit propagation in (s, b), and on an
exact-speed hover the loading it adds to what the gyro measures is far below today's."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from propid.cfilter import FilterConfig
from propid.reference_filter import VAR_LOADING, ReferenceFilter


def quad_config(**overrides) -> FilterConfig:
    settings = dict(rate_process_noise=2e-5, thrust_coeff_rel_walk=0.0, drag_coeff_rel_walk=0.0,
                    gyro_bias_walk=0.0)
    settings.update(overrides)
    return FilterConfig.symmetric(4, 0.17, math.pi / 4, 1.0, 5.57e-6, 1.36e-7, [3.65e-3, 3.68e-3, 7.03e-3],
                                  **settings)


def gyro_map(filt: ReferenceFilter) -> np.ndarray:
    """S: (omega, b, rest) -> (s = omega + b, b, rest)."""
    s = np.eye(filt.n)
    for a in range(3):
        s[a, filt.first_bias + a] = 1.0
    return s


def explicit_gyro_propagation(filt: ReferenceFilter, cov: np.ndarray, jac_dt: np.ndarray, dt: float) -> np.ndarray:
    """The prediction written in (s, b): P_s = S P S^T, F_s = S F S^-1, every diagonal of the kept P_s
    loaded as the C prediction loads its kept P (the rates by l eps m_s times their row's scale,
    m_s = 1 + the s row's entries, the rest by eps, the drag block every second step), back to omega."""
    n = filt.n
    s = gyro_map(filt)
    s_inv = np.linalg.inv(s)
    f = np.eye(n)
    f[:3, :] += jac_dt
    f_s = s @ f @ s_inv
    p_s = s @ cov @ s.T
    entries = f_s[:3] - np.eye(n)[:3]  # the s rows' Jacobian entries
    terms = 1.0 + np.count_nonzero(entries, axis=1)
    scale = terms * np.maximum(terms, 8.0) * (np.diag(p_s)[:3] + (entries ** 2) @ np.diag(p_s))
    out = f_s @ p_s @ f_s.T
    loading = np.full(n, VAR_LOADING)
    if filt.check_row % 2 != 0:
        loading[filt.first_drag:filt.first_bias] = 0.0
    scaled = np.diag(out).copy()
    scaled[:3] = scale
    out[np.diag_indices(n)] += loading * scaled
    out += s @ np.diag(filt.process_psd * dt) @ s.T
    return s_inv @ out @ s_inv.T


def quad_jacobian(filt: ReferenceFilter, rng: np.random.Generator) -> np.ndarray:
    """The quad layout's rate rows: each rate on the other two, and on four coefficients."""
    jac = np.zeros((3, filt.n))
    for a in range(3):
        for b in range(3):
            if b != a:
                jac[a, b] = rng.normal(scale=1e-3)
        jac[a, 3:3 + 4] = rng.normal(scale=10.0, size=4) if a < 2 else 0.0
        if a == 2:
            jac[a, filt.first_drag:filt.first_drag + 4] = rng.normal(scale=10.0, size=4)
    return jac


@pytest.mark.parametrize("check_row", [0, 1])
def test_gyro_coordinate_loadings_are_those_of_an_explicit_propagation_in_s(check_row):
    filt = ReferenceFilter(quad_config(), rate_coordinate="gyro")
    assert list(filt.rate_terms + filt.rate_entries) == [9.0, 9.0, 9.0]  # 1 + 2 rates + 2 biases + 4
    rng = np.random.default_rng(10 + check_row)
    root = rng.normal(size=(filt.n, filt.n)) * np.sqrt(np.concatenate([np.full(3, 1e-4), np.full(8, 1e-3),
                                                                         np.full(3, 1e-4)]))
    cov = root @ root.T + np.diag(np.full(filt.n, 1e-9))
    jac = quad_jacobian(filt, rng)
    filt.cov, filt.check_row = cov.copy(), check_row
    filt._propagate_covariance(jac, 0.002)
    expected = explicit_gyro_propagation(filt, cov, jac, 0.002)
    np.testing.assert_allclose(filt.cov, expected, rtol=1e-9, atol=1e-12 * np.max(np.abs(expected)))
    # and not those of today's (body-coordinate) loadings, which differ by far more than that
    body = ReferenceFilter(quad_config())
    body.cov, body.check_row = cov.copy(), check_row
    body._propagate_covariance(jac, 0.002)
    assert np.max(np.abs(np.diag(body.cov - expected))[:3] / np.diag(expected)[:3]) > 1e-6


def hover(rate_coordinate: str, seconds: float) -> ReferenceFilter:
    """An exact-speed hover: equal rotor speeds, a constant gyro bias with white noise the size of
    the configured density; the gyroscopic signal is nil, so the bias stays at its prior."""
    filt = ReferenceFilter(quad_config(), rate_coordinate=rate_coordinate)
    rng = np.random.default_rng(7)
    sigma = math.sqrt(filt.gyro_var)
    bias = np.array([0.004, -0.006, 0.002])
    for k in range(int(seconds * 500) + 1):
        t_us = 2000 * k
        filt.push_rotor_speeds(t_us, [1200.0] * 4)
        filt.push_gyro(t_us, (bias + rng.normal(scale=sigma, size=3)).tolist())
    return filt


def measured_variance_loading(filt: ReferenceFilter) -> np.ndarray:
    """What one prediction's loadings add to var(omega_a + b_a), the variance the gyro measures."""
    loaded, plain = copy.deepcopy(filt), copy.deepcopy(filt)
    plain.var_loading = 0.0
    jac = np.zeros((3, filt.n))
    for f in (loaded, plain):
        f._propagate_covariance(jac, 0.002)
    s = gyro_map(filt)
    return np.diag(s @ (loaded.cov - plain.cov) @ s.T)[:3]


def test_on_an_exact_speed_hover_the_gyro_coordinate_does_not_load_what_the_gyro_measures():
    """Today the rates are loaded by 56 eps of var(omega_a) ~ var(b_a) (the bias unlearnt), which is
    rate process noise on omega + b; in the gyro's coordinate by 81 eps of var(omega + b) (m_s = l = 9), and each bias's
    eps with omega + b held."""
    body, gyro = hover("body", 1.0), hover("gyro", 1.0)
    bias = slice(body.first_bias, body.first_bias + 3)
    bias_var = np.diag(body.cov)[bias]
    assert np.all(bias_var > 0.5 * body.prior_var[bias])  # not learnt
    body_load, gyro_load = measured_variance_loading(body), measured_variance_loading(gyro)
    measured_var = np.diag(gyro_map(gyro) @ gyro.cov @ gyro_map(gyro).T)[:3]
    assert np.all(measured_var < 1e-2 * bias_var)
    # (today the bias's own eps of var(b) reaches omega + b as well)
    np.testing.assert_allclose(body_load, VAR_LOADING * (56.0 * np.diag(body.cov)[:3] + bias_var), rtol=1e-6)
    assert np.all(body_load > 40.0 * VAR_LOADING * bias_var)
    np.testing.assert_allclose(gyro_load, 81.0 * VAR_LOADING * measured_var, rtol=1e-6)
    assert np.all(gyro_load < 1e-2 * body_load)
    # What that loading costs: the combinations the hover learns (the kf's roll- and pitch-torque
    # elements, the km's yaw-torque element) keep about twice the std they have without it
    # (measured 0.49 / 0.49 / 0.48 of today's); the estimates stay within 0.2 of today's std.
    body_std, gyro_std = np.sqrt(np.diag(body.cov)), np.sqrt(np.diag(gyro.cov))
    learnt = [3, 4, body.first_drag]
    assert np.all(gyro_std[learnt] < 0.6 * body_std[learnt])
    assert np.all(np.abs(gyro.state - body.state) < 0.2 * body_std)


def test_an_unknown_rate_coordinate_is_refused():
    with pytest.raises(ValueError, match="rate_coordinate"):
        ReferenceFilter(quad_config(), rate_coordinate="omega")
