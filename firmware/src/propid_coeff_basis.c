/* The coefficients' bases (propid_internal.h, docs/math.md §2): the maps of the
 * state's and P's coefficient blocks between the kept bases (km: z = H km_rel,
 * kf: z = Q kf_rel = H_1 H_0 kf_rel) and per rotor. One reflection H = I - scale
 * v v^T on a block B = P_zz, with u = B v and beta = v . u:
 *   H B H = B - scale (v u^T + u v^T) + scale^2 beta v v^T. */
#include <math.h>

#include "propid_internal.h"

#if !PROPID_GENERAL_VEHICLES
/* N = 4: v = e_0 + s_0 s / 2, row k for rotors 1..3 opposite to rotor 0 where bit
 * k - 1 of the row index is set. */
const float propid_quad_drag_basis[8][4] = {
    {1.5f, 0.5f, 0.5f, 0.5f},  {1.5f, -0.5f, 0.5f, 0.5f},  {1.5f, 0.5f, -0.5f, 0.5f},
    {1.5f, -0.5f, -0.5f, 0.5f}, {1.5f, 0.5f, 0.5f, -0.5f},  {1.5f, -0.5f, 0.5f, -0.5f},
    {1.5f, 0.5f, -0.5f, -0.5f}, {1.5f, -0.5f, -0.5f, -0.5f},
};
#endif

__attribute__((noinline)) void propid_reflection_transform(const propid_reflection_t *basis, float *x)
{
    propid_reflection_apply(basis, x);
}

/* u = B v for the count x count block B of P from state `first`, and v . u: each
 * u_i = sum_j B_ij v_j in j order, B_ij read down column first + i above the
 * diagonal and along row first + i from it (the packed triangle walked by pointer,
 * not indexed element by element). */
static float block_times(const float *cov, uint8_t first, uint8_t count, const float *v, float *u)
{
    const float *block_row = propid_cov_row_const(cov, first); /* row `first`: P_(first)c at [c] */
    float beta = 0.0f;
    for (uint8_t i = 0; i < count; ++i) {
        const uint8_t column = (uint8_t)(first + i);
        float sum = 0.0f;
        const float *above = block_row + column; /* P_(first)(column), then down the column */
        for (uint8_t j = 0; j < i; ++j) {
            sum += *above * v[j];
            above += PROPID_MAX_STATES - 1u - (uint32_t)(first + j);
        }
        const float *row = propid_cov_row_const(cov, column);
        for (uint8_t j = i; j < count; ++j) {
            sum += row[first + j] * v[j];
        }
        u[i] = sum;
        beta += v[i] * sum;
    }
    return beta;
}

#if PROPID_MAX_ROTORS >= 4 && !PROPID_SIZE_LEAN
/* The same for a quad's block (count 4), its loops unrolled: the same sums in the
 * same order. */
static float block_times_quad(const float *cov, uint8_t first, const float *v, float *u)
{
    const float *block_row = propid_cov_row_const(cov, first);
    float beta = 0.0f;
    PROPID_UNROLL(4)
    for (uint8_t i = 0; i < 4u; ++i) {
        const uint8_t column = (uint8_t)(first + i);
        float sum = 0.0f;
        const float *above = block_row + column;
        PROPID_UNROLL(3)
        for (uint8_t j = 0; j < i; ++j) {
            sum += *above * v[j];
            above += PROPID_MAX_STATES - 1u - (uint32_t)(first + j);
        }
        const float *row = propid_cov_row_const(cov, column);
        PROPID_UNROLL(4)
        for (uint8_t j = i; j < 4u; ++j) {
            sum += row[first + j] * v[j];
        }
        u[i] = sum;
        beta += v[i] * sum;
    }
    return beta;
}
#endif

/* u = B v over the reflection's packed block, and beta = v . u. */
static float block_times_basis(const propid_reflection_t *basis, const float *cov, float *u)
{
    return block_times(cov, basis->first, basis->count, basis->vector, u);
}

