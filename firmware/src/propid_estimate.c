/* Outputs: the scaled state converted to SI, standard deviations, flags.
 * The only place with square roots (std), called at the reader's pace. */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "propid_internal.h"

static float std_of(float variance)
{
    return variance > 0.0f ? sqrtf(variance) : 0.0f;
}

propid_status_t propid_get_estimate(const propid_filter_t *filter, propid_estimate_t *estimate)
{
    if (filter == NULL || estimate == NULL) {
        return PROPID_ERR_NULL;
    }
    if (filter->magic != PROPID_MAGIC) {
        return PROPID_ERR_NOT_INITIALISED;
    }
    const propid_kept_config_t *config = &filter->config;
    const propid_derived_t *derived = &filter->derived;
    const propid_core_t *core = &filter->core;
    const uint8_t rotor_count = config->rotor_count;
    const uint8_t first_drag = propid_first_drag(rotor_count);
    const uint8_t first_bias = propid_first_bias(rotor_count);

    memset(estimate, 0, sizeof(*estimate));
    estimate->time_us = core->time_us;
    estimate->rotor_count = rotor_count;
    for (uint8_t a = 0; a < 3u; ++a) {
        estimate->body_rate[a] = core->state[a];
        estimate->body_rate_std[a] = std_of(core->cov[propid_cov_index(a, a)]);
        estimate->gyro_bias[a] = core->state[first_bias + a];
        estimate->gyro_bias_std[a] = std_of(core->cov[propid_cov_index(first_bias + a, first_bias + a)]);
        estimate->innovation[a] = core->innovation[a];
        estimate->innovation_test_ratio[a] = core->innovation_test_ratio[a];
    }
    uint16_t all_rotors = 0u;
    /* Claim thresholds (propid_config.c: 3 std, the inertia's uncertainty
     * included); kf's without the inertia when the torque-scale state takes the
     * scale error and the accelerometer sets kf. */
    const float km_claim_var = derived->claim_var;
    float kf_claim_var = km_claim_var;
#if PROPID_WITH_ACCEL && PROPID_GENERAL_VEHICLES /* (the configuration kept whole) */
    if (derived->layout.torque_scale != PROPID_NO_STATE) {
        kf_claim_var += config->inertia_rel_std * config->inertia_rel_std;
    }
#endif
    /* The drag coefficients per rotor from their yaw basis (propid_internal.h). */
    float km_rel[PROPID_MAX_ROTORS];
    float km_rel_var[PROPID_MAX_ROTORS];
    const propid_reflection_t basis = propid_drag_basis(derived, config);
    propid_drag_per_rotor(&basis, core, km_rel, km_rel_var);
    /* The thrust coefficients per rotor from their torque basis. */
    float kf_state[PROPID_MAX_ROTORS];
    float kf_state_var[PROPID_MAX_ROTORS];
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, derived, config);
    propid_thrust_per_rotor(&thrust, core, kf_state, kf_state_var);
    /* With the thrust-torque scale the thrust states carry g_i = s kf_rel_i and the
     * scale state r = 1/s (docs/math.md §9): kf_rel_i = r g_i, its variance to first
     * order r^2 P_gg + g^2 P_rr + 2 r g P_gr. */
    const uint8_t scale = derived->layout.torque_scale;
    const int scaled = PROPID_WITH_ACCEL && scale != PROPID_NO_STATE;
    const float inverse_scale = scaled ? core->state[scale] : 1.0f;
    const float inverse_scale_var = scaled ? core->cov[propid_cov_index(scale, scale)] : 0.0f;
    float kf_scale_cov[PROPID_MAX_ROTORS] = {0.0f}; /* cov(g_i, r) per rotor */
    if (scaled) {
        for (uint8_t i = 0; i < rotor_count; ++i) {
            kf_scale_cov[i] = core->cov[propid_cov_index((uint8_t)(propid_first_thrust() + i), scale)];
        }
        propid_thrust_to_rotor(&thrust, kf_scale_cov);
    }
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const uint8_t kf = (uint8_t)(propid_first_thrust() + i);
        const uint8_t km = (uint8_t)(first_drag + i);
        const float kf_nominal = config->rotor[i].thrust_coeff_nominal;
        const float km_nominal = config->rotor[i].drag_coeff_nominal;
        const float gain = kf_state[i];
        float kf_var = kf_state_var[i];
        if (scaled) {
            kf_var = inverse_scale * inverse_scale * kf_var + gain * gain * inverse_scale_var +
                     2.0f * inverse_scale * gain * kf_scale_cov[i];
        }
        const float km_var = km_rel_var[i];
        const uint16_t bit = (uint16_t)(1u << i);
        all_rotors |= bit;
        estimate->thrust_coeff[i] = inverse_scale * gain * kf_nominal;
        estimate->thrust_coeff_std[i] = std_of(kf_var) * kf_nominal;
        estimate->drag_coeff[i] = km_rel[i] * km_nominal;
        estimate->drag_coeff_std[i] = std_of(km_var) * km_nominal;
        /* "Converging": std below half its prior, i.e. variance below a quarter. */
        if (kf_var < 0.25f * propid_prior_var(derived, kf)) {
            estimate->thrust_coeff_converging |= bit;
        }
        if (km_var < 0.25f * propid_prior_var(derived, km)) {
            estimate->drag_coeff_converging |= bit;
        }
        if (kf_var < kf_claim_var) {
            estimate->thrust_coeff_converged |= bit;
        }
        if (km_var < km_claim_var) {
            estimate->drag_coeff_converged |= bit;
        }
    }
    const uint8_t disturbance = derived->layout.disturbance;
