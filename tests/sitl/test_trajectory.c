/*
 * Trajectories: analytic derivatives against central finite differences,
 * start at the origin, the step is a real step, name lookup, input checks.
 * Plain C (no framework): prints each failure, exit status = failure count.
 */
#include <math.h>
#include <string.h>
#include <stdio.h>

#include "trajectory.h"
#include "check.h"

/* Relative-or-absolute closeness: |a - b| <= tol * max(1, |b|). */
static int close_to(double a, double b, double tol) { return fabs(a - b) <= tol * fmax(1.0, fabs(b)); }

/* Compare each derivative with the central difference of the order below. */
static void check_derivatives(const sitl_trajectory_t *traj, double t)
{
    const double h = 1e-5;
    sitl_flat_output_t f, fp, fm;
    sitl_trajectory_eval(traj, t, &f);
    sitl_trajectory_eval(traj, t + h, &fp);
    sitl_trajectory_eval(traj, t - h, &fm);
    const char *name = sitl_trajectory_name(traj->kind);
    for (int i = 0; i < 3; i++) {
        double dpos = (fp.position[i] - fm.position[i]) / (2 * h);
        double dvel = (fp.velocity[i] - fm.velocity[i]) / (2 * h);
        double dacc = (fp.acceleration[i] - fm.acceleration[i]) / (2 * h);
        double djerk = (fp.jerk[i] - fm.jerk[i]) / (2 * h);
        /* Finite differences carry ~h^2 f''' truncation and ~eps/h rounding. */
        CHECK(close_to(f.velocity[i], dpos, 1e-6), "%s t=%g axis %d velocity %g vs fd %g", name, t,
              i, f.velocity[i], dpos);
        CHECK(close_to(f.acceleration[i], dvel, 1e-6), "%s t=%g axis %d accel %g vs fd %g", name,
              t, i, f.acceleration[i], dvel);
        CHECK(close_to(f.jerk[i], dacc, 1e-5), "%s t=%g axis %d jerk %g vs fd %g", name, t, i,
              f.jerk[i], dacc);
        CHECK(close_to(f.snap[i], djerk, 1e-4), "%s t=%g axis %d snap %g vs fd %g", name, t, i,
              f.snap[i], djerk);
    }
    double dyaw = (fp.yaw - fm.yaw) / (2 * h);
    double dyaw_rate = (fp.yaw_rate - fm.yaw_rate) / (2 * h);
    CHECK(close_to(f.yaw_rate, dyaw, 1e-6), "%s t=%g yaw rate %g vs fd %g", name, t, f.yaw_rate,
          dyaw);
    CHECK(close_to(f.yaw_acceleration, dyaw_rate, 1e-6), "%s t=%g yaw accel %g vs fd %g", name, t,
          f.yaw_acceleration, dyaw_rate);
}

static double max_abs(const double v[3]) { return fmax(fabs(v[0]), fmax(fabs(v[1]), fabs(v[2]))); }

static void test_derivatives_all_kinds(void)
{
    const double origin[3] = {0.3, -0.2, 1.0};
    const double times[] = {0.0137, 0.5, 1.234, 2.5, 4.9, 7.77, 9.99};
    for (int k = 0; k < SITL_TRAJ_KIND_COUNT; k++) {
        sitl_trajectory_t traj;
        CHECK(sitl_trajectory_init(&traj, (sitl_trajectory_kind_t)k, 10.0, origin) == 0,
              "init kind %d", k);
        if (k == SITL_TRAJ_STEP) {
            traj.step_time_s = 3.0; /* away from the sample times' neighbourhoods */
        }
        for (unsigned i = 0; i < sizeof(times) / sizeof(times[0]); i++) {
            check_derivatives(&traj, times[i]);
        }
    }
}

static void test_starts_at_origin_and_moves(void)
{
    const double origin[3] = {1.0, 2.0, 3.0};
    for (int k = 0; k < SITL_TRAJ_KIND_COUNT; k++) {
        sitl_trajectory_t traj;
        sitl_trajectory_init(&traj, (sitl_trajectory_kind_t)k, 10.0, origin);
        traj.step_time_s = 1.0;
        sitl_flat_output_t f;
        sitl_trajectory_eval(&traj, 0.0, &f);
        for (int i = 0; i < 3; i++) {
            CHECK(fabs(f.position[i] - origin[i]) < 1e-12, "%s starts off origin axis %d: %g",
                  sitl_trajectory_name(traj.kind), i, f.position[i]);
        }
        /* Everything except hover must actually go somewhere. */
        double travelled = 0.0;
        for (double t = 0.0; t <= 10.0; t += 0.01) {
            sitl_trajectory_eval(&traj, t, &f);
            double d[3] = {f.position[0] - origin[0], f.position[1] - origin[1],
                           f.position[2] - origin[2]};
            travelled = fmax(travelled, max_abs(d));
        }
        if (k == SITL_TRAJ_HOVER) {
            CHECK(travelled == 0.0, "hover moved %g", travelled);
        } else {
            CHECK(travelled > 0.3, "%s barely moves: %g m", sitl_trajectory_name(traj.kind),
                  travelled);
        }
    }
}

