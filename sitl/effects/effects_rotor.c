/*
 * Rotor effects that add body forces and torques (docs/sitl.md):
 *   rotor_inertia     reaction of accelerating the rotor: the motor torque
 *                     that spins rotor i up also pushes the body the other
 *                     way: tau_z += yaw_sign_i * J_r * dOmega_i/dt (same sign
 *                     as that rotor's drag torque; the rotor spins about
 *                     -yaw_sign_i z).
 *   rotor_gyroscopic  the rotors' angular momentum h = sum_i -yaw_sign_i J_r
 *                     Omega_i z turns with the body: tau -= w x h.
 *   rotor_drag        H-force and inflow drag of rotor i, linear in the body
 *                     velocity: F_i = -Omega_i diag(k_d, k_d, k_z) v_body, at
 *                     the hub (torque r_i x F_i), plus the blade-flapping
 *                     moment M_i = -k_flap Omega_i (z x v_body) that pitches
 *                     the nose up when flying forward.
 *   aero_damping      the same rotor drag law applied to the hub velocity due
 *                     to the body rotation (w x r_i): damps roll/pitch through
 *                     the axial inflow and yaw through the in-plane drag.
 */
#include "effects_physics.h"
#include "sitl_math.h"

static void rotor_drag_force(const sitl_vehicle_t *vehicle, double omega, const double v[3],
                             double scale, double force[3])
{
    force[0] = -scale * omega * vehicle->rotor_drag_coeff * v[0];
    force[1] = -scale * omega * vehicle->rotor_drag_coeff * v[1];
    force[2] = -scale * omega * vehicle->inflow_coeff * v[2];
}

void sitl_aero_damping_rotor(const sitl_vehicle_t *vehicle, const double position[3], double rotor_speed,
                             const double body_rate[3], double strength, double force[3], double torque[3])
{
    double v_rot[3];
    sitl_vec3_cross(v_rot, body_rate, position);
    rotor_drag_force(vehicle, rotor_speed, v_rot, strength, force);
    sitl_vec3_cross(torque, position, force);
}

void sitl_effects_rotor_wrench(const sitl_plant_t *plant, const sitl_state_t *state,
                               const double velocity_body[3], const double *rotor_accel,
                               double force_body[3], double torque_body[3])
{
    const sitl_effects_t *fx = &plant->effects;
    const double j_rotor = plant->vehicle.rotor_inertia;

    double s = sitl_effect_strength(fx, SITL_EFFECT_ROTOR_INERTIA);
    if (s != 0.0) {
        for (int i = 0; i < plant->rotor_count; i++) {
            torque_body[2] += s * plant->yaw_sign[i] * j_rotor * rotor_accel[i];
        }
    }

    s = sitl_effect_strength(fx, SITL_EFFECT_ROTOR_GYROSCOPIC);
    if (s != 0.0) {
        double h[3] = {0.0, 0.0, 0.0}, wxh[3];
        for (int i = 0; i < plant->rotor_count; i++) {
            h[2] -= s * plant->yaw_sign[i] * j_rotor * state->rotor_speed[i];
        }
        sitl_vec3_cross(wxh, state->body_rate, h);
        sitl_vec3_axpy(torque_body, -1.0, wxh);
    }

    s = sitl_effect_strength(fx, SITL_EFFECT_ROTOR_DRAG);
    if (s != 0.0) {
        for (int i = 0; i < plant->rotor_count; i++) {
            double omega = state->rotor_speed[i], f[3], m[3];
            rotor_drag_force(&plant->vehicle, omega, velocity_body, s, f);
            sitl_vec3_axpy(force_body, 1.0, f);
            sitl_vec3_cross(m, plant->rotor_position[i], f);
            sitl_vec3_axpy(torque_body, 1.0, m);
            double k = s * plant->vehicle.flapping_coeff * omega;
            torque_body[0] += k * velocity_body[1];  /* -(z x v)_x = v_y */
            torque_body[1] -= k * velocity_body[0];  /* -(z x v)_y = -v_x */
        }
    }

    s = sitl_effect_strength(fx, SITL_EFFECT_AERO_DAMPING);
    if (s != 0.0) {
        for (int i = 0; i < plant->rotor_count; i++) {
            double f[3], m[3];
            sitl_aero_damping_rotor(&plant->vehicle, plant->rotor_position[i], state->rotor_speed[i],
                                    state->body_rate, s, f, m);
            sitl_vec3_axpy(force_body, 1.0, f);
            sitl_vec3_axpy(torque_body, 1.0, m);
        }
    }
}
