/*
 * Control allocation: collective thrust and body moment -> rotor speeds, for
 * any rotor count 4..SITL_ALLOC_MAX_ROTORS with arbitrary geometry.
 *
 * With u_i = Omega_i^2 the wrench w = [thrust, Mx, My, Mz] is linear in u:
 *     w = A u,   column i of A = [ kf_i,  (r_i x kf_i z)_x, (r_i x kf_i z)_y, s_i km_i ]
 *   = [ kf_i, r_iy kf_i, -r_ix kf_i, s_i km_i ]
 * (r_i rotor position in body FLU, s_i = yaw_sign: the sign of the yaw torque
 * the rotor's drag puts on the body). A is 4 x N; u = A^+ w with
 * A^+ = A^T (A A^T)^-1 (the exact inverse when N = 4, the minimum-norm
 * solution when N > 4).
 *
 * The coefficients kf_i, km_i are whatever the SITL mode supplies (truth for
 * Oracle, a fixed wrong set for Incorrect, the filter's estimate for Filter);
 * call sitl_allocation_set_coefficients() whenever they change (every step in
 * Filter mode: it is a 4x4 inversion).
 *
 * Saturation (u must lie in [Omega_min^2, Omega_max^2]), in priority order:
 *   1. the full wrench if feasible;
 *   2. otherwise the yaw moment is scaled down (largest feasible fraction of it);
 *   3. if even zero yaw is infeasible, the collective thrust is moved (the
 *      smallest change) so that the roll/pitch moment fits;
 *   4. if roll/pitch alone does not fit the speed range, roll/pitch is scaled
 *      down around the best collective thrust;
 *   5. a final clip to the bounds (only numerical residue remains).
 * Roll/pitch is kept before collective thrust because the attitude is how the
 * position loop recovers a thrust shortfall; yaw is the first sacrificed
 * because it is the weakest and least urgent axis.
 */
#ifndef SITL_ALLOCATION_H
#define SITL_ALLOCATION_H

#define SITL_ALLOC_MAX_ROTORS 8

/* Bits of sitl_allocation_result_t.saturation */
#define SITL_ALLOC_SAT_YAW        (1u << 0) /* yaw moment was reduced */
#define SITL_ALLOC_SAT_THRUST     (1u << 1) /* collective thrust was moved */
#define SITL_ALLOC_SAT_ROLL_PITCH (1u << 2) /* roll/pitch moment was reduced */
#define SITL_ALLOC_SAT_CLIPPED    (1u << 3) /* a final clip changed some u */

typedef struct {
    int rotor_count;                              /* 1..SITL_ALLOC_MAX_ROTORS (>= 4 to control all axes) */
    double position[SITL_ALLOC_MAX_ROTORS][3];    /* rotor hub, body FLU [m] */
    double yaw_sign[SITL_ALLOC_MAX_ROTORS];       /* +1 or -1 */
    double rotor_speed_min;                       /* [rad/s], >= 0 */
    double rotor_speed_max;                       /* [rad/s], > min */
} sitl_allocation_geometry_t;

typedef struct {
    sitl_allocation_geometry_t geometry;
    double thrust_coeff[SITL_ALLOC_MAX_ROTORS];   /* kf in use [N/(rad/s)^2] */
    double drag_coeff[SITL_ALLOC_MAX_ROTORS];     /* km in use [N m/(rad/s)^2] */
    double wrench_map[4][SITL_ALLOC_MAX_ROTORS];  /* A: [thrust, Mx, My, Mz] = A u */
    double inverse[SITL_ALLOC_MAX_ROTORS][4];     /* A^+ */
    int ready;                                    /* coefficients set and A A^T invertible */
} sitl_allocation_t;

typedef struct {
    double rotor_speed[SITL_ALLOC_MAX_ROTORS];    /* commands [rad/s] */
    double achieved[4];                           /* A u actually commanded (with the coefficients in use) */
    unsigned saturation;                          /* SITL_ALLOC_SAT_* */
    double yaw_fraction;                          /* fraction of the requested yaw moment kept (1 = all) */
} sitl_allocation_result_t;

/* Copy and check the geometry. Returns 0, or -1 on bad input. */
int sitl_allocation_init(sitl_allocation_t *alloc, const sitl_allocation_geometry_t *geometry);

/* Rebuild A and A^+ from per-rotor kf, km (arrays of rotor_count).
 * Returns 0, or -1 on non-positive/non-finite coefficients or a singular map
 * (then the previous coefficients stay in use). */
int sitl_allocation_set_coefficients(sitl_allocation_t *alloc, const double *thrust_coeff,
                                     const double *drag_coeff);

/* Wrench -> rotor speed commands with the saturation policy above.
 * Returns 0, or -1 if no coefficients are set or an input is not finite. */
int sitl_allocation_solve(const sitl_allocation_t *alloc, double thrust, const double moment[3],
                          sitl_allocation_result_t *result);

/* sitl_allocation_solve without result->achieved (left 0): the flight loop reads the
 * speeds only. Every other field the same bit for bit. */
int sitl_allocation_solve_speeds(const sitl_allocation_t *alloc, double thrust,
                                 const double moment[3], sitl_allocation_result_t *result);

/* Null-space excitation for more than 4 rotors: adds to the commanded squared
 * speeds u the projection (I - A^+ A) d(t) of the dither
 *     d_i(t) = fraction * mean(u) * sin(2 pi (1.1 + 0.37 i) t + 1.3 i)   [Hz, rad]
 * (rotor i 0-based: a different frequency per rotor), which leaves the wrench A u
 * unchanged for the coefficients in use, scaled down as a whole where it would
 * cross a speed bound. With N rotors the controller alone moves u in a
 * 4-dimensional family (collective and three moments); the dither moves the
 * other N - 4 directions, where the individual kf and km differ (docs/results.md,
 * "Extended campaign"). The motor lag is the same for every rotor, so it commutes
 * with the projection: the rotors' actual speeds stay in the null space too (up
 * to the square). No-op for 4 rotors (no null space) or fraction 0.
 * Returns 0, or -1 on bad input (result untouched). */
int sitl_allocation_add_null_dither(const sitl_allocation_t *alloc, double fraction, double t,
                                    sitl_allocation_result_t *result);

/* Forward map: rotor speeds -> wrench [thrust, Mx, My, Mz] with the coefficients in use. */
void sitl_allocation_wrench(const sitl_allocation_t *alloc, const double *rotor_speed,
                            double wrench[4]);

#endif /* SITL_ALLOCATION_H */