void propid_reflection_flip_column(const propid_reflection_t *basis, propid_core_t *core, uint8_t column_index)
{
    const uint8_t count = basis->count;
    const uint8_t first = basis->first;
    float column[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < count; ++i) {
        column[i] = propid_cov_at(core->cov, (uint8_t)(first + i), column_index);
    }
    propid_reflection_transform(basis, column);
    for (uint8_t i = 0; i < count; ++i) {
        core->cov[propid_cov_index((uint8_t)(first + i), column_index)] = column[i];
    }
}

void propid_reflection_flip_block(const propid_reflection_t *basis, propid_core_t *core)
{
    const uint8_t count = basis->count;
    const uint8_t first = basis->first;
    const float *v = basis->vector;
    const float scale = basis->scale;
    float u[PROPID_MAX_ROTORS];
    const float beta = block_times_basis(basis, core->cov, u);
    for (uint8_t i = 0; i < count; ++i) {
        for (uint8_t j = i; j < count; ++j) {
            core->cov[propid_cov_index((uint8_t)(first + i), (uint8_t)(first + j))] -=
                scale * (v[i] * u[j] + u[i] * v[j]) - scale * scale * beta * v[i] * v[j];
        }
    }
}

void propid_reflection_flip(const propid_reflection_t *basis, propid_core_t *core)
{
    const uint8_t first = basis->first;
    const uint8_t end = (uint8_t)(first + basis->count);
    propid_reflection_transform(basis, &core->state[first]);
    /* The cross-covariances with every other state: a column of N values each
     * (state_count is not needed: the unused part of the triangle is zero). */
    for (uint8_t j = 0; j < PROPID_MAX_STATES; ++j) {
        if (j < first || j >= end) {
            propid_reflection_flip_column(basis, core, j);
        }
    }
    propid_reflection_flip_block(basis, core);
}

void propid_drag_per_rotor(const propid_reflection_t *basis, const propid_core_t *core, float *km_rel,
                           float *km_var)
{
    const uint8_t count = basis->count;
    const uint8_t first = basis->first;
    for (uint8_t i = 0; i < count; ++i) {
        km_rel[i] = core->state[first + i];
    }
    propid_reflection_transform(basis, km_rel);
    if (km_var == NULL) {
        return;
    }
    const float *v = basis->vector;
    const float scale = basis->scale;
    float u[PROPID_MAX_ROTORS];
#if PROPID_MAX_ROTORS >= 4 && !PROPID_SIZE_LEAN
    /* (the quad build: always 4 rotors) */
    const float beta = PROPID_GENERAL_VEHICLES && count != 4u ? block_times_basis(basis, core->cov, u)
                                                              : block_times_quad(core->cov, first, v, u);
#else
    const float beta = block_times_basis(basis, core->cov, u);
#endif
    for (uint8_t i = 0; i < count; ++i) {
        const uint8_t k = (uint8_t)(first + i);
        km_var[i] = propid_cov_at(core->cov, k, k) - scale * v[i] * (2.0f * u[i] - scale * beta * v[i]);
    }
}

#if PROPID_SIZE_LEAN
/* The size-lean build: one reflection routine called twice (the pair in one pass
 * below is 118 B more at -Os). */
/* x := (I - w w^T) x over `count` values (a kf reflection, its scale folded into w). */
static inline void reflect_folded(const float *w, uint8_t count, float *x)
{
    float dot = 0.0f;
    for (uint8_t i = 0; i < count; ++i) {
        dot += w[i] * x[i];
    }
    for (uint8_t i = 0; i < count; ++i) {
        x[i] -= dot * w[i];
    }
}

void propid_thrust_to_basis(const propid_thrust_basis_t *basis, float *x)
{
    const uint8_t count = basis->rotor_count;
    reflect_folded(basis->vector[0], count, x);
    if (count > 1u) {
        reflect_folded(basis->vector[1], (uint8_t)(count - 1u), x + 1);
    }
}

