/* Measurement update: one scalar update per gyro axis, y_a = omega_a + b_a + v.
 *
 * H = e_rate(a) + e_bias(a) has two non-zeros, so P H^T is the sum of two
 * columns and S = H P H^T + R needs no product. With the optimal gain
 * K = P H^T / S the covariance update is P := P - (P H^T)(P H^T)^T / S, a
 * symmetric rank-one downdate computed on one triangle and mirrored
 * (docs/math.md explains why this form and not Joseph's). */
#include "propid_internal.h"

int propid_update_axis(propid_filter_t *filter, uint8_t axis, float gyro)
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const uint8_t n = derived->state_count;
    const uint8_t bias = (uint8_t)(propid_first_bias(filter->config.rotor_count) + axis);
    float (*cov)[PROPID_MAX_STATES] = core->cov;

    float cov_h[PROPID_MAX_STATES]; /* P H^T */
    for (uint8_t i = 0; i < n; ++i) {
        cov_h[i] = cov[i][axis] + cov[i][bias];
    }
    float innovation_var = cov_h[axis] + cov_h[bias] + derived->gyro_var;
    if (!(innovation_var >= derived->gyro_var)) {
        /* var(omega + b) < 0 or NaN: P is no longer PSD. Repair and recompute. */
        if (propid_cov_repair(derived, core)) {
            core->health |= PROPID_HEALTH_COV_REPAIRED;
            filter->counters.cov_repairs++;
        }
        for (uint8_t i = 0; i < n; ++i) {
            cov_h[i] = cov[i][axis] + cov[i][bias];
        }
        innovation_var = cov_h[axis] + cov_h[bias] + derived->gyro_var;
        if (!(innovation_var >= derived->gyro_var)) {
            innovation_var = derived->gyro_var;
        }
    }
    const float innovation = gyro - core->state[axis] - core->state[bias];
    const float innovation_sq = innovation * innovation;
    float inv_innovation_var = 1.0f / innovation_var;
    core->innovation[axis] = innovation;
    core->innovation_test_ratio[axis] = innovation_sq * inv_innovation_var * derived->inv_gate_sq;

    if (derived->gate_sq > 0.0f && innovation_sq > derived->gate_sq * innovation_var) {
        if (core->gated_run[axis] < filter->config.gate_max_consecutive) {
            core->gated_run[axis]++;
            filter->counters.axis_gated[axis]++;
            return 1;
        }
        /* Too many rejections in a row: the filter, not the sensor, is probably
         * wrong. Inflate the rate variance by the innovation^2 so that the sample
         * lands inside one sigma, and fuse it. Adding to a diagonal keeps P PSD. */
        cov[axis][axis] += innovation_sq;
        cov_h[axis] += innovation_sq;
        innovation_var += innovation_sq;
        inv_innovation_var = 1.0f / innovation_var;
        filter->counters.gate_reopened++;
        core->health |= PROPID_HEALTH_GATE_REOPENED;
    }
    core->gated_run[axis] = 0u;

    const float scaled_innovation = innovation * inv_innovation_var;
    for (uint8_t i = 0; i < n; ++i) {
        core->state[i] += cov_h[i] * scaled_innovation;
    }
    for (uint8_t i = 0; i < n; ++i) {
        const float gain_i = cov_h[i] * inv_innovation_var;
        float *row = cov[i];
        for (uint8_t j = i; j < n; ++j) {
            const float value = row[j] - gain_i * cov_h[j];
            row[j] = value;
            cov[j][i] = value;
        }
    }
    return 0;
}

uint32_t propid_clamp_coefficients(const propid_config_t *config, propid_core_t *core)
{
    const uint8_t first = propid_first_thrust();
    const uint8_t end = propid_first_bias(config->rotor_count);
    uint32_t clamped = 0u;
    for (uint8_t k = first; k < end; ++k) {
        if (core->state[k] < config->coeff_rel_min) {
            core->state[k] = config->coeff_rel_min;
            clamped++;
        } else if (core->state[k] > config->coeff_rel_max) {
            core->state[k] = config->coeff_rel_max;
            clamped++;
        }
    }
    return clamped;
}
