/* Prediction: the body rates' step (the rotor torques, linear in the state, with
 * the trapezoid input; Heun on the gyroscopic term; coefficients and biases are
 * random walks) and the sparse covariance propagation
 * P := F P F^T + Q dt + the rounding loading (propid_internal.h: every
 * prediction on the rate variances, every second one on the rest).
 *
 * F = I + G with G = dt A, and A is zero except for the 3 rate rows, and within
 * them only at the entries propid_config.c found structurally non-zero
 * (derived->jac_column). So F P F^T differs from P only in the 3 rate rows and
 * columns:
 *   T    = F_rate P = P_rate + G P      (3 x n: rate rows of F P; G sparse)
 *   P_rr = T F_rate^T = T_rr + T G^T    (3 x 3 block)
 *   P_rj = T_j for every non-rate j     (F's non-rate rows are identity rows)
 * Cost: nnz(G) n + O(nnz(G)) multiply-adds; nnz(G) = 14 for a plus quad, 18 for
 * an X quad (diagonal inertia), 18 for both in the fixed quad layout
 * (propid_internal.h), which has straight-line kernels here. Only the upper
 * triangle of P is stored, packed (propid_cov_at). */
#include <math.h>

#include "propid_internal.h"
#include "propid_quad_predict.h"
#include "propid_quad_model.h"

/* The fast quad build (no general path, straight-line kernels inlined): its
 * step's prediction runs both kernels in one frame (propid_predict_step); the
 * covariance dispatcher below is not compiled there. */
#define PROPID_FAST_QUAD_PREDICT (!PROPID_GENERAL_VEHICLES && !PROPID_SIZE_LEAN)
#if PROPID_FAST_QUAD_PREDICT && PROPID_WITH_INPUT_NOISE
#error "the fast quad build's prediction has no input-noise term"
#endif

/* Rare path of the prediction's finiteness and bound test: PROPID_ERR_NUMERIC
 * when a rate or `check` is not finite, else every rate bounded to +-limit and
 * PROPID_PREDICT_CLAMPED (or PROPID_OK when none was beyond it). */
#if PROPID_FAST_QUAD_PREDICT
/* Two callers there (the step and propid_predict_stage): kept inline in the step
 * as when it was the only one (a call and 20 instructions per step otherwise). */
#define PROPID_BOUND_RATES_INLINE inline __attribute__((always_inline))
#else
#define PROPID_BOUND_RATES_INLINE
#endif
static PROPID_BOUND_RATES_INLINE propid_status_t bound_rates(float rate_next[3], float limit, float check)
{
    if (!isfinite(rate_next[0] + rate_next[1] + rate_next[2] + check)) {
        return PROPID_ERR_NUMERIC;
    }
    propid_status_t status = PROPID_OK;
    /* (Unrolled: constant indices keep an inlined caller's rates in registers.) */
PROPID_UNROLL(3)
    for (uint8_t a = 0; a < 3u; ++a) {
        if (fabsf(rate_next[a]) > limit) {
            rate_next[a] = rate_next[a] > 0.0f ? limit : -limit;
            status = PROPID_PREDICT_CLAMPED;
        }
    }
    return status;
}

/* The quad model stage's end: the predicted rates' bound test, which is their
 * finiteness test too (predict_stage_quad). */
static inline __attribute__((always_inline)) propid_status_t
quad_stage_bound(float *restrict rate_next, float rate_limit, float check)
{
    if (!(fabsf(rate_next[0]) <= rate_limit) || !(fabsf(rate_next[1]) <= rate_limit) ||
        !(fabsf(rate_next[2]) + 0.0f * check <= rate_limit)) {
        return bound_rates(rate_next, rate_limit, check);
    }
    return PROPID_OK;
}

/* propid_predict_stage for the quad layout (propid_internal.h): the same values
 * as the general loop below over the same lists (whose other two gyroscopic
 * products are exact zeros here), straight-line. Takes the arrays it reads as
 * separate pointers: in the full build, offsets from the filter's base exceed
 * the 1 KiB reach of a VFP load, each would cost an extra address computation
 * (the quad build inlines it: PROPID_QUAD_INLINE). */
static PROPID_QUAD_INLINE propid_status_t
predict_stage_quad(const float *restrict state, const float *restrict input_speed_sq,
                   const float *restrict latest_speed_sq, const float *restrict quad_gyro,
                   const float (*restrict jac_torque)[PROPID_JAC_TORQUE_ROW],
                   const float *restrict drag_basis, float drag_basis_scale,
                   const float *restrict thrust_basis,
                   float dt,
                   float rate_limit, float *restrict rate_next,
                   float (*restrict jacobian_dt)[PROPID_JAC_ROW])
{
    const float rate[3] = {state[0], state[1], state[2]};
    const float half_dt = 0.5f * dt;
    float speed_sq_dt[4];
PROPID_UNROLL(4)
    for (uint8_t i = 0; i < 4u; ++i) {
        speed_sq_dt[i] = half_dt * (input_speed_sq[i] + latest_speed_sq[i]);
    }
    /* Heun on the gyroscopic term (docs/math.md §2): the rotor part is linear in
     * the state with the trapezoid input already; the gyroscopic acceleration is
     * evaluated at omega and at the Euler predictor and averaged. */
    float rotors[3];
    float gyroscopic[3];
    float predictor[3];
PROPID_UNROLL(3)
    for (uint8_t a = 0; a < 3u; ++a) {
        float *g = jacobian_dt[a];
        const uint8_t other0 = a == 0u ? 1u : 0u;
        const uint8_t other1 = a == 2u ? 1u : 2u;
        /* A_a,other0 depends on the third rate, which is other1, and vice versa
         * (the general loop's other two products are exact zeros). */
        const float entry0 = dt * (quad_gyro[a] * rate[other1]);
        const float entry1 = dt * (quad_gyro[a] * rate[other0]);
        gyroscopic[a] = entry0 * rate[other0] + entry1 * rate[other1];
        const float *coefficient = state + (a < 2u ? PROPID_QUAD_FIRST_THRUST : PROPID_QUAD_FIRST_DRAG);
        const float *torque = jac_torque[a];
        float entry[4];
PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            entry[i] = torque[PROPID_QUAD_TORQUE_FIRST + i] * speed_sq_dt[i];
        }
        if (a < 2u) {
            /* The thrust entries times Q^T (Q e = H_1 H_0 e, H = I - w w^T): the row
             * over the torque-basis states (propid_internal.h, propid_thrust_basis). */
            const float *w = thrust_basis;
            const float along0 = entry[0] * w[0] + entry[1] * w[1] + entry[2] * w[2] + entry[3] * w[3];
PROPID_UNROLL(4)
            for (uint8_t i = 0; i < 4u; ++i) {
                entry[i] -= along0 * w[i];
            }
            w = thrust_basis + PROPID_MAX_ROTORS; /* H_1, elements 1..3 */
            const float along1 = entry[1] * w[0] + entry[2] * w[1] + entry[3] * w[2];
PROPID_UNROLL(3)
            for (uint8_t i = 1; i < 4u; ++i) {
                entry[i] -= along1 * w[i - 1u];
            }
        } else {
            /* The drag entries times H: the yaw row over the yaw-basis states
             * (propid_internal.h, propid_reflection_apply). */
            const float along = drag_basis_scale * (entry[0] * drag_basis[0] + entry[1] * drag_basis[1] +
                                                    entry[2] * drag_basis[2] + entry[3] * drag_basis[3]);
PROPID_UNROLL(4)
            for (uint8_t i = 0; i < 4u; ++i) {
                entry[i] -= along * drag_basis[i];
            }
        }
        float sum = 0.0f;
PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            sum += entry[i] * coefficient[i];
            g[2u + i] = entry[i];
        }
        rotors[a] = sum;
        predictor[a] = rate[a] + (sum + 0.5f * gyroscopic[a]); /* the Euler step */
    }
