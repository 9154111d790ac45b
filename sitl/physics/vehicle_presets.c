/*
 * Built-in vehicles. Inertial, coefficient and motor numbers are those of
 * the MEAM 620 / RotorPy "crazyflie" and "hummingbird" sets; the rotor
 * aerodynamic numbers used by the optional effects are documented with their
 * sources in docs/sitl.md.
 */
#include "vehicle.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "sitl_math.h"

const char *const sitl_vehicle_preset_names[] = {
    "crazyflie-plus", "crazyflie-x", "hummingbird-plus", "hummingbird-x",
    "hexa-plus",      "hexa-x",      "octo-plus",        "octo-x",      NULL};

void sitl_vehicle_symmetric_rotors(sitl_vehicle_t *v, int rotor_count, double arm,
                                   double first_angle, double thrust_coeff, double drag_coeff)
{
    v->rotor_count = rotor_count;
    v->arm_length = arm;
    for (int i = 0; i < rotor_count; i++) {
        double angle = first_angle + 2.0 * SITL_PI * (double)i / (double)rotor_count;
        sitl_vec3_set(v->rotor[i].position, arm * cos(angle), arm * sin(angle), 0.0);
        v->rotor[i].yaw_sign = (i % 2 == 0) ? 1.0 : -1.0;
        v->rotor[i].thrust_coeff = thrust_coeff;
        v->rotor[i].drag_coeff = drag_coeff;
    }
}

static void set_diag_inertia(sitl_vehicle_t *v, double jxx, double jyy, double jzz)
{
    memset(v->inertia, 0, sizeof(v->inertia));
    v->inertia[0][0] = jxx;
    v->inertia[1][1] = jyy;
    v->inertia[2][2] = jzz;
}

static void crazyflie(sitl_vehicle_t *v, double first_angle)
{
    v->mass = 0.03;
    set_diag_inertia(v, 1.43e-5, 1.43e-5, 2.89e-5);
    sitl_vehicle_symmetric_rotors(v, 4, 0.043, first_angle, 2.3e-8, 7.8e-10);
    v->motor_time_constant = 0.072;
    v->rotor_speed_min = 0.0;
    v->rotor_speed_max = 2500.0;
    v->rotor_radius = 0.0231;          /* 46 mm propeller */
    v->rotor_inertia = 3.5e-8;         /* thin rod 0.2 g over 46 mm; motor rotor neglected */
    v->rotor_drag_coeff = 1.02506e-6;  /* RotorPy crazyflie k_d */
    v->inflow_coeff = 7.553e-7;        /* RotorPy crazyflie k_z */
    v->translational_lift_coeff = 1.8e-4; /* Hummingbird k_h scaled by disc area */
    v->flapping_coeff = 0.5 * 0.0231 * 1.02506e-6; /* k_d x half the radius */
}

static void hummingbird(sitl_vehicle_t *v, double first_angle)
{
    v->mass = 0.5;
    set_diag_inertia(v, 3.65e-3, 3.68e-3, 7.03e-3);
    sitl_vehicle_symmetric_rotors(v, 4, 0.17, first_angle, 5.57e-6, 1.36e-7);
    v->motor_time_constant = 0.005;
    v->rotor_speed_min = 0.0;
    v->rotor_speed_max = 1500.0;
    v->rotor_radius = 0.10;            /* RotorPy hummingbird */
    v->rotor_inertia = 1.5e-5;         /* 8" propeller ~5 g + motor bell, estimate */
    v->rotor_drag_coeff = 1.19e-4;     /* RotorPy hummingbird k_d */
    v->inflow_coeff = 2.32e-4;         /* RotorPy hummingbird k_z */
    v->translational_lift_coeff = 3.39e-3; /* RotorPy hummingbird k_h */
    v->flapping_coeff = 0.5 * 0.10 * 1.19e-4;
}

/*
 * Six and eight Crazyflie rotors (same propeller, motor and speed range) on a
 * frame scaled so the hover speed and thrust-to-weight stay the quad's: mass x
 * N/4. The arm keeps neighbouring propellers 5 % of a radius apart
 * (2 arm sin(pi/N) = 2.1 r), never shorter than the quad's 0.043 m; the
 * inertia scales as mass x arm^2 from the quad's.
 */
