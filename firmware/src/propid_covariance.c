/* Covariance housekeeping: prior, per-state variance bounds, integrity checks and
 * repair. Only the upper triangle of the symmetric P is kept, packed
 * (propid_internal.h, propid_cov_at): symmetry is exact by construction, there
 * is no mirror to check. */
#include <float.h>
#include <math.h>
#include <string.h>

#include "propid_internal.h"

#if !PROPID_GENERAL_VEHICLES
const uint8_t propid_quad_state_kind[PROPID_MAX_STATES] = {
    PROPID_KIND_RATE,   PROPID_KIND_RATE,   PROPID_KIND_RATE,   PROPID_KIND_THRUST, PROPID_KIND_THRUST,
    PROPID_KIND_THRUST, PROPID_KIND_THRUST, PROPID_KIND_DRAG,   PROPID_KIND_DRAG,   PROPID_KIND_DRAG,
    PROPID_KIND_DRAG,   PROPID_KIND_BIAS,   PROPID_KIND_BIAS,   PROPID_KIND_BIAS};
#endif

void propid_cov_set_prior(const propid_derived_t *derived, const propid_kept_config_t *config, propid_core_t *core)
{
    const uint8_t rotor_count = config->rotor_count;
    const uint8_t n = derived->state_count;
    memset(core->state, 0, sizeof(core->state));
    memset(core->cov, 0, sizeof(core->cov));
    const uint8_t first_bias = propid_first_bias(rotor_count);
    for (uint8_t k = propid_first_thrust(); k < first_bias; ++k) {
        core->state[k] = 1.0f; /* coefficients start at their nominal */
    }
    const uint8_t scale = derived->layout.torque_scale;
    if (scale != PROPID_NO_STATE) {
        core->state[scale] = 1.0f; /* r = 1/s: the configured J and arms */
    }
    /* The coefficient blocks in their bases (propid_internal.h): the nominal
     * mapped. Their prior variances are equal, so the prior P is the same in
     * either basis. */
    const propid_reflection_t drag = propid_drag_basis(derived, config);
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, derived, config);
    propid_reflection_transform(&drag, &core->state[drag.first]);
    propid_thrust_to_basis(&thrust, &core->state[propid_first_thrust()]);
    for (uint8_t k = 0; k < n; ++k) {
        core->cov[propid_cov_index(k, k)] = propid_prior_var(derived, k);
    }
    if (scale != PROPID_NO_STATE) {
        /* The thrust states carry g_i = s kf_i and the scale state r = 1/s
         * (docs/math.md §9): independent priors on kf_i and s, carried to first
         * order at the nominal, give var g_i = P_kf + P_s, cov(g_i, g_j) = P_s and
         * cov(g_i, r) = -P_s per rotor; in the torque basis P_s c c^T and -P_s c
         * with c = Q 1, the nominal's image (the state just set). */
        const float scale_var = propid_prior_var(derived, scale);
        const uint8_t first_drag = propid_first_drag(rotor_count);
        for (uint8_t i = propid_first_thrust(); i < first_drag; ++i) {
            for (uint8_t j = i; j < first_drag; ++j) {
                core->cov[propid_cov_index(i, j)] += scale_var * core->state[i] * core->state[j];
            }
            core->cov[propid_cov_index(i, scale)] = -scale_var * core->state[i];
        }
    }
}

void propid_cov_reset_state(const propid_derived_t *derived, propid_core_t *core, uint8_t index)
{
    const uint8_t n = derived->state_count;
    for (uint8_t j = 0; j < n; ++j) {
        core->cov[propid_cov_index(index, j)] = 0.0f;
    }
    core->cov[propid_cov_index(index, index)] = propid_prior_var(derived, index);
}