PROPID_UNROLL(3)
    for (uint8_t a = 0; a < 3u; ++a) {
        float *g = jacobian_dt[a];
        const uint8_t other0 = a == 0u ? 1u : 0u;
        const uint8_t other1 = a == 2u ? 1u : 2u;
        const float entry0 = dt * (quad_gyro[a] * predictor[other1]);
        const float entry1 = dt * (quad_gyro[a] * predictor[other0]);
        const float corrector = entry0 * predictor[other0] + entry1 * predictor[other1];
        /* The rate block of F: the gyroscopic Jacobian at the midpoint of omega and
         * the predictor (it is linear in omega, so this is the mean of the two). */
        g[0] = 0.5f * (entry0 + dt * (quad_gyro[a] * rate[other1]));
        g[1] = 0.5f * (entry1 + dt * (quad_gyro[a] * rate[other0]));
        rate_next[a] = rate[a] + (rotors[a] + 0.25f * (gyroscopic[a] + corrector));
    }
    /* rate_next holds every rate, the rotor sums and the correctors, and through
     * a product every coefficient and Jacobian entry (each coefficient appears in
     * at least one row; a zero times a non-finite value is NaN): its bound test
     * (NaN fails it) is their finiteness test. The biases join the last test as
     * 0 * sum: exactly zero when finite, NaN otherwise. */
    const float check = state[PROPID_QUAD_FIRST_BIAS] + state[PROPID_QUAD_FIRST_BIAS + 1u] +
                        state[PROPID_QUAD_FIRST_BIAS + 2u];
    return quad_stage_bound(rate_next, rate_limit, check);
}

#if PROPID_GENERAL_VEHICLES
/* Any vehicle and any optional term, over the sparsity lists. Not inlined: its
 * frame stays off the quad path's stack. */
static __attribute__((noinline)) propid_status_t
predict_stage_any(const propid_filter_t *filter, float dt, float rate_next[3],
                  float jacobian_dt[3][PROPID_JAC_ROW])
{
    const propid_derived_t *derived = &filter->derived;
    const float *state = filter->core.state;
    const uint8_t rotor_count = filter->config.rotor_count;
    const float rate[3] = {state[0], state[1], state[2]};
    /* dt u_i with u_i the trapezoid mean of the input at the start of the interval
     * and the latest one: holding only the latest over the interval leaves a model
     * error that, on agile flights, swamps the small process noise the gyro-bias
     * observability needs (docs/math.md, "Input over the interval"). */
    float speed_sq_dt[PROPID_MAX_ROTORS + 1u] = {0.0f}; /* (entries past rotor_count + 1 are never read) */
    const float half_dt = 0.5f * dt;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        speed_sq_dt[i] = half_dt * (filter->core.input_speed_sq[i] + filter->core.rotor_speed_sq[i]);
    }
    speed_sq_dt[rotor_count] = dt; /* the disturbance's input slot (propid_config.c) */
    /* Rotor inertia (docs/math.md §8): the yaw reaction integrates exactly to
     * rotor_reaction_i (Omega_i(end) - Omega_i(start)) over the interval; the
     * rotors' angular momentum h (trapezoid mean of the speeds) makes a
     * gyroscopic torque linear in omega, A_ab += rotor_gyro[a][b] h. */
    float reaction[3] = {0.0f, 0.0f, 0.0f};
    float momentum_dt = 0.0f;
#if PROPID_WITH_ROTOR_INERTIA
    if (derived->rotor_inertia_on) {
        for (uint8_t i = 0; i < rotor_count; ++i) {
            const float start = sqrtf(filter->core.input_speed_sq[i]);
            const float end = sqrtf(filter->core.rotor_speed_sq[i]);
            momentum_dt += derived->rotor_momentum[i] * (start + end);
            for (uint8_t a = 0; a < 3u; ++a) {
                reaction[a] += derived->rotor_reaction[i][a] * (end - start);
            }
        }
        momentum_dt *= half_dt;
    }
