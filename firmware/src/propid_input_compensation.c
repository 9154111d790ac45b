/* Errors-in-variables compensation of the coefficient update (docs/math.md §14,
 * config.input_error_compensation).
 *
 * The prediction integrates the rotor torques with the measured u_i = Omega_i^2.
 * An error e_i of u_i enters twice: the predicted rate is off by dt B_ai e_i
 * (B_ai = d(omega_dot_a)/d(u_i) at the current coefficients), and the Jacobian
 * entry dt T_ap u_i that builds the coefficients' cross-covariance with the rate
 * carries dt T_ap e_i. Their product does not average out: the gyro update of
 * axis a moves coefficient j on average by
 *   - v_a dt^2 / S_a  sum_i Var(e_i) B_ai sum_(p of rotor i) P_(j, column p) T_ap
 * (the least-squares attenuation towards 0). This file adds that amount back to
 * each coefficient after an axis is fused. v_a counts how much error the rate
 * estimate still carries from earlier steps: with the update's rate gain K_a and
 * an error correlated over the steps as exp(-dt / tau), x = (1 - K) (x + e) has
 *   E[(x + e)^2] = E[x^2] + 2 rho E[x e] + 1,   E[x e] -> (1 - K) (rho E[x e] + 1),
 * in units of one sample's error variance (1 when the gyro resets the rate at
 * every step). The covariance is left as it is: the correction moves the mean
 * only, so it cannot make P indefinite.
 *
 * Validity. The corrected filter settles where the information the updates
 * draw from the data balances the corrections: at the uncorrected value divided
 * by (1 - share) along the coefficients' common scale (the direction of the
 * estimate itself, theta), share the part of that information the configured
 * error explains. That grows without bound as the share nears 1, where the
 * configured error is no classical error of this stream (a quantised speed held
 * on one step while the true speed moves within it is not). Per axis, the
 * information an update draws about theta . x is (theta . P (H_a)^T)^2 / S_a,
 * the error's part of it v_a dt^2 / S_a sum_i Var(u_i) (sum_(p of rotor i) T_ap
 * (P theta)_(column p))^2; an axis is corrected only while the dt-weighted mean
 * of the second since init is at most PROPID_INPUT_ERROR_MAX_SHARE of the
 * first's (at most a 2x attenuation is removed). */
#include <math.h>

#include "propid_internal.h"

#if PROPID_WITH_INPUT_NOISE

/* The coefficient block's products with theta and the three factor vectors in one
 * pass over its packed upper triangle (each P element loaded once). */
static void coefficient_products(propid_core_t *core, uint8_t first, uint8_t coefficients)
{
    const float *theta = core->state + first;
    float (*out)[2 * PROPID_MAX_ROTORS] = core->input_product;
    for (uint8_t v = 0; v < 4u; ++v) {
        for (uint8_t k = 0; k < coefficients; ++k) {
            out[v][k] = 0.0f;
        }
    }
    for (uint8_t k = 0; k < coefficients; ++k) {
        const float *row = propid_cov_row_const(core->cov, (uint8_t)(first + k)) + first; /* row[c] = P_kc, c >= k */
        for (uint8_t c = k; c < coefficients; ++c) {
            const float element = row[c];
            const float twice = c == k ? 0.0f : element; /* the lower triangle's copy */
            out[0][k] += element * theta[c];
            out[0][c] += twice * theta[k];
            for (uint8_t a = 0; a < 3u; ++a) {
                out[1u + a][k] += element * core->input_factor[a][c];
                out[1u + a][c] += twice * core->input_factor[a][k];
            }
        }
    }
}

