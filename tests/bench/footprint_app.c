/*
 * The smallest application that uses the filter the way an autopilot does
 * (benchmark only): configure and initialise once, then push rotor speeds and
 * gyro samples and read the estimate. bench.py links it with --gc-sections to
 * measure the flash the filter costs such an application. Built with
 * -DFOOTPRINT_PREPARED=1 it starts the filter from the vehicle's prepared setup
 * (propid_init_prepared: firmware/codegen/setup_blob.py wrote it from
 * footprint_vehicle.json, the same vehicle) and links no configuration code.
 */
#include "propid/propid.h"
#include "semihosting.h"

static propid_filter_t filter;

#if FOOTPRINT_PREPARED
extern const propid_setup_t *const propid_vehicle_setup;
#endif

int main(void)
{
#if FOOTPRINT_PREPARED
    if (propid_init_prepared(&filter, propid_vehicle_setup) != PROPID_OK) {
        return 1;
    }
#else
    propid_config_t config;
    propid_config_default(&config);
    if (propid_config_set_symmetric(&config, 4u, 0.17f, 0.0f, 1.0f, 5.57e-6f, 1.36e-7f) != PROPID_OK) {
        return 1;
    }
    propid_config_set_inertia_diag(&config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
    if (propid_init(&filter, &config) != PROPID_OK) {
        return 1;
    }
#endif
    const float speed[4] = {900.0f, 910.0f, 890.0f, 905.0f};
    const float gyro[3] = {0.01f, -0.02f, 0.0f};
    propid_estimate_t estimate;
    for (uint64_t t = 1000u; t < 20000u; t += 2000u) {
        (void)propid_push_rotor_speeds(&filter, t, speed, 4u);
        (void)propid_push_gyro(&filter, t + 1000u, gyro);
    }
    (void)propid_get_estimate(&filter, &estimate);
    propid_qemu_puts(estimate.thrust_coeff[0] > 0.0f ? "ok\n" : "bad\n");
    return 0;
}
