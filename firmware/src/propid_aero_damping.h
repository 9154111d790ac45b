/*
 * A known aerodynamic rate damping (docs/math.md §17), internal: the body torque
 * -D omega, D = diag(config.aero_damping) [N m s/rad], joins the rate dynamics as
 * omega_dot += -J^-1 D omega, a term linear in omega (no state added). The step
 * reads its entries through propid_aero_damping_entry (propid_internal.h).
 */
#ifndef PROPID_AERO_DAMPING_H
#define PROPID_AERO_DAMPING_H

#include "propid_internal.h"

/* 1 when every config.aero_damping is finite, >= 0 and at most 1e3, and (compiled
 * out, the quad build) zero. */
int propid_aero_damping_valid(const propid_config_t *config);

#if PROPID_WITH_AERO_DAMPING
/* out->aero_damping = -J^-1 D and out->aero_damping_on. 0 when the damping is so
 * fast that one gyro gap (max_gyro_gap_us) would overshoot it (a row sum of
 * |J^-1 D| times the gap above 1) or a derived value is not finite. */
int propid_aero_damping_derive(const propid_config_t *config, const float inertia_inv[3][3],
                               propid_derived_t *out);
#endif

#endif /* PROPID_AERO_DAMPING_H */