void propid_input_compensation_prepare(propid_filter_t *filter, float dt)
{
    const propid_derived_t *derived = &filter->derived;
    propid_core_t *core = &filter->core;
    const float *state = core->state;
    const float *cov = core->cov;
    const uint8_t rotor_count = filter->config.rotor_count;
    const uint8_t first = derived->layout.thrust;
    const uint8_t coefficients = (uint8_t)(2u * rotor_count);
    const float tau = derived->input_noise_time;
    const float rho = tau > 0.0f ? expf(-dt / tau) : 0.0f;
    /* Var(u_i) at the step's input, the trapezoid mean of the interval's ends. */
    float input_var[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < rotor_count; ++i) {
        input_var[i] = 0.5f * derived->input_noise_var * (core->input_speed_sq[i] + core->rotor_speed_sq[i]);
    }
    /* The coefficients per rotor (the blocks are kept in their bases:
     * propid_internal.h). */
    float coefficient[2u * PROPID_MAX_ROTORS];
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, derived, &filter->config);
    propid_thrust_per_rotor(&thrust, core, coefficient, NULL);
    const propid_reflection_t basis = propid_drag_basis(derived, &filter->config);
    propid_drag_per_rotor(&basis, core, coefficient + rotor_count, NULL);
    float innovation_var[3];
    float weight[3];
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t bias = (uint8_t)(derived->layout.gyro_bias + a);
        const float p_rate = propid_cov_at(cov, a, a) + propid_cov_at(cov, a, bias);
        innovation_var[a] = p_rate + propid_cov_at(cov, a, bias) + propid_cov_at(cov, bias, bias) +
                            derived->gyro_var;
        core->input_rate_gain[a] = p_rate / innovation_var[a];
        core->input_step_cross[a] = rho * core->input_error_cross[a];
        core->input_step_carried[a] = core->input_error_carried[a] + 2.0f * core->input_step_cross[a] + 1.0f;
        weight[a] = core->input_step_carried[a] * dt * dt / innovation_var[a];
        /* B_ai summed over the row's rotor entries, then the factor of each column:
         * weight Var(u_i) B_ai T_ap for entry p of rotor i. */
        float gain[PROPID_MAX_ROTORS] = {0.0f};
        float *factor = core->input_factor[a];
        for (uint8_t k = 0; k < coefficients; ++k) {
            factor[k] = 0.0f;
        }
        const uint8_t count = derived->jac_count[a];
        for (uint8_t p = derived->jac_rate_count[a]; p < count; ++p) {
            const uint8_t rotor = derived->jac_rotor[a][p];
            if (rotor < rotor_count) { /* not the disturbance's entry */
                gain[rotor] += derived->jac_torque[a][p] * coefficient[derived->jac_column[a][p] - first];
            }
        }
        for (uint8_t p = derived->jac_rate_count[a]; p < count; ++p) {
            const uint8_t rotor = derived->jac_rotor[a][p];
            if (rotor < rotor_count) {
                factor[derived->jac_column[a][p] - first] +=
                    weight[a] * input_var[rotor] * gain[rotor] * derived->jac_torque[a][p];
            }
        }
        /* The factors per coefficient to the bases of P's coefficient blocks, so
         * that P times them is the correction of the states as kept. */
        propid_thrust_to_basis(&thrust, factor);
        propid_reflection_apply(&basis, factor + rotor_count);
    }
    coefficient_products(core, first, coefficients);
    /* P theta per rotor (the products are in the basis the states are kept in). */
    float direction[2u * PROPID_MAX_ROTORS];
    for (uint8_t k = 0; k < coefficients; ++k) {
        direction[k] = core->input_product[0][k];
    }
    propid_thrust_to_rotor(&thrust, direction);
    propid_reflection_apply(&basis, direction + rotor_count);
    core->input_information_time += dt;
    const float share = dt / core->input_information_time;
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t bias = (uint8_t)(derived->layout.gyro_bias + a);
        /* The validity test's information, the data's and the error's (math.md §14). */
        float cross_cov = 0.0f;
        for (uint8_t k = 0; k < coefficients; ++k) {
            cross_cov += state[first + k] * (propid_cov_at(cov, (uint8_t)(first + k), a) +
                                             propid_cov_at(cov, (uint8_t)(first + k), bias));
        }
        float along[PROPID_MAX_ROTORS] = {0.0f};
        const uint8_t count = derived->jac_count[a];
        for (uint8_t p = derived->jac_rate_count[a]; p < count; ++p) {
            const uint8_t rotor = derived->jac_rotor[a][p];
            if (rotor < rotor_count) {
                along[rotor] += derived->jac_torque[a][p] * direction[derived->jac_column[a][p] - first];
            }
        }
        float error_information = 0.0f;
        for (uint8_t i = 0; i < rotor_count; ++i) {
            error_information += input_var[i] * along[i] * along[i];
        }
        core->input_information[a] += share * (cross_cov * cross_cov / innovation_var[a] - core->input_information[a]);
        core->input_error_information[a] += share * (weight[a] * error_information - core->input_error_information[a]);
        core->input_valid[a] = (uint8_t)(core->input_error_information[a] <=
                                         PROPID_INPUT_ERROR_MAX_SHARE * core->input_information[a]);
    }
}

void propid_input_compensation_apply(propid_filter_t *filter, uint32_t gated_mask)
{
    propid_core_t *core = &filter->core;
    const uint8_t first = filter->derived.layout.thrust;
    const uint8_t coefficients = (uint8_t)(2u * filter->config.rotor_count);
    for (uint8_t a = 0; a < 3u; ++a) {
        /* A gated axis was not fused: nothing to correct, and its rate keeps the whole error. */
        const int fused = ((gated_mask >> a) & 1u) == 0u;
        const float kept = fused ? 1.0f - core->input_rate_gain[a] : 1.0f;
        if (fused && core->input_valid[a]) {
            for (uint8_t k = 0; k < coefficients; ++k) {
                core->state[first + k] += core->input_product[1u + a][k];
            }
        }
        core->input_error_cross[a] = kept * (core->input_step_cross[a] + 1.0f);
        core->input_error_carried[a] = kept * kept * core->input_step_carried[a];
    }
}

#endif