#endif
    /* Aerodynamic damping (docs/math.md §17): A_ab += aero_damping[a][b], in the
     * rows' rate entries (propid_config.c lists them). */
    const float damping_dt = propid_aero_damping_on(derived) ? dt : 0.0f;
    const uint8_t n = derived->state_count;
    const propid_reflection_t basis = propid_drag_basis(derived, &filter->config);
    propid_thrust_basis_t thrust_basis;
    propid_thrust_basis_init(&thrust_basis, derived, &filter->config);
    float check = 0.0f;
    float rotors[3];
    float gyroscopic[3];
    float predictor[3];
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t rate_count = derived->jac_rate_count[a];
        const uint8_t count = derived->jac_count[a];
        const uint8_t *column = derived->jac_column[a];
        float *g = jacobian_dt[a];
        /* Gyroscopic part: A_ab = sum_c gyro_jacobian[a][b][c] omega_c, and since the
         * gyroscopic torque is quadratic in omega, its acceleration is A_rr omega / 2. */
        float sum = 0.0f;
        for (uint8_t p = 0; p < rate_count; ++p) {
            const float *coeff = derived->gyro_jacobian[a][column[p]];
            const float entry = dt * (coeff[0] * rate[0] + coeff[1] * rate[1] + coeff[2] * rate[2]);
            /* The rotor term is linear in omega: twice its share in this sum,
             * which holds twice the (quadratic) gyroscopic acceleration. */
            const float rotor_entry = column[p] < 2u ? propid_rotor_gyro(derived, a, column[p]) * momentum_dt : 0.0f;
            sum += (entry + 2.0f * rotor_entry) * rate[column[p]];
            g[p] = entry + rotor_entry;
        }
        if (damping_dt != 0.0f) {
            /* Aerodynamic damping, linear in omega like the rotor term (twice its
             * share in the sum). Its own pass: the plain step pays one test. */
            for (uint8_t p = 0; p < rate_count; ++p) {
                const float damping = propid_aero_damping_entry(derived, a, column[p]) * damping_dt;
                sum += 2.0f * damping * rate[column[p]];
                g[p] += damping;
            }
        }
        gyroscopic[a] = sum;
        /* Rotor torques: G = torque dt u, velocity change sum G x_coefficient.
         * (With the thrust-torque scale the thrust states carry s kf: math.md §9.) */
        sum = 0.0f;
        uint8_t drag_entry = count;
        uint8_t thrust_entry = count;
        const float *torque = derived->jac_torque[a];
        const uint8_t *rotor = derived->jac_rotor[a];
        for (uint8_t p = rate_count; p < count; ++p) {
            const float entry = torque[p] * speed_sq_dt[rotor[p]];
            g[p] = entry;
            if (column[p] >= derived->layout.drag && column[p] < derived->layout.gyro_bias) {
                drag_entry = drag_entry < p ? drag_entry : p; /* summed in the yaw basis below */
                continue;
            }
            if (column[p] >= derived->layout.thrust && column[p] < derived->layout.drag) {
                thrust_entry = thrust_entry < p ? thrust_entry : p; /* in the torque basis below */
                continue;
            }
            sum += entry * state[column[p]];
        }
        /* The row's thrust entries (all N, contiguous, rotor order: propid_config.c)
         * times Q^T: the row over the torque-basis states. */
        if (thrust_entry < count) {
            propid_thrust_to_basis(&thrust_basis, &g[thrust_entry]);
            const float *z = &state[derived->layout.thrust];
            for (uint8_t i = 0; i < rotor_count; ++i) {
                sum += g[thrust_entry + i] * z[i];
            }
        }
        /* The row's drag entries (all N, contiguous, rotor order: propid_config.c)
         * times H: the row over the yaw-basis states z (propid_internal.h). */
        if (drag_entry < count) {
            propid_reflection_apply(&basis, &g[drag_entry]);
            const float *z = &state[derived->layout.drag];
            for (uint8_t i = 0; i < rotor_count; ++i) {
                sum += g[drag_entry + i] * z[i];
            }
        }
        rotors[a] = sum + reaction[a];
        /* The Euler step omega + dt f (the G entries already carry dt). */
        predictor[a] = rate[a] + (rotors[a] + 0.5f * gyroscopic[a]);
    }
    /* Heun on the gyroscopic term (docs/math.md §2): its acceleration again at
     * the predictor, averaged; the rate block of F is the gyroscopic Jacobian at
     * the midpoint (the mean of the two: it is linear in omega). */
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t rate_count = derived->jac_rate_count[a];
        const uint8_t *column = derived->jac_column[a];
        float *g = jacobian_dt[a];
        float corrector = 0.0f;
        for (uint8_t p = 0; p < rate_count; ++p) {
            const float *coeff = derived->gyro_jacobian[a][column[p]];
            const float entry = dt * (coeff[0] * predictor[0] + coeff[1] * predictor[1] +
                                      coeff[2] * predictor[2]);
            const float rotor_entry = column[p] < 2u ? propid_rotor_gyro(derived, a, column[p]) * momentum_dt : 0.0f;
            corrector += (entry + 2.0f * rotor_entry) * predictor[column[p]];
            g[p] = 0.5f * (entry + g[p] + rotor_entry); /* g[p] held entry(omega) + rotor_entry */
        }
        if (damping_dt != 0.0f) {
            /* g[p] held the damping entry L too, halved above: L in full. */
            for (uint8_t p = 0; p < rate_count; ++p) {
                const float damping = propid_aero_damping_entry(derived, a, column[p]) * damping_dt;
                corrector += 2.0f * damping * predictor[column[p]];
                g[p] += 0.5f * damping;
            }
        }
        rate_next[a] = rate[a] + (rotors[a] + 0.25f * (gyroscopic[a] + corrector));
        /* A non-finite G entry makes its product in a sum non-finite (Inf times
         * anything is Inf or NaN), so testing the sums tests every entry. */
        check += rate_next[a] + gyroscopic[a] + corrector + rotors[a];
    }
    /* One finiteness test on a running sum (NaN and Inf propagate through sums),
     * covering every state the step reads. */
    for (uint8_t k = 0; k < n; ++k) {
        check += state[k];
    }
    return bound_rates(rate_next, derived->rate_limit, check);
}
#endif

/* Not inlined into propid_predict_step (same file): the dispatcher's tail call
 * keeps the kernels' frames apart from the step's (the size-lean build's chain).
 * The fast quad build's step inlines the stage itself and never calls this; it is
 * still compiled there for the dense baseline of make bench (tests/qemu/dense_ekf.c)
 * and the model tests, and --gc-sections drops it from a linked application. */
__attribute__((noinline)) propid_status_t propid_predict_stage(const propid_filter_t *filter, float dt, float rate_next[3],
                                     float jacobian_dt[3][PROPID_JAC_ROW])
{
#if PROPID_GENERAL_VEHICLES
    if (!filter->derived.quad_layout) {
        return predict_stage_any(filter, dt, rate_next, jacobian_dt);
    }
#endif
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, &filter->config);
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, &filter->config);
    return predict_stage_quad(filter->core.state, filter->core.input_speed_sq,
                              filter->core.rotor_speed_sq, filter->derived.quad_gyro,
                              filter->derived.jac_torque, basis.vector, basis.scale,
                              filter->derived.thrust_basis, dt,
                              propid_rate_limit(filter), rate_next, jacobian_dt);
}

#if PROPID_GENERAL_VEHICLES
/* The propagation for any vehicle and state count over the sparsity lists
 * (plain loops, small code; the quad layout has its straight-line kernel below). */
