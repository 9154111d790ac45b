/*
 * Motor + ESC speed loop as a first-order lag with speed limits:
 *   dOmega/dt = (clamp(command, min, max) - Omega) / tau
 * (the MEAM 620 / RotorPy motor model). The rotor speed is part of the
 * integrated plant state so its derivative is exact inside RK4 (the
 * rotor_inertia effect needs dOmega/dt).
 */
#ifndef SITL_MOTOR_H
#define SITL_MOTOR_H

typedef struct {
    double time_constant;   /* tau [s] */
    double speed_min;       /* [rad/s] */
    double speed_max;       /* [rad/s] */
} sitl_motor_t;

/* dOmega/dt for a speed command. */
double sitl_motor_acceleration(const sitl_motor_t *motor, double command, double speed);

/* Keep a speed inside the limits (after an integration step). */
double sitl_motor_clamp(const sitl_motor_t *motor, double speed);

#endif /* SITL_MOTOR_H */