#if PROPID_WITH_DISTURBANCE /* (a build without it keeps no inertia) */
    if (disturbance != PROPID_NO_STATE) {
        for (uint8_t a = 0; a < 3u; ++a) {
            float torque = 0.0f;
            float torque_var = 0.0f;
            for (uint8_t b = 0; b < 3u; ++b) {
                const uint8_t k = (uint8_t)(disturbance + b);
                torque += config->inertia[a][b] * core->state[k];
                torque_var += config->inertia[a][b] * config->inertia[a][b] * core->cov[propid_cov_index(k, k)];
            }
            estimate->disturbance_torque[a] = torque;
            estimate->disturbance_torque_std[a] = std_of(torque_var);
        }
    }
#endif
    const uint8_t accel_bias = derived->layout.accel_bias;
    if (PROPID_WITH_ACCEL && accel_bias != PROPID_NO_STATE) {
        estimate->accel_bias = core->state[accel_bias];
        estimate->accel_bias_std = std_of(core->cov[propid_cov_index(accel_bias, accel_bias)]);
#if PROPID_WITH_ACCEL
        estimate->accel_innovation = core->accel_innovation;
        estimate->accel_innovation_test_ratio = core->accel_innovation_test_ratio;
#endif
    }
    estimate->torque_scale = 1.0f;
    if (scaled) {
        /* s = 1/r (r kept positive by the clamp), std by the first-order rule. */
        estimate->torque_scale = 1.0f / inverse_scale;
        estimate->torque_scale_std = std_of(inverse_scale_var) / (inverse_scale * inverse_scale);
    }
    uint8_t terms = 0u;
    terms |= disturbance != PROPID_NO_STATE ? PROPID_TERM_DISTURBANCE : 0u;
    terms |= accel_bias != PROPID_NO_STATE ? PROPID_TERM_ACCEL : 0u;
    terms |= derived->layout.torque_scale != PROPID_NO_STATE ? PROPID_TERM_TORQUE_SCALE : 0u;
#if PROPID_WITH_ROTOR_INERTIA
    terms |= derived->rotor_inertia_on ? PROPID_TERM_ROTOR_INERTIA : 0u;
#endif
    terms |= propid_aero_damping_on(derived) ? PROPID_TERM_AERO_DAMPING : 0u;
    terms |= propid_kept_delay_us(config) != 0 ? PROPID_TERM_ESC_DELAY : 0u;
    estimate->model_terms = terms;
    estimate->rotor_delay_us = propid_kept_delay_us(config);
#if PROPID_CONSISTENCY
    {
        /* And the data vouch for the std: at least one full window of the
         * consistency monitor passed since the start (or the last mismatch),
         * and in the last window the coefficient moved by no more than
         * PROPID_CLAIM_DRIFT_Z of the std its updates explain
         * (propid_consistency.c). */
        const propid_consistency_t *monitor = &filter->consistency;
        const uint16_t steady = monitor->passed_windows > 0u ? monitor->steady_coeff : 0u;
        estimate->thrust_coeff_converged &= (uint16_t)(steady & all_rotors);
        estimate->drag_coeff_converged &= (uint16_t)((uint32_t)steady >> rotor_count & all_rotors);
    }
#endif
    uint32_t health = core->health;
    if (health & PROPID_HEALTH_MODEL_MISMATCH) {
        /* The innovations say the model misses something: a small std is then
         * no evidence that a coefficient is right (propid_consistency.c). */
        estimate->thrust_coeff_converged = 0u;
        estimate->drag_coeff_converged = 0u;
    }
    if (!core->has_rotor_data) {
        health |= PROPID_HEALTH_NO_ROTOR_DATA;
    }
    if (filter->counters.rejected[PROPID_REJECT_SLOT(PROPID_ERR_ROTOR_STALE)] != core->stale_mark) {
        health |= PROPID_HEALTH_ROTOR_STALE;
    }
    if (estimate->thrust_coeff_converged == all_rotors && estimate->drag_coeff_converged == all_rotors) {
        health |= PROPID_HEALTH_ALL_CONVERGED;
    }
    estimate->health = health;
    return PROPID_OK;
}

propid_status_t propid_get_counters(const propid_filter_t *filter, propid_counters_t *counters)
{
    if (filter == NULL || counters == NULL) {
        return PROPID_ERR_NULL;
    }
    if (filter->magic != PROPID_MAGIC) {
        return PROPID_ERR_NOT_INITIALISED;
    }
#if PROPID_GENERAL_VEHICLES
    *counters = filter->counters;
#else
    /* The quad build keeps only the counters it can move (propid.h). */
    const propid_kept_counters_t *kept = &filter->counters;
    memset(counters, 0, sizeof(*counters));
    counters->gyro_accepted = kept->gyro_accepted;
    counters->rotor_accepted = kept->rotor_accepted;
    memcpy(counters->axis_gated, kept->axis_gated, sizeof(counters->axis_gated));
    counters->gate_reopened = kept->gate_reopened;
    counters->cov_repairs = kept->cov_repairs;
    counters->state_clamps = kept->state_clamps;
    counters->resyncs = kept->resyncs;
    memcpy(&counters->rejected[1], kept->rejected, sizeof(kept->rejected)); /* (slot 0: no rejection) */
#endif
    return PROPID_OK;
}
