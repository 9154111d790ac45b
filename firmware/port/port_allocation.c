/*
 * Quadrotor control allocation rebuilt from identified coefficients.
 *
 * Effectiveness (body FLU, rotor i at (x_i, y_i), yaw sign s_i, u_i = omega_i^2):
 *   thrust = sum kf_i u_i
 *   tau_x  = sum  y_i kf_i u_i
 *   tau_y  = sum -x_i kf_i u_i
 *   tau_z  = sum  s_i km_i u_i
 * Four rotors, four wrench components: the 4x4 matrix is inverted once per
 * rebuild (Gauss-Jordan, partial pivoting), not in every control step.
 */
#include "port_allocation.h"

#include <math.h>
#include <string.h>

static float coefficient(uint16_t converged_mask, uint8_t rotor, const float *estimate,
                         float nominal, uint16_t *used_mask)
{
    if ((((uint32_t)converged_mask >> rotor) & 1u) != 0u && isfinite(estimate[rotor]) &&
        estimate[rotor] > 0.0f) {
        *used_mask = (uint16_t)(*used_mask | (1u << rotor));
        return estimate[rotor];
    }
    return nominal;
}

/* Invert a 4x4 matrix in place of `inverse`; 0 on success, -1 if singular. */
static int invert4(const float matrix[4][4], float inverse[4][4])
{
    float work[4][8];
    for (uint8_t r = 0; r < 4u; ++r) {
        for (uint8_t c = 0; c < 4u; ++c) {
            work[r][c] = matrix[r][c];
            work[r][c + 4u] = (r == c) ? 1.0f : 0.0f;
        }
    }
    for (uint8_t col = 0; col < 4u; ++col) {
        uint8_t pivot = col;
        for (uint8_t r = (uint8_t)(col + 1u); r < 4u; ++r) {
            if (fabsf(work[r][col]) > fabsf(work[pivot][col])) {
                pivot = r;
            }
        }
        if (!(fabsf(work[pivot][col]) > 1.0e-30f)) {
            return -1;
        }
        if (pivot != col) {
            for (uint8_t c = 0; c < 8u; ++c) {
                const float swap = work[col][c];
                work[col][c] = work[pivot][c];
                work[pivot][c] = swap;
            }
        }
        const float scale = 1.0f / work[col][col];
        for (uint8_t c = 0; c < 8u; ++c) {
            work[col][c] *= scale;
        }
        for (uint8_t r = 0; r < 4u; ++r) {
            if (r == col) {
                continue;
            }
            const float factor = work[r][col];
            for (uint8_t c = 0; c < 8u; ++c) {
                work[r][c] -= factor * work[col][c];
            }
        }
    }
    for (uint8_t r = 0; r < 4u; ++r) {
        for (uint8_t c = 0; c < 4u; ++c) {
            inverse[r][c] = work[r][c + 4u];
            if (!isfinite(inverse[r][c])) {
                return -1;
            }
        }
    }
    return 0;
}

int port_allocation_build(port_allocation_t *allocation, const propid_config_t *config,
                          const propid_estimate_t *estimate)
{
    port_allocation_t next;
    memset(&next, 0, sizeof(next));
    float effectiveness[4][4];
    for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
        const propid_rotor_config_t *rotor = &config->rotor[i];
        float kf = rotor->thrust_coeff_nominal;
        float km = rotor->drag_coeff_nominal;
        if (estimate != NULL) {
            kf = coefficient(estimate->thrust_coeff_converged, i, estimate->thrust_coeff, kf,
                             &next.estimated_thrust_mask);
            km = coefficient(estimate->drag_coeff_converged, i, estimate->drag_coeff, km,
                             &next.estimated_drag_mask);
        }
        next.thrust_coeff[i] = kf;
        next.drag_coeff[i] = km;
        effectiveness[0][i] = kf;
        effectiveness[1][i] = rotor->position_m[1] * kf;
        effectiveness[2][i] = -rotor->position_m[0] * kf;
        effectiveness[3][i] = rotor->yaw_sign * km;
    }
    if (invert4(effectiveness, next.speed_sq_per_wrench) != 0) {
        return -1;
    }
    *allocation = next;
    return 0;
}

void port_allocation_apply(const port_allocation_t *allocation, const float wrench[4],
                           float max_rotor_speed, float rotor_speed[PORT_ROTORS])
{
    const float max_sq = max_rotor_speed * max_rotor_speed;
    for (uint8_t i = 0; i < PORT_ROTORS; ++i) {
        float speed_sq = 0.0f;
        for (uint8_t k = 0; k < 4u; ++k) {
            speed_sq += allocation->speed_sq_per_wrench[i][k] * wrench[k];
        }
        /* A rotor cannot push negative thrust: saturate rather than fold over. */
        speed_sq = speed_sq < 0.0f ? 0.0f : (speed_sq > max_sq ? max_sq : speed_sq);
        rotor_speed[i] = sqrtf(speed_sq);
    }
}
