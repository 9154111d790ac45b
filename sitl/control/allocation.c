/* Control allocation with a saturation priority; see allocation.h. */
#include "allocation.h"
#include "sitl_math.h"

#include <math.h>
#include <string.h>

int sitl_allocation_init(sitl_allocation_t *alloc, const sitl_allocation_geometry_t *geometry)
{
    if (alloc == NULL || geometry == NULL || geometry->rotor_count < 1 ||
        geometry->rotor_count > SITL_ALLOC_MAX_ROTORS || !isfinite(geometry->rotor_speed_min) ||
        !isfinite(geometry->rotor_speed_max) || geometry->rotor_speed_min < 0.0 ||
        geometry->rotor_speed_max <= geometry->rotor_speed_min) {
        return -1;
    }
    for (int i = 0; i < geometry->rotor_count; i++) {
        for (int k = 0; k < 3; k++) {
            if (!isfinite(geometry->position[i][k])) {
                return -1;
            }
        }
        if (geometry->yaw_sign[i] != 1.0 && geometry->yaw_sign[i] != -1.0) {
            return -1;
        }
    }
    memset(alloc, 0, sizeof(*alloc));
    alloc->geometry = *geometry;
    return 0;
}

/* The body of sitl_allocation_set_coefficients; n is a constant where it is
 * inlined, so the loops over the rotors unroll (the filter mode calls this at
 * every control step). */
static inline __attribute__((always_inline)) int
set_coefficients(sitl_allocation_t *alloc, const int n, const double *thrust_coeff,
                 const double *drag_coeff)
{
    for (int i = 0; i < n; i++) {
        if (!isfinite(thrust_coeff[i]) || !isfinite(drag_coeff[i]) || thrust_coeff[i] <= 0.0 ||
            drag_coeff[i] <= 0.0) {
            return -1;
        }
    }
    double map[4][SITL_ALLOC_MAX_ROTORS] = {{0}};
    for (int i = 0; i < n; i++) {
        const double *r = alloc->geometry.position[i];
        map[0][i] = thrust_coeff[i];
        map[1][i] = r[1] * thrust_coeff[i];  /* (r x kf z)_x */
        map[2][i] = -r[0] * thrust_coeff[i]; /* (r x kf z)_y */
        map[3][i] = alloc->geometry.yaw_sign[i] * drag_coeff[i];
    }
    /* Rows differ by orders of magnitude (kf ~ 1e-8, km ~ 1e-10): scale each row
     * to unit norm, pseudo-invert the scaled map, undo the scaling:
     * A = D^-1 S  =>  A^+ = S^T (S S^T)^-1 D. */
    double scale[4], scaled[4][SITL_ALLOC_MAX_ROTORS];
    for (int k = 0; k < 4; k++) {
        double norm = 0.0;
        for (int i = 0; i < n; i++) {
            norm += map[k][i] * map[k][i];
        }
        norm = sqrt(norm);
        if (!(norm > 0.0)) {
            return -1; /* e.g. all rotors on one axis: that moment is uncontrollable */
        }
        scale[k] = 1.0 / norm;
        for (int i = 0; i < n; i++) {
            scaled[k][i] = map[k][i] * scale[k];
        }
    }
    if (n == 4) {
        /* Square map: its exact inverse directly, A^-1 = S^-1 D, by cofactors (no Gram, no
         * product; the same result up to rounding). |det S| (rows of unit length: the
         * volume they span) is about the product of the Gram's pivots' square roots, so
         * the threshold is the square root of the Gram's below. */
        double square[4][4], square_inv[4][4];
        for (int k = 0; k < 4; k++) {
            for (int i = 0; i < 4; i++) {
                square[k][i] = scaled[k][i];
            }
        }
        if (sitl_mat4_inverse(square, square_inv, 3.1622776601683795e-5) != 0) {
            return -1;
        }
        for (int i = 0; i < 4; i++) {
            for (int k = 0; k < 4; k++) {
                alloc->inverse[i][k] = square_inv[i][k] * scale[k];
            }
        }
    } else {
        double gram[4][4], gram_inv[4][4];
        for (int a = 0; a < 4; a++) {
            for (int b = a; b < 4; b++) {
                double s = 0.0;
                for (int i = 0; i < n; i++) {
                    s += scaled[a][i] * scaled[b][i];
                }
                gram[a][b] = s;
                gram[b][a] = s; /* the same products in the same order: symmetric bit for bit */
            }
        }
        for (int i = 0; i < 4; i++) {
            for (int j = 0; j < 4; j++) {
                gram_inv[i][j] = (i == j) ? 1.0 : 0.0;
            }
        }
        if (sitl_mat4_solve(gram, gram_inv, 4, 1e-9) != 0) {
            return -1;
        }
        for (int i = 0; i < n; i++) {
            for (int k = 0; k < 4; k++) {
                double s = 0.0;
                for (int a = 0; a < 4; a++) {
                    s += scaled[a][i] * gram_inv[a][k];
                }
                alloc->inverse[i][k] = s * scale[k];
            }
        }
    }
    for (int k = 0; k < 4; k++) {
        for (int i = 0; i < SITL_ALLOC_MAX_ROTORS; i++) {
            alloc->wrench_map[k][i] = (i < n) ? map[k][i] : 0.0;
        }
    }
    for (int i = 0; i < n; i++) {
        alloc->thrust_coeff[i] = thrust_coeff[i];
        alloc->drag_coeff[i] = drag_coeff[i];
    }
    alloc->ready = 1;
    return 0;
}

