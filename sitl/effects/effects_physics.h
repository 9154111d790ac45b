/*
 * Internal: the hooks through which the physical effects enter the plant
 * (plant.c calls them; each is a no-op when its effects are off).
 */
#ifndef SITL_EFFECTS_PHYSICS_H
#define SITL_EFFECTS_PHYSICS_H

#include "plant.h"

/* effects_setup.c: com_offset and inertia_error change the true body once. */
void sitl_effects_setup_body(sitl_plant_t *plant);

/* effects_thrust.c: thrust [N] and |drag torque| [N m] of rotor i, starting
 * from the quadratic law with the true coefficients and applying
 * thrust_nonlinearity, translational_lift and ground_effect. */
void sitl_effects_rotor_loads(const sitl_plant_t *plant, const sitl_state_t *state,
                              const double velocity_body[3], int rotor, double *thrust,
                              double *drag_torque);

/* effects_rotor.c: extra body force and torque from rotor_inertia,
 * rotor_gyroscopic, rotor_drag (with blade flapping) and aero_damping. */
void sitl_effects_rotor_wrench(const sitl_plant_t *plant, const sitl_state_t *state,
                               const double velocity_body[3], const double *rotor_accel,
                               double force_body[3], double torque_body[3]);

/* aero_damping's force and torque (position x force) of one rotor at `position`
 * spinning at rotor_speed while the body turns at body_rate (effects_rotor.c). */
void sitl_aero_damping_rotor(const sitl_vehicle_t *vehicle, const double position[3], double rotor_speed,
                             const double body_rate[3], double strength, double force[3], double torque[3]);

#endif /* SITL_EFFECTS_PHYSICS_H */
