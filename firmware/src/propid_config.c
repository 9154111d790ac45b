/* Configuration: documented defaults, geometry helpers, validation, and the
 * quantities derived once so that the filter step needs no division.
 * Every default is explained in docs/design.md ("Defaults"). */
#include <math.h>
#include <stddef.h>
#include <string.h>

#include "propid_aero_damping.h"
#include "propid_delay.h"
#include "propid_internal.h"

/* Largest accepted nominal kf or km [SI]: far above any propeller (a 1 m rotor has
 * kf ~ 3e-3 N/(rad/s)^2), small enough that coefficient x relative std stays finite
 * in float32 (relative values are clamped to <= 1e3). */
#define PROPID_COEFF_NOMINAL_MAX 1.0f

#define PROPID_TWO_PI 6.28318530717958647692f

void propid_config_default(propid_config_t *config)
{
    if (config == NULL) {
        return;
    }
    memset(config, 0, sizeof(*config));
    config->rotor_count = 0u;

    config->rate_std0 = 1.0f;
    config->thrust_coeff_rel_std0 = 0.3f;
    config->drag_coeff_rel_std0 = 0.3f;
    config->gyro_bias_std0 = 0.05f;

    config->gyro_noise_density = 5.0e-4f;
    config->gyro_sample_rate_hz = 500.0f;
    config->rate_process_noise = 0.2f;
    config->thrust_coeff_rel_walk = 0.02f;
    config->drag_coeff_rel_walk = 0.02f;
    config->gyro_bias_walk = 1.0e-4f;

    config->gate_sigma = 5.0f;
    config->gate_max_consecutive = 25u;
    config->max_rotor_speed = 6000.0f;
    config->gyro_range = 34.0f;
    config->rotor_stale_us = 50000u;
    config->max_gyro_gap_us = 50000u;
    config->coeff_rel_min = 0.05f;
    config->coeff_rel_max = 5.0f;
    config->converged_rel_std = 0.05f;

    /* Optional terms off (rotor_inertia zeroed above, mass 0); their noise and
     * prior defaults apply when a caller switches them on. */
    config->disturbance_torque = 0u;
    config->disturbance_std0 = 20.0f;
    config->disturbance_walk = 0.2f;
    config->disturbance_bandwidth = 0.0f;
    config->mass = 0.0f;
    config->accel_noise_std = 0.5f;
    config->accel_bias_std0 = 0.5f;
    config->accel_bias_walk = 1.0e-3f;
    config->accel_range = 160.0f;
    config->accel_error_std = 0.0f; /* off: the row's error taken as white */
    config->accel_error_time = 0.0f;
    config->torque_scale = 0u;
    config->torque_scale_std0 = 0.5f;
    config->torque_scale_walk = 0.0f;
    config->rotor_speed_noise = 0.0f;
    config->rotor_speed_noise_time = 0.0f;
    config->inertia_rel_std = 0.0f;
    config->motor_time_constant = 0.01f;
    config->input_error_compensation = 0u;
    config->rotor_speed_noise_hold = 0u;
    config->rotor_speed_noise_split = 0u;
    config->rotor_timing_error = 0.0f;
    config->motor_command_instrument = 0u;
    config->motor_command_lag = 0.03f;
    config->motor_command_memory = 10.0f;
    config->motor_command_min_f = 0.0f;
}

propid_status_t propid_config_set_symmetric(propid_config_t *config, uint8_t rotor_count,
                                            float arm_m, float first_angle_rad,
                                            float first_yaw_sign, float thrust_coeff_nominal,
                                            float drag_coeff_nominal)
{
    if (config == NULL) {
        return PROPID_ERR_NULL;
    }
    if (rotor_count < 1u || rotor_count > PROPID_MAX_ROTORS || !isfinite(arm_m) || !(arm_m > 0.0f) ||
        !isfinite(first_angle_rad) || (first_yaw_sign != 1.0f && first_yaw_sign != -1.0f) ||
        !isfinite(thrust_coeff_nominal) || !(thrust_coeff_nominal > 0.0f) ||
        !isfinite(drag_coeff_nominal) || !(drag_coeff_nominal > 0.0f)) {
        return PROPID_ERR_CONFIG;
    }
    config->rotor_count = rotor_count;
    const float step = PROPID_TWO_PI / (float)rotor_count;
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        propid_rotor_config_t *rotor = &config->rotor[i];
        if (i >= rotor_count) {
            memset(rotor, 0, sizeof(*rotor));
            continue;
        }
        const float angle = first_angle_rad + step * (float)i;
        rotor->position_m[0] = arm_m * cosf(angle);
        rotor->position_m[1] = arm_m * sinf(angle);
        rotor->position_m[2] = 0.0f;
        rotor->yaw_sign = (i % 2u == 0u) ? first_yaw_sign : -first_yaw_sign;
        rotor->thrust_coeff_nominal = thrust_coeff_nominal;
        rotor->drag_coeff_nominal = drag_coeff_nominal;
    }
    return PROPID_OK;
}

void propid_config_set_inertia_diag(propid_config_t *config, float jxx, float jyy, float jzz)
{
    if (config == NULL) {
        return;
    }
    memset(config->inertia, 0, sizeof(config->inertia));
    config->inertia[0][0] = jxx;
    config->inertia[1][1] = jyy;
    config->inertia[2][2] = jzz;
}

static int positive_finite(float value)
{
    return isfinite(value) && value > 0.0f;
}

static int all_finite(const float *values, size_t count)
{
    for (size_t i = 0; i < count; ++i) {
        if (!isfinite(values[i])) {
            return 0;
        }
    }
    return 1;
}

/* Inverse of the symmetric positive definite inertia; 0 if it is not SPD. */
static int inertia_inverse(const float inertia[3][3], float inverse[3][3])
{
    float j[3][3];
    float scale = 0.0f;
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = 0; b < 3u; ++b) {
            j[a][b] = 0.5f * (inertia[a][b] + inertia[b][a]);
            const float magnitude = fabsf(inertia[a][b]);
            scale = magnitude > scale ? magnitude : scale;
        }
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t b = 0; b < 3u; ++b) {
            if (fabsf(inertia[a][b] - inertia[b][a]) > 1.0e-5f * scale) {
                return 0;
            }
        }
    }
    /* Sylvester: leading principal minors positive. For a positive definite
     * matrix minor/(product of its diagonal) lies in (0, 1] (Hadamard); asking
     * for > 1e-6 rejects singular and near-singular inertias robustly, whatever
     * the rounding (FMA contraction on the MCU leaves residues of ~1e-7). */
    const float minor2 = j[0][0] * j[1][1] - j[0][1] * j[1][0];
    const float cof00 = j[1][1] * j[2][2] - j[1][2] * j[2][1];
    const float cof01 = j[1][2] * j[2][0] - j[1][0] * j[2][2];
    const float cof02 = j[1][0] * j[2][1] - j[1][1] * j[2][0];
    const float det = j[0][0] * cof00 + j[0][1] * cof01 + j[0][2] * cof02;
    const float diag01 = j[0][0] * j[1][1];
    if (!(j[0][0] > 0.0f) || !(j[1][1] > 0.0f) || !(j[2][2] > 0.0f) ||
        !(minor2 > 1.0e-6f * diag01) || !(det > 1.0e-6f * diag01 * j[2][2]) || !isfinite(det)) {
        return 0;
    }
    const float inv_det = 1.0f / det;
    inverse[0][0] = cof00 * inv_det;
    inverse[0][1] = (j[0][2] * j[2][1] - j[0][1] * j[2][2]) * inv_det;
    inverse[0][2] = (j[0][1] * j[1][2] - j[0][2] * j[1][1]) * inv_det;
    inverse[1][0] = cof01 * inv_det;
    inverse[1][1] = (j[0][0] * j[2][2] - j[0][2] * j[2][0]) * inv_det;
    inverse[1][2] = (j[0][2] * j[1][0] - j[0][0] * j[1][2]) * inv_det;
    inverse[2][0] = cof02 * inv_det;
    inverse[2][1] = (j[0][1] * j[2][0] - j[0][0] * j[2][1]) * inv_det;
    inverse[2][2] = minor2 * inv_det;
    return all_finite(&inverse[0][0], 9u);
}

