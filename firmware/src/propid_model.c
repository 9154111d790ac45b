/* Body-rate dynamics and their Jacobian (see propid_model.h, docs/math.md). */
#include "propid_model.h"

#include <stddef.h>

static void cross(const float a[3], const float b[3], float out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static void mat3_vec(const float m[3][3], const float v[3], float out[3])
{
    for (uint8_t a = 0; a < 3u; ++a) {
        out[a] = m[a][0] * v[0] + m[a][1] * v[1] + m[a][2] * v[2];
    }
}

void propid_model_rates(const propid_config_t *config, const propid_derived_t *derived,
                        const float *state, const float *rotor_speed_sq, float rate_dot[3],
                        float rows[3][PROPID_MAX_STATES])
{
    const uint8_t rotor_count = config->rotor_count;
    const float *rate = state;
    const float *thrust_rel = state + PROPID_RATE_STATES;
    const float *drag_rel = thrust_rel + rotor_count;

    /* Gyroscopic term c = omega x (J omega), and its body-rate derivative
     * dc/domega = [omega]x J - [J omega]x. */
    float momentum[3];
    float gyroscopic[3];
    mat3_vec(config->inertia, rate, momentum);
    cross(rate, momentum, gyroscopic);

    if (rate_dot != NULL) {
        float torque_accel[3];
        mat3_vec(derived->inertia_inv, gyroscopic, torque_accel);
        float acc[3] = {-torque_accel[0], -torque_accel[1], -torque_accel[2]};
        for (uint8_t i = 0; i < rotor_count; ++i) {
            const float thrust_term = thrust_rel[i] * rotor_speed_sq[i];
            const float drag_term = drag_rel[i] * rotor_speed_sq[i];
            for (uint8_t a = 0; a < 3u; ++a) {
                acc[a] += derived->thrust_torque[i][a] * thrust_term +
                          derived->drag_torque[i][a] * drag_term;
            }
        }
        rate_dot[0] = acc[0];
        rate_dot[1] = acc[1];
        rate_dot[2] = acc[2];
    }

    if (rows != NULL) {
        /* Column b of dc/domega: omega x J e_b - (J omega) x e_b. */
        float dgyro[3][3];
        for (uint8_t b = 0; b < 3u; ++b) {
            const float inertia_col[3] = {config->inertia[0][b], config->inertia[1][b],
                                          config->inertia[2][b]};
            const float unit[3] = {b == 0u ? 1.0f : 0.0f, b == 1u ? 1.0f : 0.0f,
                                   b == 2u ? 1.0f : 0.0f};
            float first[3];
            float second[3];
            cross(rate, inertia_col, first);
            cross(momentum, unit, second);
            for (uint8_t a = 0; a < 3u; ++a) {
                dgyro[a][b] = first[a] - second[a];
            }
        }
        for (uint8_t a = 0; a < 3u; ++a) {
            for (uint8_t b = 0; b < 3u; ++b) {
                rows[a][b] = -(derived->inertia_inv[a][0] * dgyro[0][b] +
                               derived->inertia_inv[a][1] * dgyro[1][b] +
                               derived->inertia_inv[a][2] * dgyro[2][b]);
            }
            for (uint8_t i = 0; i < rotor_count; ++i) {
                rows[a][PROPID_RATE_STATES + i] = derived->thrust_torque[i][a] * rotor_speed_sq[i];
                rows[a][PROPID_RATE_STATES + rotor_count + i] =
                    derived->drag_torque[i][a] * rotor_speed_sq[i];
            }
        }
    }
}

void propid_model_rate_derivative(const propid_config_t *config, const propid_derived_t *derived,
                                  const float *state, const float *rotor_speed_sq,
                                  float rate_dot[3])
{
    propid_model_rates(config, derived, state, rotor_speed_sq, rate_dot, NULL);
}

void propid_model_rate_jacobian(const propid_config_t *config, const propid_derived_t *derived,
                                const float *state, const float *rotor_speed_sq,
                                float rows[3][PROPID_MAX_STATES])
{
    propid_model_rates(config, derived, state, rotor_speed_sq, NULL, rows);
}
