/*
 * Reference trajectories of the paper's experiment (Folk & Spinos, section 4.4)
 * as differentially flat outputs: position and yaw with their ANALYTIC time
 * derivatives (velocity, acceleration, jerk, snap; yaw rate, yaw acceleration),
 * which the SE(3) controller uses for its feed-forward.
 *
 * World frame ENU-like: z up. Every trajectory starts at `origin` (the position
 * passed to sitl_trajectory_init) at t = 0 and is defined for every t (after
 * one period T it keeps following its formula). The period T is a parameter of
 * the trajectory (the paper's T = 10 s), independent of how long the SITL flies:
 * a 2 s flight flies the first fifth of the same 10 s trajectory, not a
 * trajectory five times faster.
 *
 * Kinds:
 *   hover      constant position origin, yaw 0.
 *   step       origin up to and including step_time_s, then
 *              origin + step_amplitude_m * x: a genuine position step (all
 *              derivatives zero), no yaw. The default step_time_s = 0 steps
 *              right after the start.
 *   circle     horizontal circle of radius circle_radius_m through origin,
 *              circle_cycles turns (counter-clockwise) per period T, origin
 *              at angle circle_start_angle_rad on the circle:
 *                x = R (cos(phi + w t) - cos phi), y = R (sin(phi + w t) - sin phi);
 *              yaw back-and-forth
 *              yaw_amplitude_rad * sin(2 pi yaw_cycles t / T).
 *   lissajous  the compound Lissajous of the paper's equation 9: the sum of a
 *              large slow and a small fast Lissajous, each axis
 *                x = A_x (1 - cos(2 pi n_x t / T)),  y = A_y sin(2 pi n_y t / T),
 *                z = A_z sin(2 pi n_z t / T),
 *              plus yaw A_psi sin(2 pi n_psi t / T), T = period_s.
 *
 * sitl_trajectory_init() fills documented defaults for a Crazyflie-class
 * vehicle (docs/results.md explains the choice); the parameter fields are
 * public, so a caller may change them after init.
 */
#ifndef SITL_TRAJECTORY_H
#define SITL_TRAJECTORY_H

/* A new kind: a value here (before the count), its parameters in
 * sitl_trajectory_t, defaults in sitl_trajectory_init(), an eval function and
 * a registry row in trajectory.c (docs/sitl.md "Adding a trajectory"). */
typedef enum {
    SITL_TRAJ_HOVER = 0,
    SITL_TRAJ_STEP = 1,
    SITL_TRAJ_CIRCLE = 2,
    SITL_TRAJ_LISSAJOUS = 3,
    SITL_TRAJ_KIND_COUNT
} sitl_trajectory_kind_t;

/* The paper's trajectory period T [s]. */
#define SITL_TRAJ_DEFAULT_PERIOD_S 10.0

/* One Lissajous component of equation 9 (amplitudes in m, cycles per period T). */
typedef struct {
    double amplitude_m[3];   /* A_x, A_y, A_z */
    double cycles[3];        /* n_x, n_y, n_z */
} sitl_lissajous_part_t;

typedef struct {
    sitl_trajectory_kind_t kind;
    double period_s;         /* T [s] */
    double origin[3];        /* position at t = 0 [m] */

    /* step */
    double step_time_s;
    double step_amplitude_m;

    /* circle */
    double circle_radius_m;
    double circle_cycles;
    double circle_start_angle_rad; /* phi: where on the circle the origin lies */

    /* lissajous: large slow part + small fast part */
    sitl_lissajous_part_t lissajous_slow;
    sitl_lissajous_part_t lissajous_fast;

    /* yaw (circle and lissajous): A_psi sin(2 pi n_psi t / T) */
    double yaw_amplitude_rad;
    double yaw_cycles;
} sitl_trajectory_t;

/* Flat outputs and their derivatives at one time. */
typedef struct {
    double position[3];      /* [m] */
    double velocity[3];      /* [m/s] */
    double acceleration[3];  /* [m/s^2] */
    double jerk[3];          /* [m/s^3] */
    double snap[3];          /* [m/s^4] */
    double yaw;              /* [rad] */
    double yaw_rate;         /* [rad/s] */
    double yaw_acceleration; /* [rad/s^2] */
} sitl_flat_output_t;

/* One registry row: the --trajectory name, whether the yaw swing
 * (yaw_amplitude_rad, yaw_cycles) applies, and the flat outputs relative to
 * the origin (flat arrives zeroed; t >= 0). */
typedef struct {
    const char *name;
    int yaws;
    void (*eval)(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat);
} sitl_trajectory_info_t;

/* The registry row of kind, or NULL when out of range. */
const sitl_trajectory_info_t *sitl_trajectory_info(sitl_trajectory_kind_t kind);

/* Every registered name joined by separator (for help and error messages). */
void sitl_trajectory_names(char *out, int out_size, const char *separator);

/* Fill traj with the defaults of kind and period T = period_s (the paper's
 * trajectories use SITL_TRAJ_DEFAULT_PERIOD_S). origin may be NULL (= 0,0,0).
 * Returns 0, or -1 for an unknown kind or a non-positive/non-finite period. */
int sitl_trajectory_init(sitl_trajectory_t *traj, sitl_trajectory_kind_t kind,
                         double period_s, const double origin[3]);

/* Evaluate the flat outputs at time t [s] (any t; t < 0 is treated as 0). */
void sitl_trajectory_eval(const sitl_trajectory_t *traj, double t, sitl_flat_output_t *flat);

/* Registered name -> kind. Returns 0, or -1 if unknown. */
int sitl_trajectory_from_name(const char *name, sitl_trajectory_kind_t *kind);

/* kind -> its name ("?" when out of range). */
const char *sitl_trajectory_name(sitl_trajectory_kind_t kind);

#endif /* SITL_TRAJECTORY_H */
