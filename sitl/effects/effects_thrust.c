/*
 * Thrust-side effects on each rotor (docs/sitl.md has the sources):
 *   thrust_nonlinearity  T = kf w^2 (w / w_ref)^s, Q = km w^2 (w / w_ref)^s,
 *                        w_ref = nominal hover speed: equal at hover, stronger
 *                        above it for s > 0 (low-Reynolds-number props).
 *   translational_lift   T += s * k_h * (u^2 + v^2), with u, v the rotor's
 *                        in-plane airspeed (body-frame velocity, no wind).
 *   ground_effect        T *= 1 + s * (1 / (1 - (R / 4h)^2) - 1)
 *                        (Cheeseman & Bennett 1955), h = hub height above
 *                        ground, clamped to h >= R/2 where the formula ends.
 */
#include <math.h>

#include "effects_physics.h"
#include "sitl_math.h"

void sitl_effects_rotor_loads(const sitl_plant_t *plant, const sitl_state_t *state,
                              const double velocity_body[3], int rotor, double *thrust,
                              double *drag_torque)
{
    const sitl_effects_t *fx = &plant->effects;
    double w = state->rotor_speed[rotor];
    double w2 = w * w;
    double t = plant->thrust_coeff[rotor] * w2;
    double q = plant->drag_coeff[rotor] * w2;

    double s = sitl_effect_strength(fx, SITL_EFFECT_THRUST_NONLINEARITY);
    if (s != 0.0 && plant->reference_rotor_speed > 0.0) {
        double ratio = w / plant->reference_rotor_speed;
        double factor = ratio > 1e-6 ? pow(ratio, s) : 0.0;
        t *= factor;
        q *= factor;
    }

    s = sitl_effect_strength(fx, SITL_EFFECT_TRANSLATIONAL_LIFT);
    if (s != 0.0) {
        double inplane2 = velocity_body[0] * velocity_body[0] + velocity_body[1] * velocity_body[1];
        t += s * plant->vehicle.translational_lift_coeff * inplane2;
    }

    s = sitl_effect_strength(fx, SITL_EFFECT_GROUND_EFFECT);
    if (s != 0.0 && plant->vehicle.rotor_radius > 0.0) {
        double radius = plant->vehicle.rotor_radius;
        double hub_world[3];
        sitl_quat_rotate(state->quat, plant->rotor_position[rotor], hub_world);
        double h = state->position[2] + hub_world[2];
        if (h < 0.5 * radius) {
            h = 0.5 * radius;
        }
        double k = radius / (4.0 * h);
        t *= 1.0 + s * (1.0 / (1.0 - k * k) - 1.0);
    }
    *thrust = t;
    *drag_torque = q;
}