static __attribute__((noinline)) void predict_covariance_any(
                 const propid_derived_t *derived, float *cov, float dt,
                 const float jacobian_dt[3][PROPID_JAC_ROW], const uint8_t n, float drag_factor)
{
    /* T = rate rows of F P = P_a + sum_p G_ap P_(column p). */
    float rows[3][PROPID_MAX_STATES];
    /* Each rate variance is loaded by eps l m (P_aa + sum_p (G_ap dt)^2 P_(column p)),
     * m = 1 + the row's entries, l = max(8, m) (docs/math.md §2, "The rate block's
     * loading"): by Cauchy-Schwarz at least l eps (|F| |P| |F|^T)_aa, above what the
     * rounding of this prediction (at most about m eps of that) can take from it. */
    float scale[3];
    for (uint8_t a = 0; a < 3u; ++a) {
        float *acc = rows[a];
        /* Row `a` of the stored triangle: column a above the diagonal, then the row. */
        for (uint8_t j = 0; j < a; ++j) {
            acc[j] = cov[propid_cov_index(j, a)];
        }
        const float *row_a = propid_cov_row_const(cov, a);
        for (uint8_t j = a; j < n; ++j) {
            acc[j] = row_a[j];
        }
        float squares = row_a[a];
        const uint8_t count = derived->jac_count[a];
        const uint8_t *column = derived->jac_column[a];
        /* Two entries at a time (the lists are ascending: propid_config.c): each
         * element of T loaded and stored once per pair, the same multiply-adds in
         * the same order as one entry at a time. */
        uint8_t p = 0;
        for (; p + 1u < count; p += 2u) {
            const float g1 = jacobian_dt[a][p];
            const float g2 = jacobian_dt[a][p + 1u];
            const uint8_t s1 = column[p];
            const uint8_t s2 = column[p + 1u];
            if (s2 >= n || s1 >= s2) { /* never (propid_config.c): one at a time below */
                break;
            }
            const float *row1 = propid_cov_row_const(cov, s1);
            const float *row2 = propid_cov_row_const(cov, s2);
            squares += g1 * g1 * row1[s1];
            squares += g2 * g2 * row2[s2];
            uint32_t above1 = s1;
            uint32_t above2 = s2;
            uint8_t j = 0;
            for (; j < s1; ++j) { /* both above the diagonal: down their columns */
                float value = acc[j];
                value += g1 * cov[above1];
                value += g2 * cov[above2];
                acc[j] = value;
                above1 += PROPID_MAX_STATES - 1u - j;
                above2 += PROPID_MAX_STATES - 1u - j;
            }
            for (; j < s2; ++j) { /* along row s1, down column s2 */
                float value = acc[j];
                value += g1 * row1[j];
                value += g2 * cov[above2];
                acc[j] = value;
                above2 += PROPID_MAX_STATES - 1u - j;
            }
            for (; j < n; ++j) { /* along both rows */
                float value = acc[j];
                value += g1 * row1[j];
                value += g2 * row2[j];
                acc[j] = value;
            }
        }
        for (; p < count; ++p) {
            const float g = jacobian_dt[a][p];
            const uint8_t source = derived->jac_column[a][p];
            if (source >= n) { /* never (propid_config.c); bounds the index for the compiler */
                continue;
            }
            /* P_(source, j) from the stored triangle, without a branch per element: down
             * column `source` above the diagonal (the packed step shrinks by one per row),
             * then along row `source`. */
            uint32_t above = source;
            for (uint8_t j = 0; j < source; ++j) {
                acc[j] += g * cov[above];
                above += PROPID_MAX_STATES - 1u - j;
            }
            const float *row_source = propid_cov_row_const(cov, source);
            squares += g * g * row_source[source];
            for (uint8_t j = source; j < n; ++j) {
                acc[j] += g * row_source[j];
            }
        }
        const uint32_t terms = count + 1u;
        scale[a] = (float)(terms * (terms > 8u ? terms : 8u)) * squares;
    }
    /* Rate block: (T F^T)_ab = T_ab + sum_p T_a,(column p of row b) G_bp, upper
     * triangle; Q dt on its diagonal. */
    for (uint8_t b = 0; b < 3u; ++b) {
        const uint8_t count = derived->jac_count[b];
        const uint8_t *column = derived->jac_column[b];
        const float *g = jacobian_dt[b];
        for (uint8_t a = 0; a <= b; ++a) {
            const float *row = rows[a];
            float value = row[b];
            for (uint8_t p = 0; p < count; ++p) {
                value += row[column[p]] * g[p];
            }
            if (a == b) { /* Q dt and the rate block's rounding loading (above) */
                value += PROPID_VAR_LOADING * scale[b] + propid_process_psd(derived, b) * dt;
            }
            cov[propid_cov_index(a, b)] = value;
        }
    }
    /* Cross terms with every non-rate state; Q dt on the other diagonals. */
    for (uint8_t j = 3u; j < n; ++j) {
        const float t0 = rows[0][j];
        const float t1 = rows[1][j];
        const float t2 = rows[2][j];
        cov[propid_cov_index(0u, j)] = t0;
        cov[propid_cov_index(1u, j)] = t1;
        cov[propid_cov_index(2u, j)] = t2;
        float *diagonal = &cov[propid_cov_index(j, j)];
        const float factor = propid_state_kind(derived, j) == PROPID_KIND_DRAG ? drag_factor
                                                                              : 1.0f + PROPID_VAR_LOADING;
        *diagonal = factor * *diagonal + propid_process_psd(derived, j) * dt;
    }
}
#endif

/* The propagation for the quad layout: the straight-line kernel generated from
 * the symbolic model (firmware/codegen/quad_predict.py). Apart in the full build,
 * for the same reason as predict_stage_quad: its own base registers. */
static PROPID_QUAD_INLINE void
predict_covariance_quad_layout(const propid_derived_t *derived, float *restrict cov,
                               float dt, const float jacobian_dt[3][PROPID_JAC_ROW], float drag_factor)
{
#if PROPID_ARM_PREDICT_KERNEL
    propid_quad_predict_covariance_arm(cov, jacobian_dt, derived->kind_process_psd, dt, drag_factor);
#else
    propid_quad_predict_covariance(cov, jacobian_dt, derived->kind_process_psd[PROPID_KIND_RATE] * dt,
                                   derived->kind_process_psd[PROPID_KIND_THRUST] * dt,
                                   derived->kind_process_psd[PROPID_KIND_DRAG] * dt,
                                   derived->kind_process_psd[PROPID_KIND_BIAS] * dt, drag_factor);
#endif
}

#if PROPID_WITH_INPUT_NOISE
/* Rotor-speed input error (docs/math.md §14): the step integrates the rotor
 * torques with the measured u_i = Omega_i^2, whose error e_i (variance
 * input_noise_var u_i, correlated over input_noise_time) moves the predicted rate
 * by dt B e with B_ai = d(omega_dot_a)/d(u_i) at the current coefficients. Its
 * white-noise equivalent over the step is B Sigma_u B^T dt max(dt, time): a 3x3
 * symmetric add to the rate block (6 entries), after the propagation. */
