/*
 * The simulated truth: rigid body (quaternion attitude body->world, world z
 * up, body FLU), N rotors with their own true kf/km and first-order motors,
 * gravity, flat ground at z = 0, and the enabled effects. Integrated with
 * classic RK4; the caller picks the step (physics rate).
 */
#ifndef SITL_PLANT_H
#define SITL_PLANT_H

#include "effects.h"
#include "motor.h"
#include "vehicle.h"

typedef struct {
    sitl_vehicle_t vehicle;      /* the description (nominal) the truth came from */
    sitl_effects_t effects;
    double gravity;              /* [m/s^2] */
    int ground_enabled;          /* flat ground at z = 0 */

    /* Truth (after effects_setup: com_offset moves the rotors, inertia_error J). */
    double mass;
    double inertia[3][3];
    double inertia_inv[3][3];
    int rotor_count;
    double rotor_position[SITL_MAX_ROTORS][3];   /* hub relative to the TRUE centre of mass */
    double yaw_sign[SITL_MAX_ROTORS];
    double thrust_coeff[SITL_MAX_ROTORS];        /* true kf */
    double drag_coeff[SITL_MAX_ROTORS];          /* true km */
    sitl_motor_t motor;
    double reference_rotor_speed;                /* nominal hover speed (thrust_nonlinearity) */
    /* A body torque from outside the model (gusts, a flexing frame) [N m], held between the
     * simulation's updates of it (sim.c, --disturbance-torque); 0: none. */
    double disturbance_torque[3];
} sitl_plant_t;

typedef struct {
    double position[3];          /* CoM, world [m] */
    double velocity[3];          /* world [m/s] */
    double quat[4];              /* body -> world (w, x, y, z) */
    double body_rate[3];         /* body [rad/s] */
    double rotor_speed[SITL_MAX_ROTORS]; /* [rad/s] */
    int on_ground;               /* resting on the ground (held by the contact) */
} sitl_state_t;

/* Loads at one instant (for the accelerometer, logs and tests). */
typedef struct {
    double thrust[SITL_MAX_ROTORS];        /* along body z [N] */
    double drag_torque[SITL_MAX_ROTORS];   /* |yaw drag torque| [N m] */
    double rotor_accel[SITL_MAX_ROTORS];   /* dOmega/dt [rad/s^2] */
    double force_body[3];                  /* all non-gravity forces, body [N] */
    double torque_body[3];                 /* all torques about the CoM, body [N m] */
    double effect_torque_body[3];          /* the part of torque_body from effects_rotor.c */
    double specific_force_body[3];         /* what an ideal accelerometer reads [m/s^2] */
} sitl_loads_t;

typedef struct {
    double position[3];
    double velocity[3];
    double quat[4];
    double body_rate[3];
    double rotor_speed[SITL_MAX_ROTORS];
} sitl_state_derivative_t;

/* Build the truth from a vehicle, true coefficients and effects.
 * Returns 0, or -1 with a message. */
int sitl_plant_init(sitl_plant_t *plant, const sitl_vehicle_t *vehicle,
                    const double *true_thrust_coeff, const double *true_drag_coeff,
                    const sitl_effects_t *effects, char *err, int err_size);

/* Time derivative and the loads behind it for constant rotor speed commands. */
void sitl_plant_derivative(const sitl_plant_t *plant, const sitl_state_t *state,
                           const double *rotor_command, sitl_state_derivative_t *deriv,
                           sitl_loads_t *loads);

/* What an ideal accelerometer reads in the body frame: the specific force of
 * sitl_plant_derivative's loads, without computing the rest. */
void sitl_plant_specific_force(const sitl_plant_t *plant, const sitl_state_t *state,
                               const double *rotor_command, double specific_force_body[3]);

/* Advance state by dt with RK4 (commands held), then normalise the quaternion,
 * clamp rotor speeds and apply the ground contact. */
void sitl_plant_step(const sitl_plant_t *plant, sitl_state_t *state, const double *rotor_command,
                     double dt);

/* What sitl_plant_step takes from the plant and the command before it
 * integrates: the command, clamped, each rotor's load coefficients (kf, its
 * lever arms times kf, yaw sign times km), the reciprocals of the motor time
 * constant and of the mass, and which derivative applies. A flight holds one
 * command for several steps (the physics rate is a multiple of the control
 * rate, and the ESC reports split steps): it prepares once per command and
 * steps with sitl_plant_step_prepared, bit for bit the state sitl_plant_step
 * gives. Prepare again after anything of the plant changes (coefficients,
 * disturbance torque) or the command does. */
typedef struct {
    double command[SITL_MAX_ROTORS];         /* as given */
    double clamped_command[SITL_MAX_ROTORS]; /* sitl_motor_clamp(command) */
    double thrust[SITL_MAX_ROTORS];          /* kf: thrust per speed^2 */
    double roll[SITL_MAX_ROTORS];            /* r_y kf: x torque per speed^2 */
    double pitch[SITL_MAX_ROTORS];           /* -r_x kf: y torque per speed^2 */
    double yaw[SITL_MAX_ROTORS];             /* yaw_sign km: z torque per speed^2 */
    double inv_time_constant, inv_mass;
    int plain;            /* no effect, no disturbance torque: the plain rigid body */
    int diagonal_inertia; /* J and J^-1 diagonal: the 3x3 products are 3 */
} sitl_plant_prepared_t;

void sitl_plant_prepare(const sitl_plant_t *plant, const double *rotor_command,
                        sitl_plant_prepared_t *prepared);

/* sitl_plant_step with the command and the plant's constants of prepared. */
void sitl_plant_step_prepared(const sitl_plant_t *plant, const sitl_plant_prepared_t *prepared,
                              sitl_state_t *state, double dt);

/* sitl_plant_step_prepared (the same end state, bit for bit), and the state at
 * t + theta dt (0 < theta < 1) from the step's own stages: classic RK4's free
 * continuous extension, third order (local error O(dt^4); the step's O(dt^5)),
 * quaternion normalised, rotor speeds clamped, on_ground of the start. For a
 * sensor sample inside a step (docs/sitl.md "The loop"): nothing of it goes back
 * into the plant. */
void sitl_plant_step_prepared_sampled(const sitl_plant_t *plant, const sitl_plant_prepared_t *prepared,
                                      sitl_state_t *state, double dt, double theta,
                                      sitl_state_t *sample);

/* Rotor speeds (true coefficients) that hold the vehicle still in the air:
 * total thrust m g, zero torque (minimum norm for N != 4). Returns 0, or -1
 * if that needs speeds outside the motor limits (speeds are then clipped). */
int sitl_plant_hover_speeds(const sitl_plant_t *plant, double *rotor_speed);

/* State hovering at position with yaw, rotors at hover speed. */
void sitl_plant_hover_state(const sitl_plant_t *plant, const double position[3], double yaw,
                            sitl_state_t *state);

#endif /* SITL_PLANT_H */