void propid_thrust_to_rotor(const propid_thrust_basis_t *basis, float *x)
{
    const uint8_t count = basis->rotor_count;
    if (count > 1u) {
        reflect_folded(basis->vector[1], (uint8_t)(count - 1u), x + 1);
    }
    reflect_folded(basis->vector[0], count, x);
}

#else
/* z = Q x = H_1 H_0 x, each H_k = I - w w^T (its scale folded into w), both in one
 * pass over x: H_1's dot product taken as H_0 writes the elements (the same
 * operations in the same order as one reflection after the other). */
void propid_thrust_to_basis(const propid_thrust_basis_t *basis, float *x)
{
    const uint8_t count = basis->rotor_count;
    const float *w0 = basis->vector[0];
    const float *w1 = basis->vector[1] - 1; /* w1[k]: element k's entry, k >= 1 */
    if (count == 0u) {
        return;
    }
    float dot0 = 0.0f;
    for (uint8_t i = 0; i < count; ++i) {
        dot0 += w0[i] * x[i];
    }
    x[0] -= dot0 * w0[0];
    float dot1 = 0.0f;
    for (uint8_t i = 1; i < count; ++i) {
        x[i] -= dot0 * w0[i];
        dot1 += w1[i] * x[i];
    }
    for (uint8_t i = 1; i < count; ++i) {
        x[i] -= dot1 * w1[i];
    }
}

/* H_0 H_1 x the same way: H_1's update and H_0's dot product in one pass. */
void propid_thrust_to_rotor(const propid_thrust_basis_t *basis, float *x)
{
    const uint8_t count = basis->rotor_count;
    if (count == 0u) {
        return;
    }
    const float *w0 = basis->vector[0];
    const float *w1 = basis->vector[1] - 1;
    float dot1 = 0.0f;
    for (uint8_t i = 1; i < count; ++i) {
        dot1 += w1[i] * x[i];
    }
    float dot0 = 0.0f;
    dot0 += w0[0] * x[0]; /* (from zero, as H_0 alone sums it) */
    for (uint8_t i = 1; i < count; ++i) {
        x[i] -= dot1 * w1[i];
        dot0 += w0[i] * x[i];
    }
    for (uint8_t i = 0; i < count; ++i) {
        x[i] -= dot0 * w0[i];
    }
}

#endif

void propid_coeff_flip(const propid_derived_t *derived, const propid_kept_config_t *config, propid_core_t *core,
                       int to_rotor)
{
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, derived, config);
    const propid_reflection_t drag = propid_drag_basis(derived, config);
    /* P_x = Q^T P_z Q = H_0 H_1 P_z H_1 H_0: H_1 first on the way out, last on the way in. */
    const propid_reflection_t first = propid_thrust_reflection(&thrust, (uint8_t)(to_rotor ? 1u : 0u));
    const propid_reflection_t second = propid_thrust_reflection(&thrust, (uint8_t)(to_rotor ? 0u : 1u));
    propid_reflection_flip(&first, core);
    propid_reflection_flip(&second, core);
    propid_reflection_flip(&drag, core);
}

#if PROPID_MAX_ROTORS >= 4 && !PROPID_SIZE_LEAN
/* diag(Q^T B Q) for a quad, B the kf block of P: kf_rel_i = a_i . z with a_i = Q e_i,
 * variance a_i^T B a_i = sum_j a_ij (sum_k B_jk a_ik). The four a_i are built side by
 * side (column[k][i] = (a_i)_k) by the operations propid_thrust_to_basis does on
 * e_i, in the same order, and each element of B is loaded once for all four, in
 * the same order of sums as one a_i at a time (thrust_variances_any): the same
 * bits, without mapping each e_i through both reflections and reading all of B
 * again for it (docs/performance.md, "The estimate's per-rotor variances"). */