int sitl_allocation_set_coefficients(sitl_allocation_t *alloc, const double *thrust_coeff,
                                     const double *drag_coeff)
{
    if (alloc == NULL || thrust_coeff == NULL || drag_coeff == NULL) {
        return -1;
    }
    const int n = alloc->geometry.rotor_count;
    return n == 4 ? set_coefficients(alloc, 4, thrust_coeff, drag_coeff)
                  : set_coefficients(alloc, n, thrust_coeff, drag_coeff);
}

/*
 * Largest s in [0, 1] with lo <= base_i + s * dir_i <= hi for every rotor, given
 * that s = 0 is feasible (base inside the bounds).
 */
static double largest_feasible_fraction(const double *base, const double *dir, int n, double lo,
                                        double hi)
{
    double s = 1.0;
    for (int i = 0; i < n; i++) {
        if (dir[i] > 0.0 && base[i] + dir[i] > hi) {
            s = fmin(s, (hi - base[i]) / dir[i]);
        } else if (dir[i] < 0.0 && base[i] + dir[i] < lo) {
            s = fmin(s, (lo - base[i]) / dir[i]);
        }
    }
    return s > 0.0 ? s : 0.0;
}

/*
 * Interval of collective-thrust parameter t with lo <= base_i + t * dir_i <= hi
 * for every rotor. Returns 0 if non-empty.
 */
static int thrust_interval(const double *base, const double *dir, int n, double lo, double hi,
                           double *t_lo, double *t_hi)
{
    double a = -INFINITY, b = INFINITY;
    for (int i = 0; i < n; i++) {
        if (dir[i] > 0.0) {
            a = fmax(a, (lo - base[i]) / dir[i]);
            b = fmin(b, (hi - base[i]) / dir[i]);
        } else if (dir[i] < 0.0) {
            a = fmax(a, (hi - base[i]) / dir[i]);
            b = fmin(b, (lo - base[i]) / dir[i]);
        } else if (base[i] < lo || base[i] > hi) {
            return -1;
        }
    }
    *t_lo = a;
    *t_hi = b;
    return a <= b ? 0 : -1;
}

static int inside(const double *u, int n, double lo, double hi)
{
    for (int i = 0; i < n; i++) {
        if (u[i] < lo || u[i] > hi) {
            return 0;
        }
    }
    return 1;
}

