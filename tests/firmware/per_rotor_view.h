/* The filter's state and covariance with the coefficients per rotor: the filter
 * keeps them in their bases (firmware/src/propid_internal.h, "The coefficients'
 * bases"), tests that read kf_i, km_i or their variances directly look through
 * this view. */
#ifndef PER_ROTOR_VIEW_H
#define PER_ROTOR_VIEW_H

#include "../../firmware/src/propid_internal.h"

static inline propid_core_t per_rotor_core(const propid_filter_t *filter)
{
    propid_core_t core = filter->core;
    propid_coeff_flip(&filter->derived, &filter->config, &core, 1);
    return core;
}

#endif