static void add_input_block(float *cov, const float (*gain)[PROPID_MAX_ROTORS], const float *input_var,
                            uint8_t rotor_count)
{
    for (uint8_t b = 0; b < 3u; ++b) {
        for (uint8_t a = 0; a <= b; ++a) {
            float sum = 0.0f;
            for (uint8_t i = 0; i < rotor_count; ++i) {
                sum += gain[a][i] * gain[b][i] * input_var[i];
            }
            cov[propid_cov_index(a, b)] += sum;
        }
    }
}

/* An error common to every rotor (rotor_speed_noise_split; docs/math.md §14, "An
 * error common to every rotor"): rank one, along = B c with c_i the common error's
 * white-equivalent std in rotor i's input; adds along along^T to the rate block. */
static void add_common_block(float *cov, const float along[3])
{
    for (uint8_t b = 0; b < 3u; ++b) {
        for (uint8_t a = 0; a <= b; ++a) {
            cov[propid_cov_index(a, b)] += along[a] * along[b];
        }
    }
}

/* The quad layout (propid_internal.h): entries 2..5 of each row are rotors 0..3,
 * thrust columns in the roll and pitch rows, drag columns in the yaw row;
 * straight-line. */
static __attribute__((noinline)) void add_input_noise_quad(const propid_derived_t *derived,
                                                           propid_core_t *core, const float *kf_rel,
                                                           const float *km_rel, const float *weight,
                                                           const float *common, const float *timing)
{
    float input_var[4];
    float gain[3][4];
PROPID_UNROLL(4)
    for (uint8_t i = 0; i < 4u; ++i) {
        input_var[i] = weight[i] * (core->input_speed_sq[i] + core->rotor_speed_sq[i]);
        gain[0][i] = derived->jac_torque[0][PROPID_QUAD_TORQUE_FIRST + i] * kf_rel[i];
        gain[1][i] = derived->jac_torque[1][PROPID_QUAD_TORQUE_FIRST + i] * kf_rel[i];
        gain[2][i] = derived->jac_torque[2][PROPID_QUAD_TORQUE_FIRST + i] * km_rel[i];
    }
    float *cov = core->cov;
PROPID_UNROLL(3)
    for (uint8_t b = 0; b < 3u; ++b) {
PROPID_UNROLL(3)
        for (uint8_t a = 0; a <= b; ++a) {
            cov[propid_cov_index(a, b)] += gain[a][0] * gain[b][0] * input_var[0] +
                                           gain[a][1] * gain[b][1] * input_var[1] +
                                           gain[a][2] * gain[b][2] * input_var[2] +
                                           gain[a][3] * gain[b][3] * input_var[3];
        }
    }
    if (common != NULL) {
        float along[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            along[a] = gain[a][0] * common[0] + gain[a][1] * common[1] + gain[a][2] * common[2] +
                       gain[a][3] * common[3];
        }
        add_common_block(cov, along);
    }
    if (timing != NULL) {
        float along[3];
        for (uint8_t a = 0; a < 3u; ++a) {
            along[a] = gain[a][0] * timing[0] + gain[a][1] * timing[1] + gain[a][2] * timing[2] +
                       gain[a][3] * timing[3];
        }
        add_common_block(cov, along);
    }
}

/* Any vehicle, over the sparsity lists. */
static __attribute__((noinline)) void add_input_noise_any(const propid_derived_t *derived,
                                                          propid_core_t *core, const float *kf_rel,
                                                          const float *km_rel, const float *weight,
                                                          const float *common, const float *timing)
{
    const uint8_t rotor_count = (uint8_t)(derived->layout.drag - derived->layout.thrust);
    float input_var[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotor_count; ++i) {
        input_var[i] = weight[i] * (core->input_speed_sq[i] + core->rotor_speed_sq[i]);
    }
    float gain[3][PROPID_MAX_ROTORS] = {{0.0f}}; /* B */
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t count = derived->jac_count[a];
        for (uint8_t p = derived->jac_rate_count[a]; p < count; ++p) {
            const uint8_t rotor = derived->jac_rotor[a][p];
            if (rotor >= rotor_count) { /* the disturbance's entries */
                continue;
            }
            const uint8_t column = derived->jac_column[a][p];
            const int thrust = column < derived->layout.drag;
            gain[a][rotor] += derived->jac_torque[a][p] * (thrust ? kf_rel[rotor] : km_rel[rotor]);
        }
    }
    add_input_block(core->cov, (const float (*)[PROPID_MAX_ROTORS])gain, input_var, rotor_count);
    if (common != NULL) {
        float along[3] = {0.0f, 0.0f, 0.0f};
        for (uint8_t a = 0; a < 3u; ++a) {
            for (uint8_t i = 0; i < rotor_count; ++i) {
                along[a] += gain[a][i] * common[i];
            }
        }
        add_common_block(core->cov, along);
    }
    if (timing != NULL) {
        float along[3] = {0.0f, 0.0f, 0.0f};
        for (uint8_t a = 0; a < 3u; ++a) {
            for (uint8_t i = 0; i < rotor_count; ++i) {
                along[a] += gain[a][i] * timing[i];
            }
        }
        add_common_block(core->cov, along);
    }
}

/* The held error's span per rotor (docs/math.md §14, "Hold time from the
 * telemetry"): an error that has stood for a (its value unchanged since) and
 * stays through the step adds dt (dt + 2 a) to the variance of its integrated
 * effect, dt alone when the value changes within the step (a fresh error); the
 * configured time bounds it as before. The age then moves on. */
static float held_span(propid_core_t *core, uint8_t rotor, float dt, float ceiling)
{
    float span;
    if (core->rotor_speed_sq[rotor] != core->input_speed_sq[rotor]) {
        span = dt;
        core->input_hold_age[rotor] = 0.0f;
    } else {
        span = dt + 2.0f * core->input_hold_age[rotor];
        const float age = core->input_hold_age[rotor] + dt;
        core->input_hold_age[rotor] = age < ceiling ? age : ceiling; /* (bounded: the span is) */
    }
    return span < ceiling ? span : ceiling;
}

/* The same age with the configured time as the span's floor instead of its ceiling
 * (rotor_speed_noise_hold = 2; docs/math.md §14, "The hold as a floor"): a moving
 * rotor's quantisation error follows its speed, not its code changes, so it keeps
 * the configured time; a value that has stood longer than that (a hover's code)
 * spans its hold, up to the configuration's largest time. */