/* Torque components below float32 resolution (2^-23) of the largest one are the
 * rounding residue of the geometry (a plus frame's cosf(pi/2) gives r_x ~ 1e-8 m,
 * not 0), not physics: make them exact zeros so the step skips them. */
static void flush_residues(float *values, size_t count)
{
    float largest = 0.0f;
    for (size_t k = 0; k < count; ++k) {
        largest = fabsf(values[k]) > largest ? fabsf(values[k]) : largest;
    }
    const float threshold = largest * 1.1920929e-7f;
    for (size_t k = 0; k < count; ++k) {
        if (fabsf(values[k]) <= threshold) {
            values[k] = 0.0f;
        }
    }
}

static void cross3(const float a[3], const float b[3], float out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* Structure of the 3 rate rows of A = df/dx, so the step touches only entries that
 * can be non-zero (docs/design.md, "Cost"):
 * - rate columns: the gyroscopic term c = omega x J omega is quadratic in omega,
 *   so A_ab = -(J^-1 dc/domega)_ab = sum_c gyro_jacobian[a][b][c] omega_c with
 *   gyro_jacobian[a][b][c] = -sum_d Jinv_ad ((e_b x J e_c)_d + (e_c x J e_b)_d);
 *   (and -J^-1 c = A_rr omega / 2). A diagonal inertia leaves 2 entries per row
 *   (1 in the yaw row when Jxx == Jyy);
 * - coefficient columns: A = thrust_torque[i][a] u_i or drag_torque[i][a] u_i,
 *   present only when that torque component is not exactly zero (a diagonal
 *   inertia has no yaw thrust and no roll/pitch drag entries). */
/* The geometry and inertia terms the derivation works from (the general build
 * keeps them in propid_derived_t too: its step and model read them). */
typedef struct {
    float inertia_inv[3][3];
    float thrust_torque[PROPID_MAX_ROTORS][3];      /* J^-1 (r_i x z) kf_nominal_i */
    float drag_torque[PROPID_MAX_ROTORS][3];        /* J^-1 z yaw_sign_i km_nominal_i */
    float gyro_jacobian[3][3][3];                   /* A_ab = sum_c gyro_jacobian[a][b][c] omega_c */
} geometry_t;

/* A quad whose structure fits the fixed layout of propid_internal.h (gyroscopic
 * entries A_ab that depend on the third rate only, no drag in the roll/pitch rows,
 * no thrust in the yaw row: any diagonal inertia) gets its lists rewritten to exactly that layout and
 * quad_layout = 1, so the step can use its straight-line quad kernels. The lists
 * then may hold entries that are zero for this frame; they add exact zeros. */
static void derive_quad_layout(const propid_config_t *config, const geometry_t *geo, propid_derived_t *out)
{
    out->quad_layout = 0u;
    if (config->rotor_count != 4u || out->state_count != PROPID_QUAD_STATES || propid_rotor_inertia_on(out) ||
        propid_aero_damping_on(out)) {
        return; /* the fixed kernels know neither the optional states nor the rotor terms */
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        /* Gyroscopic block of a diagonal inertia: A_ab depends on the third rate only. */
        for (uint8_t b = 0; b < 3u; ++b) {
            for (uint8_t c = 0; c < 3u; ++c) {
                const int third = a != b && c != a && c != b;
                if (!third && geo->gyro_jacobian[a][b][c] != 0.0f) {
                    return;
                }
            }
        }
        for (uint8_t i = 0; i < 4u; ++i) {
            if ((a < 2u && geo->drag_torque[i][a] != 0.0f) || (a == 2u && geo->thrust_torque[i][a] != 0.0f)) {
                return;
            }
        }
    }
    out->quad_layout = 1u;
    for (uint8_t a = 0; a < 3u; ++a) {
        for (uint8_t p = 0; p < (uint8_t)PROPID_QUAD_JAC_ENTRIES; ++p) {
            const uint8_t i = (uint8_t)(p - 2u);
#if PROPID_GENERAL_VEHICLES
            out->jac_torque[a][p] = p < 2u ? 0.0f : (a < 2u ? geo->thrust_torque[i][a] : geo->drag_torque[i][a]);
            out->jac_column[a][p] = propid_quad_layout_column(a, p);
            out->jac_rotor[a][p] = p < 2u ? 0u : i;
#else
            if (p >= 2u) {
                out->jac_torque[a][i] = a < 2u ? geo->thrust_torque[i][a] : geo->drag_torque[i][a];
            }
#endif
        }
#if PROPID_GENERAL_VEHICLES
        out->jac_rate_count[a] = 2u;
        out->jac_count[a] = (uint8_t)PROPID_QUAD_JAC_ENTRIES;
#endif
        /* gyro_jacobian[a][b][c] is symmetric in b and c (the same two cross
         * products summed in either order): one value per row. */
        const uint8_t b = propid_quad_layout_column(a, 0u);
        out->quad_gyro[a] = geo->gyro_jacobian[a][b][3u - a - b];
    }
}

#if PROPID_GENERAL_VEHICLES
/* The drag coefficients' yaw basis (propid_internal.h): v = e_0 + s_0 s / sqrt(N),
 * v.v = 2 + 2 / sqrt(N), H = I - (2 / v.v) v v^T maps e_0 to -s_0 s / sqrt(N). */
static void derive_drag_basis(const propid_config_t *config, propid_derived_t *out)
{
    const uint8_t rotor_count = config->rotor_count;
    const float inv_root = 1.0f / sqrtf((float)rotor_count);
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        const float relative = i < rotor_count ? config->rotor[0].yaw_sign * config->rotor[i].yaw_sign : 0.0f;
        out->drag_basis[i] = (i == 0u ? 1.0f : 0.0f) + relative * inv_root;
    }
    out->drag_basis_scale = 1.0f / (1.0f + inv_root);
}
#endif