static __attribute__((noinline)) void thrust_variances_quad(const propid_thrust_basis_t *basis, const float *cov,
                                                            float *var)
{
    const uint8_t first = propid_first_thrust();
    float column[4][4];
    /* H_0 e_i = e_i - w_i w (w = vector[0]): the reflection's dot product of w with
     * e_i is w_i exactly (its other terms are zeros; a zero w_i gives a zero
     * product either way). */
    const float *w = basis->vector[0];
    PROPID_UNROLL(4)
    for (uint8_t k = 0; k < 4u; ++k) {
        PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            column[k][i] = (k == i ? 1.0f : 0.0f) - w[i] * w[k];
        }
    }
    /* H_1 on elements 1..3 of every column. */
    float dot[4] = {0.0f, 0.0f, 0.0f, 0.0f};
    w = basis->vector[1] - 1; /* w[k]: element k's entry */
    PROPID_UNROLL(3)
    for (uint8_t k = 1; k < 4u; ++k) {
        PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            dot[i] += w[k] * column[k][i];
        }
    }
    PROPID_UNROLL(3)
    for (uint8_t k = 1; k < 4u; ++k) {
        PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            column[k][i] -= dot[i] * w[k];
        }
    }
    const float *block_row = propid_cov_row_const(cov, first); /* P_(first)c at [c] */
    PROPID_UNROLL(4)
    for (uint8_t i = 0; i < 4u; ++i) {
        var[i] = 0.0f;
    }
    PROPID_UNROLL(4)
    for (uint8_t j = 0; j < 4u; ++j) {
        float sum[4] = {0.0f, 0.0f, 0.0f, 0.0f}; /* (B a_i)_j for every i */
        const float *above = block_row + first + j; /* B_kj, k < j: down column first + j */
        PROPID_UNROLL(3)
        for (uint8_t k = 0; k < j; ++k) {
            const float b = *above;
            PROPID_UNROLL(4)
            for (uint8_t i = 0; i < 4u; ++i) {
                sum[i] += b * column[k][i];
            }
            above += PROPID_MAX_STATES - 1u - (uint32_t)(first + k);
        }
        const float *row = propid_cov_row_const(cov, (uint8_t)(first + j)); /* B_jk, k >= j */
        PROPID_UNROLL(4)
        for (uint8_t k = j; k < 4u; ++k) {
            const float b = row[first + k];
            PROPID_UNROLL(4)
            for (uint8_t i = 0; i < 4u; ++i) {
                sum[i] += b * column[k][i];
            }
        }
        PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            var[i] += column[j][i] * sum[i];
        }
    }
}
#endif

#if PROPID_GENERAL_VEHICLES || PROPID_SIZE_LEAN
/* The same for any rotor count (and the size-lean build's quad: less code), one
 * rotor at a time: a_i = Q e_i through both reflections, then a_i^T B a_i. */
static __attribute__((noinline)) void thrust_variances_any(const propid_thrust_basis_t *basis, const float *cov,
                                                           float *var)
{
    const uint8_t count = basis->rotor_count;
    for (uint8_t i = 0; i < count; ++i) {
        float a[PROPID_MAX_ROTORS];
        float u[PROPID_MAX_ROTORS];
        for (uint8_t j = 0; j < count; ++j) {
            a[j] = j == i ? 1.0f : 0.0f;
        }
        propid_thrust_to_basis(basis, a);
        var[i] = block_times(cov, propid_first_thrust(), count, a, u);
    }
}
#endif

void propid_thrust_per_rotor(const propid_thrust_basis_t *basis, const propid_core_t *core, float *kf_rel,
                             float *kf_var)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_thrust();
    for (uint8_t i = 0; i < rotor_count; ++i) {
        kf_rel[i] = core->state[first + i];
    }
    propid_thrust_to_rotor(basis, kf_rel);
    if (kf_var == NULL) {
        return;
    }
