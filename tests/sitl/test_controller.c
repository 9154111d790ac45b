/*
 * SE(3) controller: hover equilibrium, gain scaling, error signs, the
 * desired body rate / acceleration feed-forward against finite differences of
 * the desired attitude, and closed-loop tracking on an ideal rigid body
 * (direct wrench, no motors) for both vehicle classes.
 * Plain C (no framework): prints each failure, exit status = failure count.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "controller.h"
#include "sitl_math.h"
#include "trajectory.h"
#include "check.h"

static const double gravity = 9.81;

typedef struct {
    double mass;
    double inertia[3][3];
} vehicle_t;

static const vehicle_t crazyflie = {0.03, {{1.43e-5, 0, 0}, {0, 1.43e-5, 0}, {0, 0, 2.89e-5}}};
static const vehicle_t hummingbird = {0.5, {{3.65e-3, 0, 0}, {0, 3.68e-3, 0}, {0, 0, 7.03e-3}}};

static void on_trajectory_state(const sitl_flat_output_t *f, sitl_vehicle_state_t *s)
{
    memset(s, 0, sizeof(*s));
    memcpy(s->position, f->position, sizeof(s->position));
    memcpy(s->velocity, f->velocity, sizeof(s->velocity));
    s->quat_wxyz[0] = 1.0;
}

static void test_hover_equilibrium(const vehicle_t *v)
{
    sitl_controller_t ctl;
    CHECK(sitl_controller_init(&ctl, v->mass, v->inertia, gravity, NULL) == 0, "init");
    sitl_trajectory_t traj;
    const double origin[3] = {0.5, -1.0, 2.0};
    sitl_trajectory_init(&traj, SITL_TRAJ_HOVER, 10.0, origin);
    sitl_flat_output_t f;
    sitl_trajectory_eval(&traj, 3.0, &f);
    sitl_vehicle_state_t s;
    on_trajectory_state(&f, &s);
    sitl_control_output_t out;
    sitl_controller_update(&ctl, &s, &f, &out);
    CHECK(fabs(out.thrust - v->mass * gravity) < 1e-12, "hover thrust %g vs m g %g", out.thrust,
          v->mass * gravity);
    for (int i = 0; i < 3; i++) {
        CHECK(fabs(out.moment[i]) < 1e-15, "hover moment %d = %g", i, out.moment[i]);
        CHECK(fabs(out.desired_body_rate[i]) < 1e-15, "hover desired rate %d", i);
    }
    double q[4];
    sitl_quat_from_matrix(out.desired_rotation, q);
    CHECK(fabs(q[0] - 1.0) < 1e-12, "hover desired attitude not level");
}

static void test_gain_scaling(void)
{
    sitl_controller_t a, b;
    sitl_controller_init(&a, crazyflie.mass, crazyflie.inertia, gravity, NULL);
    sitl_controller_init(&b, hummingbird.mass, hummingbird.inertia, gravity, NULL);
    for (int i = 0; i < 3; i++) {
        CHECK(fabs(a.kx[i] / a.mass - b.kx[i] / b.mass) < 1e-9, "kx/m differs");
        CHECK(fabs(a.kv[i] / a.mass - b.kv[i] / b.mass) < 1e-9, "kv/m differs");
        CHECK(fabs(a.kR[i] / a.inertia[i][i] - b.kR[i] / b.inertia[i][i]) < 1e-6, "kR/J differs");
        CHECK(fabs(a.kw[i] / a.inertia[i][i] - b.kw[i] / b.inertia[i][i]) < 1e-6, "kw/J differs");
        CHECK(a.kx[i] > 0 && a.kv[i] > 0 && a.kR[i] > 0 && a.kw[i] > 0, "non-positive gain");
    }
    const double bad_inertia[3][3] = {{0, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    CHECK(sitl_controller_init(&a, 1.0, bad_inertia, gravity, NULL) == -1, "zero inertia accepted");
    CHECK(sitl_controller_init(&a, -1.0, crazyflie.inertia, gravity, NULL) == -1,
          "negative mass accepted");
    CHECK(sitl_controller_init(&a, 1.0, crazyflie.inertia, NAN, NULL) == -1, "NaN gravity accepted");
}

static void test_error_signs(void)
{
    sitl_controller_t ctl;
    sitl_controller_init(&ctl, crazyflie.mass, crazyflie.inertia, gravity, NULL);
    sitl_trajectory_t traj;
    sitl_trajectory_init(&traj, SITL_TRAJ_HOVER, 10.0, NULL);
    sitl_flat_output_t f;
    sitl_trajectory_eval(&traj, 0.0, &f);
    sitl_vehicle_state_t s;
    sitl_control_output_t out;

    /* Too low: more thrust. Too far +x: pitch nose down to go back (FLU: negative
     * rotation about +y tilts thrust towards -x, so the desired attitude has q_y < 0). */
    on_trajectory_state(&f, &s);
    s.position[2] = -0.1;
    sitl_controller_update(&ctl, &s, &f, &out);
    CHECK(out.thrust > crazyflie.mass * gravity, "below target but thrust %g", out.thrust);
    on_trajectory_state(&f, &s);
    s.position[0] = 0.2;
    sitl_controller_update(&ctl, &s, &f, &out);
    double q[4];
    sitl_quat_from_matrix(out.desired_rotation, q);
    CHECK(q[2] < 0.0, "desired q_y %g for a +x offset", q[2]);
    CHECK(out.moment[1] < 0.0, "pitch moment %g for a +x offset", out.moment[1]);

    /* Rolled right-wing-down about +x: restoring moment about -x; spinning in yaw: damped. */
    on_trajectory_state(&f, &s);
    double half = 0.5 * 0.2;
    s.quat_wxyz[0] = cos(half);
    s.quat_wxyz[1] = sin(half);
    sitl_controller_update(&ctl, &s, &f, &out);
    CHECK(out.moment[0] < 0.0, "roll moment %g for a +x roll", out.moment[0]);
    CHECK(out.attitude_error[0] > 0.0, "roll error %g", out.attitude_error[0]);
    on_trajectory_state(&f, &s);
    s.body_rate[2] = 1.0;
    sitl_controller_update(&ctl, &s, &f, &out);
    CHECK(out.moment[2] < 0.0, "yaw moment %g for a +z spin", out.moment[2]);
}

