/* The drag coefficients' yaw basis (propid_internal.h, docs/math.md §2): the
 * maps of the state's and P's drag block between z = H km_rel and the per-rotor
 * km_rel. H = I - scale v v^T; for the block B = P_zz and u = B v, beta = v . u:
 *   H B H = B - scale (v u^T + u v^T) + scale^2 beta v v^T. */
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

__attribute__((noinline)) void propid_drag_basis_transform(const propid_drag_basis_t *basis, float *x)
{
    propid_drag_basis_apply(basis, x);
}

/* u = B v over the packed drag block, and beta = v . u. */
static float block_times_basis(const propid_drag_basis_t *basis, const float *cov, float *u)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_drag(rotor_count);
    const float *v = basis->vector;
    float beta = 0.0f;
    for (uint8_t i = 0; i < rotor_count; ++i) {
        float sum = 0.0f;
        for (uint8_t j = 0; j < rotor_count; ++j) {
            sum += propid_cov_at(cov, (uint8_t)(first + i), (uint8_t)(first + j)) * v[j];
        }
        u[i] = sum;
        beta += v[i] * sum;
    }
    return beta;
}

void propid_drag_basis_flip_column(const propid_drag_basis_t *basis, propid_core_t *core, uint8_t column_index)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_drag(rotor_count);
    float column[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotor_count; ++i) {
        column[i] = propid_cov_at(core->cov, (uint8_t)(first + i), column_index);
    }
    propid_drag_basis_transform(basis, column);
    for (uint8_t i = 0; i < rotor_count; ++i) {
        core->cov[propid_cov_index((uint8_t)(first + i), column_index)] = column[i];
    }
}

void propid_drag_basis_flip_block(const propid_drag_basis_t *basis, propid_core_t *core)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_drag(rotor_count);
    const float *v = basis->vector;
    const float scale = basis->scale;
    float u[PROPID_MAX_ROTORS];
    const float beta = block_times_basis(basis, core->cov, u);
    for (uint8_t i = 0; i < rotor_count; ++i) {
        for (uint8_t j = i; j < rotor_count; ++j) {
            core->cov[propid_cov_index((uint8_t)(first + i), (uint8_t)(first + j))] -=
                scale * (v[i] * u[j] + u[i] * v[j]) - scale * scale * beta * v[i] * v[j];
        }
    }
}

void propid_drag_basis_flip(const propid_drag_basis_t *basis, propid_core_t *core)
{
    const uint8_t first = propid_first_drag(basis->rotor_count);
    const uint8_t end = (uint8_t)(first + basis->rotor_count);
    propid_drag_basis_transform(basis, &core->state[first]);
    /* The cross-covariances with every other state: a column of N values each
     * (state_count is not needed: the unused part of the triangle is zero). */
    for (uint8_t j = 0; j < PROPID_MAX_STATES; ++j) {
        if (j < first || j >= end) {
            propid_drag_basis_flip_column(basis, core, j);
        }
    }
    propid_drag_basis_flip_block(basis, core);
}

void propid_drag_per_rotor(const propid_drag_basis_t *basis, const propid_core_t *core, float *km_rel,
                           float *km_var)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_drag(rotor_count);
    for (uint8_t i = 0; i < rotor_count; ++i) {
        km_rel[i] = core->state[first + i];
    }
    propid_drag_basis_transform(basis, km_rel);
    if (km_var == NULL) {
        return;
    }
    const float *v = basis->vector;
    const float scale = basis->scale;
    float u[PROPID_MAX_ROTORS];
    const float beta = block_times_basis(basis, core->cov, u);
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const uint8_t k = (uint8_t)(first + i);
        km_var[i] = propid_cov_at(core->cov, k, k) - scale * v[i] * (2.0f * u[i] - scale * beta * v[i]);
    }
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

void propid_drag_along_basis(const propid_drag_basis_t *basis, const propid_core_t *core, uint8_t state_count,
                             float *scratch, float *along)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_drag(rotor_count);
    for (uint8_t j = 0; j < state_count; ++j) {
        along[j] = 0.0f;
    }
    for (uint8_t d = 0; d < rotor_count; ++d) {
        const float vd = basis->vector[d];
        cov_column(core->cov, state_count, (uint8_t)(first + d), scratch);
        for (uint8_t j = 0; j < state_count; ++j) {
            along[j] += scratch[j] * vd;
        }
    }
}

void propid_drag_per_rotor_column(const propid_drag_basis_t *basis, const propid_core_t *core,
                                  uint8_t state_count, uint8_t k, const float *along, float *column)
{
    const uint8_t rotor_count = basis->rotor_count;
    const uint8_t first = propid_first_drag(rotor_count);
    cov_column(core->cov, state_count, k, column);
    if (k >= first && k < first + rotor_count) {
        /* T e_k = H e_i = e_k - scale v_i v (within the drag block). */
        const float scaled = basis->scale * basis->vector[k - first];
        for (uint8_t j = 0; j < state_count; ++j) {
            column[j] -= scaled * along[j];
        }
    } /* else T e_k = e_k: P's column as stored */
    propid_drag_basis_transform(basis, &column[first]); /* T on the left */
}

void propid_cov_reset_rotor(const propid_derived_t *derived, const propid_drag_basis_t *basis, propid_core_t *core,
                            uint8_t rotor, int to_nominal)
{
    const uint8_t thrust = (uint8_t)(propid_first_thrust() + rotor);
    const uint8_t drag = (uint8_t)(propid_first_drag(basis->rotor_count) + rotor);
    propid_drag_basis_flip(basis, core);
    if (to_nominal) {
        /* With the torque scale the state is g = s kf = kf / r (docs/math.md §9). */
        const uint8_t scale = derived->layout.torque_scale;
        core->state[thrust] = PROPID_WITH_ACCEL && scale != PROPID_NO_STATE ? 1.0f / core->state[scale] : 1.0f;
        core->state[drag] = 1.0f;
    }
    propid_cov_reset_state(derived, core, thrust);
    propid_cov_reset_state(derived, core, drag);
    propid_drag_basis_flip(basis, core);
}
