/* The accelerometer as a measurement (docs/math.md §9): when and how it is fused.
 *
 * The body-z specific force of a multirotor is its collective thrust over its mass
 * (rotor thrust is the only large z force; aerodynamic drag of the airframe is
 * small at the speeds the filter is flown at and is left to the noise and gate):
 *
 *   f_z = sum_i kf_i Omega_i^2 / m + b_z + v
 *       = sum_i (kf_nominal_i / m) u_i kf_rel_i + b_z + v
 *
 * linear in the state, H = [(kf_nominal_i / m) u_i at kf_rel_i, 1 at b_z]. It
 * measures the thrust coefficients' scale directly, independent of the inertia
 * and the arm lengths through which the gyro sees them. With the thrust-torque
 * scale the thrust states carry g_i = s kf_rel_i (what the gyro sees) and the
 * scale state r = 1/s, so kf_rel_i = r g_i and this row is the only one with r:
 * f_z = r sum_i (kf_nominal_i / m) u_i g_i + b_z, H = [r (kf_nominal_i / m) u_i at
 * g_i, sum_i (kf_nominal_i / m) u_i g_i at r, 1 at b_z]. Fused against the
 * current state with the latest rotor speeds (the coefficients and the bias are
 * random walks: no prediction to the sample's time is needed). With
 * config.accel_error_std > 0 the row's slow model error e is a state of its own
 * (a first-order Gauss-Markov process, docs/math.md §9): f_z = ... + b_z + e + v,
 * one more entry 1 at e; it decays with the gyro step's prediction (at the gyro's
 * rate, far faster than its correlation time). */
#include <math.h>
#include <stddef.h>

#include "propid_delay.h"
#include "propid_internal.h"

static propid_status_t reject(propid_filter_t *filter, propid_status_t status)
{
    filter->counters.rejected[PROPID_REJECT_SLOT(status)]++;
    return status;
}

/* Every check of an accelerometer sample that does not need the rotor data;
 * for a sample to be held, its time against the newest held one. Rejections
 * counted. Not inlined: held samples are fused under propid_push_accel's frame. */
static __attribute__((noinline)) propid_status_t accel_sample_check(propid_filter_t *filter, uint64_t time_us,
                                                                    const float specific_force[3])
{
    if (filter == NULL) {
        return PROPID_ERR_NULL;
    }
    if (filter->magic != PROPID_MAGIC) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    if (specific_force == NULL) {
        return reject(filter, PROPID_ERR_NULL);
    }
    if (!PROPID_WITH_ACCEL || filter->derived.layout.accel_bias == PROPID_NO_STATE) {
        /* No mass configured, or compiled out (propid_config.h). */
        return reject(filter, PROPID_ERR_CONFIG);
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        if (!isfinite(specific_force[a])) {
            return reject(filter, PROPID_ERR_NOT_FINITE);
        }
    }
#if PROPID_WITH_ACCEL /* (the configuration this build keeps has no accelerometer fields) */
    for (uint8_t a = 0; a < 3u; ++a) {
        if (fabsf(specific_force[a]) > filter->config.accel_range) {
            return reject(filter, PROPID_ERR_ACCEL_RANGE);
        }
    }
#endif
#if PROPID_DELAY_SLOTS == 0 || !PROPID_WITH_ACCEL
    (void)time_us; /* only a held sample's time is checked here */
#else
    if (filter->config.rotor_delay_us > 0) {
        uint64_t previous = filter->core.accel_time_us;
        int has_previous = filter->core.has_accel;
        has_previous |= propid_delay_newest(filter, PROPID_DELAY_ACCEL, &previous);
        if (has_previous && time_us <= previous) {
            return reject(filter, PROPID_ERR_TIME_BACKWARDS);
        }
    }
#endif
    return PROPID_OK;
}

propid_status_t propid_push_accel(propid_filter_t *filter, uint64_t time_us, const float specific_force[3])
{
    const propid_status_t checked = accel_sample_check(filter, time_us, specific_force);
    if (checked != PROPID_OK) {
        return checked;
    }
#if PROPID_DELAY_SLOTS > 0
    if (filter->config.rotor_delay_us > 0) {
        /* Held until the rotor speeds of its time arrive (propid_delay.c). */
        propid_delay_release_imu(filter, time_us, 1, 1);
        return propid_delay_hold_imu(filter, PROPID_DELAY_ACCEL, time_us, specific_force);
    }
#endif
    return propid_fuse_accel(filter, time_us, specific_force);
}

