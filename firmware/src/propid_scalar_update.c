/* The one scalar measurement update (docs/math.md §3): y = H x + v, H sparse.
 *
 *   h = P H^T            (H has a few non-zero entries: h is a sum of a few columns
 *                         of the symmetric P, n * count multiply-adds)
 *   S = H h + R          (S >= R: var(H x) is never negative; rounding-aware test)
 *   gate: nu^2 > gate^2 S leaves state and covariance untouched
 *   x += h nu / S,  P -= h h^T / S   (stored upper triangle; the Joseph form's
 *                                     result for this optimal gain)
 *   floors and ceilings on every variance (propid_cov_enforce_bounds)
 *
 * Every sensor's file (propid_gyro.c, propid_accel.c) decides when to fuse and
 * builds H and the innovation; this file decides how. The quad gyro sample has a
 * straight-line equivalent of three of these in one pass (propid_gyro.c). */
#include <math.h>

#include "propid_internal.h"

/* h = P H^T into ph[0..n); returns the running sum (non-finite when any is). */
static float form_gain_vector(const float *cov, const propid_sparse_row_t *row,
                              uint8_t n, float *ph)
{
    float check = 0.0f;
    for (uint8_t i = 0; i < n; ++i) {
        float value = 0.0f;
        for (uint8_t k = 0; k < row->count; ++k) {
            value += row->value[k] * propid_cov_at(cov, i, row->index[k]);
        }
        ph[i] = value;
        check += value;
    }
    return check;
}

propid_scalar_result_t propid_scalar_update(propid_filter_t *filter, const propid_sparse_row_t *row,
                                            float innovation, float noise_var, float gate_sq,
                                            float *test_ratio)
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const uint8_t n = derived->state_count;
    float *cov = core->cov;
    float *ph = core->update_vector[0]; /* in the filter object: off the stack */
    float innovation_var = noise_var;
    for (uint8_t attempt = 0; attempt < 2u; ++attempt) {
        const float check = form_gain_vector(cov, row, n, ph);
        float hph = 0.0f;
        float scale = 0.0f; /* count * sum_k v_k^2 P_kk >= (sum_k |v_k| sigma_k)^2 */
        for (uint8_t k = 0; k < row->count; ++k) {
            const uint8_t column = row->index[k];
            hph += row->value[k] * ph[column];
            scale += row->value[k] * row->value[k] * cov[propid_cov_index(column, column)];
        }
        innovation_var = hph + noise_var;
        /* var(H x) < 0 beyond the rounding of its sum (propid_internal.h), or a
         * non-finite element in the columns H reads: P is broken. Repair, redo. */
        const float rounding = PROPID_ROUNDING_TOL * (float)row->count * scale;
        if (isfinite(check) && innovation_var >= noise_var - rounding) {
            innovation_var = innovation_var > noise_var ? innovation_var : noise_var;
            break;
        }
        if (attempt == 0u) {
            if (propid_cov_repair(derived, core)) {
                core->health |= PROPID_HEALTH_COV_REPAIRED;
                filter->counters.cov_repairs++;
            }
            continue;
        }
        if (!isfinite(check)) {
            return PROPID_SCALAR_NUMERIC;
        }
        innovation_var = noise_var;
    }
    {
        /* Update loading (propid_internal.h): R_eff = loading * P_hh when larger. */
        const float loaded_noise = PROPID_UPDATE_LOADING * (innovation_var - noise_var);
        if (loaded_noise > noise_var) {
            innovation_var += loaded_noise - noise_var;
        }
    }
    const float inv_innovation_var = 1.0f / innovation_var;
    const float innovation_sq = innovation * innovation;
    *test_ratio = innovation_sq * inv_innovation_var * derived->inv_gate_sq;
    if (gate_sq > 0.0f && !(innovation_sq <= gate_sq * innovation_var)) { /* NaN is gated too */
        return PROPID_SCALAR_GATED;
    }
    const float step = innovation * inv_innovation_var;
    for (uint8_t i = 0; i < n; ++i) {
        const float gain = ph[i] * inv_innovation_var;
        core->state[i] += ph[i] * step;
        float *cov_row = propid_cov_row(cov, i);
        for (uint8_t j = i; j < n; ++j) {
            cov_row[j] -= gain * ph[j];
        }
    }
    if (propid_cov_enforce_bounds(derived, core)) {
        core->health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    return PROPID_SCALAR_FUSED;
}