/* Desired rate and acceleration vs finite differences of the desired attitude
 * along a trajectory the vehicle follows exactly (so R_d depends on t only). */
static void test_feed_forward_matches_attitude_derivative(sitl_trajectory_kind_t kind)
{
    sitl_controller_t ctl;
    sitl_controller_init(&ctl, crazyflie.mass, crazyflie.inertia, gravity, NULL);
    sitl_trajectory_t traj;
    sitl_trajectory_init(&traj, kind, 10.0, NULL);
    if (kind == SITL_TRAJ_LISSAJOUS) {
        /* a more aggressive variant so the feed-forward terms are large */
        traj.lissajous_fast.amplitude_m[0] = 0.2;
        traj.lissajous_fast.amplitude_m[2] = 0.1;
    }
    const double h = 1e-5;
    for (double t = 0.3; t < 10.0; t += 1.1) {
        sitl_control_output_t o[3];
        double rates[3][3];
        double rd[3][3][3];
        for (int k = 0; k < 3; k++) {
            sitl_flat_output_t f;
            sitl_trajectory_eval(&traj, t + (k - 1) * h, &f);
            sitl_vehicle_state_t s;
            on_trajectory_state(&f, &s);
            sitl_controller_update(&ctl, &s, &f, &o[k]);
            double q[4];
            sitl_quat_from_matrix(o[k].desired_rotation, q);
            sitl_quat_to_matrix(q, rd[k]);
            memcpy(rates[k], o[k].desired_body_rate, sizeof(rates[k]));
        }
        /* w_d = vee(R_d^T dR_d/dt) */
        double m[3][3];
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) {
                double s = 0.0;
                for (int k = 0; k < 3; k++) {
                    s += rd[1][k][i] * (rd[2][k][j] - rd[0][k][j]) / (2 * h);
                }
                m[i][j] = s;
            }
        }
        double fd_rate[3] = {m[2][1], m[0][2], m[1][0]};
        for (int i = 0; i < 3; i++) {
            double fd_acc = (rates[2][i] - rates[0][i]) / (2 * h);
            CHECK(fabs(o[1].desired_body_rate[i] - fd_rate[i]) < 1e-5 * fmax(1.0, fabs(fd_rate[i])),
                  "%s t=%g rate %d: %g vs fd %g", sitl_trajectory_name(kind), t, i,
                  o[1].desired_body_rate[i], fd_rate[i]);
            CHECK(fabs(o[1].desired_body_accel[i] - fd_acc) < 1e-4 * fmax(1.0, fabs(fd_acc)),
                  "%s t=%g accel %d: %g vs fd %g", sitl_trajectory_name(kind), t, i,
                  o[1].desired_body_accel[i], fd_acc);
        }
    }
}

