/* Prediction: forward-Euler step of the body rates (coefficients and biases are
 * random walks) and the sparse covariance propagation P := F P F^T + Q dt.
 *
 * F = I + G with G = dt A, and A is zero except for the 3 rate rows, and within
 * them only at the entries propid_config.c found structurally non-zero
 * (derived->jac_column). So F P F^T differs from P only in the 3 rate rows and
 * columns:
 *   T    = F_rate P = P_rate + G P      (3 x n: rate rows of F P; G sparse)
 *   P_rr = T F_rate^T = T_rr + T G^T    (3 x 3 block)
 *   P_rj = T_j for every non-rate j     (F's non-rate rows are identity rows)
 * Cost: (nnz(G) + 3) n + nnz(G) multiply-adds; nnz(G) = 12 for a plus quad,
 * 18 for an X quad (diagonal inertia). */
#include <math.h>

#include "propid_internal.h"

propid_status_t propid_predict_stage(const propid_filter_t *filter, float dt, float rate_next[3],
                                     float jacobian_dt[3][PROPID_MAX_STATES])
{
    const propid_derived_t *derived = &filter->derived;
    const float *state = filter->core.state;
    const uint8_t rotor_count = filter->config.rotor_count;
    const float rate[3] = {state[0], state[1], state[2]};
    /* dt u_i with u_i the trapezoid mean of the input at the start of the interval
     * and the latest one: holding only the latest over the interval leaves a model
     * error that, on agile flights, swamps the small process noise the gyro-bias
     * observability needs (docs/math.md, "Input over the interval"). */
    float speed_sq_dt[PROPID_MAX_ROTORS];
    const float half_dt = 0.5f * dt;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        speed_sq_dt[i] = half_dt * (filter->core.input_speed_sq[i] + filter->core.rotor_speed_sq[i]);
    }
    const uint8_t n = derived->state_count;
    float check = 0.0f;
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t rate_count = derived->jac_rate_count[a];
        const uint8_t count = derived->jac_count[a];
        const uint8_t *column = derived->jac_column[a];
        float *g = jacobian_dt[a];
        /* Gyroscopic part: A_ab = sum_c gyro_jacobian[a][b][c] omega_c, and since the
         * gyroscopic torque is quadratic in omega, its acceleration is A_rr omega / 2. */
        float gyroscopic = 0.0f;
        for (uint8_t p = 0; p < rate_count; ++p) {
            const float *coeff = derived->gyro_jacobian[a][column[p]];
            const float entry = dt * (coeff[0] * rate[0] + coeff[1] * rate[1] + coeff[2] * rate[2]);
            gyroscopic += entry * rate[column[p]];
            g[p] = entry;
        }
        /* Rotor torques: G = torque dt u, velocity change sum G x_coefficient. */
        float rotors = 0.0f;
        const float *torque = derived->jac_torque[a];
        const uint8_t *rotor = derived->jac_rotor[a];
        for (uint8_t p = rate_count; p < count; ++p) {
            const float entry = torque[p] * speed_sq_dt[rotor[p]];
            rotors += entry * state[column[p]];
            g[p] = entry;
        }
        /* omega + dt f: the G entries already carry dt. */
        rate_next[a] = rate[a] + (rotors + 0.5f * gyroscopic);
        /* A non-finite G entry makes its product in `gyroscopic` or `rotors`
         * non-finite (Inf times anything is Inf or NaN), so testing the sums tests
         * every entry. */
        check += rate_next[a] + gyroscopic + rotors;
    }
    /* One finiteness test on a running sum (NaN and Inf propagate through sums),
     * covering every state the step reads. */
    for (uint8_t k = 0; k < n; ++k) {
        check += state[k];
    }
    if (!isfinite(check)) {
        return PROPID_ERR_NUMERIC;
    }
    return PROPID_OK;
}

/* The propagation for a given state count, defined twice by this macro: for the
 * quad (n constant, loops over the state fully unrolled by PROPID_UNROLL, addresses
 * folded into immediates) and for any n (plain loops, small code). */
