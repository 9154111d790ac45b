/*
 * Vehicle description: what the vehicle file / catalogue says about a
 * multirotor (geometry, mass, inertia, nominal coefficients, motor limits,
 * rotor aerodynamics used by the optional effects). The simulated truth is
 * derived from it in plant.c (per-rotor coefficient spread, effects).
 *
 * Body FLU, origin at the centre of mass; rotor yaw_sign = sign of the yaw
 * torque the rotor's drag puts on the body (tau_z += yaw_sign * km * w^2).
 */
#ifndef SITL_VEHICLE_H
#define SITL_VEHICLE_H

#include "propid/propid_config.h"

#define SITL_MAX_ROTORS PROPID_MAX_ROTORS
#define SITL_NAME_MAX 64

typedef struct {
    double position[3];        /* rotor hub in body FLU [m] */
    double yaw_sign;           /* +1 or -1 */
    double thrust_coeff;       /* nominal kf [N/(rad/s)^2] */
    double drag_coeff;         /* nominal km [N m/(rad/s)^2] */
} sitl_rotor_t;

typedef struct {
    char name[SITL_NAME_MAX];
    double mass;               /* [kg] */
    double inertia[3][3];      /* [kg m^2] */
    int rotor_count;           /* 1..SITL_MAX_ROTORS */
    sitl_rotor_t rotor[SITL_MAX_ROTORS];
    double arm_length;         /* typical hub distance from the CoM [m] (effect scales) */

    /* Motor: first-order response to the speed command, speed limits. */
    double motor_time_constant;  /* [s] */
    double rotor_speed_min;      /* [rad/s] */
    double rotor_speed_max;      /* [rad/s] */

    /* Rotor properties used only by the switchable effects (docs/sitl.md). */
    double rotor_radius;         /* [m] */
    double rotor_inertia;        /* spinning parts of one rotor about its axis [kg m^2] */
    int rotor_inertia_assumed;   /* 1: rotor_inertia is the radius-scaled assumption for the effects,
                                    not the vehicle file's: the log's vehicle file leaves it null */
    double rotor_drag_coeff;     /* in-plane H-force k_d [N/(rad/s * m/s)] */
    double inflow_coeff;         /* axial inflow k_z [N/(rad/s * m/s)] */
    double translational_lift_coeff; /* k_h [N/(m/s)^2] */
    double flapping_coeff;       /* k_flap [N m/(rad/s * m/s)] */
} sitl_vehicle_t;

/* Names of the built-in presets, NULL-terminated. */
extern const char *const sitl_vehicle_preset_names[];

/* Fill v with a preset ("crazyflie-plus", "crazyflie-x", "hummingbird-plus",
 * "hummingbird-x"). Returns 0, or -1 if the name is unknown. */
int sitl_vehicle_preset(const char *name, sitl_vehicle_t *v);

/* Place rotor_count rotors evenly on a circle of radius arm, rotor 1 at angle
 * first_angle from +x, counter-clockwise seen from above, yaw signs alternating
 * +, -, +, - (an odd count leaves a net yaw imbalance the allocation handles). */
void sitl_vehicle_symmetric_rotors(sitl_vehicle_t *v, int rotor_count, double arm,
                                   double first_angle, double thrust_coeff, double drag_coeff);

/* Check a vehicle for physical sense. Returns 0, or -1 with a message in err. */
int sitl_vehicle_check(const sitl_vehicle_t *v, char *err, int err_size);

/* Load a flight-log v1 vehicle JSON file (mass, inertia, kf/km nominal must be
 * non-null). Motor and aerodynamic fields the format does not carry keep the
 * values already in v (the caller fills defaults / CLI options first).
 * Returns 0, or -1 with a one-line reason in err. */
int sitl_vehicle_load_json(const char *path, sitl_vehicle_t *v, char *err, int err_size);

/* Write v in the flight-log v1 vehicle format (nominal coefficients, geometry,
 * rotor radius and inertia) with notes. Returns 0, or -1 on an I/O error. */
int sitl_vehicle_write_json(const char *path, const sitl_vehicle_t *v, const char *notes);

#endif /* SITL_VEHICLE_H */