static float held_span_floor(propid_core_t *core, uint8_t rotor, float dt, float floor_span)
{
    float held = dt;
    if (core->rotor_speed_sq[rotor] != core->input_speed_sq[rotor]) {
        core->input_hold_age[rotor] = 0.0f;
    } else {
        held = dt + 2.0f * core->input_hold_age[rotor];
        const float age = core->input_hold_age[rotor] + dt;
        core->input_hold_age[rotor] = age < PROPID_ROTOR_SPEED_NOISE_TIME_MAX ? age : PROPID_ROTOR_SPEED_NOISE_TIME_MAX;
    }
    const float span = held > floor_span ? held : floor_span;
    return span < PROPID_ROTOR_SPEED_NOISE_TIME_MAX ? span : PROPID_ROTOR_SPEED_NOISE_TIME_MAX;
}

/* Not inlined: its per-rotor arrays stay out of propid_predict_covariance's frame,
 * which is on the deepest stack chain (predict_covariance_any). */
static __attribute__((noinline)) void add_input_noise(const propid_derived_t *derived, propid_core_t *core, float dt)
{
    /* Var(u_i) dt max(dt, time) = input_noise_var u_i dt span, u_i the trapezoid mean
     * (the factor 0.5 of that mean folded in). */
    const uint8_t rotor_count = (uint8_t)(derived->layout.drag - derived->layout.thrust);
    const float span = derived->input_noise_time > dt ? derived->input_noise_time : dt;
    float weight[PROPID_MAX_ROTORS];
    /* The truncation's mean, common to every rotor: Cov(e_i, e_j) = common_var Omega_i
     * Omega_j in u (common_var = 3 input_noise_var: (q / 2)^2 against the spread's
     * q^2 / 12), each rotor's share over its own span, so c_i = sqrt(common_var u_i dt
     * span_i), u_i the trapezoid mean; rank one, positive semi-definite. */
    float common[PROPID_MAX_ROTORS];
    const int with_common = derived->input_noise_split != 0u;
    const float common_var = 3.0f * derived->input_noise_var;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        float rotor_span = span;
        if (derived->input_noise_hold == 1u) {
            rotor_span = held_span(core, i, dt, span);
        } else if (derived->input_noise_hold == 2u) {
            rotor_span = held_span_floor(core, i, dt, span);
        }
        weight[i] = 0.5f * derived->input_noise_var * dt * rotor_span;
        if (with_common) {
            const float speed_sq = 0.5f * (core->input_speed_sq[i] + core->rotor_speed_sq[i]);
            common[i] = sqrtf(common_var * dt * rotor_span * speed_sq);
        }
    }
    const float *common_or_null = with_common ? common : NULL;
    /* The report's timing (docs/math.md §14, "The report's timing"): a report tau older
     * or newer than assumed puts tau du_i/dt into every rotor's input at once (one age
     * per report), du_i/dt over the step from its two ends: rank one, along = B t with
     * t_i = tau (u_end,i - u_start,i) / dt, the rate increment's error over the step. */
    float timing[PROPID_MAX_ROTORS];
    const int with_timing = derived->input_timing_error > 0.0f;
    const float timing_per_dt = derived->input_timing_error / dt;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        timing[i] = timing_per_dt * (core->rotor_speed_sq[i] - core->input_speed_sq[i]);
    }
    const float *timing_or_null = with_timing ? timing : NULL;
    /* B at the drag coefficients per rotor (kept in their yaw basis; this term is
     * in the general build only, whose derived data holds the basis). */
    const propid_reflection_t basis = {derived->drag_basis, derived->drag_basis_scale,
                                       derived->layout.drag, rotor_count};
    float km_rel[PROPID_MAX_ROTORS];
    propid_drag_per_rotor(&basis, core, km_rel, NULL);
    /* B at the thrust coefficients per rotor too (kept in their torque basis). */
    propid_thrust_basis_t thrust_basis;
    thrust_basis.vector[0] = derived->thrust_basis;
    thrust_basis.vector[1] = derived->thrust_basis + PROPID_MAX_ROTORS;
    thrust_basis.rotor_count = rotor_count;
    float kf_rel[PROPID_MAX_ROTORS];
    propid_thrust_per_rotor(&thrust_basis, core, kf_rel, NULL);
    if (derived->quad_layout) {
        add_input_noise_quad(derived, core, kf_rel, km_rel, weight, common_or_null, timing_or_null);
    } else {
        add_input_noise_any(derived, core, kf_rel, km_rel, weight, common_or_null, timing_or_null);
    }
}
#endif

#if PROPID_WITH_ACCEL
/* The accelerometer row's model error, a first-order Gauss-Markov state (docs/math.md
 * §9, "The row's model error"): e' = a e with a = exp(-dt / tau), so its row and
 * column of P scale by a and its variance by a^2 before the prediction adds its
 * process noise 2 sigma^2 / tau dt (propid_config.c; the rate rows then see the
 * decayed column, as F P F^T with a on e's diagonal). N + 6 + blocks multiplies. */
static __attribute__((noinline)) void decay_accel_error(const propid_derived_t *derived, propid_core_t *core,
                                                       float dt, uint8_t n)
{
    const uint8_t e = derived->accel_error;
    if (e >= n) { /* never (the caller tests PROPID_NO_STATE); bounds the index */
        return;
    }
    const float a = expf(-dt * derived->accel_error_rate);
    core->state[e] *= a;
    for (uint8_t j = 0; j < e; ++j) {
        core->cov[propid_cov_index(j, e)] *= a;
    }
    float *row_e = propid_cov_row(core->cov, e);
    row_e[e] *= a * a;
    for (uint8_t j = (uint8_t)(e + 1u); j < n; ++j) {
        row_e[j] *= a;
    }
}

/* A walking thrust-torque scale (docs/math.md §9): ds = w_s moves g_i = s kf_i by
 * kf_i ds and r = 1/s by -r^2 ds, so Q dt = q^2 dt v v^T with v = kf_i = r g_i at
 * each g_i and -r^2 at r, at the current state (the walk keeps kf where it is). The
 * per-state process noise already put q^2 dt on P_rr (propid_config.c). */
static void add_scale_walk(const propid_derived_t *derived, propid_core_t *core, float dt)
{
    const uint8_t scale = derived->layout.torque_scale;
    if (scale == PROPID_NO_STATE) {
        return;
    }
    const float walk = propid_process_psd(derived, scale) * dt;
    if (!(walk > 0.0f)) {
        return;
    }
    const uint8_t first = derived->layout.thrust;
    const uint8_t end = derived->layout.drag;
    const float r = core->state[scale];
    const float r_sq = r * r;
    for (uint8_t i = first; i < end; ++i) {
        const float along_i = walk * r * core->state[i];
        for (uint8_t j = i; j < end; ++j) {
            core->cov[propid_cov_index(i, j)] += along_i * r * core->state[j];
        }
        core->cov[propid_cov_index(i, scale)] -= along_i * r_sq;
    }
    core->cov[propid_cov_index(scale, scale)] += walk * (r_sq * r_sq - 1.0f);
}
#endif