#define PROPID_DEFINE_PREDICT(name, UNROLL)                                                     \
static inline __attribute__((always_inline)) void name(                                          \
                 const propid_derived_t *derived, float (*cov)[PROPID_MAX_STATES], float dt,   \
                 const float jacobian_dt[3][PROPID_MAX_STATES], const uint8_t n)               \
{                                                                                               \
    /* T = rate rows of F P = P_a + sum_p G_ap P_(column p). */                                 \
    float rows[3][PROPID_MAX_STATES];                                                           \
    for (uint8_t a = 0; a < 3u; ++a) {                                                          \
        float acc[PROPID_MAX_STATES]; /* registers in the unrolled quad copy */                 \
        const float *own = cov[a];                                                              \
UNROLL                                                                                          \
        for (uint8_t j = 0; j < n; ++j) {                                                       \
            acc[j] = own[j];                                                                    \
        }                                                                                       \
        const uint8_t count = derived->jac_count[a];                                            \
        for (uint8_t p = 0; p < count; ++p) {                                                   \
            const float g = jacobian_dt[a][p];                                                  \
            const float *source = cov[derived->jac_column[a][p]];                               \
UNROLL                                                                                          \
            for (uint8_t j = 0; j < n; ++j) {                                                   \
                acc[j] += g * source[j];                                                        \
            }                                                                                   \
        }                                                                                       \
        float *row = rows[a];                                                                   \
UNROLL                                                                                          \
        for (uint8_t j = 0; j < n; ++j) {                                                       \
            row[j] = acc[j];                                                                    \
        }                                                                                       \
    }                                                                                           \
    /* Rate block: (T F^T)_ab = T_ab + sum_p T_a,(column p of row b) G_bp, one                  \
     * triangle, both halves written from the same value; Q dt on its diagonal. */              \
    for (uint8_t b = 0; b < 3u; ++b) {                                                          \
        const uint8_t count = derived->jac_count[b];                                            \
        const uint8_t *column = derived->jac_column[b];                                         \
        const float *g = jacobian_dt[b];                                                        \
        for (uint8_t a = 0; a <= b; ++a) {                                                      \
            const float *row = rows[a];                                                         \
            float value = row[b];                                                               \
            for (uint8_t p = 0; p < count; ++p) {                                               \
                value += row[column[p]] * g[p];                                                 \
            }                                                                                   \
            if (a == b) {                                                                       \
                value += derived->process_psd[b] * dt;                                          \
            }                                                                                   \
            cov[a][b] = value;                                                                  \
            cov[b][a] = value;                                                                  \
        }                                                                                       \
    }                                                                                           \
    /* Cross terms with every non-rate state; Q dt on the other diagonals. */                   \
UNROLL                                                                                          \
    for (uint8_t j = 3u; j < n; ++j) {                                                          \
        const float t0 = rows[0][j];                                                            \
        const float t1 = rows[1][j];                                                            \
        const float t2 = rows[2][j];                                                            \
        float *row_j = cov[j];                                                                  \
        cov[0][j] = t0;                                                                         \
        cov[1][j] = t1;                                                                         \
        cov[2][j] = t2;                                                                         \
        row_j[0] = t0;                                                                          \
        row_j[1] = t1;                                                                          \
        row_j[2] = t2;                                                                          \
        row_j[j] += derived->process_psd[j] * dt;                                               \
    }                                                                                           \
}

PROPID_DEFINE_PREDICT(predict_covariance_quad, PROPID_UNROLL_QUAD)
PROPID_DEFINE_PREDICT(predict_covariance_any, PROPID_NO_UNROLL)

void propid_predict_covariance(const propid_derived_t *derived, propid_core_t *core, float dt,
                               const float jacobian_dt[3][PROPID_MAX_STATES])
{
    const uint8_t n = derived->state_count;
    if (n == PROPID_QUAD_STATES) {
        predict_covariance_quad(derived, core->cov, dt, jacobian_dt, PROPID_QUAD_STATES);
    } else {
        predict_covariance_any(derived, core->cov, dt, jacobian_dt, n);
    }
}
