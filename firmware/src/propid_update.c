/* Measurement update: three scalar updates, one per gyro axis,
 * y_a = omega_a + b_a + v_a, in the order x, y, z (docs/math.md §3).
 *
 * For axis a, H_a = e_rate(a) + e_bias(a), so h_a = P H_a^T is the sum of two rows
 * of the symmetric P, S_a = h_a[a] + h_a[bias] + R, and the update is
 *   x += h_a nu_a / S_a,    P -= h_a h_a^T / S_a
 * applied to the P left by the previous axis. The three downdates are applied in
 * ONE pass over P: the later axes' vectors are computed from the P in memory
 * with the earlier axes' pending rank-one terms folded in,
 *   h_a = P H_a^T - sum_{p<a} g_p (h_p . H_a),   g_p = h_p / S_p,
 * which is the same matrix algebra (each h_a and S_a equals the sequential one in
 * exact arithmetic), then one sweep over the upper triangle writes
 *   P_ij -= sum_a g_a,i h_a,j   (upper triangle),   x_i += sum_a g_a,i nu_a.
 * Cost: ~3 n per axis for the vectors plus one pass of n (n + 1) / 2 elements
 * instead of three. Rare paths (a covariance that fails S >= R, a gate re-open)
 * first apply the pending terms, then work on the updated P. The usual quad
 * sample (every axis fused) takes a straight-line copy: fuse_quad_usual, then
 * apply_three_quad four rows at a time. */
#include <math.h>
#include <string.h>

#include "propid_internal.h"


/* h[i] = EXPR for i < N, with a running sum for the finiteness test. */
#define PROPID_FORM_VECTOR(N, UNROLL, EXPR)                                                        \
    do {                                                                                           \
        UNROLL for (uint8_t i = 0; i < (N); ++i)                                                   \
        {                                                                                          \
            const float value = (EXPR);                                                            \
            h[i] = value;                                                                          \
            check += value;                                                                        \
        }                                                                                          \
    } while (0)

typedef struct {
    uint8_t count;                      /* pending fused axes */
    float h[3][PROPID_MAX_STATES];      /* P H^T of each pending axis (its gain is h / S) */
    float inv_var[3];                   /* 1 / S: the gain is g = h / S */
    float innovation[3];
} pending_t;

/* 1 when a value is outside [floor, ceiling] (or negative, or not finite): for
 * non-negative floats the bit patterns are ordered like the values, so one
 * unsigned comparison of (bits - floor_bits) with (ceiling_bits - floor_bits)
 * tests both bounds; negative values and NaN land far above the range. */
static inline uint32_t outside_positive_range(float value, uint32_t floor_bits, uint32_t range_bits)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof(bits));
    return (uint32_t)(bits - floor_bits) > range_bits ? 1u : 0u;
}

/* Rows first .. first + rows - 1 of the quad's three-term pass: their gains
 * g_k,i = h_k,i / S_k and state updates, the upper triangle of their diagonal
 * block, then every column to the right, where each h_j triple is loaded once
 * for all the group's rows (4 rows: 23 instructions per 4 elements, with the 12
 * gains in registers). Returns non-zero when a new variance of the group is
 * outside its [floor, ceiling]. */