int propid_cov_repair(const propid_derived_t *derived, propid_core_t *core)
{
    const uint8_t n = derived->state_count;
    int changed = 0;
    /* Bad variances: the state forgets its correlations and returns to its prior. */
    for (uint8_t i = 0; i < n; ++i) {
        const float p = core->cov[propid_cov_index(i, i)];
        if (!propid_outside_positive_range(p, propid_floor_bits(derived, i), propid_range_bits(derived, i))) {
            continue; /* the usual case: one test per diagonal (NaN fails it) */
        }
        if (!(p > 0.0f && p <= FLT_MAX)) {
            propid_cov_reset_state(derived, core, i);
            changed = 1;
        }
    }
    /* Off-diagonals: finite, and correlation inside [-1, 1] up to the rounding of
     * the test itself (PROPID_ROUNDING_TOL: two rounded products). */
    for (uint8_t i = 0; i < n; ++i) {
        float *row = propid_cov_row(core->cov, i);
        for (uint8_t j = (uint8_t)(i + 1u); j < n; ++j) {
            const float pij = row[j];
            const float limit_sq = row[i] * core->cov[propid_cov_index(j, j)];
            float fixed = pij;
            if (!isfinite(pij)) {
                fixed = 0.0f;
            } else if (pij * pij > limit_sq * (1.0f + PROPID_ROUNDING_TOL)) {
                /* Pull the correlation back to 0.99 (rare path: sqrtf is fine here). */
                const float limit = 0.99f * sqrtf(limit_sq);
                fixed = pij > 0.0f ? limit : -limit;
            }
            if (fixed != pij) {
                row[j] = fixed;
                changed = 1;
            }
        }
    }
    return changed;
}

int propid_cov_check_row(const propid_derived_t *derived, propid_core_t *core, uint8_t row)
{
    return propid_cov_check_row_inline(derived, core, row);
}

int propid_cov_enforce_bounds(const propid_derived_t *derived, propid_core_t *core)
{
    const uint8_t n = derived->state_count;
    int repaired = 0;
    for (uint8_t i = 0; i < n; ++i) {
        float *diagonal = &core->cov[propid_cov_index(i, i)];
        const float p = *diagonal;
        if (!propid_outside_positive_range(p, propid_floor_bits(derived, i), propid_range_bits(derived, i))) {
            continue; /* the usual case: one test per diagonal (NaN fails it) */
        }
        if (!(p > 0.0f && p <= FLT_MAX)) {
            repaired |= propid_cov_repair(derived, core);
        } else if (p < propid_var_floor(derived, i)) {
            /* Adding to a diagonal keeps P positive semi-definite. */
            *diagonal = propid_var_floor(derived, i);
        } else if (p > propid_var_ceiling(derived, i)) {
            /* Scale row and column by c = ceiling / p and set the diagonal to the
             * ceiling: D P D plus a non-negative diagonal term, still PSD. Rare. */
            const float c = propid_var_ceiling(derived, i) / p;
            for (uint8_t j = 0; j < i; ++j) {
                core->cov[propid_cov_index(j, i)] *= c; /* column i above the diagonal */
            }
            for (uint8_t j = (uint8_t)(i + 1u); j < n; ++j) {
                diagonal[j - i] *= c; /* row i right of the diagonal */
            }
            *diagonal = propid_var_ceiling(derived, i);
        }
    }
    return repaired;
}

/* The coefficients found outside the range: the estimate projected onto each
 * one's bound (propid_bound_projection.c), per rotor. Only the state is mapped
 * out of the bases and back (2N values); P stays in them and each projection
 * reads its column per rotor (propid_coeff_per_rotor_column: N columns of P
 * times the basis' column, N x n products), so a coefficient riding its bound
 * costs little per sample and P is not rounded through the reflections. Apart,
 * so the usual sample's test stays lean. */
