/* Prepared setup: the configuration's checks and derivation stored once (host
 * generator firmware/codegen/setup_blob.py, or propid_setup_prepare on the
 * board), and the checks a stored setup must pass before a filter uses it.
 * propid_init_prepared (propid_filter.c) reads it without the derivation, so an
 * application that only calls it links none of propid_config.c's code. */
#include <stddef.h>
#include <string.h>

#include "propid_internal.h"

/* CRC-32 (reflected polynomial 0xEDB88320, the zlib one, so the generator's
 * Python computes the same) of every byte before the checksum field. Bitwise:
 * init-only, a few hundred bytes, no table in flash. */
uint32_t propid_setup_checksum(const propid_setup_t *setup)
{
    const uint8_t *bytes = (const uint8_t *)setup;
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t k = 0; k < offsetof(propid_setup_t, checksum); ++k) {
        crc ^= bytes[k];
        for (uint8_t bit = 0; bit < 8u; ++bit) {
            crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
        }
    }
    return ~crc;
}

propid_status_t propid_setup_prepare(const propid_config_t *config, propid_setup_t *setup)
{
    if (config == NULL || setup == NULL) {
        return PROPID_ERR_NULL;
    }
    if (propid_config_derive(config, NULL, NULL) != PROPID_OK) {
        return PROPID_ERR_CONFIG;
    }
    /* Zeroed first: padding is part of the checksummed bytes. */
    memset(setup, 0, sizeof(*setup));
    setup->format = PROPID_SETUP_FORMAT;
    setup->size = (uint32_t)sizeof(*setup);
    (void)propid_config_derive(config, &setup->derived, NULL);
    propid_config_keep(config, &setup->config);
    setup->checksum = propid_setup_checksum(setup);
    return PROPID_OK;
}

static int optional_block_fits(uint8_t first, uint8_t count, uint8_t state_count)
{
    return first == PROPID_NO_STATE || (count > 0u && first + count <= state_count);
}

/* The indices the step uses without further checks: a setup whose checksum
 * matches came from the derivation, which only writes these; a forged one that
 * breaks them would index outside the filter object. */
static int setup_structure_ok(const propid_setup_t *setup)
{
    const propid_derived_t *derived = &setup->derived;
    const uint8_t rotor_count = setup->config.rotor_count;
    if (rotor_count < 1u || rotor_count > PROPID_MAX_ROTORS) {
        return 0;
    }
    const propid_layout_t *layout = &derived->layout;
    const uint8_t fixed = (uint8_t)(propid_first_bias(rotor_count) + PROPID_BIAS_STATES);
    if (layout->rate != 0u || layout->thrust != propid_first_thrust() ||
        layout->drag != propid_first_drag(rotor_count) || layout->gyro_bias != propid_first_bias(rotor_count) ||
        derived->state_count < fixed || derived->state_count > PROPID_MAX_STATES ||
        !optional_block_fits(layout->disturbance, PROPID_DISTURBANCE_STATES, derived->state_count) ||
        !optional_block_fits(layout->accel_bias, PROPID_ACCEL_BIAS_STATES, derived->state_count) ||
        !optional_block_fits(layout->torque_scale, PROPID_TORQUE_SCALE_STATES, derived->state_count)) {
        return 0;
    }
#if PROPID_WITH_ACCEL
    /* The row's model error sits right after the bias, or is off. */
    if (derived->accel_error != PROPID_NO_STATE &&
        (layout->accel_bias == PROPID_NO_STATE || derived->accel_error != layout->accel_bias + 1u ||
         derived->accel_error >= derived->state_count)) {
        return 0;
    }
#endif
#if PROPID_GENERAL_VEHICLES
    for (uint8_t a = 0; a < 3u; ++a) {
        if (derived->jac_count[a] > PROPID_MAX_STATES - 3u || derived->jac_rate_count[a] > derived->jac_count[a]) {
            return 0;
        }
        for (uint8_t p = 0; p < derived->jac_count[a]; ++p) {
            if (derived->jac_column[a][p] >= derived->state_count || derived->jac_rotor[a][p] > rotor_count) {
                return 0;
            }
        }
    }
    for (uint8_t k = 0; k < derived->state_count; ++k) {
        if (derived->state_kind[k] >= PROPID_STATE_KINDS) {
            return 0;
        }
    }
#else
    /* This build has the quad kernels only (propid_config_derive). */
    if (rotor_count != 4u || derived->state_count != PROPID_QUAD_STATES || !derived->quad_layout ||
        !derived->quad_core) {
        return 0;
    }
#endif
    return 1;
}

int propid_setup_usable(const propid_setup_t *setup)
{
    return setup->format == PROPID_SETUP_FORMAT && setup->size == (uint32_t)sizeof(*setup) &&
           setup->checksum == propid_setup_checksum(setup) && setup_structure_ok(setup);
}
