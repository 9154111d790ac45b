/* Model-consistency monitor (propid_consistency.c): private hooks of the filter. */
#ifndef PROPID_CONSISTENCY_PRIVATE_H
#define PROPID_CONSISTENCY_PRIVATE_H

#include "propid/propid.h"

#if PROPID_CONSISTENCY
/* Window length and bound from the configuration; a fresh window, flag down. */
void propid_consistency_reset(propid_filter_t *filter);
/* The coefficients' variances were reset (propid_reset_rotor): a new window. */
void propid_consistency_restart(propid_filter_t *filter);
/* After every accepted gyro sample's update; gated_mask bit a: axis a was gated out. */
void propid_consistency_observe(propid_filter_t *filter, uint32_t gated_mask);
#endif

#endif /* PROPID_CONSISTENCY_PRIVATE_H */