/* r and p the roll- and pitch-torque directions, r normalised, p orthogonalised
 * against it and normalised. H_0 = I - (2 / v.v) v v^T with v = r + sigma e_0
 * (sigma the sign of r_0, v.v = 2 (1 + |r_0|)) has first row -sigma r; H_0 p then
 * has no element 0, and H_1 built the same way from it on elements 1..N-1 makes
 * the second row of H_1 H_0 -sigma' p. Each kept as w = v / sqrt(1 + |d_k|)
 * (H = I - w w^T). A direction that vanishes (one rotor, rotors on one line) or
 * is parallel to r leaves its reflection the identity (w = 0). Into
 * basis[0 .. N) (H_0) and basis[PROPID_MAX_ROTORS + i - 1] for element i of H_1. */
static void thrust_basis_from_torques(const float *roll, const float *pitch, uint8_t rotor_count,
                                      float basis[2 * PROPID_MAX_ROTORS - 1])
{
    float direction[2][PROPID_MAX_ROTORS];
    float w[2][PROPID_MAX_ROTORS];
    float size[2] = {0.0f, 0.0f};
    for (uint8_t k = 0; k < 2u; ++k) {
        const float *source = k == 0u ? roll : pitch;
        for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
            direction[k][i] = i < rotor_count ? source[i] : 0.0f;
            w[k][i] = 0.0f;
            size[k] += direction[k][i] * direction[k][i];
        }
    }
    int have_first = 0;
    for (uint8_t k = 0; k < 2u && k < rotor_count; ++k) {
        float *d = direction[k];
        if (k == 1u && have_first) {
            /* p - (p.r) r, then H_0 applied (its element 0 is zero up to rounding). */
            const float *r = direction[0];
            float along = 0.0f;
            for (uint8_t i = 0; i < rotor_count; ++i) {
                along += d[i] * r[i];
            }
            for (uint8_t i = 0; i < rotor_count; ++i) {
                d[i] -= along * r[i];
            }
            float dot = 0.0f;
            for (uint8_t i = 0; i < rotor_count; ++i) {
                dot += w[0][i] * d[i];
            }
            for (uint8_t i = 0; i < rotor_count; ++i) {
                d[i] -= dot * w[0][i];
            }
            d[0] = 0.0f;
        }
        float norm_sq = 0.0f;
        for (uint8_t i = k; i < rotor_count; ++i) {
            norm_sq += d[i] * d[i];
        }
        /* Kept only when it keeps more than 1e-6 of its squared size (a pitch
         * direction nearly parallel to the roll one is not a direction of its own). */
        if (!(norm_sq > 1.0e-6f * size[k]) || !(norm_sq <= FLT_MAX)) {
            continue;
        }
        const float inv_norm = 1.0f / sqrtf(norm_sq);
        for (uint8_t i = k; i < rotor_count; ++i) {
            d[i] *= inv_norm;
        }
        const float sigma = d[k] >= 0.0f ? 1.0f : -1.0f;
        const float fold = 1.0f / sqrtf(1.0f + fabsf(d[k]));
        for (uint8_t i = k; i < rotor_count; ++i) {
            w[k][i] = (i == k ? d[i] + sigma : d[i]) * fold;
        }
        have_first |= k == 0u;
    }
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        basis[i] = w[0][i];
        if (i > 0u) {
            basis[PROPID_MAX_ROTORS + i - 1u] = w[1][i];
        }
    }
}

/* The thrust coefficients' torque basis (propid_internal.h) from the roll- and
 * pitch-torque rows per unit kf_rel (J^-1 (r_i x z)
 * kf_nominal_i). */
static void derive_thrust_basis(const propid_config_t *config, const geometry_t *geo, propid_derived_t *out)
{
    float roll[PROPID_MAX_ROTORS];
    float pitch[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        roll[i] = geo->thrust_torque[i][0];
        pitch[i] = geo->thrust_torque[i][1];
    }
    thrust_basis_from_torques(roll, pitch, config->rotor_count, out->thrust_basis);
}

static void derive_gyro_jacobian(const propid_config_t *config, geometry_t *geo)
{
    for (uint8_t b = 0; b < 3u; ++b) {
        for (uint8_t c = 0; c < 3u; ++c) {
            const float unit_b[3] = {b == 0u ? 1.0f : 0.0f, b == 1u ? 1.0f : 0.0f, b == 2u ? 1.0f : 0.0f};
            const float unit_c[3] = {c == 0u ? 1.0f : 0.0f, c == 1u ? 1.0f : 0.0f, c == 2u ? 1.0f : 0.0f};
            const float column_b[3] = {config->inertia[0][b], config->inertia[1][b], config->inertia[2][b]};
            const float column_c[3] = {config->inertia[0][c], config->inertia[1][c], config->inertia[2][c]};
            float first[3];
            float second[3];
            cross3(unit_b, column_c, first);
            cross3(unit_c, column_b, second);
            for (uint8_t a = 0; a < 3u; ++a) {
                float sum = 0.0f;
                for (uint8_t d = 0; d < 3u; ++d) {
                    sum += geo->inertia_inv[a][d] * (first[d] + second[d]);
                }
                geo->gyro_jacobian[a][b][c] = -sum;
            }
        }
    }
}

#if PROPID_GENERAL_VEHICLES
static void derive_sparsity(const propid_config_t *config, const geometry_t *geo, propid_derived_t *out)
{
    const uint8_t rotor_count = config->rotor_count;
    for (uint8_t a = 0; a < 3u; ++a) {
        uint8_t count = 0u;
        for (uint8_t b = 0; b < 3u; ++b) {
            const float *coeff = geo->gyro_jacobian[a][b];
            const int rotor_term = b < 2u && propid_rotor_gyro(out, a, b) != 0.0f;
            const int damping_term = propid_aero_damping_entry(out, a, b) != 0.0f;
            if (coeff[0] != 0.0f || coeff[1] != 0.0f || coeff[2] != 0.0f || rotor_term || damping_term) {
                out->jac_column[a][count] = b;
                out->jac_rotor[a][count] = 0u;
                out->jac_torque[a][count] = 0.0f;
                count++;
            }
        }
        out->jac_rate_count[a] = count;
        /* All of a row's thrust columns or none: the torque basis makes any of
         * them a combination of all (the same for the drag columns below). */
        int thrust_row = 0;
        for (uint8_t i = 0; i < rotor_count; ++i) {
            thrust_row |= geo->thrust_torque[i][a] != 0.0f;
        }
        for (uint8_t i = 0; i < rotor_count; ++i) {
            if (thrust_row) {
                out->jac_column[a][count] = (uint8_t)(PROPID_RATE_STATES + i);
                out->jac_rotor[a][count] = i;
                out->jac_torque[a][count] = geo->thrust_torque[i][a];
                count++;
            }
        }
        /* All of a row's drag columns or none: the yaw basis (propid_internal.h). */
        int drag_row = 0;
        for (uint8_t i = 0; i < rotor_count; ++i) {
            drag_row |= geo->drag_torque[i][a] != 0.0f;
        }
        for (uint8_t i = 0; i < rotor_count; ++i) {
            if (drag_row) {
                out->jac_column[a][count] = (uint8_t)(PROPID_RATE_STATES + rotor_count + i);
                out->jac_rotor[a][count] = i;
                out->jac_torque[a][count] = geo->drag_torque[i][a];
                count++;
            }
        }
        /* The disturbance acts like one more "rotor" with torque 1 and input 1
         * (jac_rotor = rotor_count: the step's input slot holding dt). */
        if (out->layout.disturbance != PROPID_NO_STATE) {
            out->jac_column[a][count] = (uint8_t)(out->layout.disturbance + a);
            out->jac_rotor[a][count] = rotor_count;
            out->jac_torque[a][count] = 1.0f;
            count++;
        }
        out->jac_count[a] = count;
    }
}
#endif