#if PROPID_GENERAL_VEHICLES || PROPID_SIZE_LEAN
    if (PROPID_SIZE_LEAN || PROPID_MAX_ROTORS < 4 || rotor_count != 4u) {
        thrust_variances_any(basis, core->cov, kf_var);
        return;
    }
#endif
#if PROPID_MAX_ROTORS >= 4 && !PROPID_SIZE_LEAN
    thrust_variances_quad(basis, core->cov, kf_var); /* (the quad build: always 4 rotors) */
#endif
}

/* P_jk for every j < state_count: down column k to the diagonal, then along row k. */
static void cov_column(const float *cov, uint8_t state_count, uint8_t k, float *column)
{
    const float *p = cov + k; /* P_0k; row j's start moves by PROPID_MAX_STATES - 1 - j */
    for (uint8_t j = 0; j < k; ++j) {
        column[j] = *p;
        p += PROPID_MAX_STATES - 1u - j;
    }
    const float *row = propid_cov_row_const(cov, k);
    for (uint8_t j = k; j < state_count; ++j) {
        column[j] = row[j];
    }
}

void propid_coeff_per_rotor_column(const propid_derived_t *derived, const propid_kept_config_t *config,
                                   const propid_core_t *core, uint8_t state_count, uint8_t k, float *scratch,
                                   float *column)
{
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, derived, config);
    const propid_reflection_t drag = propid_drag_basis(derived, config);
    const uint8_t rotor_count = config->rotor_count;
    const uint8_t first_thrust = propid_first_thrust();
    const uint8_t first_drag = drag.first;
    /* t = T e_k: zero outside k's block, Q e_i or H e_i within it. */
    float t[PROPID_MAX_ROTORS];
    uint8_t block = PROPID_NO_STATE;
    if (k >= first_thrust && k < first_drag) {
        block = first_thrust;
    } else if (k >= first_drag && k < first_drag + rotor_count) {
        block = first_drag;
    }
    if (block == PROPID_NO_STATE) {
        cov_column(core->cov, state_count, k, column); /* T e_k = e_k */
    } else {
        for (uint8_t i = 0; i < rotor_count; ++i) {
            t[i] = i == k - block ? 1.0f : 0.0f;
        }
        if (block == first_thrust) {
            propid_thrust_to_basis(&thrust, t);
        } else {
            propid_reflection_transform(&drag, t);
        }
        for (uint8_t j = 0; j < state_count; ++j) {
            column[j] = 0.0f;
        }
        for (uint8_t m = 0; m < rotor_count; ++m) {
            cov_column(core->cov, state_count, (uint8_t)(block + m), scratch);
            for (uint8_t j = 0; j < state_count; ++j) {
                column[j] += scratch[j] * t[m];
            }
        }
    }
    /* T^T on the left. */
    propid_thrust_to_rotor(&thrust, &column[first_thrust]);
    propid_reflection_transform(&drag, &column[first_drag]);
}

/* One per-rotor coefficient back to `prior`, uncorrelated, in the kept basis: with
 * a = T e_k its direction in the block from `first` (count entries), P := (I - a a^T) P
 * (I - a a^T) + prior a a^T = P - a u^T - u a^T + (beta + prior) a a^T, u = P a,
 * beta = a . u: one rank-2 update, each element rounded once (flipping P to per
 * rotor and back rounded the coefficient rows through every reflection twice, and
 * left a nearly singular P indefinite). `u`: state_count floats of scratch. */