static inline __attribute__((always_inline)) uint32_t
apply_row_group(float (*restrict cov)[PROPID_MAX_STATES], float *restrict state,
                const pending_t *restrict pending, const propid_derived_t *restrict derived,
                const uint8_t first, const uint8_t rows)
{
    const float *h0 = pending->h[0];
    const float *h1 = pending->h[1];
    const float *h2 = pending->h[2];
    const float inv0 = pending->inv_var[0];
    const float inv1 = pending->inv_var[1];
    const float inv2 = pending->inv_var[2];
    const float nu0 = pending->innovation[0];
    const float nu1 = pending->innovation[1];
    const float nu2 = pending->innovation[2];
    float gain[4][3];
    uint32_t outside = 0u;
#pragma GCC unroll 4
    for (uint8_t r = 0; r < rows; ++r) {
        const uint8_t i = (uint8_t)(first + r);
        gain[r][0] = h0[i] * inv0;
        gain[r][1] = h1[i] * inv1;
        gain[r][2] = h2[i] * inv2;
        state[i] += gain[r][0] * nu0 + gain[r][1] * nu1 + gain[r][2] * nu2;
    }
#pragma GCC unroll 4
    for (uint8_t r = 0; r < rows; ++r) {
        const uint8_t i = (uint8_t)(first + r);
#pragma GCC unroll 4
        for (uint8_t c = r; c < rows; ++c) {
            const uint8_t j = (uint8_t)(first + c);
            cov[i][j] = cov[i][j] - gain[r][0] * h0[j] - gain[r][1] * h1[j] - gain[r][2] * h2[j];
        }
        /* Floors and ceilings are per kind of state (rate, thrust, drag, bias:
         * propid_config.c): the first state of its kind stands for each, so
         * the constants stay in registers across the groups. */
        const uint8_t kind = i < 3u ? 0u : (i < 7u ? 3u : (i < 11u ? 7u : 11u));
        outside |= outside_positive_range(cov[i][i], derived->var_floor_bits[kind], derived->var_range_bits[kind]);
    }
#pragma GCC unroll 10
    for (uint8_t j = (uint8_t)(first + rows); j < PROPID_QUAD_STATES; ++j) {
        const float hj0 = h0[j];
        const float hj1 = h1[j];
        const float hj2 = h2[j];
#pragma GCC unroll 4
        for (uint8_t r = 0; r < rows; ++r) {
            float *p = &cov[first + r][j];
            *p = *p - gain[r][0] * hj0 - gain[r][1] * hj1 - gain[r][2] * hj2;
        }
    }
    return outside;
}

/* P_ij -= sum_k g_k,i h_k,j on the stored upper triangle, x += sum_k g_k nu_k,
 * for three pending terms of a quad: n constant, fully unrolled, four rows at a
 * time. Also tests every new variance against its floor and ceiling; returns 1
 * when all are inside. */
static int apply_three_quad(float (*restrict cov)[PROPID_MAX_STATES], float *restrict state,
                            const pending_t *restrict pending, const propid_derived_t *restrict derived)
{
    uint32_t outside = apply_row_group(cov, state, pending, derived, 0u, 4u);
    outside |= apply_row_group(cov, state, pending, derived, 4u, 4u);
    outside |= apply_row_group(cov, state, pending, derived, 8u, 4u);
    outside |= apply_row_group(cov, state, pending, derived, 12u, 2u);
    return outside == 0u;
}

/* Applies the pending terms; returns 1 only when it also verified every variance
 * against its floor and ceiling (the quad's three-term pass), else 0. */
static int apply_pending(propid_core_t *core, const propid_derived_t *derived, pending_t *pending)
{
    const uint8_t n = derived->state_count;
    int verified = 0;
    if (pending->count == 3u && n == PROPID_QUAD_STATES) {
        verified = apply_three_quad(core->cov, core->state, pending, derived);
    } else {
        for (uint8_t k = 0; k < pending->count; ++k) {
            const float *h = pending->h[k];
            const float inv_var = pending->inv_var[k];
            const float nu = pending->innovation[k];
            for (uint8_t i = 0; i < n; ++i) {
                const float g = h[i] * inv_var;
                core->state[i] += g * nu;
                float *row = core->cov[i];
                for (uint8_t j = i; j < n; ++j) {
                    row[j] -= g * h[j];
                }
            }
        }
    }
    pending->count = 0u;
    return verified;
}

/* h_a[i] for one i: the two rows of P plus the pending terms. */
static float pending_h(const float (*cov)[PROPID_MAX_STATES], const pending_t *pending,
                       const float *projection, uint8_t rate, uint8_t bias, uint8_t i)
{
    float value = propid_cov_at(cov, rate, i) + propid_cov_at(cov, bias, i);
    for (uint8_t k = 0; k < pending->count; ++k) {
        value -= projection[k] * pending->h[k][i];
    }
    return value;
}

/* The axis' rate forgets everything and restarts from this sample: rate :=
 * measurement - bias estimate, rate variance := its prior, correlations zeroed
 * (zeroing a row/column and setting a positive diagonal keeps P PSD). */