/* The field whose process noise state k's check found too large (k past the rates and coefficients). */
static const char *process_noise_name(const propid_layout_t *layout, const propid_config_t *config, uint8_t k)
{
    if (k == layout->accel_bias) {
        return "accel_bias_walk";
    }
    if (k == layout->torque_scale) {
        return "torque_scale_walk";
    }
    if (layout->disturbance != PROPID_NO_STATE && k >= layout->disturbance && k < layout->disturbance + 3u) {
        return config->disturbance_bandwidth > 0.0f ? "disturbance_bandwidth" : "disturbance_walk";
    }
    return "gyro_bias_walk";
}

#define PROPID_BAD(name)                                                                           \
    do {                                                                                           \
        if (bad_field != NULL) {                                                                   \
            *bad_field = (name);                                                                   \
        }                                                                                          \
        return PROPID_ERR_CONFIG;                                                                  \
    } while (0)

propid_status_t propid_config_derive(const propid_config_t *config, propid_derived_t *derived,
                                     const char **bad_field)
{
    if (config == NULL) {
        return PROPID_ERR_NULL;
    }
    const uint8_t rotor_count = config->rotor_count;
    if (rotor_count < 1u || rotor_count > PROPID_MAX_ROTORS) {
        PROPID_BAD("rotor_count");
    }
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const propid_rotor_config_t *rotor = &config->rotor[i];
        if (!all_finite(rotor->position_m, 3u) || fabsf(rotor->position_m[0]) > 100.0f ||
            fabsf(rotor->position_m[1]) > 100.0f || fabsf(rotor->position_m[2]) > 100.0f) {
            PROPID_BAD("rotor.position_m");
        }
        if (rotor->yaw_sign != 1.0f && rotor->yaw_sign != -1.0f) {
            PROPID_BAD("rotor.yaw_sign");
        }
        if (!positive_finite(rotor->thrust_coeff_nominal) ||
            rotor->thrust_coeff_nominal > PROPID_COEFF_NOMINAL_MAX) {
            PROPID_BAD("rotor.thrust_coeff_nominal");
        }
        if (!positive_finite(rotor->drag_coeff_nominal) ||
            rotor->drag_coeff_nominal > PROPID_COEFF_NOMINAL_MAX) {
            PROPID_BAD("rotor.drag_coeff_nominal");
        }
    }
    if (!all_finite(&config->inertia[0][0], 9u)) {
        PROPID_BAD("inertia");
    }
#if !PROPID_GENERAL_VEHICLES
    if (rotor_count != 4u) {
        PROPID_BAD("rotor_count"); /* this build has the quad kernels only (propid_config.h) */
    }
#endif
    propid_derived_t out;
    memset(&out, 0, sizeof(out));
    geometry_t geo;
    memset(&geo, 0, sizeof(geo));
    if (!inertia_inverse(config->inertia, geo.inertia_inv)) {
        PROPID_BAD("inertia");
    }
    if (!positive_finite(config->rate_std0)) {
        PROPID_BAD("rate_std0");
    }
    if (!positive_finite(config->thrust_coeff_rel_std0)) {
        PROPID_BAD("thrust_coeff_rel_std0");
    }
    if (!positive_finite(config->drag_coeff_rel_std0)) {
        PROPID_BAD("drag_coeff_rel_std0");
    }
    if (!positive_finite(config->gyro_bias_std0)) {
        PROPID_BAD("gyro_bias_std0");
    }
    if (!positive_finite(config->gyro_noise_density)) {
        PROPID_BAD("gyro_noise_density");
    }
    if (!positive_finite(config->gyro_sample_rate_hz) || config->gyro_sample_rate_hz > 1.0e6f) {
        PROPID_BAD("gyro_sample_rate_hz");
    }
    if (!positive_finite(config->rate_process_noise)) {
        PROPID_BAD("rate_process_noise");
    }
    if (!isfinite(config->thrust_coeff_rel_walk) || config->thrust_coeff_rel_walk < 0.0f) {
        PROPID_BAD("thrust_coeff_rel_walk");
    }
    if (!isfinite(config->drag_coeff_rel_walk) || config->drag_coeff_rel_walk < 0.0f) {
        PROPID_BAD("drag_coeff_rel_walk");
    }
    if (!isfinite(config->gyro_bias_walk) || config->gyro_bias_walk < 0.0f) {
        PROPID_BAD("gyro_bias_walk");
    }
    /* A gate below 1 sigma would refuse a third of valid samples. */
    if (!isfinite(config->gate_sigma) || config->gate_sigma > 1.0e3f ||
        (config->gate_sigma > 0.0f && config->gate_sigma < 1.0f)) {
        PROPID_BAD("gate_sigma");
    }
    if (config->gate_max_consecutive < 1u) {
        PROPID_BAD("gate_max_consecutive");
    }
    if (!positive_finite(config->max_rotor_speed) || config->max_rotor_speed > 1.0e5f) {
        PROPID_BAD("max_rotor_speed");
    }
    if (!positive_finite(config->gyro_range) || config->gyro_range > 1.0e4f) {
        PROPID_BAD("gyro_range");
    }
    /* From micro motors (a few ms) to large ones (about a second), with margin. */
    if (!isfinite(config->motor_time_constant) || !(config->motor_time_constant >= 1.0e-4f) ||
        config->motor_time_constant > 6.5f) {
        PROPID_BAD("motor_time_constant");
    }
    if (config->rotor_stale_us < 1u) {
        PROPID_BAD("rotor_stale_us");
    }
    if (config->max_gyro_gap_us < 1u || config->max_gyro_gap_us > 10000000u) {
        PROPID_BAD("max_gyro_gap_us");
    }
    if (!positive_finite(config->coeff_rel_min) || !(config->coeff_rel_min < 1.0f)) {
        PROPID_BAD("coeff_rel_min");
    }
    if (!isfinite(config->coeff_rel_max) || !(config->coeff_rel_max > 1.0f) ||
        config->coeff_rel_max > 1.0e3f) {
        PROPID_BAD("coeff_rel_max");
    }
    /* A prior wider than the clamp range says nothing the clamp does not, and it
     * keeps the reported std (relative std x nominal) finite. */
    if (config->thrust_coeff_rel_std0 > config->coeff_rel_max) {
        PROPID_BAD("thrust_coeff_rel_std0");
    }
    if (config->drag_coeff_rel_std0 > config->coeff_rel_max) {
        PROPID_BAD("drag_coeff_rel_std0");
    }
    if (!positive_finite(config->converged_rel_std)) {
        PROPID_BAD("converged_rel_std");
    }
    if (!isfinite(config->inertia_rel_std) || config->inertia_rel_std < 0.0f || config->inertia_rel_std > 1.0f) {
        PROPID_BAD("inertia_rel_std");
    }
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const float rotor_inertia = config->rotor_inertia[i];
        if (!isfinite(rotor_inertia) || rotor_inertia < 0.0f || rotor_inertia > 1.0f ||
            (!PROPID_WITH_ROTOR_INERTIA && rotor_inertia > 0.0f)) { /* compiled out */
            PROPID_BAD("rotor_inertia");
        }
    }
    if (!propid_aero_damping_valid(config)) {
        PROPID_BAD("aero_damping");
    }
    if (config->disturbance_torque > (PROPID_WITH_DISTURBANCE ? 1u : 0u)) {
        PROPID_BAD("disturbance_torque");
    }