static void reset_along(const propid_derived_t *derived, propid_core_t *core, uint8_t first, uint8_t count,
                        const float *a, float prior, float *u)
{
    const uint8_t n = derived->state_count;
    for (uint8_t j = 0; j < n; ++j) {
        float sum = 0.0f;
        for (uint8_t m = 0; m < count; ++m) {
            sum += propid_cov_at(core->cov, j, (uint8_t)(first + m)) * a[m];
        }
        u[j] = sum;
    }
    float beta = 0.0f;
    for (uint8_t m = 0; m < count; ++m) {
        beta += a[m] * u[first + m];
    }
    const float c = beta + prior;
    /* The update's rounding, a few eps of the magnitudes each element combines,
     * is covered by a diagonal term that keeps the computed P at least the exact
     * one's definiteness: an error matrix E is dominated by diag(d) with d_i =
     * w_i sum_j |E_ij| / w_j for any positive weights (the scaled matrix is then
     * diagonally dominant); with w_i = sqrt(P'_ii), the updated variance, it is a
     * few eps times n of each variance, relative, also for the well-determined
     * combinations a nearly singular P holds (unscaled row sums would re-open
     * them far beyond their own variance). */
    float weight[PROPID_MAX_STATES];
    float *load = core->update_vector[1];
    for (uint8_t i = 0; i < n; ++i) {
        const float ai = i >= first && i < first + count ? a[i - first] : 0.0f;
        const float updated = propid_cov_at(core->cov, i, i) + ai * (c * ai - 2.0f * u[i]);
        weight[i] = updated > 0.0f ? sqrtf(updated) : 0.0f;
        load[i] = 0.0f;
    }
    for (uint8_t i = 0; i < n; ++i) {
        const float ai = i >= first && i < first + count ? a[i - first] : 0.0f;
        float *row = propid_cov_row(core->cov, i);
        for (uint8_t j = i; j < n; ++j) {
            const float aj = j >= first && j < first + count ? a[j - first] : 0.0f;
            if (ai != 0.0f || aj != 0.0f) {
                const float magnitude = fabsf(c * ai * aj) + fabsf(ai * u[j]) + fabsf(u[i] * aj) + fabsf(row[j]);
                row[j] += c * ai * aj - ai * u[j] - u[i] * aj;
                const float error = 4.0f * PROPID_VAR_LOADING * magnitude;
                if (weight[i] > 0.0f && weight[j] > 0.0f) {
                    load[i] += error * (weight[i] / weight[j]);
                    if (j != i) {
                        load[j] += error * (weight[j] / weight[i]);
                    }
                }
            }
        }
    }
    for (uint8_t i = 0; i < n; ++i) {
        core->cov[propid_cov_index(i, i)] += load[i];
    }
}

void propid_cov_reset_rotor(const propid_derived_t *derived, const propid_kept_config_t *config, propid_core_t *core,
                            uint8_t rotor, int to_nominal)
{
    const uint8_t rotor_count = config->rotor_count;
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, derived, config);
    const propid_reflection_t drag = propid_drag_basis(derived, config);
    const uint8_t first_thrust = propid_first_thrust();
    /* The step's work area, free between calls: u of reset_along. */
    float *u = core->update_vector[0];
    for (uint8_t block = 0; block < 2u; ++block) {
        const uint8_t first = block == 0u ? first_thrust : drag.first;
        float a[PROPID_MAX_ROTORS]; /* T e_rotor in the block */
        for (uint8_t m = 0; m < rotor_count; ++m) {
            a[m] = m == rotor ? 1.0f : 0.0f;
        }
        if (block == 0u) {
            propid_thrust_to_basis(&thrust, a);
        } else {
            propid_reflection_transform(&drag, a);
        }
        if (to_nominal) {
            /* The per-rotor value is a . z; moved to its nominal along a. With the
             * torque scale the thrust state is g = s kf = kf / r (docs/math.md §9). */
            const uint8_t scale = derived->layout.torque_scale;
            const float target = block == 0u && PROPID_WITH_ACCEL && scale != PROPID_NO_STATE
                                     ? 1.0f / core->state[scale]
                                     : 1.0f;
            float value = 0.0f;
            for (uint8_t m = 0; m < rotor_count; ++m) {
                value += a[m] * core->state[first + m];
            }
            for (uint8_t m = 0; m < rotor_count; ++m) {
                core->state[first + m] += a[m] * (target - value);
            }
        }
        reset_along(derived, core, first, rotor_count, a, propid_prior_var(derived, first), u);
    }
}