static void reanchor_rate(propid_filter_t *filter, uint8_t axis, uint8_t bias, float gyro)
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    core->state[axis] = gyro - core->state[bias];
    propid_cov_reset_state(derived, core, axis);
}

/* One axis: S, innovation, gate (and re-anchor), then its vector queued in
 * `pending`. Returns 1 when the axis was gated out. One copy, plain loops: for a
 * quad this is the rare path (the usual sample takes fuse_quad_usual), and the
 * three unrolled per-axis copies it had cost 5.8 KB of flash for no measured
 * step. */
static uint32_t
fuse_axis(propid_filter_t *filter, pending_t *pending_ref, int *repaired, const uint8_t axis,
          const float measured, const uint8_t n)
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const float noise_var = derived->gyro_var;
    float (*cov)[PROPID_MAX_STATES] = core->cov;
    pending_t *const pending = pending_ref;
    const uint8_t bias = (uint8_t)(n - PROPID_BIAS_STATES + axis);
    for (;;) { /* at most twice: the repair-and-retry below happens once per sample */
        float projection[3]; /* (h_k . H_axis) / S_k of each pending axis k */
        float shift_rate = 0.0f;
        float shift_bias = 0.0f;
        for (uint8_t k = 0; k < pending->count; ++k) {
            projection[k] = (pending->h[k][axis] + pending->h[k][bias]) * pending->inv_var[k];
            const float step = pending->innovation[k] * pending->inv_var[k];
            shift_rate += pending->h[k][axis] * step;
            shift_bias += pending->h[k][bias] * step;
        }
        float h_rate = pending_h((const float (*)[PROPID_MAX_STATES])cov, pending, projection, axis, bias, axis);
        float h_bias = pending_h((const float (*)[PROPID_MAX_STATES])cov, pending, projection, axis, bias, bias);
        float innovation_var = h_rate + h_bias + noise_var;
        /* S >= R up to the rounding of the sum var(omega + b) = P_rr + 2 P_rb + P_bb
         * (|P_rb| <= (P_rr + P_bb) / 2): within it, var(omega + b) is zero, not a
         * fault (propid_internal.h, design.md §12). */
        const float rounding = PROPID_ROUNDING_TOL * (cov[axis][axis] + cov[bias][bias]);
        if (innovation_var >= noise_var - rounding) {
            innovation_var = innovation_var > noise_var ? innovation_var : noise_var;
        } else {
            /* var(omega + b) < 0 or NaN: P is no longer PSD. Repair and recompute. */
            (void)apply_pending(core, derived, pending);
            if (propid_cov_repair(derived, core)) {
                core->health |= PROPID_HEALTH_COV_REPAIRED;
                filter->counters.cov_repairs++;
            }
            shift_rate = 0.0f;
            shift_bias = 0.0f;
            h_rate = cov[axis][axis] + cov[axis][bias]; /* P_bias,axis */
            h_bias = cov[axis][bias] + cov[bias][bias];
            innovation_var = h_rate + h_bias + noise_var;
            if (!(innovation_var >= noise_var)) {
                innovation_var = noise_var;
            }
        }
        {
            /* Update loading (propid_internal.h): R_eff = loading * P_hh when larger. */
            const float loaded_noise = PROPID_UPDATE_LOADING * (innovation_var - noise_var);
            if (loaded_noise > noise_var) {
                innovation_var += loaded_noise - noise_var;
            }
        }
        /* The state after the pending axes, on the two components H reads. */
        float innovation = measured - (core->state[axis] + shift_rate) - (core->state[bias] + shift_bias);
        const float innovation_sq = innovation * innovation;
        float inv_innovation_var = 1.0f / innovation_var;
        core->innovation[axis] = innovation;
        core->innovation_test_ratio[axis] = innovation_sq * inv_innovation_var * derived->inv_gate_sq;

        if (!(innovation_sq <= derived->gate_sq * innovation_var)) {
            if (core->gated_run[axis] < filter->config.gate_max_consecutive) {
                core->gated_run[axis]++;
                filter->counters.axis_gated[axis]++;
                return 1u;
            }
            /* Too many rejections in a row: the filter, not the sensor, is probably
             * wrong. Re-anchor this axis' rate on the sample (prior variance, no
             * correlations) and fuse it: the update then has the conditioning of
             * the very first sample (P_hh <= rate prior + bias variance), never the
             * P_hh ~ nu^2 of an inflation by the innovation. */
            (void)apply_pending(core, derived, pending);
            reanchor_rate(filter, axis, bias, measured);
            h_rate = cov[axis][axis] + cov[axis][bias]; /* P_bias,axis */
            h_bias = cov[axis][bias] + cov[bias][bias];
            innovation_var = h_rate + h_bias + noise_var;
            inv_innovation_var = 1.0f / innovation_var;
            innovation = measured - core->state[axis] - core->state[bias];
            filter->counters.gate_reopened++;
            core->health |= PROPID_HEALTH_GATE_REOPENED;
        }
        core->gated_run[axis] = 0u;

        /* This axis' vectors (pending terms folded in), queued for the joint pass. */
        const uint8_t slot = pending->count;
        float *h = pending->h[slot];
        const float (*stored)[PROPID_MAX_STATES] = (const float (*)[PROPID_MAX_STATES])cov;
#define PROPID_PH(i) (propid_cov_at(stored, axis, (i)) + propid_cov_at(stored, bias, (i)))
        const float *h0 = pending->h[0];
        const float *h1 = pending->h[1];
        float check = 0.0f;
        /* One loop per number of folded-in terms (plain loops: this is the rare
         * path for a quad, whose usual sample takes fuse_quad_usual; small code). */
        if (slot == 0u) {
            PROPID_FORM_VECTOR(n, PROPID_NO_UNROLL, PROPID_PH(i));
        } else if (slot == 1u) {
            const float c0 = projection[0];
            PROPID_FORM_VECTOR(n, PROPID_NO_UNROLL, PROPID_PH(i) - c0 * h0[i]);
        } else {
            const float c0 = projection[0];
            const float c1 = projection[1];
            PROPID_FORM_VECTOR(n, PROPID_NO_UNROLL, PROPID_PH(i) - c0 * h0[i] - c1 * h1[i]);
        }
#undef PROPID_PH
        /* A non-finite covariance element in the two rows this axis reads (e.g.
         * spread from a corrupted element by the prediction) must never reach the
         * state: repair P (after the pending terms) and redo this axis. */
        if (!isfinite(check) && !*repaired) {
            *repaired = 1;
            (void)apply_pending(core, derived, pending);
            if (propid_cov_repair(derived, core)) {
                core->health |= PROPID_HEALTH_COV_REPAIRED;
                filter->counters.cov_repairs++;
            }
            continue; /* redo this axis on the repaired P */
        }
        pending->innovation[slot] = innovation;
        pending->inv_var[slot] = inv_innovation_var;
        pending->count++;
        return 0u;
    }
}