static void test_step_and_yaw(void)
{
    sitl_trajectory_t traj;
    sitl_trajectory_init(&traj, SITL_TRAJ_STEP, 10.0, NULL);
    traj.step_time_s = 2.0;
    traj.step_amplitude_m = 1.5;
    sitl_flat_output_t f;
    sitl_trajectory_eval(&traj, 1.999, &f);
    CHECK(f.position[0] == 0.0, "before the step x = %g", f.position[0]);
    sitl_trajectory_eval(&traj, 2.0, &f);
    CHECK(f.position[0] == 0.0, "at the step time x = %g", f.position[0]);
    sitl_trajectory_eval(&traj, 2.0001, &f);
    CHECK(f.position[0] == 1.5, "after the step x = %g", f.position[0]);
    CHECK(f.position[1] == 0.0 && f.position[2] == 0.0, "step moves only x");
    CHECK(max_abs(f.velocity) == 0.0 && max_abs(f.acceleration) == 0.0, "step derivatives zero");
    CHECK(f.yaw == 0.0 && f.yaw_rate == 0.0, "step has no yaw");

    /* circle and lissajous yaw back and forth with the configured amplitude */
    const sitl_trajectory_kind_t yawing[2] = {SITL_TRAJ_CIRCLE, SITL_TRAJ_LISSAJOUS};
    for (int k = 0; k < 2; k++) {
        sitl_trajectory_init(&traj, yawing[k], 10.0, NULL);
        double lo = 0.0, hi = 0.0;
        for (double t = 0.0; t <= 10.0; t += 0.001) {
            sitl_trajectory_eval(&traj, t, &f);
            lo = fmin(lo, f.yaw);
            hi = fmax(hi, f.yaw);
        }
        CHECK(traj.yaw_amplitude_rad > 0.0, "%s does not yaw", sitl_trajectory_name(yawing[k]));
        CHECK(fabs(hi - traj.yaw_amplitude_rad) < 1e-4 && fabs(lo + traj.yaw_amplitude_rad) < 1e-4,
              "%s yaw range [%g, %g]", sitl_trajectory_name(yawing[k]), lo, hi);
    }

    /* the circle really is a circle of the configured radius */
    sitl_trajectory_init(&traj, SITL_TRAJ_CIRCLE, 10.0, NULL);
    double cx = -traj.circle_radius_m * cos(traj.circle_start_angle_rad);
    double cy = -traj.circle_radius_m * sin(traj.circle_start_angle_rad);
    for (double t = 0.0; t <= 10.0; t += 0.37) {
        sitl_trajectory_eval(&traj, t, &f);
        double r = hypot(f.position[0] - cx, f.position[1] - cy);
        CHECK(fabs(r - traj.circle_radius_m) < 1e-12, "circle radius %g at t=%g", r, t);
    }
}

static void test_names_and_bad_input(void)
{
    for (int k = 0; k < SITL_TRAJ_KIND_COUNT; k++) {
        sitl_trajectory_kind_t back;
        const char *name = sitl_trajectory_name((sitl_trajectory_kind_t)k);
        CHECK(sitl_trajectory_from_name(name, &back) == 0 && back == (sitl_trajectory_kind_t)k,
              "name round trip %s", name);
    }
    char names[256];
    sitl_trajectory_names(names, (int)sizeof(names), "|");
    CHECK(strcmp(names, "hover|step|circle|lissajous") == 0, "registry names: %s", names);
    for (int k = 0; k < SITL_TRAJ_KIND_COUNT; k++) {
        const sitl_trajectory_info_t *info = sitl_trajectory_info((sitl_trajectory_kind_t)k);
        CHECK(info != NULL && info->name != NULL && info->eval != NULL, "registry row %d", k);
    }
    CHECK(sitl_trajectory_info(SITL_TRAJ_KIND_COUNT) == NULL, "row past the registry");
    sitl_trajectory_kind_t kind;
    CHECK(sitl_trajectory_from_name("loop-de-loop", &kind) == -1, "unknown name accepted");
    CHECK(sitl_trajectory_from_name(NULL, &kind) == -1, "NULL name accepted");
    sitl_trajectory_t traj;
    CHECK(sitl_trajectory_init(&traj, SITL_TRAJ_CIRCLE, 0.0, NULL) == -1, "zero duration");
    CHECK(sitl_trajectory_init(&traj, SITL_TRAJ_CIRCLE, NAN, NULL) == -1, "NaN duration");
    CHECK(sitl_trajectory_init(&traj, (sitl_trajectory_kind_t)7, 10.0, NULL) == -1, "bad kind");
    CHECK(sitl_trajectory_init(NULL, SITL_TRAJ_CIRCLE, 10.0, NULL) == -1, "NULL traj");
}

int main(void)
{
    test_derivatives_all_kinds();
    test_starts_at_origin_and_moves();
    test_step_and_yaw();
    test_names_and_bad_input();
    printf("test_trajectory: %d failure(s)\n", failures);
    return failures == 0 ? 0 : 1;
}