propid_status_t propid_fuse_accel(propid_filter_t *filter, uint64_t time_us, const float specific_force[3])
{
#if !PROPID_WITH_ACCEL
    (void)time_us;
    (void)specific_force;
    return reject(filter, PROPID_ERR_CONFIG); /* compiled out (propid_config.h) */
#else
    const propid_kept_config_t *config = &filter->config;
    const propid_derived_t *derived = &filter->derived;
    propid_core_t *core = &filter->core;
    if (core->has_accel && time_us <= core->accel_time_us) {
        return reject(filter, PROPID_ERR_TIME_BACKWARDS);
    }
#if PROPID_DELAY_SLOTS > 0
    propid_delay_release_rotor(filter, time_us); /* held rotor samples that act by now */
#endif
    if (!core->has_rotor_data) {
        return reject(filter, PROPID_ERR_NO_ROTOR_DATA);
    }
    const uint64_t rotor_clock = time_us + propid_delay_imu_shift(config);
    if (rotor_clock > core->rotor_time_us && rotor_clock - core->rotor_time_us > (uint64_t)config->rotor_stale_us) {
        return reject(filter, PROPID_ERR_ROTOR_STALE);
    }

    const uint8_t rotor_count = config->rotor_count;
    const uint8_t bias = derived->layout.accel_bias;
    const uint8_t scale = derived->layout.torque_scale;
    const float inverse_scale = scale != PROPID_NO_STATE ? core->state[scale] : 1.0f; /* r */
    propid_sparse_row_t row;
    row.count = (uint8_t)(rotor_count + 1u);
    float thrust_states = 0.0f; /* sum_i (kf_nominal_i / m) u_i x_i over the thrust states */
    /* The row per rotor times Q^T: over the torque-basis states (propid_internal.h). */
    float per_state[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotor_count; ++i) {
        per_state[i] = derived->thrust_per_mass[i] * core->rotor_speed_sq[i];
    }
    propid_thrust_basis_t thrust_basis;
    propid_thrust_basis_init(&thrust_basis, derived, config);
    propid_thrust_to_basis(&thrust_basis, per_state);
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const uint8_t k = (uint8_t)(derived->layout.thrust + i);
        row.index[i] = k;
        row.value[i] = inverse_scale * per_state[i];
        thrust_states += per_state[i] * core->state[k];
    }
    row.index[rotor_count] = bias;
    row.value[rotor_count] = 1.0f;
    const uint8_t model_error = derived->accel_error; /* PROPID_NO_STATE: off */
    float offset = core->state[bias];
    if (model_error != PROPID_NO_STATE) {
        row.index[row.count] = model_error;
        row.value[row.count] = 1.0f;
        row.count++;
        offset += core->state[model_error];
    }
    if (scale != PROPID_NO_STATE) {
        row.index[row.count] = scale;
        row.value[row.count] = thrust_states;
        row.count++;
    }
    const float thrust = inverse_scale * thrust_states; /* collective thrust over mass */
    const float measured = specific_force[2];
    float innovation = measured - thrust - offset;
    if (!isfinite(innovation)) {
        return reject(filter, PROPID_ERR_NUMERIC);
    }

    /* Accepted: from here on the filter changes. */
    float test_ratio = 0.0f;
    propid_scalar_result_t result =
        propid_scalar_update(filter, &row, innovation, derived->accel_var, derived->gate_sq, &test_ratio);
    core->accel_innovation = innovation;
    core->accel_innovation_test_ratio = test_ratio;
    core->accel_time_us = time_us;
    core->has_accel = 1u;
    filter->counters.accel_accepted++;
    if (result == PROPID_SCALAR_GATED) {
        if (core->accel_gated_run < config->gate_max_consecutive) {
            core->accel_gated_run++;
            filter->counters.accel_gated++;
            return PROPID_OK_GATED;
        }
        /* Persistently outside the gate: the bias, not the sensor, is probably
         * wrong (a changed mounting, a payload). Re-anchor it on this sample
         * (prior variance, no correlations) and fuse: the coefficients keep
         * what the gyro taught them. */
        core->state[bias] = measured - thrust;
        propid_cov_reset_state(derived, core, bias);
        if (model_error != PROPID_NO_STATE) { /* the bias takes the whole offset */
            core->state[model_error] = 0.0f;
            propid_cov_reset_state(derived, core, model_error);
        }
        innovation = 0.0f;
        (void)propid_scalar_update(filter, &row, innovation, derived->accel_var, 0.0f, &test_ratio);
        filter->counters.accel_reanchored++;
    }
    core->accel_gated_run = 0u;
    const uint32_t clamped = propid_clamp_coefficients(filter) + propid_clamp_torque_scale(config, derived, core);
    if (clamped != 0u) {
        core->health |= PROPID_HEALTH_STATE_CLAMPED;
        filter->counters.state_clamps += clamped;
    }
    return PROPID_OK;
#endif
}
