/*
 * The physics step chosen by an accuracy rule (docs/sitl.md "The physics
 * step"): the plant's fastest dynamics are the motors' first-order lag (time
 * constant tau_m) and, for the attitude, the body rate itself. Classic RK4 on
 * dOmega/dt = (c - Omega)/tau_m leaves a global rotor-speed error of
 * |c - Omega| (h/tau_m)^4 / 120, so h <= tau_m / 10 keeps it below 8.4e-7 of
 * the speed range; h <= 0.1 / w_max does the same for the attitude at the
 * fastest body rate a multirotor flies (2000 deg/s).
 */
#ifndef SITL_PHYSICS_RATE_H
#define SITL_PHYSICS_RATE_H

/* Largest step over the motor time constant, and over 1 / (fastest body rate). */
#define SITL_PHYSICS_STEP_PER_TIME_CONSTANT 0.1
/* The fastest body rate the rule provides for [rad/s] (2000 deg/s). */
#define SITL_PHYSICS_FASTEST_BODY_RATE 34.906585039886591

/* The rule's physics rate [Hz]: the smallest whole multiple of the control
 * rate whose step meets both bounds (so every control instant is a physics
 * step boundary). 0 if an argument is not positive and finite. */
double sitl_physics_rate_for(double motor_time_constant_s, double control_rate_hz);

#endif /* SITL_PHYSICS_RATE_H */