#if PROPID_WITH_DISTURBANCE /* (compiled out: disturbance_torque 0 only, checked above) */
    if (config->disturbance_torque) {
        if (!positive_finite(config->disturbance_std0) || config->disturbance_std0 > 1.0e4f) {
            PROPID_BAD("disturbance_std0");
        }
        if (!isfinite(config->disturbance_walk) || config->disturbance_walk < 0.0f) {
            PROPID_BAD("disturbance_walk");
        }
        /* Below the gyro's Nyquist frequency: above it the states would take every sample. */
        if (!isfinite(config->disturbance_bandwidth) || config->disturbance_bandwidth < 0.0f ||
            config->disturbance_bandwidth >= 0.5f * config->gyro_sample_rate_hz) {
            PROPID_BAD("disturbance_bandwidth");
        }
    }
#endif
    if (!isfinite(config->mass) || config->mass < 0.0f || config->mass > 1.0e4f ||
        (!PROPID_WITH_ACCEL && config->mass > 0.0f)) { /* compiled out */
        PROPID_BAD("mass");
    }
#if PROPID_WITH_ACCEL /* (compiled out: mass 0 only, checked above; then no torque scale either) */
    if (config->mass > 0.0f) {
        if (!positive_finite(config->accel_noise_std) || config->accel_noise_std > 1.0e3f) {
            PROPID_BAD("accel_noise_std");
        }
        if (!positive_finite(config->accel_bias_std0) || config->accel_bias_std0 > 1.0e3f) {
            PROPID_BAD("accel_bias_std0");
        }
        if (!isfinite(config->accel_bias_walk) || config->accel_bias_walk < 0.0f) {
            PROPID_BAD("accel_bias_walk");
        }
        if (!positive_finite(config->accel_range) || config->accel_range > 1.0e4f) {
            PROPID_BAD("accel_range");
        }
    }
    if (!isfinite(config->accel_error_std) || config->accel_error_std < 0.0f || config->accel_error_std > 1.0e3f ||
        (config->accel_error_std > 0.0f && !(config->mass > 0.0f))) {
        PROPID_BAD("accel_error_std"); /* the row's error needs the row */
    }
    if (config->accel_error_std > 0.0f &&
        (!positive_finite(config->accel_error_time) || config->accel_error_time > 1.0e6f)) {
        PROPID_BAD("accel_error_time");
    }
    if (config->torque_scale > 1u || (config->torque_scale && !(config->mass > 0.0f))) {
        PROPID_BAD("torque_scale"); /* only the accelerometer makes it observable */
    }
    if (config->torque_scale && (!positive_finite(config->torque_scale_std0) || config->torque_scale_std0 > 10.0f)) {
        PROPID_BAD("torque_scale_std0");
    }
    if (config->torque_scale &&
        (!isfinite(config->torque_scale_walk) || config->torque_scale_walk < 0.0f || config->torque_scale_walk > 10.0f)) {
        PROPID_BAD("torque_scale_walk");
    }
#else
    if (config->torque_scale != 0u) {
        PROPID_BAD("torque_scale"); /* only the accelerometer makes it observable */
    }
    if (config->accel_error_std != 0.0f) {
        PROPID_BAD("accel_error_std"); /* compiled out with the accelerometer */
    }
#endif
    if (!propid_delay_config_ok(config)) {
        PROPID_BAD("rotor_delay_us"); /* beyond 1 s or what PROPID_DELAY_SLOTS holds */
    }
    /* Compiled out, only 0 (off) is accepted; a rotor-speed error beyond the
     * largest speed is not a measurement. */
    if (!isfinite(config->rotor_speed_noise) || config->rotor_speed_noise < 0.0f ||
        config->rotor_speed_noise > config->max_rotor_speed ||
        (!PROPID_WITH_INPUT_NOISE && config->rotor_speed_noise != 0.0f)) {
        PROPID_BAD("rotor_speed_noise");
    }
    if (!isfinite(config->rotor_speed_noise_time) || config->rotor_speed_noise_time < 0.0f ||
        config->rotor_speed_noise_time > PROPID_ROTOR_SPEED_NOISE_TIME_MAX) {
        PROPID_BAD("rotor_speed_noise_time");
    }
    if (!isfinite(config->rotor_timing_error) || config->rotor_timing_error < 0.0f ||
        config->rotor_timing_error > PROPID_ROTOR_TIMING_ERROR_MAX ||
        (!PROPID_WITH_INPUT_NOISE && config->rotor_timing_error != 0.0f)) {
        PROPID_BAD("rotor_timing_error"); /* compiled out with the input error: only 0 */
    }
    /* The compensation removes the part of the update an error of the configured
     * size explains: without a size there is nothing to remove. */
    if (config->input_error_compensation > 1u ||
        (config->input_error_compensation && !(config->rotor_speed_noise > 0.0f))) {
        PROPID_BAD("input_error_compensation");
    }
    /* The hold sets the time of an error of the configured size: nothing without one.
     * The compensation's memory is per axis with one time for all rotors. */
    if (config->rotor_speed_noise_hold > 2u ||
        (config->rotor_speed_noise_hold && (!(config->rotor_speed_noise > 0.0f) || config->input_error_compensation))) {
        PROPID_BAD("rotor_speed_noise_hold");
    }
    /* The split divides an error of the configured size; the compensation assumes
     * independent errors. */
    if (config->rotor_speed_noise_split > 1u ||
        (config->rotor_speed_noise_split && (!(config->rotor_speed_noise > 0.0f) || config->input_error_compensation))) {
        PROPID_BAD("rotor_speed_noise_split");
    }

    /* The commands' first stage (propid_instrument.c): compiled out, only 0. A lag
     * or memory is needed only with it on; off, any finite non-negative value. */
    if (config->motor_command_instrument > 1u || (config->motor_command_instrument && !PROPID_WITH_INSTRUMENT)) {
        PROPID_BAD("motor_command_instrument");
    }
    if (!isfinite(config->motor_command_lag) || config->motor_command_lag < 0.0f || config->motor_command_lag > 1.0f ||
        (config->motor_command_instrument && !(config->motor_command_lag >= 1.0e-4f))) {
        PROPID_BAD("motor_command_lag");
    }
    if (!isfinite(config->motor_command_memory) || config->motor_command_memory < 0.0f ||
        config->motor_command_memory > 1.0e4f || (config->motor_command_instrument && !(config->motor_command_memory >= 0.01f))) {
        PROPID_BAD("motor_command_memory");
    }
    if (!isfinite(config->motor_command_min_f) || config->motor_command_min_f < 0.0f ||
        config->motor_command_min_f > 1.0e6f) {
        PROPID_BAD("motor_command_min_f");
    }
    /* One reading is no repeat: 1 would refuse every sample after the first. */
    if (config->gyro_stuck_samples == 1u || (config->gyro_stuck_samples != 0u && !PROPID_WITH_GYRO_STUCK_CHECK)) {
        PROPID_BAD("gyro_stuck_samples");
    }