/* The usual quad sample, straight-line: all three axes pass the gate, every
 * S >= R and the vectors are finite. Same arithmetic in the same order as
 * fuse_axis (the scalars S, innovation and projections are formed from the few
 * vector entries they need before the vectors themselves). Returns 1 with the
 * three axes queued in `pending` and their innovations recorded, or 0 without
 * writing anything: the general path then handles the sample. Not inlined, and
 * given the covariance as its own pointer: offsets from the filter's base exceed
 * the 1 KiB reach of a VFP load. */
static __attribute__((noinline)) int
fuse_quad_usual(const float (*restrict cov)[PROPID_MAX_STATES], propid_core_t *restrict core,
                const propid_derived_t *restrict derived, pending_t *restrict pending,
                const float *restrict gyro)
{
#define PROPID_P(i, j) propid_cov_at(cov, (i), (j))
    const float *state = core->state;
    const float noise_var = derived->gyro_var;
    const float gate_sq = derived->gate_sq;
    /* S outside [R, R + R / loading] (or NaN) leaves the fast path: below, the
     * general path decides about rounding; above, it loads R. */
    const uint32_t var_bits = derived->innovation_var_bits;
    const uint32_t var_range_bits = derived->innovation_range_bits;
    const uint8_t b0 = PROPID_QUAD_STATES - 3u; /* bias states 11, 12, 13 */
    const uint8_t b1 = PROPID_QUAD_STATES - 2u;
    const uint8_t b2 = PROPID_QUAD_STATES - 1u;

    /* x axis: h_0 = P_:,0 + P_:,11 */
    const float h0_r0 = PROPID_P(0, 0) + PROPID_P(b0, 0);
    const float h0_b0 = PROPID_P(0, b0) + PROPID_P(b0, b0);
    const float var0 = h0_r0 + h0_b0 + noise_var;
    const float nu0 = gyro[0] - state[0] - state[b0];
    const float nu0_sq = nu0 * nu0;
    /* S < R (even within rounding: fuse_axis decides) leaves the fast path. */
    if (outside_positive_range(var0, var_bits, var_range_bits) || !(nu0_sq <= gate_sq * var0)) {
        return 0;
    }
    const float inv0 = 1.0f / var0;
    const float step0 = nu0 * inv0;

    /* y axis: h_1 = P_:,1 + P_:,12 - c10 h_0 */
    const float h0_r1 = PROPID_P(0, 1) + PROPID_P(b0, 1);
    const float h0_b1 = PROPID_P(0, b1) + PROPID_P(b0, b1);
    const float c10 = (h0_r1 + h0_b1) * inv0;
    const float h1_r1 = PROPID_P(1, 1) + PROPID_P(b1, 1) - c10 * h0_r1;
    const float h1_b1 = PROPID_P(1, b1) + PROPID_P(b1, b1) - c10 * h0_b1;
    const float var1 = h1_r1 + h1_b1 + noise_var;
    const float nu1 = gyro[1] - (state[1] + h0_r1 * step0) - (state[b1] + h0_b1 * step0);
    const float nu1_sq = nu1 * nu1;
    if (outside_positive_range(var1, var_bits, var_range_bits) || !(nu1_sq <= gate_sq * var1)) {
        return 0;
    }
    const float inv1 = 1.0f / var1;
    const float step1 = nu1 * inv1;

    /* z axis: h_2 = P_:,2 + P_:,13 - c20 h_0 - c21 h_1 */
    const float h0_r2 = PROPID_P(0, 2) + PROPID_P(b0, 2);
    const float h0_b2 = PROPID_P(0, b2) + PROPID_P(b0, b2);
    const float h1_r2 = PROPID_P(1, 2) + PROPID_P(b1, 2) - c10 * h0_r2;
    const float h1_b2 = PROPID_P(1, b2) + PROPID_P(b1, b2) - c10 * h0_b2;
    const float c20 = (h0_r2 + h0_b2) * inv0;
    const float c21 = (h1_r2 + h1_b2) * inv1;
    const float h2_r2 = PROPID_P(2, 2) + PROPID_P(b2, 2) - c20 * h0_r2 - c21 * h1_r2;
    const float h2_b2 = PROPID_P(2, b2) + PROPID_P(b2, b2) - c20 * h0_b2 - c21 * h1_b2;
    const float var2 = h2_r2 + h2_b2 + noise_var;
    const float shift_r2 = h0_r2 * step0 + h1_r2 * step1;
    const float shift_b2 = h0_b2 * step0 + h1_b2 * step1;
    const float nu2 = gyro[2] - (state[2] + shift_r2) - (state[b2] + shift_b2);
    const float nu2_sq = nu2 * nu2;
    if (outside_positive_range(var2, var_bits, var_range_bits) || !(nu2_sq <= gate_sq * var2)) {
        return 0;
    }
    const float inv2 = 1.0f / var2;

    /* The three vectors, with one finiteness test over all of them: h_2 folds in
     * h_0 and h_1 (c * Inf is Inf, or NaN when c = 0), so a non-finite element of
     * any of the three makes that element of h_2 non-finite; summing h_2 covers all. */
    float *h0 = pending->h[0];
    float *h1 = pending->h[1];
    float *h2 = pending->h[2];
    float check = 0.0f;
#pragma GCC unroll 14
    for (uint8_t i = 0; i < PROPID_QUAD_STATES; ++i) {
        const float value0 = PROPID_P(0, i) + PROPID_P(b0, i);
        const float value1 = PROPID_P(1, i) + PROPID_P(b1, i) - c10 * value0;
        const float value2 = PROPID_P(2, i) + PROPID_P(b2, i) - c20 * value0 - c21 * value1;
        h0[i] = value0;
        h1[i] = value1;
        h2[i] = value2;
        check += value2;
    }
#undef PROPID_P
    if (!isfinite(check)) {
        return 0;
    }
    const float inv_gate_sq = derived->inv_gate_sq;
    core->innovation[0] = nu0;
    core->innovation[1] = nu1;
    core->innovation[2] = nu2;
    core->innovation_test_ratio[0] = nu0_sq * inv0 * inv_gate_sq;
    core->innovation_test_ratio[1] = nu1_sq * inv1 * inv_gate_sq;
    core->innovation_test_ratio[2] = nu2_sq * inv2 * inv_gate_sq;
    core->gated_run[0] = 0u;
    core->gated_run[1] = 0u;
    core->gated_run[2] = 0u;
    pending->innovation[0] = nu0;
    pending->innovation[1] = nu1;
    pending->innovation[2] = nu2;
    pending->inv_var[0] = inv0;
    pending->inv_var[1] = inv1;
    pending->inv_var[2] = inv2;
    pending->count = 3u;
    return 1;
}