/* Ideal rigid body driven directly by the controller's wrench (RK4 at 1 kHz,
 * controller at 500 Hz). Returns the RMS position error [m] and max |error|. */
typedef struct {
    double p[3], v[3], q[4], w[3];
} body_t;

static void body_derivative(const vehicle_t *veh, const body_t *b, double thrust,
                            const double moment[3], body_t *d)
{
    double r[3][3];
    sitl_quat_to_matrix(b->q, r);
    for (int i = 0; i < 3; i++) {
        d->p[i] = b->v[i];
        d->v[i] = thrust / veh->mass * r[i][2];
    }
    d->v[2] -= gravity;
    const double *w = b->w;
    double jw[3] = {veh->inertia[0][0] * w[0], veh->inertia[1][1] * w[1], veh->inertia[2][2] * w[2]};
    double gyro[3] = {w[1] * jw[2] - w[2] * jw[1], w[2] * jw[0] - w[0] * jw[2],
                      w[0] * jw[1] - w[1] * jw[0]};
    for (int i = 0; i < 3; i++) {
        d->w[i] = (moment[i] - gyro[i]) / veh->inertia[i][i];
    }
    const double *q = b->q;
    d->q[0] = 0.5 * (-q[1] * w[0] - q[2] * w[1] - q[3] * w[2]);
    d->q[1] = 0.5 * (q[0] * w[0] + q[2] * w[2] - q[3] * w[1]);
    d->q[2] = 0.5 * (q[0] * w[1] + q[3] * w[0] - q[1] * w[2]);
    d->q[3] = 0.5 * (q[0] * w[2] + q[1] * w[1] - q[2] * w[0]);
}

static void body_add(body_t *out, const body_t *a, const body_t *d, double h)
{
    const double *pa = (const double *)a, *pd = (const double *)d;
    double *po = (double *)out;
    for (size_t i = 0; i < sizeof(body_t) / sizeof(double); i++) {
        po[i] = pa[i] + h * pd[i];
    }
}

