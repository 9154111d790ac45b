/*
 * Effects that change the true body once, at plant set-up:
 *   com_offset     the centre of mass sits d = s * arm * (0.6, 0.8, -0.5) away
 *                  from the geometric centre the vehicle file describes (below
 *                  the rotor plane and off to one side, like a battery pack
 *                  strapped off-centre). Hubs relative to the true CoM are r_i - d.
 *   inertia_error  the true inertia is the file's times (1 + s) on every element
 *                  (an inertia estimated from CAD without wiring and battery).
 */
#include <math.h>

#include "effects_physics.h"

void sitl_effects_setup_body(sitl_plant_t *plant)
{
    double s = sitl_effect_strength(&plant->effects, SITL_EFFECT_COM_OFFSET);
    if (s != 0.0) {
        const double direction[3] = {0.6, 0.8, -0.5};
        for (int i = 0; i < plant->rotor_count; i++) {
            for (int k = 0; k < 3; k++) {
                plant->rotor_position[i][k] -= s * plant->vehicle.arm_length * direction[k];
            }
        }
    }
    double e = sitl_effect_strength(&plant->effects, SITL_EFFECT_INERTIA_ERROR);
    if (e != 0.0 && 1.0 + e > 0.0) {
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) {
                plant->inertia[i][j] *= 1.0 + e;
            }
        }
    }
}