uint32_t propid_update_gyro(propid_filter_t *filter, const float gyro[3])
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const uint8_t n = derived->state_count;
    pending_t pending;
    pending.count = 0u;
    int repaired = 0; /* at most one repair-and-retry per sample */
    uint32_t gated_mask;
    if (n == PROPID_QUAD_STATES &&
        fuse_quad_usual((const float (*)[PROPID_MAX_STATES])core->cov, core, derived, &pending, gyro)) {
        gated_mask = 0u;
    } else {
        /* Every other sample (a gated axis, S out of its range, a non-finite
         * vector) and every other vehicle: the general per-axis code. A
         * prediction across a long gap at high rates can inflate the rate
         * variances by orders of magnitude: the ceilings first (they keep P
         * PSD), so no update sees an S that float32 cannot downdate. */
        if (propid_cov_enforce_bounds(derived, core)) {
            core->health |= PROPID_HEALTH_COV_REPAIRED;
            filter->counters.cov_repairs++;
        }
        gated_mask = 0u;
        for (uint8_t axis = 0; axis < 3u; ++axis) {
            gated_mask |= fuse_axis(filter, &pending, &repaired, axis, gyro[axis], n) << axis;
        }
    }
    /* Variance floors and ceilings: already tested inside the quad's pass; the
     * full pass (which also repairs) runs when that found one outside, or when
     * the pass was not the quad's three-term one. */
    if (!apply_pending(core, derived, &pending) && propid_cov_enforce_bounds(derived, core)) {
        core->health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    return gated_mask;
}

