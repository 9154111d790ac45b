/* A known aerodynamic rate damping (docs/math.md §17): configuration check and
 * the derived rate-block entries -J^-1 D. */
#include <math.h>

#include "propid_aero_damping.h"

int propid_aero_damping_valid(const propid_config_t *config)
{
    for (uint8_t a = 0; a < 3u; ++a) {
        const float damping = config->aero_damping[a];
        if (!isfinite(damping) || damping < 0.0f || damping > 1.0e3f ||
            (!PROPID_WITH_AERO_DAMPING && damping > 0.0f)) { /* compiled out: 0 only */
            return 0;
        }
    }
    return 1;
}

#if PROPID_WITH_AERO_DAMPING
int propid_aero_damping_derive(const propid_config_t *config, const float inertia_inv[3][3],
                               propid_derived_t *out)
{
    /* A = -J^-1 D with D diagonal: A_ab = -Jinv_ab d_b (a diagonal J leaves the
     * diagonal only, so the sparsity lists gain one rate entry per damped axis). */
    const float gap_s = (float)config->max_gyro_gap_us * 1.0e-6f;
    out->aero_damping_on = 0u;
    for (uint8_t a = 0; a < 3u; ++a) {
        float rate_sum = 0.0f;
        for (uint8_t b = 0; b < 3u; ++b) {
            const float entry = config->aero_damping[b] > 0.0f ? -inertia_inv[a][b] * config->aero_damping[b] : 0.0f;
            out->aero_damping[a][b] = entry;
            rate_sum += fabsf(entry);
            if (entry != 0.0f) {
                out->aero_damping_on = 1u;
            }
        }
        /* Decay faster than one gyro gap is no damping a rate loop flies with, and
         * the step's Heun integration of it would overshoot. */
        if (!isfinite(rate_sum) || rate_sum * gap_s > 1.0f) {
            return 0;
        }
    }
    return 1;
}
#endif
