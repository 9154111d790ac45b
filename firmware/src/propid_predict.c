/* Prediction: forward-Euler step of the body rates (coefficients and biases are
 * random walks) and the sparse covariance propagation P := F P F^T + Q dt.
 *
 * F = I + dt A, and A is zero except for the 3 rate rows, whose bias columns are
 * zero too. So F P F^T differs from P only in the 3 rate rows and columns:
 *   T    = F_rate P            (3 x n: rate rows of F P)
 *   P_rr = T F_rate^T           (3 x 3 block)
 *   P_rj = T_j for every non-rate j (F's non-rate rows are identity rows).
 * Cost 3 m n + 6 m multiply-adds with m = 3 + 2N active Jacobian columns. */
#include <math.h>

#include "propid_internal.h"
#include "propid_model.h"

propid_status_t propid_predict_stage(const propid_filter_t *filter, float dt, float rate_next[3],
                                     float rate_jacobian_dt[3][PROPID_MAX_STATES])
{
    const propid_core_t *core = &filter->core;
    const uint8_t m = propid_first_bias(filter->config.rotor_count);
    float rate_dot[3];
    propid_model_rates(&filter->config, &filter->derived, core->state, core->rotor_speed_sq,
                       rate_dot, rate_jacobian_dt);
    /* One finiteness test on a running sum: NaN and Inf propagate through sums. */
    float check = 0.0f;
    for (uint8_t a = 0; a < 3u; ++a) {
        rate_next[a] = core->state[a] + dt * rate_dot[a];
        check += rate_next[a];
        for (uint8_t k = 0; k < m; ++k) {
            rate_jacobian_dt[a][k] *= dt;
            check += rate_jacobian_dt[a][k];
        }
    }
    const uint8_t n = filter->derived.state_count;
    for (uint8_t k = m; k < n; ++k) {
        check += core->state[k]; /* biases are read by the update */
    }
    if (!isfinite(check)) {
        return PROPID_ERR_NUMERIC;
    }
    return PROPID_OK;
}

void propid_predict_covariance(const propid_derived_t *derived, propid_core_t *core, float dt,
                               const float rate_jacobian_dt[3][PROPID_MAX_STATES])
{
    const uint8_t n = derived->state_count;
    const uint8_t m = (uint8_t)(n - PROPID_BIAS_STATES); /* active Jacobian columns */
    float (*cov)[PROPID_MAX_STATES] = core->cov;

    /* T = rate rows of F P = P_a + sum_k G_ak P_k. */
    float rows[3][PROPID_MAX_STATES];
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t j = 0; j < n; ++j) {
            rows[a][j] = cov[a][j];
        }
        for (uint8_t k = 0; k < m; ++k) {
            const float g = rate_jacobian_dt[a][k];
            const float *cov_k = cov[k];
            for (uint8_t j = 0; j < n; ++j) {
                rows[a][j] += g * cov_k[j];
            }
        }
    }
    /* Rate block: (T F^T)_ab = T_ab + sum_k T_ak G_bk, upper triangle then mirror. */
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = a; b < 3u; ++b) {
            float value = rows[a][b];
            for (uint8_t k = 0; k < m; ++k) {
                value += rows[a][k] * rate_jacobian_dt[b][k];
            }
            cov[a][b] = value;
            cov[b][a] = value;
        }
    }
    /* Cross terms with every non-rate state. */
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t j = 3u; j < n; ++j) {
            cov[a][j] = rows[a][j];
            cov[j][a] = rows[a][j];
        }
    }
    /* Q dt on the diagonal. */
    for (uint8_t k = 0; k < n; ++k) {
        cov[k][k] += derived->process_psd[k] * dt;
    }
}