#if PROPID_WITH_INPUT_NOISE
    /* Var(Omega^2) = (2 Omega sigma)^2 = input_noise_var Omega^2 (docs/math.md §14). */
    out.input_noise_var = 4.0f * config->rotor_speed_noise * config->rotor_speed_noise;
    if (config->rotor_speed_noise_split) {
        out.input_noise_var *= 0.25f; /* the spread's (q^2 / 12 of q^2 / 3); the mean's 3x that */
    }
    out.input_noise_split = config->rotor_speed_noise_split;
    out.input_noise_time = config->rotor_speed_noise_time;
    out.input_compensation = config->input_error_compensation;
    out.input_noise_hold = config->rotor_speed_noise_hold;
    out.input_timing_error = config->rotor_timing_error;
#endif
#if PROPID_WITH_INPUT_NOISE || PROPID_WITH_GYRO_STUCK_CHECK
    out.rare_gyro_update = (uint8_t)((PROPID_WITH_INPUT_NOISE && config->input_error_compensation) ||
                                     (PROPID_WITH_GYRO_STUCK_CHECK && config->gyro_stuck_samples != 0u));
#endif
    out.layout.rate = 0u;
    out.layout.thrust = propid_first_thrust();
    out.layout.drag = propid_first_drag(rotor_count);
    out.layout.gyro_bias = propid_first_bias(rotor_count);
    uint8_t next = (uint8_t)(out.layout.gyro_bias + PROPID_BIAS_STATES);
    out.layout.disturbance = PROPID_NO_STATE;
    out.layout.accel_bias = PROPID_NO_STATE;
    out.layout.torque_scale = PROPID_NO_STATE;
    /* (PROPID_WITH_*: a compiled-out block's code is left out, its value is 0.) */
    if (PROPID_WITH_DISTURBANCE && config->disturbance_torque) {
        out.layout.disturbance = next;
        next = (uint8_t)(next + PROPID_DISTURBANCE_STATES);
    }
#if PROPID_WITH_ACCEL
    out.accel_error = PROPID_NO_STATE;
#endif
    if (PROPID_WITH_ACCEL && config->mass > 0.0f) {
        out.layout.accel_bias = next;
        next = (uint8_t)(next + PROPID_ACCEL_BIAS_STATES);
#if PROPID_WITH_ACCEL
        if (config->accel_error_std > 0.0f) { /* right after the bias (propid_setup.c checks it) */
            out.accel_error = next;
            out.accel_error_rate = 1.0f / config->accel_error_time;
            next = (uint8_t)(next + PROPID_ACCEL_ERROR_STATES);
        }
        out.accel_var = config->accel_noise_std * config->accel_noise_std;
        for (uint8_t i = 0; i < rotor_count; ++i) {
            out.thrust_per_mass[i] = config->rotor[i].thrust_coeff_nominal / config->mass;
        }
#endif
    }
    if (PROPID_WITH_ACCEL && config->torque_scale) {
        out.layout.torque_scale = next;
        next = (uint8_t)(next + PROPID_TORQUE_SCALE_STATES);
    }
    if (next > PROPID_MAX_STATES) {
        PROPID_BAD("accel_error_std"); /* the one block PROPID_MAX_STATES does not count (propid_config.h) */
    }
    out.state_count = next;
#if PROPID_WITH_ROTOR_INERTIA
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const float rotor_inertia = config->rotor_inertia[i];
        if (rotor_inertia > 0.0f) {
            out.rotor_inertia_on = 1u;
        }
        out.rotor_momentum[i] = config->rotor[i].yaw_sign * rotor_inertia;
        for (uint8_t a = 0; a < 3u; ++a) {
            out.rotor_reaction[i][a] = geo.inertia_inv[a][2] * out.rotor_momentum[i];
        }
    }
    /* Rotor angular momentum h z_B with h = -sum_i yaw_sign_i J_r,i Omega_i (a rotor
     * spins opposite to the yaw torque its drag puts on the body): the body torque
     * -omega x (h z) = sum_i yaw_sign_i J_r,i Omega_i (omega_y, -omega_x, 0). */
    for (uint8_t a = 0; a < 3u; ++a) {
        out.rotor_gyro[a][0] = out.rotor_inertia_on ? -geo.inertia_inv[a][1] : 0.0f;
        out.rotor_gyro[a][1] = out.rotor_inertia_on ? geo.inertia_inv[a][0] : 0.0f;
    }
#endif
#if PROPID_WITH_AERO_DAMPING
    if (!propid_aero_damping_derive(config, (const float (*)[3])geo.inertia_inv, &out)) {
        PROPID_BAD("aero_damping");
    }
#endif
    for (uint8_t i = 0; i < rotor_count; ++i) {
        const propid_rotor_config_t *rotor = &config->rotor[i];
        /* r x z = (r_y, -r_x, 0) */
        const float arm_torque[3] = {rotor->position_m[1], -rotor->position_m[0], 0.0f};
        for (uint8_t a = 0; a < 3u; ++a) {
            geo.thrust_torque[i][a] =
                (geo.inertia_inv[a][0] * arm_torque[0] + geo.inertia_inv[a][1] * arm_torque[1]) *
                rotor->thrust_coeff_nominal;
            geo.drag_torque[i][a] =
                geo.inertia_inv[a][2] * rotor->yaw_sign * rotor->drag_coeff_nominal;
        }
    }
    if (!all_finite(&geo.thrust_torque[0][0], 3u * PROPID_MAX_ROTORS) ||
        !all_finite(&geo.drag_torque[0][0], 3u * PROPID_MAX_ROTORS)) {
        PROPID_BAD("inertia");
    }

    flush_residues(&geo.thrust_torque[0][0], 3u * PROPID_MAX_ROTORS);
    flush_residues(&geo.drag_torque[0][0], 3u * PROPID_MAX_ROTORS);