/* The body of both solves; with_achieved a constant where it is inlined. */
static inline __attribute__((always_inline)) int
solve(const sitl_allocation_t *alloc, double thrust, const double moment[3],
      sitl_allocation_result_t *result, const int with_achieved)
{
    if (alloc == NULL || moment == NULL || result == NULL || !alloc->ready || !isfinite(thrust) ||
        !isfinite(moment[0]) || !isfinite(moment[1]) || !isfinite(moment[2])) {
        return -1;
    }
    memset(result, 0, sizeof(*result));
    const int n = alloc->geometry.rotor_count;
    const double lo = alloc->geometry.rotor_speed_min * alloc->geometry.rotor_speed_min;
    const double hi = alloc->geometry.rotor_speed_max * alloc->geometry.rotor_speed_max;

    /* u = thrust * thrust_dir + u_roll_pitch + u_yaw (columns of A^+). */
    double thrust_dir[SITL_ALLOC_MAX_ROTORS], u_rp[SITL_ALLOC_MAX_ROTORS];
    double u_yaw[SITL_ALLOC_MAX_ROTORS], u[SITL_ALLOC_MAX_ROTORS], base[SITL_ALLOC_MAX_ROTORS];
    for (int i = 0; i < n; i++) {
        thrust_dir[i] = alloc->inverse[i][0];
        u_rp[i] = alloc->inverse[i][1] * moment[0] + alloc->inverse[i][2] * moment[1];
        u_yaw[i] = alloc->inverse[i][3] * moment[2];
        base[i] = thrust * thrust_dir[i] + u_rp[i];
        u[i] = base[i] + u_yaw[i];
    }
    result->yaw_fraction = 1.0;

    if (!inside(u, n, lo, hi)) {
        if (inside(base, n, lo, hi)) {
            /* 2. keep thrust and roll/pitch, as much yaw as fits */
            double s = largest_feasible_fraction(base, u_yaw, n, lo, hi);
            result->yaw_fraction = s;
            result->saturation |= SITL_ALLOC_SAT_YAW;
            for (int i = 0; i < n; i++) {
                u[i] = base[i] + s * u_yaw[i];
            }
        } else {
            result->yaw_fraction = 0.0;
            result->saturation |= SITL_ALLOC_SAT_YAW;
            double t_lo, t_hi;
            if (thrust_interval(u_rp, thrust_dir, n, lo, hi, &t_lo, &t_hi) == 0) {
                /* 3. full roll/pitch, nearest feasible collective thrust */
                double t = fmin(fmax(thrust, t_lo), t_hi);
                if (t != thrust) {
                    result->saturation |= SITL_ALLOC_SAT_THRUST;
                }
                for (int i = 0; i < n; i++) {
                    u[i] = t * thrust_dir[i] + u_rp[i];
                }
            } else {
                /* 4. largest roll/pitch fraction that fits at some thrust (bisection;
                 * the feasible set of fractions is an interval containing 0 when the
                 * bounds admit any hover-like command at all). */
                double s_ok = 0.0, s_bad = 1.0, scaled_rp[SITL_ALLOC_MAX_ROTORS];
                for (int iter = 0; iter < 40; iter++) {
                    double s = 0.5 * (s_ok + s_bad);
                    for (int i = 0; i < n; i++) {
                        scaled_rp[i] = s * u_rp[i];
                    }
                    if (thrust_interval(scaled_rp, thrust_dir, n, lo, hi, &t_lo, &t_hi) == 0) {
                        s_ok = s;
                    } else {
                        s_bad = s;
                    }
                }
                for (int i = 0; i < n; i++) {
                    scaled_rp[i] = s_ok * u_rp[i];
                }
                result->saturation |= SITL_ALLOC_SAT_ROLL_PITCH | SITL_ALLOC_SAT_THRUST;
                double t = thrust;
                if (thrust_interval(scaled_rp, thrust_dir, n, lo, hi, &t_lo, &t_hi) == 0) {
                    t = fmin(fmax(thrust, t_lo), t_hi);
                }
                for (int i = 0; i < n; i++) {
                    u[i] = t * thrust_dir[i] + scaled_rp[i];
                }
            }
        }
    }

    /* 5. final clip: removes rounding residue, or everything when nothing fits. */
    for (int i = 0; i < n; i++) {
        /* fmin(fmax(u, lo), hi) without libm's calls (a NaN u gives lo, as there). */
        const double c_lo = u[i] > lo ? u[i] : lo;
        double c = c_lo < hi ? c_lo : hi;
        if (c != u[i] && fabs(c - u[i]) > 1e-9 * hi) {
            result->saturation |= SITL_ALLOC_SAT_CLIPPED;
        }
        u[i] = c;
        result->rotor_speed[i] = sqrt(c);
    }
    if (!with_achieved) {
        return 0;
    }
    for (int k = 0; k < 4; k++) {
        double s = 0.0;
        for (int i = 0; i < n; i++) {
            s += alloc->wrench_map[k][i] * u[i];
        }
        result->achieved[k] = s;
    }
    return 0;
}