/* The rounding loading of the drag coefficients, every second step (the even
 * rows of the integrity-check cycle; propid_internal.h). */
static inline float drag_loading_factor(const propid_core_t *core)
{
    return (core->check_row & 1u) == 0u ? 1.0f + PROPID_VAR_LOADING : 1.0f;
}

#if !PROPID_FAST_QUAD_PREDICT
__attribute__((noinline)) void propid_predict_covariance(const propid_derived_t *derived, propid_core_t *core, float dt,
                               const float jacobian_dt[3][PROPID_JAC_ROW])
{
    const float drag_factor = drag_loading_factor(core);
#if PROPID_GENERAL_VEHICLES
    if (!derived->quad_layout) {
#if PROPID_WITH_ACCEL
        if (derived->accel_error != PROPID_NO_STATE) { /* (no such state in the quad layout) */
            decay_accel_error(derived, core, dt, derived->state_count);
        }
#endif
        predict_covariance_any(derived, core->cov, dt, jacobian_dt, derived->state_count, drag_factor);
#if PROPID_WITH_ACCEL
        add_scale_walk(derived, core, dt); /* (the quad layout has no scale state) */
#endif
    } else
#endif
    {
        predict_covariance_quad_layout(derived, core->cov, dt, jacobian_dt, drag_factor);
    }
#if PROPID_WITH_INPUT_NOISE
    /* Both are >= 0 (propid_config.c): one compare for either term. */
    if (derived->input_noise_var + derived->input_timing_error > 0.0f) {
        add_input_noise(derived, core, dt);
    }
#endif
}
#endif

#if PROPID_FAST_QUAD_PREDICT && PROPID_ARM_BLOCK_MOVES
/* The round-robin row check's test (propid_cov_check_row_inline: the same tests,
 * |P_ij|^2 <= P_ii (1 + tol) P_jj per element and 0 < P_ii <= FLT_MAX, a NaN
 * failing each) for the quad on the Cortex-M4: a TBB table chooses row i's
 * stub, which loads P_ii and row i's elements right of its diagonal in one
 * VLDM into s(19 + j - 1).. s31 (P_ij in s(18 + j) for every row), all at
 * fixed offsets; then the shared tests of columns i + 1..13, each P_jj at its
 * fixed offset (no pointer arithmetic, no loop: 6 instructions an element where
 * the C loop took 12), and P_ii's, leaving at the first failure. Returns 1 when
 * row i is bad; writes nothing (the caller repairs). */
static inline __attribute__((always_inline)) int quad_row_bad(const float *cov, uint8_t row)
{
    _Static_assert(PROPID_MAX_STATES == 14, "the offsets below are those of the 14-state packed triangle");
    if (row >= PROPID_QUAD_STATES) {
        return 0;
    }
    int bad = 0;
    float pii_tol;
    const uint32_t index = row;
    __asm__("tbb [pc, %[row]]\n"
                     ".Lrc%=table:\n\t"
                     ".byte (.Lrc%=row0 - .Lrc%=table) / 2, (.Lrc%=row1 - .Lrc%=table) / 2, (.Lrc%=row2 - .Lrc%=table) / 2, (.Lrc%=row3 - .Lrc%=table) / 2, (.Lrc%=row4 - .Lrc%=table) / 2, (.Lrc%=row5 - .Lrc%=table) / 2, (.Lrc%=row6 - .Lrc%=table) / 2, (.Lrc%=row7 - .Lrc%=table) / 2, (.Lrc%=row8 - .Lrc%=table) / 2, (.Lrc%=row9 - .Lrc%=table) / 2, (.Lrc%=row10 - .Lrc%=table) / 2, (.Lrc%=row11 - .Lrc%=table) / 2, (.Lrc%=row12 - .Lrc%=table) / 2, (.Lrc%=row13 - .Lrc%=table) / 2\n\t"
                     ".align 1\n"
                     ".Lrc%=row0: vldr s18, [%[cov], #0]\n\t"
                     "add ip, %[cov], #4\n\tvldmia ip, {s19-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column1\n"
                     ".Lrc%=row1: vldr s18, [%[cov], #56]\n\t"
                     "add ip, %[cov], #60\n\tvldmia ip, {s20-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column2\n"
                     ".Lrc%=row2: vldr s18, [%[cov], #108]\n\t"
                     "add ip, %[cov], #112\n\tvldmia ip, {s21-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column3\n"
                     ".Lrc%=row3: vldr s18, [%[cov], #156]\n\t"
                     "add ip, %[cov], #160\n\tvldmia ip, {s22-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column4\n"
                     ".Lrc%=row4: vldr s18, [%[cov], #200]\n\t"
                     "add ip, %[cov], #204\n\tvldmia ip, {s23-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column5\n"
                     ".Lrc%=row5: vldr s18, [%[cov], #240]\n\t"
                     "add ip, %[cov], #244\n\tvldmia ip, {s24-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column6\n"
                     ".Lrc%=row6: vldr s18, [%[cov], #276]\n\t"
                     "add ip, %[cov], #280\n\tvldmia ip, {s25-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column7\n"
                     ".Lrc%=row7: vldr s18, [%[cov], #308]\n\t"
                     "add ip, %[cov], #312\n\tvldmia ip, {s26-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column8\n"
                     ".Lrc%=row8: vldr s18, [%[cov], #336]\n\t"
                     "add ip, %[cov], #340\n\tvldmia ip, {s27-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column9\n"
                     ".Lrc%=row9: vldr s18, [%[cov], #360]\n\t"
                     "add ip, %[cov], #364\n\tvldmia ip, {s28-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column10\n"
                     ".Lrc%=row10: vldr s18, [%[cov], #380]\n\t"
                     "add ip, %[cov], #384\n\tvldmia ip, {s29-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column11\n"
                     ".Lrc%=row11: vldr s18, [%[cov], #396]\n\t"
                     "add ip, %[cov], #400\n\tvldmia ip, {s30-s31}\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column12\n"
                     ".Lrc%=row12: vldr s18, [%[cov], #408]\n\t"
                     "vldr s31, [%[cov], #412]\n\tvmul.f32 %[pii_tol], s18, %[tol]\n\tb .Lrc%=column13\n"
                     ".Lrc%=row13: vldr s18, [%[cov], #416]\n\tb .Lrc%=diagonal\n"
                     ".Lrc%=column1: vldr s16, [%[cov], #56]\n\tvmul.f32 s17, s19, s19\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column2: vldr s16, [%[cov], #108]\n\tvmul.f32 s17, s20, s20\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column3: vldr s16, [%[cov], #156]\n\tvmul.f32 s17, s21, s21\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column4: vldr s16, [%[cov], #200]\n\tvmul.f32 s17, s22, s22\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column5: vldr s16, [%[cov], #240]\n\tvmul.f32 s17, s23, s23\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column6: vldr s16, [%[cov], #276]\n\tvmul.f32 s17, s24, s24\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column7: vldr s16, [%[cov], #308]\n\tvmul.f32 s17, s25, s25\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column8: vldr s16, [%[cov], #336]\n\tvmul.f32 s17, s26, s26\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column9: vldr s16, [%[cov], #360]\n\tvmul.f32 s17, s27, s27\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column10: vldr s16, [%[cov], #380]\n\tvmul.f32 s17, s28, s28\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column11: vldr s16, [%[cov], #396]\n\tvmul.f32 s17, s29, s29\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column12: vldr s16, [%[cov], #408]\n\tvmul.f32 s17, s30, s30\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=column13: vldr s16, [%[cov], #416]\n\tvmul.f32 s17, s31, s31\n\t"
                     "vmul.f32 s16, %[pii_tol], s16\n\tvcmpe.f32 s17, s16\n\tvmrs APSR_nzcv, fpscr\n\tbhi .Lrc%=bad\n"
                     ".Lrc%=diagonal: vcmpe.f32 s18, #0\n\tvmrs APSR_nzcv, fpscr\n\tble .Lrc%=bad\n\t"
                     "vcmpe.f32 s18, %[largest]\n\tvmrs APSR_nzcv, fpscr\n\tbls .Lrc%=done\n"
                     ".Lrc%=bad: movs %[bad], #1\n"
                     ".Lrc%=done:\n"
                     : [bad] "+r"(bad), [pii_tol] "=&t"(pii_tol)
                     : [row] "r"(index), [cov] "r"(cov), [tol] "t"(1.0f + PROPID_ROUNDING_TOL), [largest] "t"(FLT_MAX),
                       "m"(*(const float(*)[PROPID_COV_SIZE])cov)
                     : "s16", "s17", "s18", "s19", "s20", "s21", "s22", "s23", "s24", "s25", "s26", "s27", "s28",
                       "s29", "s30", "s31", "ip", "cc");
    return bad;
}
#endif

