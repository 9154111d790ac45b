/* Host-only (shared library): sizes and a few offsets of the public structs, so
 * the Python ctypes binding can verify that its layout matches this build. */
#include <stddef.h>
#include <stdint.h>

#include "propid/propid.h"
#include "propid_internal.h"

uint32_t propid_abi_max_rotors(void);
uint32_t propid_abi_delay_slots(void);
uint32_t propid_abi_max_states(void);
uint32_t propid_abi_sizeof_config(void);
uint32_t propid_abi_sizeof_filter(void);
uint32_t propid_abi_sizeof_estimate(void);
uint32_t propid_abi_sizeof_counters(void);
uint32_t propid_abi_offsetof_config_gate_sigma(void);
uint32_t propid_abi_offsetof_config_converged_rel_std(void);
uint32_t propid_abi_offsetof_estimate_health(void);
uint32_t propid_abi_offsetof_counters_rejected(void);
void propid_abi_copy_state(const propid_filter_t *filter, float *state, float *covariance);
void propid_abi_instrument_counts(const propid_filter_t *filter, uint32_t counts[3]);

uint32_t propid_abi_max_rotors(void) { return PROPID_MAX_ROTORS; }
uint32_t propid_abi_delay_slots(void) { return PROPID_DELAY_SLOTS; }
uint32_t propid_abi_max_states(void) { return PROPID_MAX_STATES; }
uint32_t propid_abi_sizeof_config(void) { return (uint32_t)sizeof(propid_config_t); }
uint32_t propid_abi_sizeof_filter(void) { return (uint32_t)sizeof(propid_filter_t); }
uint32_t propid_abi_sizeof_estimate(void) { return (uint32_t)sizeof(propid_estimate_t); }
uint32_t propid_abi_sizeof_counters(void) { return (uint32_t)sizeof(propid_counters_t); }
uint32_t propid_abi_offsetof_config_gate_sigma(void)
{
    return (uint32_t)offsetof(propid_config_t, gate_sigma);
}
uint32_t propid_abi_offsetof_config_converged_rel_std(void)
{
    return (uint32_t)offsetof(propid_config_t, converged_rel_std);
}
uint32_t propid_abi_offsetof_estimate_health(void)
{
    return (uint32_t)offsetof(propid_estimate_t, health);
}
uint32_t propid_abi_offsetof_counters_rejected(void)
{
    return (uint32_t)offsetof(propid_counters_t, rejected);
}

/* Scaled state (PROPID_MAX_STATES floats) and covariance (row-major
 * PROPID_MAX_STATES^2 floats, both triangles: the filter stores only the packed
 * upper one) for cross-checks against the reference filter. */
void propid_abi_copy_state(const propid_filter_t *filter, float *state, float *covariance)
{
    if (filter == NULL) {
        return;
    }
    /* Per rotor, as the reference keeps them: the coefficient blocks back from their bases. */
    propid_core_t core = filter->core;
    if (filter->config.rotor_count > 0u && filter->config.rotor_count <= PROPID_MAX_ROTORS) {
        propid_coeff_flip(&filter->derived, &filter->config, &core, 1);
    }
    for (uint32_t i = 0; i < PROPID_MAX_STATES; ++i) {
        if (state != NULL) {
            state[i] = core.state[i];
        }
        for (uint32_t j = 0; j < PROPID_MAX_STATES && covariance != NULL; ++j) {
            covariance[i * PROPID_MAX_STATES + j] = core.cov[propid_cov_index(i, j)];
        }
    }
}

/* The motor commands' first stage (propid_instrument.c): commands accepted, rotor
 * samples whose input came from it, rotor inputs its weak-instrument guard left to the
 * telemetry; zeros in a build without it. */
void propid_abi_instrument_counts(const propid_filter_t *filter, uint32_t counts[3])
{
    if (filter == NULL || counts == NULL) {
        return;
    }
#if PROPID_WITH_INSTRUMENT
    counts[0] = filter->instrument.command_accepted;
    counts[1] = filter->instrument.inputs;
    counts[2] = filter->instrument.guarded;
#else
    counts[0] = 0u;
    counts[1] = 0u;
    counts[2] = 0u;
#endif
}