static __attribute__((noinline)) PROPID_RARE uint32_t project_outside(propid_filter_t *filter)
{
    const propid_kept_config_t *config = &filter->config;
    propid_core_t *core = &filter->core;
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, config);
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, config);
    const uint8_t n = filter->derived.state_count;
    const uint8_t first = propid_first_thrust();
    const uint8_t end = propid_first_bias(config->rotor_count);
    /* The step's work area, free after the update: P's column and one column
     * of the block it is formed from. */
    float *column = core->update_vector[0];
    float *scratch = core->update_vector[1];
    propid_reflection_transform(&basis, &core->state[basis.first]);
    propid_thrust_to_rotor(&thrust, &core->state[first]);
    uint32_t clamped = 0u;
    for (uint8_t k = first; k < end; ++k) {
        const float x = core->state[k];
        if (x < config->coeff_rel_min || x > config->coeff_rel_max) {
            const float bound = x < config->coeff_rel_min ? config->coeff_rel_min : config->coeff_rel_max;
            propid_coeff_per_rotor_column(&filter->derived, config, core, n, k, scratch, column);
            (void)propid_project_onto_bound(n, column, core->state, k, bound);
            clamped++;
        }
    }
    if (clamped != 0u) {
        /* A later projection moves the earlier coefficients by their regression:
         * the range holds again with the plain clamp (no further projection). */
        for (uint8_t k = first; k < end; ++k) {
            const float x = core->state[k];
            core->state[k] = x < config->coeff_rel_min   ? config->coeff_rel_min
                             : x > config->coeff_rel_max ? config->coeff_rel_max
                                                         : x;
        }
    }
    propid_reflection_transform(&basis, &core->state[basis.first]);
    propid_thrust_to_basis(&thrust, &core->state[first]);
    return clamped;
}

uint32_t propid_clamp_coefficients(propid_filter_t *filter)
{
    const propid_kept_config_t *config = &filter->config;
    const propid_core_t *core = &filter->core;
    const uint8_t rotor_count = config->rotor_count;
    /* Fast test of both bounds on the bit patterns (0 < min < max, see
     * outside_positive_range); the rare projection then compares the values. The
     * drag coefficients are bounded per rotor: their yaw-basis states mapped back. */
    uint32_t min_bits;
    uint32_t max_bits;
    memcpy(&min_bits, &config->coeff_rel_min, sizeof(min_bits));
    memcpy(&max_bits, &config->coeff_rel_max, sizeof(max_bits));
    const uint32_t range_bits = max_bits - min_bits;
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, config);
    float km_rel[PROPID_MAX_ROTORS];
    float kf_rel[PROPID_MAX_ROTORS];
    uint32_t outside = 0u;
    /* The quad build has 4 rotors only (its configuration check): no other
     * branch, so the values and the bases stay in registers (14 instructions less). */
    if (!PROPID_GENERAL_VEHICLES || rotor_count == 4u) {
        /* The quad: straight-line tests of the 8 coefficients' bit patterns. */
#if PROPID_ARM_BLOCK_MOVES && !PROPID_GENERAL_VEHICLES
        /* On the Cortex-M4 the 8 coefficient states (adjacent) and the thrust
         * basis's 7 entries (adjacent) arrive by two VLDMs, the drag basis by a
         * third once the thrust basis is no longer needed (GCC made a load of
         * each); the same C arithmetic as below, the kf's tested first. */
        _Static_assert(PROPID_QUAD_FIRST_DRAG == PROPID_QUAD_FIRST_THRUST + 4u, "the coefficients are adjacent");
        register float y0 __asm__("s0");
        register float y1 __asm__("s1");
        register float y2 __asm__("s2");
        register float y3 __asm__("s3");
        register float z0 __asm__("s4");
        register float z1 __asm__("s5");
        register float z2 __asm__("s6");
        register float z3 __asm__("s7");
        register float w00 __asm__("s8");
        register float w01 __asm__("s9");
        register float w02 __asm__("s10");
        register float w03 __asm__("s11");
        register float w10 __asm__("s12");
        register float w11 __asm__("s13");
        register float w12 __asm__("s14");
        __asm__("vldmia %[coefficients], {s0-s7}\n\tvldmia %[thrust], {s8-s14}"
                : "=t"(y0), "=t"(y1), "=t"(y2), "=t"(y3), "=t"(z0), "=t"(z1), "=t"(z2), "=t"(z3), "=t"(w00),
                  "=t"(w01), "=t"(w02), "=t"(w03), "=t"(w10), "=t"(w11), "=t"(w12)
                : [coefficients] "r"(&core->state[PROPID_QUAD_FIRST_THRUST]),
                  [thrust] "r"(filter->derived.thrust_basis),
                  "m"(*(const float (*)[8])&core->state[PROPID_QUAD_FIRST_THRUST]),
                  "m"(*(const float (*)[2 * PROPID_MAX_ROTORS - 1])filter->derived.thrust_basis));
        const float y[4] = {y0, y1, y2, y3};
        const float w1[3] = {w10, w11, w12};
        const float w0[4] = {w00, w01, w02, w03};
        const float along1 = y[1] * w1[0] + y[2] * w1[1] + y[3] * w1[2];
        kf_rel[0] = y[0];
PROPID_UNROLL(3)
        for (uint8_t i = 1; i < 4u; ++i) {
            kf_rel[i] = y[i] - along1 * w1[i - 1u];
        }
        const float along0 = kf_rel[0] * w0[0] + kf_rel[1] * w0[1] + kf_rel[2] * w0[2] + kf_rel[3] * w0[3];
        uint32_t inside = 0u; /* (counted: a carry added per test, propid_count_inside) */
PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            kf_rel[i] -= along0 * w0[i];
            inside = propid_count_inside(inside, propid_float_bits(kf_rel[i]), min_bits, range_bits);
        }
        /* (after the kf tests, whose count it reads: the thrust basis's registers are free) */
        register float v0 __asm__("s8");
        register float v1 __asm__("s9");
        register float v2 __asm__("s10");
        register float v3 __asm__("s11");
        __asm__("vldmia %[drag], {s8-s11}"
                : "=t"(v0), "=t"(v1), "=t"(v2), "=t"(v3)
                : [drag] "r"(basis.vector), "r"(inside), "m"(*(const float (*)[4])basis.vector));
        const float z[4] = {z0, z1, z2, z3};
        const float v[4] = {v0, v1, v2, v3};
        const float along = basis.scale * (z[0] * v[0] + z[1] * v[1] + z[2] * v[2] + z[3] * v[3]);
PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            km_rel[i] = z[i] - along * v[i];
            inside = propid_count_inside(inside, propid_float_bits(km_rel[i]), min_bits, range_bits);
        }
#else
        const float *z = &core->state[PROPID_QUAD_FIRST_DRAG];
        const float *v = basis.vector;
        const float along = basis.scale * (z[0] * v[0] + z[1] * v[1] + z[2] * v[2] + z[3] * v[3]);
        /* kf_rel = Q^T z = H_0 H_1 z. */
        propid_thrust_basis_t thrust;
        propid_thrust_basis_init(&thrust, &filter->derived, config);
        const float *y = &core->state[PROPID_QUAD_FIRST_THRUST];
        const float *w1 = thrust.vector[1]; /* elements 1..3 */
        const float along1 = y[1] * w1[0] + y[2] * w1[1] + y[3] * w1[2];
        kf_rel[0] = y[0];
PROPID_UNROLL(3)
        for (uint8_t i = 1; i < 4u; ++i) {
            kf_rel[i] = y[i] - along1 * w1[i - 1u];
        }
        const float *v0 = thrust.vector[0];
        const float along0 = kf_rel[0] * v0[0] + kf_rel[1] * v0[1] + kf_rel[2] * v0[2] + kf_rel[3] * v0[3];
        uint32_t inside = 0u; /* (counted: a carry added per test, propid_count_inside) */
PROPID_UNROLL(4)
        for (uint8_t i = 0; i < 4u; ++i) {
            km_rel[i] = z[i] - along * v[i];
            kf_rel[i] -= along0 * v0[i];
            inside = propid_count_inside(inside, propid_float_bits(kf_rel[i]), min_bits, range_bits);
            inside = propid_count_inside(inside, propid_float_bits(km_rel[i]), min_bits, range_bits);
        }
#endif
        outside = inside != 8u;
    }
#if PROPID_GENERAL_VEHICLES
    else {
        propid_thrust_basis_t thrust;
        propid_thrust_basis_init(&thrust, &filter->derived, config);
        propid_drag_per_rotor(&basis, core, km_rel, NULL);
        propid_thrust_per_rotor(&thrust, core, kf_rel, NULL);
        for (uint8_t i = 0; i < rotor_count; ++i) {
            outside |= propid_outside_positive_range(kf_rel[i], min_bits, range_bits);
            outside |= propid_outside_positive_range(km_rel[i], min_bits, range_bits);
        }
    }
#else
    (void)rotor_count;
#endif
    return outside == 0u ? 0u : project_outside(filter);
}