/* The accepted sample's prediction (propid_internal.h). The fast quad build
 * runs its two straight-line kernels in this one frame, the 18 Jacobian entries
 * passed in a local array the compiler keeps in registers (no store to and
 * reload from the filter's work area, no two calls: 28 instructions less per
 * step); the other builds call the two stages. Not inlined: this frame stays
 * off the update's chain. */
__attribute__((noinline)) propid_status_t propid_predict_step(propid_filter_t *filter, float dt)
{
    propid_core_t *core = &filter->core;
    float rate_next[3];
#if !PROPID_GENERAL_VEHICLES && PROPID_SIZE_LEAN
    /* The size-lean build's rows in the filter's work area, which the update
     * uses only after them (off the stack: the prediction's chain). */
    float (*rate_jacobian_dt)[PROPID_JAC_ROW] = (float (*)[PROPID_JAC_ROW])(void *)core->update_vector;
#else
    float rate_jacobian_dt[3][PROPID_JAC_ROW];
#endif
#if PROPID_FAST_QUAD_PREDICT && PROPID_ARM_BLOCK_MOVES
    /* The row check's test first, while the FPU registers are free (it reads P,
     * which the rate step does not change); the repair, if any, after the rate
     * step is accepted, as propid_check_next_row does it. */
    const int row_bad = quad_row_bad(core->cov, core->check_row);
#endif
#if PROPID_ARM_MODEL_STAGE
    /* The model stage in generated assembly (propid_quad_model.h): the same
     * operations as predict_stage_quad, its entries left in the registers the
     * kernel reads. */
    float check;
    propid_quad_model_stage_arm(filter, propid_drag_basis(&filter->derived, &filter->config).vector, dt,
                                rate_jacobian_dt, rate_next, &check);
    const propid_status_t staged = quad_stage_bound(rate_next, propid_rate_limit(filter), check);
#elif PROPID_FAST_QUAD_PREDICT
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, &filter->config);
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, &filter->config);
    const propid_status_t staged = predict_stage_quad(
        core->state, core->input_speed_sq, core->rotor_speed_sq, filter->derived.quad_gyro,
        filter->derived.jac_torque, basis.vector, basis.scale, filter->derived.thrust_basis, dt,
        propid_rate_limit(filter), rate_next, rate_jacobian_dt);
#else
    const propid_status_t staged = propid_predict_stage(filter, dt, rate_next, rate_jacobian_dt);
#endif
    if (staged < 0) {
        return PROPID_ERR_NUMERIC;
    }
    /* Accepted: from here on the filter changes (no rejection follows). */
#if PROPID_FAST_QUAD_PREDICT
    /* The rates now, from the registers (the covariance kernels below read P
     * and the Jacobian only; kept to the end they were stored and loaded again). */
    core->state[0] = rate_next[0];
    core->state[1] = rate_next[1];
    core->state[2] = rate_next[2];
#endif
    core->health &= ~(PROPID_HEALTH_GATED | PROPID_HEALTH_STATE_CLAMPED);
    if (staged != PROPID_OK) { /* the prediction was bounded */
        core->health |= PROPID_HEALTH_STATE_CLAMPED;
        filter->counters.state_clamps++;
    }
#if PROPID_FAST_QUAD_PREDICT && PROPID_ARM_BLOCK_MOVES
    if (row_bad && propid_cov_repair(&filter->derived, core)) {
        core->health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    core->check_row = (uint8_t)(core->check_row + 1u >= PROPID_QUAD_STATES ? 0u : core->check_row + 1u);
#else
    propid_check_next_row(filter, PROPID_FAST_QUAD_PREDICT);
#endif
#if PROPID_FAST_QUAD_PREDICT
    predict_covariance_quad_layout(&filter->derived, core->cov, dt,
                                   (const float (*)[PROPID_JAC_ROW])rate_jacobian_dt, drag_loading_factor(core));
#else
    propid_predict_covariance(&filter->derived, core, dt, rate_jacobian_dt);
#endif
#if !PROPID_FAST_QUAD_PREDICT
    core->state[0] = rate_next[0];
    core->state[1] = rate_next[1];
    core->state[2] = rate_next[2];
#endif
    return PROPID_OK;
}