#if PROPID_GENERAL_VEHICLES
    derive_drag_basis(config, &out);
#endif
    derive_thrust_basis(config, &geo, &out);
    derive_gyro_jacobian(config, &geo);
#if PROPID_GENERAL_VEHICLES
    derive_sparsity(config, &geo, &out);
    memcpy(out.inertia_inv, geo.inertia_inv, sizeof(out.inertia_inv));
    memcpy(out.thrust_torque, geo.thrust_torque, sizeof(out.thrust_torque));
    memcpy(out.drag_torque, geo.drag_torque, sizeof(out.drag_torque));
    memcpy(out.gyro_jacobian, geo.gyro_jacobian, sizeof(out.gyro_jacobian));
#endif
    derive_quad_layout(config, &geo, &out);
#if !PROPID_GENERAL_VEHICLES
    if (!out.quad_layout) {
        PROPID_BAD("inertia"); /* not the quad layout's structure: this build's kernels cannot run it */
    }
#endif
    out.quad_core = (uint8_t)(rotor_count == 4u && out.state_count == PROPID_QUAD_STATES);

    out.gyro_var = config->gyro_noise_density * config->gyro_noise_density *
                   config->gyro_sample_rate_hz;
    /* (A huge noise is allowed: it only makes the measurement weightless,
     * which probes of the prediction use.) */
    if (!positive_finite(out.gyro_var) || out.gyro_var < 1.0e-20f || out.gyro_var > 1.0e20f) {
        PROPID_BAD("gyro_noise_density");
    }
    /* A gyro sample measures omega + b with variance R: after it, 1 - rho^2 of
     * omega and b is ~R / min(P_omega, P_b), which float32 holds only while
     * it is well above epsilon. A bias prior (or a bias walk over the longest
     * gap) above R / (64 epsilon) leaves a covariance that is not positive
     * definite. (The rate prior needs no such bound: the update loading,
     * propid_internal.h, covers a large P_omega.) */
    const float bias_var_max = out.gyro_var * (1.0f / PROPID_UPDATE_LOADING);
    if (config->gyro_bias_std0 * config->gyro_bias_std0 > bias_var_max) {
        PROPID_BAD("gyro_bias_std0");
    }
    if (config->gyro_bias_walk * config->gyro_bias_walk * ((float)config->max_gyro_gap_us * 1.0e-6f) >
        bias_var_max) {
        PROPID_BAD("gyro_bias_walk");
    }
    if (config->gate_sigma > 0.0f) {
        out.gate_sq = config->gate_sigma * config->gate_sigma;
        out.inv_gate_sq = 1.0f / out.gate_sq;
    } else {
        out.gate_sq = PROPID_GATE_OFF_SQ;
        out.inv_gate_sq = 1.0f;
    }
#if PROPID_GENERAL_VEHICLES
    out.rate_limit = 2.0f * config->gyro_range;