int sitl_allocation_solve(const sitl_allocation_t *alloc, double thrust, const double moment[3],
                          sitl_allocation_result_t *result)
{
    return solve(alloc, thrust, moment, result, 1);
}

int sitl_allocation_solve_speeds(const sitl_allocation_t *alloc, double thrust,
                                 const double moment[3], sitl_allocation_result_t *result)
{
    return solve(alloc, thrust, moment, result, 0);
}

int sitl_allocation_add_null_dither(const sitl_allocation_t *alloc, double fraction, double t,
                                    sitl_allocation_result_t *result)
{
    if (alloc == NULL || result == NULL || !alloc->ready || !isfinite(fraction) || fraction < 0.0 ||
        !isfinite(t)) {
        return -1;
    }
    const int n = alloc->geometry.rotor_count;
    if (n <= 4 || fraction == 0.0) {
        return 0;
    }
    const double lo = alloc->geometry.rotor_speed_min * alloc->geometry.rotor_speed_min;
    const double hi = alloc->geometry.rotor_speed_max * alloc->geometry.rotor_speed_max;
    double u[SITL_ALLOC_MAX_ROTORS], d[SITL_ALLOC_MAX_ROTORS], mean = 0.0;
    for (int i = 0; i < n; i++) {
        u[i] = result->rotor_speed[i] * result->rotor_speed[i];
        mean += u[i] / (double)n;
    }
    for (int i = 0; i < n; i++) {
        d[i] = fraction * mean * sin(2.0 * SITL_PI * (1.1 + 0.37 * (double)i) * t + 1.3 * (double)i);
    }
    /* d - A^+ (A d): the part of d the wrench map does not see. */
    double wrench[4];
    for (int k = 0; k < 4; k++) {
        double s = 0.0;
        for (int i = 0; i < n; i++) {
            s += alloc->wrench_map[k][i] * d[i];
        }
        wrench[k] = s;
    }
    for (int i = 0; i < n; i++) {
        double s = d[i];
        for (int k = 0; k < 4; k++) {
            s -= alloc->inverse[i][k] * wrench[k];
        }
        d[i] = s;
    }
    const double scale = inside(u, n, lo, hi) ? largest_feasible_fraction(u, d, n, lo, hi) : 0.0;
    for (int i = 0; i < n; i++) {
        result->rotor_speed[i] = sqrt(u[i] + scale * d[i]);
    }
    return 0;
}

void sitl_allocation_wrench(const sitl_allocation_t *alloc, const double *rotor_speed,
                            double wrench[4])
{
    const int n = alloc->geometry.rotor_count;
    for (int k = 0; k < 4; k++) {
        double s = 0.0;
        for (int i = 0; i < n; i++) {
            s += alloc->wrench_map[k][i] * rotor_speed[i] * rotor_speed[i];
        }
        wrench[k] = s;
    }
}