static void crazyflie_multirotor(sitl_vehicle_t *v, int rotor_count, double first_angle)
{
    crazyflie(v, 0.0);
    const double scale_mass = (double)rotor_count / 4.0;
    const double arm = fmax(0.043, 1.05 * v->rotor_radius / sin(SITL_PI / (double)rotor_count));
    const double scale_arm_sq = (arm / 0.043) * (arm / 0.043);
    v->mass *= scale_mass;
    for (int k = 0; k < 3; k++) {
        v->inertia[k][k] *= scale_mass * scale_arm_sq;
    }
    sitl_vehicle_symmetric_rotors(v, rotor_count, arm, first_angle, 2.3e-8, 7.8e-10);
}

int sitl_vehicle_preset(const char *name, sitl_vehicle_t *v)
{
    if (name == NULL || v == NULL) {
        return -1;
    }
    memset(v, 0, sizeof(*v));
    if (strcmp(name, "crazyflie-plus") == 0) {
        crazyflie(v, 0.0);
    } else if (strcmp(name, "crazyflie-x") == 0) {
        crazyflie(v, 0.25 * SITL_PI);
    } else if (strcmp(name, "hummingbird-plus") == 0) {
        hummingbird(v, 0.0);
    } else if (strcmp(name, "hummingbird-x") == 0) {
        hummingbird(v, 0.25 * SITL_PI);
    } else if (strcmp(name, "hexa-plus") == 0) {
        crazyflie_multirotor(v, 6, 0.0);
    } else if (strcmp(name, "hexa-x") == 0) {
        crazyflie_multirotor(v, 6, SITL_PI / 6.0);
    } else if (strcmp(name, "octo-plus") == 0) {
        crazyflie_multirotor(v, 8, 0.0);
    } else if (strcmp(name, "octo-x") == 0) {
        crazyflie_multirotor(v, 8, SITL_PI / 8.0);
    } else {
        return -1;
    }
    snprintf(v->name, sizeof(v->name), "%s", name);
    return 0;
}

static int positive_finite(double x)
{
    return isfinite(x) && x > 0.0;
}

int sitl_vehicle_check(const sitl_vehicle_t *v, char *err, int err_size)
{
    const char *why = NULL;
    if (!positive_finite(v->mass)) {
        why = "mass must be positive";
    } else if (v->rotor_count < 1 || v->rotor_count > SITL_MAX_ROTORS) {
        why = "rotor count out of range";
    } else if (!positive_finite(v->motor_time_constant)) {
        why = "motor time constant must be positive";
    } else if (!(isfinite(v->rotor_speed_min) && v->rotor_speed_min >= 0.0 &&
                 positive_finite(v->rotor_speed_max) &&
                 v->rotor_speed_max > v->rotor_speed_min)) {
        why = "rotor speed limits must satisfy 0 <= min < max";
    } else {
        double inv[3][3];
        for (int i = 0; i < 3 && why == NULL; i++) {
            if (!positive_finite(v->inertia[i][i])) {
                why = "inertia diagonal must be positive";
            }
            for (int j = 0; j < 3 && why == NULL; j++) {
                if (!isfinite(v->inertia[i][j]) ||
                    fabs(v->inertia[i][j] - v->inertia[j][i]) >
                        1e-9 * fabs(v->inertia[i][i] + v->inertia[j][j])) {
                    why = "inertia must be finite and symmetric";
                }
            }
        }
        if (why == NULL && sitl_mat3_inverse(v->inertia, inv) != 0) {
            why = "inertia is singular";
        }
        /* Positive definite (leading minors positive), as the filter's configuration
         * check wants it: a bad vehicle file is a usage error, named here. */
        const double (*j)[3] = v->inertia;
        const double minor2 = j[0][0] * j[1][1] - j[0][1] * j[1][0];
        const double det = j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1]) -
                           j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0]) +
                           j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
        if (why == NULL && !(minor2 > 0.0 && det > 0.0)) {
            why = "inertia must be positive definite";
        }
        for (int i = 0; i < v->rotor_count && why == NULL; i++) {
            const sitl_rotor_t *r = &v->rotor[i];
            if (!positive_finite(r->thrust_coeff) || !positive_finite(r->drag_coeff)) {
                why = "rotor coefficients must be positive";
            } else if (fabs(fabs(r->yaw_sign) - 1.0) > 0.0) {
                why = "rotor yaw_sign must be +1 or -1";
            } else if (!isfinite(r->position[0]) || !isfinite(r->position[1]) ||
                       !isfinite(r->position[2])) {
                why = "rotor position must be finite";
            }
        }
    }
    if (why != NULL) {
        if (err != NULL && err_size > 0) {
            snprintf(err, (size_t)err_size, "vehicle '%s': %s", v->name, why);
        }
        return -1;
    }
    return 0;
}
