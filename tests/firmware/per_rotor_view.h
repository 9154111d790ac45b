/* The filter's state and covariance with the drag coefficients per rotor: the
 * filter keeps them in their yaw basis (firmware/src/propid_internal.h), tests
 * that read km_i or its variance directly look through this view. */
#ifndef PER_ROTOR_VIEW_H
#define PER_ROTOR_VIEW_H

#include "../../firmware/src/propid_internal.h"

static inline propid_core_t per_rotor_core(const propid_filter_t *filter)
{
    propid_core_t core = filter->core;
    const propid_drag_basis_t basis = propid_drag_basis(&filter->derived, &filter->config);
    propid_drag_basis_flip(&basis, &core);
    return core;
}

#endif