uint32_t propid_clamp_coefficients(const propid_config_t *config, propid_core_t *core)
{
    const uint8_t first = propid_first_thrust();
    const uint8_t end = propid_first_bias(config->rotor_count);
    /* Fast test of both bounds on the bit patterns (0 < min < max, see
     * outside_positive_range); the rare clamp then compares the values. */
    uint32_t min_bits;
    uint32_t max_bits;
    memcpy(&min_bits, &config->coeff_rel_min, sizeof(min_bits));
    memcpy(&max_bits, &config->coeff_rel_max, sizeof(max_bits));
    const uint32_t range_bits = max_bits - min_bits;
    if (config->rotor_count == 4u) {
        /* The quad: one straight-line test of the 8 coefficients' bit patterns. */
        uint32_t outside = 0u;
#pragma GCC unroll 8
        for (uint8_t k = PROPID_RATE_STATES; k < PROPID_RATE_STATES + 8u; ++k) {
            outside |= outside_positive_range(core->state[k], min_bits, range_bits);
        }
        if (outside == 0u) {
            return 0u;
        }
    }
    uint32_t clamped = 0u;
    for (uint8_t k = first; k < end; ++k) {
        if (!outside_positive_range(core->state[k], min_bits, range_bits)) {
            continue;
        }
        if (core->state[k] < config->coeff_rel_min) {
            core->state[k] = config->coeff_rel_min;
            clamped++;
        } else if (core->state[k] > config->coeff_rel_max) {
            core->state[k] = config->coeff_rel_max;
            clamped++;
        }
    }
    return clamped;
}
