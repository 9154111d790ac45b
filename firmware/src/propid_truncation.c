/* A coefficient bound applied to the Gaussian, not only to the estimate
 * (docs/math.md §15). The filter's belief after an update is N(x, P); the bound
 * coeff_rel_min <= x_k <= coeff_rel_max says the truth is not beyond it. Setting
 * x_k to the bound alone (the plain clamp) undoes part of the update while P and
 * the correlated states still count it: the torque the filter then predicts is
 * off by an amount its covariance does not hold, and its innovations ramp.
 *
 * Here the Gaussian is truncated at the bound and replaced by the truncated
 * distribution's first two moments (PDF truncation): along x_k, with
 * s = sqrt(P_kk) and alpha = the distance beyond the bound in s,
 *
 *   lambda = phi(alpha) / Q(alpha)          (inverse Mills ratio, Q = 1 - Phi)
 *   x_k   -> x_k + lambda s                 (towards the inside; beyond the bound)
 *   P_kk  -> f P_kk,  f = 1 - lambda (lambda - alpha)   in (0, 1)
 *
 * and every other state moves by its regression on x_k (the Gaussian's
 * conditional): x_j += P_jk / P_kk * shift, P_ij -= P_ik P_jk / P_kk * (1 - f).
 * A rank-one downdate of P, so P stays positive semi-definite; the states the
 * update had moved together with x_k (the body rates, the other rotors'
 * coefficients) take back the part that belonged to it. Only on a sample whose
 * update left a coefficient outside its range: not on the usual step. */
#include <math.h>

#include "propid_internal.h"

/* Beyond this alpha Q(alpha) approaches float's smallest normal values; the
 * continued fraction of the Mills ratio is accurate to 1e-6 there with 6 terms. */
#define PROPID_TRUNCATION_SERIES_FROM 5.0f
/* Distances beyond this are taken as this (the variance factor is then ~1e-3:
 * the variance floor holds it anyway). */
#define PROPID_TRUNCATION_MAX_ALPHA 30.0f

/* lambda(alpha) = phi(alpha) / Q(alpha) for alpha >= 0. */
static float inverse_mills_ratio(float alpha)
{
    if (alpha < PROPID_TRUNCATION_SERIES_FROM) {
        const float phi = 0.39894228f * expf(-0.5f * alpha * alpha);
        const float q = 0.5f * erfcf(alpha * 0.70710678f);
        return phi / q;
    }
    /* lambda = alpha + 1/(alpha + 2/(alpha + 3/(alpha + ...))), evaluated from the tail. */
    float tail = alpha;
    for (uint8_t term = 6u; term >= 1u; --term) {
        tail = alpha + (float)term / tail;
    }
    return tail;
}

int propid_truncate_at_bound(const propid_derived_t *derived, propid_core_t *core, uint8_t k, float bound)
{
    const uint8_t n = derived->state_count;
    float *cov = core->cov;
    const float pkk = cov[propid_cov_index(k, k)];
    const float beyond = core->state[k] - bound; /* > 0 above an upper bound, < 0 below a lower one */
    if (!(pkk > 0.0f) || !isfinite(pkk) || !isfinite(beyond)) {
        core->state[k] = bound; /* no Gaussian to truncate: the plain clamp */
        return 0;
    }
    const float s = sqrtf(pkk);
    float alpha = fabsf(beyond) / s;
    if (alpha > PROPID_TRUNCATION_MAX_ALPHA) {
        alpha = PROPID_TRUNCATION_MAX_ALPHA;
    }
    const float lambda = inverse_mills_ratio(alpha);
    float keep = 1.0f - lambda * (lambda - alpha); /* truncated variance / P_kk */
    if (!(keep > 0.0f)) {
        keep = 0.0f; /* rounding at large alpha; the variance floor follows */
    }
    /* Truncated mean: lambda s inside from x_k; stays within the bound even if
     * alpha was capped (then the bound itself). */
    float shift = (beyond < 0.0f ? 1.0f : -1.0f) * lambda * s;
    if (fabsf(shift) < fabsf(beyond)) {
        shift = -beyond;
    }
    /* Column k of P (update_vector[0]: the update's P H^T, dead after it). */
    float *column = core->update_vector[0];
    for (uint8_t i = 0; i < n; ++i) {
        column[i] = propid_cov_at(cov, i, k);
    }
    const float truncated_mean = core->state[k] + shift;
    const float inv_pkk = 1.0f / pkk;
    const float step = shift * inv_pkk;
    const float downdate = (1.0f - keep) * inv_pkk;
    for (uint8_t i = 0; i < n; ++i) {
        core->state[i] += column[i] * step;
        const float gain = column[i] * downdate;
        float *cov_row = propid_cov_row(cov, i);
        for (uint8_t j = i; j < n; ++j) {
            cov_row[j] -= gain * column[j];
        }
    }
    /* The k-th state exactly as intended (the loop's x_k += P_kk shift / P_kk
     * rounds) and P_kk exactly keep * P_kk. */
    core->state[k] = truncated_mean;
    cov[propid_cov_index(k, k)] = keep * pkk;
    return 1;
}