#endif
    /* In 100 us units: a 16-bit field in the padding after the layout. */
    out.motor_tau_100us = (uint16_t)(config->motor_time_constant * 1.0e4f + 0.5f);
    {
        /* S range of the quad's fast update path: [R, R + R / loading]; above
         * it the general path loads R (propid_internal.h). */
        const float s_max = out.gyro_var + out.gyro_var * (1.0f / PROPID_UPDATE_LOADING);
        uint32_t low_bits;
        uint32_t high_bits;
        memcpy(&low_bits, &out.gyro_var, sizeof(low_bits));
        memcpy(&high_bits, &s_max, sizeof(high_bits));
        out.innovation_range_bits = high_bits - low_bits;
    }
    {
        /* A claim bounds the error at PROPID_CLAIM_SIGMAS std of everything the
         * error holds: the filter's variance plus the configured inertia's scale,
         * which the data cannot see (kf's claim adds it back when the torque-scale
         * state takes it and the accelerometer sets kf: propid_estimate.c).
         * Negative: never claimed. */
        const float inertia_var = config->inertia_rel_std * config->inertia_rel_std;
        out.claim_var = config->converged_rel_std * config->converged_rel_std *
                            (1.0f / (PROPID_CLAIM_SIGMAS * PROPID_CLAIM_SIGMAS)) - inertia_var;
    }

    /* Per-state prior, process noise, floor and ceiling (reasons in docs/design.md). */
    const uint8_t first_drag = propid_first_drag(rotor_count);
    const uint8_t first_bias = propid_first_bias(rotor_count);
    const float coeff_ceiling = config->coeff_rel_max * config->coeff_rel_max;
    for (uint8_t k = 0; k < out.state_count; ++k) {
        float prior;
        float psd;
        float floor_var;
        float ceiling;
        uint8_t kind;
        if (k < PROPID_RATE_STATES) {
            kind = PROPID_KIND_RATE;
            prior = config->rate_std0 * config->rate_std0;
            psd = config->rate_process_noise * config->rate_process_noise;
            floor_var = PROPID_FLOOR_RATE;
            ceiling = 4.0f * config->gyro_range * config->gyro_range;
        } else if (k < first_drag) {
            kind = PROPID_KIND_THRUST;
            prior = config->thrust_coeff_rel_std0 * config->thrust_coeff_rel_std0;
            psd = config->thrust_coeff_rel_walk * config->thrust_coeff_rel_walk;
            floor_var = PROPID_FLOOR_THRUST; /* (far below the drag's: propid_internal.h) */
            ceiling = coeff_ceiling;
        } else if (k < first_bias) {
            kind = PROPID_KIND_DRAG;
            prior = config->drag_coeff_rel_std0 * config->drag_coeff_rel_std0;
            psd = config->drag_coeff_rel_walk * config->drag_coeff_rel_walk;
            floor_var = PROPID_FLOOR_DRAG;
            ceiling = coeff_ceiling;
        } else if (k < first_bias + PROPID_BIAS_STATES) {
            kind = PROPID_KIND_BIAS;
            prior = config->gyro_bias_std0 * config->gyro_bias_std0;
            psd = config->gyro_bias_walk * config->gyro_bias_walk;
            floor_var = PROPID_FLOOR_BIAS;
            ceiling = config->gyro_range * config->gyro_range;
        } else if (PROPID_WITH_ACCEL && k == out.layout.accel_bias) {
            kind = PROPID_KIND_ACCEL_BIAS;
            prior = config->accel_bias_std0 * config->accel_bias_std0;
            psd = config->accel_bias_walk * config->accel_bias_walk;
            floor_var = 1.0e-12f;
            ceiling = config->accel_range * config->accel_range;
#if PROPID_WITH_ACCEL
        } else if (k == out.accel_error) {
            /* First-order Gauss-Markov: stationary variance sigma^2 held by a walk of
             * 2 sigma^2 / tau against the decay exp(-dt / tau) (propid_predict.c). */
            kind = PROPID_KIND_ACCEL_ERROR;
            prior = config->accel_error_std * config->accel_error_std;
            psd = 2.0f * prior * out.accel_error_rate;
            floor_var = 1.0e-12f;
            ceiling = 100.0f * prior;
#endif
        } else if (PROPID_WITH_ACCEL && k == out.layout.torque_scale) {
            kind = PROPID_KIND_TORQUE_SCALE;
            prior = config->torque_scale_std0 * config->torque_scale_std0;
            psd = config->torque_scale_walk * config->torque_scale_walk; /* 0: geometry and inertia only */
            floor_var = 1.0e-10f;
            ceiling = coeff_ceiling;
        } else { /* disturbance */
            kind = PROPID_KIND_DISTURBANCE;
            prior = config->disturbance_std0 * config->disturbance_std0;
            psd = config->disturbance_walk * config->disturbance_walk;
            if (config->disturbance_bandwidth > 0.0f) {
                /* Equal to the unmodelled acceleration's density at the bandwidth (§7). */
                const float walk = PROPID_TWO_PI * config->disturbance_bandwidth * config->rate_process_noise;
                psd = walk * walk;
            }
            floor_var = 1.0e-12f;
            ceiling = 100.0f * prior;
        }
        if (ceiling < prior) {
            ceiling = prior;
        }
        /* The process noise of one step across the longest allowed gap must stay
         * below the variance ceiling: larger is not a model but a repair on
         * every sample. */
        const float max_gap_s = (float)config->max_gyro_gap_us * 1.0e-6f;
#if PROPID_WITH_ACCEL
        if (k == out.accel_error && max_gap_s > config->accel_error_time) {
            PROPID_BAD("accel_error_time"); /* shorter than a gyro gap: not a process the step can follow */
        }
#endif
        if (psd * max_gap_s > ceiling) {
            PROPID_BAD(k < PROPID_RATE_STATES ? "rate_process_noise"
                                              : (k < first_drag ? "thrust_coeff_rel_walk"
                                                                : (k < first_bias ? "drag_coeff_rel_walk"
                                                                                  : process_noise_name(&out.layout, config, k))));
        }
        if (k < PROPID_RATE_STATES) {
            /* An update computes the new variance as P - P^2 / S, exact only to
             * ~epsilon P in float32. Every element of the rate rows then carries
             * rounding of ~epsilon P_omega, and the next axis' update (after
             * the first made it nearly certain through a correlation of ~1)
             * sees it as part of its S: the rate variance is kept below
             * R / (64 epsilon), so that rounding stays below R / 64 for every
             * update of the sample. Applied before an update that finds S
             * beyond it and after every update. The rate prior is held at the
             * same bound: it only weighs the anchoring sample, whose innovation
             * is zero (fuzz finding: a prior of 1e10 let one prediction inflate
             * the rate variance 1e7-fold, and P lost definiteness). */
            const float rate_var_max = out.gyro_var * (1.0f / PROPID_UPDATE_LOADING);
            ceiling = 4.0f * config->gyro_range * config->gyro_range;
            if (ceiling > rate_var_max) {
                ceiling = rate_var_max;
            }
            if (ceiling < floor_var) {
                ceiling = floor_var;
            }
            if (prior > ceiling) {
                prior = ceiling;
            }
        }
        if (!positive_finite(prior) || prior < floor_var) {
            const char *optional_name = k == out.layout.torque_scale ? "torque_scale_std0" : "disturbance_std0";
#if PROPID_WITH_ACCEL
            if (k == out.accel_error) {
                optional_name = "accel_error_std";
            }
#endif
            PROPID_BAD(k < PROPID_RATE_STATES ? "rate_std0"
                       : k < first_drag ? "thrust_coeff_rel_std0"
                       : k < first_bias ? "drag_coeff_rel_std0"
                       : k < first_bias + PROPID_BIAS_STATES ? "gyro_bias_std0"
                       : k == out.layout.accel_bias ? "accel_bias_std0" : optional_name);
        }
        /* (A kind's values do not depend on k: the last write is the first's.) */
#if PROPID_GENERAL_VEHICLES
        out.state_kind[k] = kind;
#endif
        out.kind_prior_var[kind] = prior;
        out.kind_process_psd[kind] = psd;
        /* Both positive and finite, floor <= ceiling: their bit patterns are ordered. */
        uint32_t floor_bits;
        uint32_t ceiling_bits;
        memcpy(&floor_bits, &floor_var, sizeof(floor_bits));
        memcpy(&ceiling_bits, &ceiling, sizeof(ceiling_bits));
        out.kind_floor_bits[kind] = floor_bits;
        out.kind_range_bits[kind] = ceiling_bits - floor_bits;
    }

    if (derived != NULL) {
        *derived = out;
    }
    return PROPID_OK;
}

void propid_config_keep(const propid_config_t *config, propid_kept_config_t *kept)
{
#if PROPID_GENERAL_VEHICLES
    *kept = *config;
#else
    memset(kept, 0, sizeof(*kept));
    kept->rotor_count = config->rotor_count;
    kept->yaw_sign_flips = 0u;
    for (uint8_t i = 0; i < config->rotor_count && i < PROPID_MAX_ROTORS; ++i) {
        if (config->rotor[i].yaw_sign != config->rotor[0].yaw_sign) {
            kept->yaw_sign_flips = (uint8_t)(kept->yaw_sign_flips | (1u << i));
        }
    }
    kept->gate_max_consecutive = config->gate_max_consecutive;
#if PROPID_DELAY_SLOTS > 0
    kept->rotor_delay_us = config->rotor_delay_us;
#endif
    kept->rotor_stale_us = config->rotor_stale_us;
    kept->max_gyro_gap_us = config->max_gyro_gap_us;
    kept->max_rotor_speed = config->max_rotor_speed;
    kept->gyro_range = config->gyro_range;
    kept->coeff_rel_min = config->coeff_rel_min;
    kept->coeff_rel_max = config->coeff_rel_max;
    for (uint8_t i = 0; i < PROPID_MAX_ROTORS; ++i) {
        kept->rotor[i].thrust_coeff_nominal = config->rotor[i].thrust_coeff_nominal;
        kept->rotor[i].drag_coeff_nominal = config->rotor[i].drag_coeff_nominal;
    }
#endif
}

propid_status_t propid_config_check(const propid_config_t *config, const char **bad_field)
{
    if (bad_field != NULL) {
        *bad_field = NULL;
    }
    return propid_config_derive(config, NULL, bad_field);
}