static void fly(const vehicle_t *veh, sitl_trajectory_kind_t kind, const double offset[3],
                double *rms, double *final_error, double *rms_yaw)
{
    sitl_controller_t ctl;
    sitl_controller_init(&ctl, veh->mass, veh->inertia, gravity, NULL);
    sitl_trajectory_t traj;
    const double origin[3] = {0, 0, 1};
    sitl_trajectory_init(&traj, kind, 10.0, origin);
    body_t b;
    memset(&b, 0, sizeof(b));
    b.q[0] = 1.0;
    for (int i = 0; i < 3; i++) {
        b.p[i] = origin[i] + offset[i];
    }
    /* start on the trajectory's velocity so only the offset is a disturbance ... */
    sitl_flat_output_t f0;
    sitl_trajectory_eval(&traj, 0.0, &f0);
    memcpy(b.v, f0.velocity, sizeof(b.v));
    /* ... and on its attitude and body rate (R_d, w_d at t = 0) */
    sitl_vehicle_state_t s0;
    on_trajectory_state(&f0, &s0);
    sitl_control_output_t o0;
    sitl_controller_update(&ctl, &s0, &f0, &o0);
    sitl_quat_from_matrix(o0.desired_rotation, b.q);
    memcpy(b.w, o0.desired_body_rate, sizeof(b.w));

    double sum = 0.0, sum_yaw = 0.0, err = 0.0;
    int n = 0;
    const double dt = 0.002;
    for (int step = 0; step < 5000; step++) {
        double t = step * dt;
        sitl_flat_output_t f;
        sitl_trajectory_eval(&traj, t, &f);
        sitl_vehicle_state_t s;
        memcpy(s.position, b.p, sizeof(b.p));
        memcpy(s.velocity, b.v, sizeof(b.v));
        memcpy(s.quat_wxyz, b.q, sizeof(b.q));
        memcpy(s.body_rate, b.w, sizeof(b.w));
        sitl_control_output_t out;
        sitl_controller_update(&ctl, &s, &f, &out);
        err = sqrt(out.position_error[0] * out.position_error[0] +
                   out.position_error[1] * out.position_error[1] +
                   out.position_error[2] * out.position_error[2]);
        sum += err * err;
        double yaw = atan2(2 * (b.q[0] * b.q[3] + b.q[1] * b.q[2]),
                           1 - 2 * (b.q[2] * b.q[2] + b.q[3] * b.q[3]));
        double ey = remainder(yaw - f.yaw, 2 * 3.14159265358979323846);
        sum_yaw += ey * ey;
        n++;
        for (int sub = 0; sub < 2; sub++) {
            const double h = dt / 2;
            body_t k1, k2, k3, k4, tmp;
            body_derivative(veh, &b, out.thrust, out.moment, &k1);
            body_add(&tmp, &b, &k1, h / 2);
            body_derivative(veh, &tmp, out.thrust, out.moment, &k2);
            body_add(&tmp, &b, &k2, h / 2);
            body_derivative(veh, &tmp, out.thrust, out.moment, &k3);
            body_add(&tmp, &b, &k3, h);
            body_derivative(veh, &tmp, out.thrust, out.moment, &k4);
            body_add(&b, &b, &k1, h / 6);
            body_add(&b, &b, &k2, h / 3);
            body_add(&b, &b, &k3, h / 3);
            body_add(&b, &b, &k4, h / 6);
            double qn = sqrt(b.q[0] * b.q[0] + b.q[1] * b.q[1] + b.q[2] * b.q[2] + b.q[3] * b.q[3]);
            for (int i = 0; i < 4; i++) {
                b.q[i] /= qn;
            }
        }
    }
    *rms = sqrt(sum / n);
    *final_error = err;
    *rms_yaw = sqrt(sum_yaw / n);
}

static void test_closed_loop(void)
{
    const vehicle_t *vehicles[2] = {&crazyflie, &hummingbird};
    const char *names[2] = {"crazyflie", "hummingbird"};
    const double zero[3] = {0, 0, 0}, offset[3] = {0.3, -0.2, 0.1};
    for (int v = 0; v < 2; v++) {
        double rms, last, rms_yaw;
        /* Started on the trajectory, with exact feed-forward, tracking is near perfect. */
        fly(vehicles[v], SITL_TRAJ_LISSAJOUS, zero, &rms, &last, &rms_yaw);
        CHECK(rms < 2e-3 && rms_yaw < 2e-3, "%s lissajous rms %g m, yaw %g rad", names[v], rms,
              rms_yaw);
        fly(vehicles[v], SITL_TRAJ_CIRCLE, zero, &rms, &last, &rms_yaw);
        CHECK(rms < 2e-3 && rms_yaw < 2e-3, "%s circle rms %g m, yaw %g rad", names[v], rms, rms_yaw);
        /* An initial offset decays (position loop ~2.5 rad/s, so ~gone after 10 s). */
        fly(vehicles[v], SITL_TRAJ_HOVER, offset, &rms, &last, &rms_yaw);
        CHECK(last < 1e-3, "%s hover offset not recovered: %g m", names[v], last);
        fly(vehicles[v], SITL_TRAJ_STEP, zero, &rms, &last, &rms_yaw);
        CHECK(last < 1e-3 && rms > 0.1, "%s step: final %g m, rms %g m", names[v], last, rms);
    }
}

int main(void)
{
    test_hover_equilibrium(&crazyflie);
    test_hover_equilibrium(&hummingbird);
    test_gain_scaling();
    test_error_signs();
    test_feed_forward_matches_attitude_derivative(SITL_TRAJ_CIRCLE);
    test_feed_forward_matches_attitude_derivative(SITL_TRAJ_LISSAJOUS);
    test_closed_loop();
    printf("test_controller: %d failure(s)\n", failures);
    return failures == 0 ? 0 : 1;
}
