/*
 * The closed-loop flight (see sim.h). Order of work at one instant: ESC
 * report, then IMU sample (both go to the filter as on the MCU), then the
 * control step (reference, controller, coefficient source, allocation, log,
 * divergence check, live summary, link). The plant is integrated between
 * instants with the commands of the last control step held.
 */
#define _POSIX_C_SOURCE 200809L
#include "sim.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include "flight_log.h"
#include "output_path.h"
#include "physics_rate.h"
#include "propid/propid_damage.h"
#include "sitl_math.h"

#ifdef PROPID_SITL_WITH_MAVLINK
#include "sitl_mavlink.h"
#endif

static volatile sig_atomic_t stop_requested;

void sitl_request_stop(void)
{
    stop_requested = 1;
}

/* A periodic event in integer nanoseconds: time_k = phase + k * period; next_ns is
 * instant k, after_ns instant k + 1 (the loop asks for it at every pass). */
typedef struct {
    double phase_ns;
    double period_ns;
    uint64_t k;
    int64_t next_ns;
    int64_t after_ns;
} schedule_t;

/* llround without the libm call (three per loop pass): for 0 <= x < 2^52 the
 * truncation and the fraction x - trunc(x) are exact, so adding one for a
 * fraction >= 0.5 rounds half away from zero as llround does (same value). */
static int64_t round_ns(double x)
{
    if (!(x >= 0.0 && x < 4.0e15)) {
        return (int64_t)llround(x);
    }
    const int64_t whole = (int64_t)x;
    return whole + (x - (double)whole >= 0.5);
}

/* The schedule's k-th instant [ns]. */
static int64_t schedule_instant(const schedule_t *s, uint64_t k)
{
    return round_ns(s->phase_ns + (double)k * s->period_ns);
}

static void schedule_init(schedule_t *s, double phase_s, double rate_hz)
{
    s->phase_ns = phase_s * 1e9;
    s->period_ns = 1e9 / rate_hz;
    s->k = 0;
    s->next_ns = round_ns(s->phase_ns);
    s->after_ns = schedule_instant(s, 1);
}

static void schedule_advance(schedule_t *s)
{
    s->k++;
    s->next_ns = s->after_ns;
    s->after_ns = schedule_instant(s, s->k + 1);
}

static double wall_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double cpu_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void sleep_seconds(double s)
{
    if (s <= 0.0) {
        return;
    }
    struct timespec ts;
    ts.tv_sec = (time_t)s;
    ts.tv_nsec = (long)((s - (double)ts.tv_sec) * 1e9);
    nanosleep(&ts, NULL);
}

static int state_finite(const sitl_state_t *s, int n)
{
    double sum = 0.0;
    for (int k = 0; k < 3; k++) {
        sum += s->position[k] + s->velocity[k] + s->body_rate[k];
    }
    for (int k = 0; k < 4; k++) {
        sum += s->quat[k];
    }
    for (int i = 0; i < n; i++) {
        sum += s->rotor_speed[i];
    }
    return isfinite(sum);
}

static void print_live(FILE *out, double t, const sitl_metrics_t *m,
                       const propid_estimate_t *e)
{
    double pos_err = sqrt(m->position_error[0] * m->position_error[0] +
                          m->position_error[1] * m->position_error[1] +
                          m->position_error[2] * m->position_error[2]);
    fprintf(out,
            "t=%6.2f s  pos_err %.3f m  yaw_err %6.2f deg  |kf/kf_true-1|max %5.1f%%  "
            "|km/km_true-1|max %5.1f%%  bias_err %.4f rad/s  health 0x%02lx\n",
            t, pos_err, m->yaw_error * 180.0 / SITL_PI, 100.0 * m->kf_rel_error_max,
            100.0 * m->km_rel_error_max, m->bias_error_max, (unsigned long)e->health);
    fflush(out);
}

typedef struct {
    sitl_vehicle_t vehicle;
    sitl_plant_t plant;
    /* The plant's constants for the held command (sitl_plant_prepare); stale
     * after a control step, a damage or a fault changes the command or the plant. */
    sitl_plant_prepared_t plant_prepared;
    int plant_prepared_stale;
    sitl_state_t state;
    sitl_trajectory_t trajectory;
    sitl_controller_t controller;
    sitl_allocation_t allocation;
    propid_config_t filter_config;
    propid_filter_t filter;
    sitl_imu_t imu;
    sitl_esc_telemetry_t esc;
    sitl_faults_t faults;
    sitl_metrics_t metrics;
    sitl_honesty_t honesty;
    sitl_flight_log_t log;
    int log_open;
    double true_kf[SITL_MAX_ROTORS], true_km[SITL_MAX_ROTORS];
    double incorrect_kf[SITL_MAX_ROTORS], incorrect_km[SITL_MAX_ROTORS];
    double used_kf[SITL_MAX_ROTORS], used_km[SITL_MAX_ROTORS];
    double command[SITL_MAX_ROTORS];        /* rotor speed commands [rad/s] */
    double last_gyro[3], last_accel[3];
    double last_omega[SITL_MAX_ROTORS];
    int last_status;
    propid_damage_t detector;
    int damage_applied[SITL_MAX_DAMAGE];
    int oracle_informed[SITL_MAX_DAMAGE]; /* the Oracle's allocation has the loss */
    int has_flown;    /* the vehicle has been off the ground */
    int touched_down; /* and has touched it again since: down, the flight is over */
    sitl_rng_t disturbance_rng; /* its own stream: every other draw is the same with and without it */
    double disturbance_pole, disturbance_drive; /* its discretisation over one control period */
#ifdef PROPID_SITL_WITH_MAVLINK
    sitl_mavlink_t *link;
#endif
} flight_t;

/* --disturbance-torque: a first-order Gauss-Markov torque of the given std per axis, exact
 * discretisation over one control period, held by the plant until the next update. */
static void setup_disturbance_torque(flight_t *f, const sitl_options_t *o, double period_ns)
{
    f->disturbance_pole = exp(-period_ns * 1e-9 / o->disturbance_torque_time);
    f->disturbance_drive =
        o->disturbance_torque_std * sqrt(1.0 - f->disturbance_pole * f->disturbance_pole);
}

static void update_disturbance_torque(flight_t *f, const sitl_options_t *o)
{
    if (!(o->disturbance_torque_std > 0.0)) {
        return;
    }
    for (int k = 0; k < 3; k++) {
        f->plant.disturbance_torque[k] = f->disturbance_pole * f->plant.disturbance_torque[k] +
                                         f->disturbance_drive * sitl_rng_normal(&f->disturbance_rng);
    }
}

static int fail(sitl_result_t *r, int code, const char *msg)
{
    r->exit_code = code;
    snprintf(r->message, sizeof(r->message), "%s", msg);
    return code;
}

/* The rigid body's true state as the controller reads it (the paper's controller flies on
 * the true state). */
static void controller_view(const flight_t *f, sitl_vehicle_state_t *vs)
{
    sitl_vec3_copy(vs->position, f->state.position);
    sitl_vec3_copy(vs->velocity, f->state.velocity);
    memcpy(vs->quat_wxyz, f->state.quat, sizeof(vs->quat_wxyz));
    sitl_vec3_copy(vs->body_rate, f->state.body_rate);
}

/* Start on the trajectory's trim instead of level: the attitude and body rate the
 * controller's feed-forward asks for at t = 0 (no tracking error there), and the true hover
 * rotor speeds scaled to the collective thrust it asks for (thrust ~ Omega^2). A level
 * start on a trajectory that accelerates at once is a state no flight passes through: the
 * first control steps then tilt the vehicle at the largest rates of the flight. */
static void trim_on_trajectory(flight_t *f, const sitl_flat_output_t *flat0)
{
    for (int pass = 0; pass < 2; pass++) { /* 2nd pass: the thrust along the trimmed body z */
        sitl_vehicle_state_t vs;
        controller_view(f, &vs);
        sitl_control_output_t cmd;
        sitl_controller_update(&f->controller, &vs, flat0, &cmd);
        if (pass == 0) {
            sitl_quat_from_matrix(cmd.desired_rotation, f->state.quat);
            sitl_vec3_copy(f->state.body_rate, cmd.desired_body_rate);
        } else if (cmd.thrust > 0.0) {
            const double ratio = sqrt(cmd.thrust / (f->controller.mass * f->controller.gravity));
            for (int i = 0; i < f->vehicle.rotor_count; i++) {
                f->state.rotor_speed[i] *= ratio;
            }
        }
    }
}

static int setup(flight_t *f, const sitl_options_t *o, sitl_result_t *r)
{
    char err[256];
    if (sitl_setup_vehicle(o, &f->vehicle, err, (int)sizeof(err)) != 0) {
        return fail(r, SITL_EXIT_USAGE, err);
    }
    const int n = f->vehicle.rotor_count;
    if (n > SITL_ALLOC_MAX_ROTORS) {
        return fail(r, SITL_EXIT_USAGE, "too many rotors for the allocation");
    }
    sitl_setup_true_coefficients(&f->vehicle, o->coeff_spread, sitl_options_vehicle_seed(o),
                                 f->true_kf, f->true_km);
    sitl_setup_incorrect_coefficients(o, &f->vehicle, f->true_kf, f->true_km, f->incorrect_kf,
                                      f->incorrect_km);
    if (sitl_plant_init(&f->plant, &f->vehicle, f->true_kf, f->true_km, &o->effects, err,
                        (int)sizeof(err)) != 0) {
        return fail(r, SITL_EXIT_USAGE, err);
    }
    f->plant.ground_enabled = o->ground_enabled;

    double origin[3] = {0.0, 0.0, o->start_height_m};
    if (sitl_trajectory_init(&f->trajectory, o->trajectory, o->trajectory_period_s, origin) != 0) {
        return fail(r, SITL_EXIT_USAGE, "bad trajectory");
    }
    if (o->trajectory == SITL_TRAJ_CIRCLE || o->trajectory == SITL_TRAJ_LISSAJOUS) {
        if (o->yaw_amplitude_rad >= 0.0) {
            f->trajectory.yaw_amplitude_rad = o->yaw_amplitude_rad;
        }
        if (o->yaw_cycles >= 0.0) {
            f->trajectory.yaw_cycles = o->yaw_cycles;
        }
    }
    if (o->trajectory == SITL_TRAJ_LISSAJOUS && o->lissajous_climb_m >= 0.0) {
        f->trajectory.lissajous_fast.amplitude_m[2] = o->lissajous_climb_m;
    }
    sitl_flat_output_t flat0;
    sitl_trajectory_eval(&f->trajectory, 0.0, &flat0);
    if (o->start_on_ground) {
        double ground[3] = {flat0.position[0], flat0.position[1], 0.0};
        sitl_plant_hover_state(&f->plant, ground, flat0.yaw, &f->state);
        memset(f->state.rotor_speed, 0, sizeof(f->state.rotor_speed));
        f->state.on_ground = 1;
    } else {
        sitl_plant_hover_state(&f->plant, flat0.position, flat0.yaw, &f->state);
        if (!o->start_at_rest) {
            sitl_vec3_copy(f->state.velocity, flat0.velocity);
        }
    }

    /* The controller knows the vehicle file, not the truth. */
    if (sitl_controller_init(&f->controller, f->vehicle.mass, f->vehicle.inertia, SITL_GRAVITY,
                             NULL) != 0) {
        return fail(r, SITL_EXIT_USAGE, "controller rejected the vehicle");
    }
    sitl_allocation_geometry_t geo;
    memset(&geo, 0, sizeof(geo));
    geo.rotor_count = n;
    for (int i = 0; i < n; i++) {
        sitl_vec3_copy(geo.position[i], f->vehicle.rotor[i].position);
        geo.yaw_sign[i] = f->vehicle.rotor[i].yaw_sign;
    }
    geo.rotor_speed_min = f->vehicle.rotor_speed_min;
    geo.rotor_speed_max = f->vehicle.rotor_speed_max;
    if (sitl_allocation_init(&f->allocation, &geo) != 0) {
        return fail(r, SITL_EXIT_USAGE, "allocation rejected the geometry");
    }
    const double *kf0 = o->mode == SITL_MODE_ORACLE ? f->true_kf : f->incorrect_kf;
    const double *km0 = o->mode == SITL_MODE_ORACLE ? f->true_km : f->incorrect_km;
    if (sitl_allocation_set_coefficients(&f->allocation, kf0, km0) != 0) {
        return fail(r, SITL_EXIT_USAGE, "allocation cannot use the coefficients (need >= 4 rotors "
                                        "spanning thrust, roll, pitch and yaw)");
    }
    memcpy(f->used_kf, kf0, sizeof(f->used_kf));
    memcpy(f->used_km, km0, sizeof(f->used_km));
    if (o->start_trimmed && !o->start_on_ground) {
        trim_on_trajectory(f, &flat0);
    }
    memcpy(f->command, f->state.rotor_speed, sizeof(f->command));

    const char *bad = NULL;
    if (sitl_setup_filter_config(o, &f->vehicle, f->true_kf, &f->filter_config, &bad) != PROPID_OK) {
        snprintf(err, sizeof(err), "filter configuration rejected: field '%s'",
                 bad != NULL ? bad : "?");
        return fail(r, SITL_EXIT_ERROR, err);
    }
    propid_status_t st = propid_init(&f->filter, &f->filter_config);
    if (st != PROPID_OK) {
        snprintf(err, sizeof(err), "propid_init failed: %s", propid_status_name(st));
        return fail(r, SITL_EXIT_ERROR, err);
    }
    double kf_std[SITL_MAX_ROTORS], km_std[SITL_MAX_ROTORS];
    for (int i = 0; i < n; i++) {
        kf_std[i] = (double)f->filter_config.thrust_coeff_rel_std0 * f->vehicle.rotor[i].thrust_coeff;
        km_std[i] = (double)f->filter_config.drag_coeff_rel_std0 * f->vehicle.rotor[i].drag_coeff;
    }
    sitl_metrics_init(&f->metrics, n, kf_std, km_std, (double)f->filter_config.gyro_bias_std0);
    sitl_honesty_init(&f->honesty, &f->filter, f->true_kf, f->true_km,
                      sitl_setup_true_torque_scale(&o->effects));
    f->honesty.check_cov = o->honesty_cov_check;
    if (o->nees_dump[0] != '\0') {
        char why[300];
        if (sitl_output_path_make_parents(o->nees_dump, why, sizeof(why)) != 0) {
            snprintf(err, sizeof(err), "cannot write --nees-dump '%.100s': %.120s", o->nees_dump, why);
            return fail(r, SITL_EXIT_ERROR, err);
        }
        if (sitl_honesty_dump_open(&f->honesty, &f->filter, o->nees_dump) != 0) {
            snprintf(err, sizeof(err), "cannot write --nees-dump '%.200s'", o->nees_dump);
            return fail(r, SITL_EXIT_ERROR, err);
        }
    }
    for (int k = 0; k < o->damage_count; k++) {
        if (o->damage[k].rotor >= n) {
            snprintf(err, sizeof(err), "--damage: rotor %d but the vehicle has %d", o->damage[k].rotor + 1, n);
            return fail(r, SITL_EXIT_USAGE, err);
        }
    }
    if (o->detect_damage) {
        propid_damage_config_t dc;
        propid_damage_config_default(&dc);
        if (o->damage_false_alarms_per_hour > 0.0) {
            dc.false_alarms_per_hour = (float)o->damage_false_alarms_per_hour;
        }
        if (o->damage_design_loss >= 0.0) {
            dc.design_loss_fraction = (float)o->damage_design_loss;
        }
        if (propid_damage_init(&f->detector, &dc, &f->filter) != PROPID_OK) {
            return fail(r, SITL_EXIT_USAGE, "damage detector rejected its configuration");
        }
    }

    sitl_imu_init(&f->imu, &o->imu, sitl_options_vehicle_seed(o), o->seed, &o->effects);
    sitl_faults_init(&f->faults, &o->faults, o->seed);
    sitl_rng_init(&f->disturbance_rng, o->seed, SITL_RNG_DISTURBANCE_TORQUE);
    /* --physics-rate auto (the default): the accuracy rule's rate for this vehicle's motors. */
    r->physics_rate_hz = o->physics_rate_hz > 0.0
                             ? o->physics_rate_hz
                             : sitl_physics_rate_for(f->vehicle.motor_time_constant, o->control_rate_hz);
    double history_rate = r->physics_rate_hz + o->imu.rate_hz + o->esc.rate_hz +
                          o->control_rate_hz;
    if (sitl_esc_init(&f->esc, &o->esc, n, sitl_effects_esc_extra_delay(&o->effects),
                      history_rate, o->seed) != 0) {
        return fail(r, SITL_EXIT_USAGE, "bad ESC telemetry parameters");
    }
    sitl_esc_record(&f->esc, 0.0, f->state.rotor_speed);
    for (int k = 0; k < 3; k++) {
        f->last_gyro[k] = NAN;
        f->last_accel[k] = NAN;
    }
    for (int i = 0; i < SITL_MAX_ROTORS; i++) {
        f->last_omega[i] = NAN;
    }
    f->last_status = PROPID_OK;

    if (o->log_path[0] != '\0') {
        char why[300];
        if (sitl_output_path_make_parents(o->log_path, why, sizeof(why)) != 0) {
            snprintf(err, sizeof(err), "cannot write the log '%.100s': %.120s", o->log_path, why);
            return fail(r, SITL_EXIT_ERROR, err);
        }
        if (sitl_flight_log_open(&f->log, o->log_path, n) != 0) {
            snprintf(err, sizeof(err), "cannot write the log '%.200s'", o->log_path);
            return fail(r, SITL_EXIT_ERROR, err);
        }
        f->log_open = 1;
        char vpath[SITL_PATH_MAX + 32];
        char notes[1024], fx[256], vseed[48] = "", assumed[128] = "";
        sitl_flight_log_vehicle_path(o->log_path, vpath, sizeof(vpath));
        sitl_effects_describe(&o->effects, fx, (int)sizeof(fx));
        if (o->vehicle_seed_set) {
            snprintf(vseed, sizeof(vseed), ", vehicle seed %llu",
                     (unsigned long long)o->vehicle_seed);
        }
        if (f->vehicle.rotor_inertia_assumed) {
            snprintf(assumed, sizeof(assumed),
                     "; rotor inertia not in the vehicle file (null), %.3g kg m^2 assumed from "
                     "the rotor radius for the effects",
                     f->vehicle.rotor_inertia);
        }
        snprintf(notes, sizeof(notes),
                 "written by propid_sitl: vehicle '%s', geometry and inertia as simulated "
                 "(before effects), nominal catalogue coefficients (the truth is in the CSV "
                 "true_kf_i/true_km_i columns); seed %llu%s, coeff spread %g, effects %s%s",
                 f->vehicle.name, (unsigned long long)o->seed, vseed, o->coeff_spread, fx, assumed);
        if (sitl_vehicle_write_json(vpath, &f->vehicle, notes) != 0) {
            snprintf(err, sizeof(err), "cannot write '%.200s'", vpath);
            return fail(r, SITL_EXIT_ERROR, err);
        }
    }
#ifdef PROPID_SITL_WITH_MAVLINK
    if (o->mavlink_url[0] != '\0') {
        sitl_mavlink_rates_t rates;
        sitl_mavlink_default_rates(&rates);
        f->link = sitl_mavlink_open(o->mavlink_url, &rates);
        if (f->link == NULL) {
            return fail(r, SITL_EXIT_ERROR, "cannot open the MAVLink link");
        }
    }
#else
    if (o->mavlink_url[0] != '\0') {
        return fail(r, SITL_EXIT_USAGE, "--mavlink: this propid_sitl was built without the "
                                        "MAVLink link (sitl_mavlink.c / propid_mavlink)");
    }
#endif
    return SITL_EXIT_OK;
}

static void teardown(flight_t *f, sitl_result_t *r)
{
    if (f->log_open && sitl_flight_log_close(&f->log) != 0 && r->exit_code == SITL_EXIT_OK) {
        fail(r, SITL_EXIT_ERROR, "error while writing the log");
    }
    f->log_open = 0;
    if (sitl_honesty_dump_close(&f->honesty) != 0 && r->exit_code == SITL_EXIT_OK) {
        fail(r, SITL_EXIT_ERROR, "error while writing --nees-dump");
    }
    sitl_esc_free(&f->esc);
#ifdef PROPID_SITL_WITH_MAVLINK
    if (f->link != NULL) {
        sitl_mavlink_close(f->link);
        f->link = NULL;
    }
#endif
}

/* Damages due by time t: the plant's (true) kf and km drop; the Oracle's
 * allocation knows at once. */
/* The Oracle's allocation takes the damaged truth (every loss applied so far). */
static void oracle_learns_damage(flight_t *f)
{
    if (sitl_allocation_set_coefficients(&f->allocation, f->true_kf, f->true_km) == 0) {
        memcpy(f->used_kf, f->true_kf, sizeof(f->used_kf));
        memcpy(f->used_km, f->true_km, sizeof(f->used_km));
    }
}

static void apply_damage(flight_t *f, const sitl_options_t *o, sitl_result_t *r, double t)
{
    /* A vehicle that has flown and touched the ground again is down: its rotors
     * may still lift it off by millimetres (the contact flag then reads 0 for a
     * sample), but the ground holds it, and no gyro-based test can see a loss. */
    if (!f->state.on_ground) {
        f->has_flown = 1;
    } else if (f->has_flown && !f->touched_down) {
        f->touched_down = 1;
        r->touchdown_at_s = t;
    }
    for (int k = 0; k < o->damage_count; k++) {
        const sitl_damage_t *d = &o->damage[k];
        if (f->damage_applied[k] || t < d->time_s) {
            continue;
        }
        f->damage_applied[k] = 1;
        r->damage_on_ground[k] = f->state.on_ground;
        r->damage_after_touchdown[k] = f->touched_down;
        f->true_kf[d->rotor] *= 1.0 - d->fraction;
        f->true_km[d->rotor] *= 1.0 - d->fraction;
        f->plant.thrust_coeff[d->rotor] = f->true_kf[d->rotor];
        f->plant.drag_coeff[d->rotor] = f->true_km[d->rotor];
        f->plant_prepared_stale = 1;
        if (o->mode == SITL_MODE_ORACLE && !(o->oracle_damage_delay_s > 0.0)) {
            f->oracle_informed[k] = 1;
            oracle_learns_damage(f);
        }
        if (!o->quiet) {
            fprintf(stderr, "t=%6.3f s  damage: rotor %d loses %.0f %% of kf and km\n", t,
                    d->rotor + 1, 100.0 * d->fraction);
        }
    }
    if (o->mode != SITL_MODE_ORACLE || !(o->oracle_damage_delay_s > 0.0)) {
        return;
    }
    /* The Oracle told late (--oracle-damage-delay): the allocation a detector that
     * takes that long could give at best. */
    for (int k = 0; k < o->damage_count; k++) {
        if (f->damage_applied[k] && !f->oracle_informed[k] &&
            t >= o->damage[k].time_s + o->oracle_damage_delay_s) {
            f->oracle_informed[k] = 1;
            oracle_learns_damage(f);
        }
    }
}

static void step_detector(flight_t *f, const sitl_options_t *o, sitl_result_t *r, double t)
{
    int8_t rotor = -1;
    if (o->damage_landed_input) {
        (void)propid_damage_set_landed(&f->detector, f->state.on_ground != 0);
    }
    propid_status_t dst = propid_damage_step(&f->detector, &f->filter, &rotor);
    if (dst != PROPID_OK || rotor < 0) {
        return;
    }
    if (r->detection_count < SITL_MAX_DAMAGE) {
        r->detection_rotor[r->detection_count] = rotor;
        r->detection_time_s[r->detection_count] = t;
        r->detection_count++;
    }
    if (!o->quiet) {
        fprintf(stderr, "t=%6.3f s  detector: rotor %d damaged, coefficients re-opened\n", t,
                rotor + 1);
    }
#ifdef PROPID_SITL_WITH_MAVLINK
    if (f->link != NULL) {
        sitl_mavlink_damage(f->link, &f->detector);
    }
#endif
}

/* e: this control step's estimate (estimate_status: what propid_get_estimate
 * returned for it). */
static void take_coefficients(flight_t *f, const sitl_options_t *o, const propid_estimate_t *e,
                              propid_status_t estimate_status)
{
    if (o->mode != SITL_MODE_FILTER || estimate_status != PROPID_OK) {
        return;
    }
    double kf[SITL_MAX_ROTORS], km[SITL_MAX_ROTORS];
    for (int i = 0; i < f->vehicle.rotor_count; i++) {
        kf[i] = (double)e->thrust_coeff[i];
        km[i] = (double)e->drag_coeff[i];
    }
    /* A rejected set (non-positive, singular) leaves the previous one in use. */
    if (sitl_allocation_set_coefficients(&f->allocation, kf, km) == 0) {
        memcpy(f->used_kf, kf, sizeof(f->used_kf));
        memcpy(f->used_km, km, sizeof(f->used_km));
    }
}

/* Returns a reason string if the flight has diverged, else NULL. */
static const char *divergence(const flight_t *f, const sitl_options_t *o,
                              const sitl_flat_output_t *ref, double tilt_limit_cos)
{
    if (!state_finite(&f->state, f->vehicle.rotor_count)) {
        return "non-finite state";
    }
    double r[3][3];
    sitl_quat_to_matrix(f->state.quat, r);
    if (r[2][2] < tilt_limit_cos) {
        return o->divergence_tilt_deg >= 90.0 ? "upside down" : "tilted beyond the limit";
    }
    double d[3];
    for (int k = 0; k < 3; k++) {
        d[k] = f->state.position[k] - ref->position[k];
    }
    if (sitl_vec3_norm(d) > o->divergence_distance_m) {
        return "too far from the reference";
    }
    return NULL;
}

static void fill_row(const flight_t *f, double t, const sitl_flat_output_t *ref,
                     const propid_estimate_t *e, sitl_log_row_t *row)
{
    const int n = f->vehicle.rotor_count;
    memset(row, 0, sizeof(*row));
    row->t = t;
    for (int k = 0; k < 3; k++) {
        row->gyro[k] = f->last_gyro[k];
        row->acc[k] = f->last_accel[k];
        row->velocity[k] = f->state.velocity[k];
        row->position[k] = f->state.position[k];
        row->ref_position[k] = ref->position[k];
        row->true_bias[k] = f->imu.gyro_bias[k];
        row->true_rate[k] = f->state.body_rate[k];
    }
    for (int k = 0; k < 4; k++) {
        row->quat[k] = f->state.quat[k];
    }
    row->ref_yaw = ref->yaw;
    for (int i = 0; i < n; i++) {
        row->omega[i] = f->last_omega[i];
        row->cmd[i] = sitl_motor_clamp(&f->plant.motor, f->command[i]) /
                      f->vehicle.rotor_speed_max;
        row->true_kf[i] = f->true_kf[i];
        row->true_km[i] = f->true_km[i];
        row->true_omega[i] = f->state.rotor_speed[i];
    }
    row->estimate = *e;
    row->status = f->last_status;
}

/* A step from now may cross the IMU instant sample_ns (and the sample read from the step's
 * stages) when nothing else happens at or before it that changes the plant: a damage or the
 * rotor-loss fault falling due, or a vehicle resting on the ground (its contact is resolved at
 * step ends; a contact inside the step is found after it, sim's loop). One sample per step
 * (the caller checks the next one). --imu-split-steps: never. */
static int imu_instant_crossable(const flight_t *f, const sitl_options_t *o, int64_t sample_ns)
{
    if (o->imu_split_steps || f->state.on_ground) {
        return 0;
    }
    const double sample_t = (double)sample_ns * 1e-9;
    for (int k = 0; k < o->damage_count; k++) {
        if (!f->damage_applied[k] && !(sample_t < o->damage[k].time_s)) {
            return 0;
        }
    }
    return !sitl_faults_rotor_loss_due(&f->faults, sample_t);
}

int sitl_run(const sitl_options_t *o, sitl_result_t *r, FILE *out)
{
    static flight_t flight; /* large (filter, history): keep it off the stack */
    flight_t *f = &flight;
    memset(f, 0, sizeof(*f));
    memset(r, 0, sizeof(*r));
    r->coeff_converged_s = -1.0;
    r->bias_converged_s = -1.0;
    r->touchdown_at_s = -1.0;
    double wall_start = wall_seconds();

    stop_requested = 0;
    if (setup(f, o, r) != SITL_EXIT_OK) {
        teardown(f, r);
        return r->exit_code;
    }
    const int n = f->vehicle.rotor_count;

    schedule_t control, imu, esc, physics, logsched, live;
    schedule_init(&control, 0.0, o->control_rate_hz);
    if (o->disturbance_torque_std > 0.0) {
        setup_disturbance_torque(f, o, control.period_ns);
    }
    schedule_init(&imu, o->imu_sample_at_start ? 0.0 : 1.0 / o->imu.rate_hz, o->imu.rate_hz);
    schedule_init(&esc, o->esc.phase_s, o->esc.rate_hz);
    schedule_init(&physics, 0.0, r->physics_rate_hz);
    schedule_advance(&physics);
    schedule_init(&logsched, 0.0, o->log_rate_hz > 0.0 ? o->log_rate_hz : o->control_rate_hz);
    schedule_init(&live, 0.0, 2.0);
    schedule_advance(&live);
    const int64_t end_ns = (int64_t)llround(o->duration_s * 1e9);
    int64_t now_ns = 0;
    double last_imu_t = 0.0;
    propid_estimate_t est;
    memset(&est, 0, sizeof(est));
    /* The accelerometer feeds only the log, the link and the filter's aiding
     * (--filter-accel): without them it is not sampled (its noise has its own
     * stream, so nothing else changes). */
    int accel_read = f->log_open || o->filter_accel;
#ifdef PROPID_SITL_WITH_MAVLINK
    accel_read |= f->link != NULL;
#endif
    const double tilt_limit_cos = cos(o->divergence_tilt_deg * SITL_PI / 180.0);
    const double esc_read_delay_s = f->esc.params.latency_s + f->esc.extra_delay_s;
    f->plant_prepared_stale = 1;
    sitl_state_t step_end; /* a step across an IMU instant: its end, handled after the instant */
    memset(&step_end, 0, sizeof(step_end));
    int64_t step_end_ns = 0;
    int step_end_pending = 0;
    const double cpu_start = cpu_seconds();

    for (;;) {
        const double t = (double)now_ns * 1e-9;
        const uint64_t t_us = (uint64_t)((now_ns + 500) / 1000);
        apply_damage(f, o, r, t);

        /* A report is handled at its instant, or at the first instant after it when its
         * reading (its instant less the ESC's latency) was already in the history (below). */
        while (esc.next_ns <= now_ns) {
            const double esc_t = (double)esc.next_ns * 1e-9;
            double speed[SITL_MAX_ROTORS];
            if (sitl_esc_report(&f->esc, esc_t, speed)) {
                float speed_f[SITL_MAX_ROTORS];
                for (int i = 0; i < n; i++) {
                    speed_f[i] = (float)speed[i];
                    f->last_omega[i] = speed[i];
                }
                uint64_t esc_us = (uint64_t)((esc.next_ns + 500) / 1000);
                if (sitl_faults_esc(&f->faults, &esc_us, speed_f, n)) {
                    propid_push_rotor_speeds(&f->filter, esc_us, speed_f, (uint8_t)n);
                }
            }
            schedule_advance(&esc);
        }
        if (now_ns == imu.next_ns) {
            if (accel_read) {
                double specific_force[3];
                sitl_plant_specific_force(&f->plant, &f->state, f->command, specific_force);
                sitl_imu_sample(&f->imu, f->state.body_rate, specific_force, t - last_imu_t,
                                f->last_gyro, f->last_accel);
            } else {
                sitl_imu_sample(&f->imu, f->state.body_rate, NULL, t - last_imu_t, f->last_gyro,
                                NULL);
            }
            last_imu_t = t;
            float gyro_f[3] = {(float)f->last_gyro[0], (float)f->last_gyro[1],
                               (float)f->last_gyro[2]};
            uint64_t gyro_us = t_us;
            sitl_faults_gyro(&f->faults, &gyro_us, gyro_f, o->imu.gyro.range);
            f->last_status = (int)propid_push_gyro(&f->filter, gyro_us, gyro_f);
            if (f->last_status == PROPID_ERR_TIME_JUMP) {
                /* The integrator's documented answer to a clock jump (propid.h). */
                propid_resync(&f->filter, gyro_us);
                f->last_status = (int)propid_push_gyro(&f->filter, gyro_us, gyro_f);
            }
            if (o->filter_accel) {
                /* Same IMU sample, same stamp: its z specific force pins the kf scale. */
                const float accel_f[3] = {(float)f->last_accel[0], (float)f->last_accel[1],
                                          (float)f->last_accel[2]};
                (void)propid_push_accel(&f->filter, gyro_us, accel_f);
            }
            if (o->detect_damage && f->last_status >= 0) {
                step_detector(f, o, r, t);
            }
            schedule_advance(&imu);
        }
        if (sitl_faults_rotor_loss_now(&f->faults, t)) {
            f->plant.thrust_coeff[0] *= 0.7;
            f->true_kf[0] *= 0.7;
            f->plant_prepared_stale = 1;
        }
        if (now_ns == control.next_ns || now_ns >= end_ns) {
            f->plant_prepared_stale = 1; /* new command, new disturbance torque */
            update_disturbance_torque(f, o);
            sitl_flat_output_t ref;
            sitl_trajectory_eval(&f->trajectory, t, &ref);
            const propid_status_t est_status = propid_get_estimate(&f->filter, &est);
            sitl_metrics_add(&f->metrics, t, f->state.position, ref.position,
                             sitl_quat_yaw(f->state.quat), ref.yaw, &est, f->true_kf, f->true_km,
                             f->imu.gyro_bias);
            sitl_honesty_add(&f->honesty, t, &est, &f->filter, f->true_kf, f->true_km, f->imu.gyro_bias);
            r->control_steps++;
            const char *why = divergence(f, o, &ref, tilt_limit_cos);
            if (why == NULL && now_ns < end_ns) {
                /* Controller on the true state (as in the paper). */
                take_coefficients(f, o, &est, est_status);
                sitl_vehicle_state_t vs;
                controller_view(f, &vs);
                sitl_control_output_t cmd;
                sitl_controller_update(&f->controller, &vs, &ref, &cmd);
                sitl_allocation_result_t alloc;
                if (sitl_allocation_solve_speeds(&f->allocation, cmd.thrust, cmd.moment, &alloc) == 0) {
                    (void)sitl_allocation_add_null_dither(&f->allocation, o->null_dither, t, &alloc);
                    memcpy(f->command, alloc.rotor_speed, (size_t)n * sizeof(double));
                }
                if (o->filter_instrument) {
                    /* The command sent at t, as the ESC receives it (0..1 of the top speed). */
                    float command[SITL_MAX_ROTORS];
                    for (int i = 0; i < n; i++) {
                        command[i] = (float)(sitl_motor_clamp(&f->plant.motor, f->command[i]) /
                                             f->vehicle.rotor_speed_max);
                    }
                    (void)propid_push_motor_command(&f->filter, t_us, command, (uint8_t)n);
                }
            }
            /* The row holds the state at t and the command sent at t. */
            if (now_ns >= logsched.next_ns || why != NULL || now_ns >= end_ns) {
                if (f->log_open) {
                    sitl_log_row_t row;
                    fill_row(f, t, &ref, &est, &row);
                    sitl_flight_log_write(&f->log, &row);
                    r->log_rows++;
                }
                while (logsched.next_ns <= now_ns) {
                    schedule_advance(&logsched);
                }
            }
            if (out != NULL && !o->quiet && now_ns >= live.next_ns) {
                print_live(out, t, &f->metrics, &est);
                schedule_advance(&live);
            }
            if (why != NULL) {
                r->diverged = 1;
                r->diverged_at_s = t;
                snprintf(r->message, sizeof(r->message), "flight diverged at t=%.3f s: %s", t,
                         why);
                r->exit_code = SITL_EXIT_DIVERGED;
                break;
            }
            if (now_ns >= end_ns) {
                break;
            }
            if (stop_requested) {
                snprintf(r->message, sizeof(r->message), "interrupted at t=%.3f s", t);
                r->exit_code = SITL_EXIT_INTERRUPTED;
                break;
            }
#ifdef PROPID_SITL_WITH_MAVLINK
            if (f->link != NULL) {
                sitl_mavlink_snapshot_t snap;
                memset(&snap, 0, sizeof(snap));
                snap.time_s = t;
                memcpy(snap.quat_wxyz, f->state.quat, sizeof(snap.quat_wxyz));
                sitl_vec3_copy(snap.position_m, f->state.position);
                sitl_vec3_copy(snap.velocity_m_s, f->state.velocity);
                for (int k = 0; k < 3; k++) {
                    snap.gyro_rad_s[k] = isfinite(f->last_gyro[k]) ? f->last_gyro[k] : 0.0;
                    snap.accel_m_s2[k] = isfinite(f->last_accel[k]) ? f->last_accel[k] : 0.0;
                }
                for (int i = 0; i < n; i++) {
                    snap.rotor_speed_rad_s[i] = isfinite(f->last_omega[i]) ? f->last_omega[i] : 0.0;
                }
                snap.rotor_count = n;
                sitl_mavlink_update(f->link, &snap, &f->filter);
                sitl_mavlink_poll(f->link, &f->filter);
            }
#endif
            if (o->realtime > 0.0) {
                sleep_seconds(t / o->realtime - (wall_seconds() - wall_start));
            }
            schedule_advance(&control);
        }

        /* Integrate to the next instant anything happens but an IMU sample a step can
         * cross (imu_instant_crossable). */
        int64_t next = physics.next_ns;
        if (imu.next_ns < next && (!imu_instant_crossable(f, o, imu.next_ns) ||
                                   imu.after_ns < next)) {
            next = imu.next_ns; /* or a second sample inside the step: split at the first */
        }
        if (control.next_ns < next) {
            next = control.next_ns;
        }
        if (end_ns < next) {
            next = end_ns;
        }
        /* A report reads the speeds of its instant less the latency from the history:
         * when that reading is already recorded (now or before) and no second report
         * falls inside the step, the step need not end at it; the report is handled at
         * the step's end with its own time (above). Otherwise the step ends there. */
        if (esc.next_ns < next &&
            (o->esc_split_steps ||
             (double)esc.next_ns * 1e-9 - esc_read_delay_s > (double)now_ns * 1e-9 ||
             esc.after_ns < next)) {
            next = esc.next_ns;
        }
        if (step_end_pending) {
            /* The IMU instant inside the step was handled: on to the step's end. */
            f->state = step_end;
            now_ns = step_end_ns;
            step_end_pending = 0;
            sitl_esc_record(&f->esc, (double)now_ns * 1e-9, f->state.rotor_speed);
        } else if (next > now_ns) {
            if (f->plant_prepared_stale) {
                sitl_plant_prepare(&f->plant, f->command, &f->plant_prepared);
                f->plant_prepared_stale = 0;
            }
            const int64_t sample_ns = imu.next_ns;
            if (sample_ns > now_ns && sample_ns < next) { /* crossable (above) */
                /* One step across the IMU instant, the sample read from the step's stages;
                 * the instant is then handled like any other with that state. */
                step_end = f->state;
                sitl_state_t sample;
                sitl_plant_step_prepared_sampled(&f->plant, &f->plant_prepared, &step_end,
                                                 (double)(next - now_ns) * 1e-9,
                                                 (double)(sample_ns - now_ns) /
                                                     (double)(next - now_ns),
                                                 &sample);
                if (!step_end.on_ground) {
                    f->state = sample;
                    step_end_ns = next;
                    step_end_pending = 1;
                    next = sample_ns;
                } else {
                    /* A contact inside the step: split it at the instant, as before. */
                    next = sample_ns;
                    sitl_plant_step_prepared(&f->plant, &f->plant_prepared, &f->state,
                                             (double)(next - now_ns) * 1e-9);
                }
            } else {
                sitl_plant_step_prepared(&f->plant, &f->plant_prepared, &f->state,
                                         (double)(next - now_ns) * 1e-9);
            }
            now_ns = next;
            sitl_esc_record(&f->esc, (double)now_ns * 1e-9, f->state.rotor_speed);
        }
        if (physics.next_ns <= now_ns) {
            schedule_advance(&physics);
        }
    }

    r->flight_cpu_s = cpu_seconds() - cpu_start;
    r->flown_s = (double)now_ns * 1e-9;
    r->rotor_count = n;
    for (int k = 0; k < 3; k++) {
        r->rmse[k] = sitl_metrics_rmse(&f->metrics, k);
        r->true_bias[k] = f->imu.gyro_bias[k];
    }
    r->true_accel_bias_z = f->imu.accel_bias[2];
    r->rmse_yaw_deg = sitl_metrics_rmse_yaw_deg(&f->metrics);
    r->final_position_error_m = sitl_vec3_norm(f->metrics.position_error);
    r->final_yaw_error_deg = f->metrics.yaw_error * 180.0 / SITL_PI;
    r->kf_rel_error_max = f->metrics.kf_rel_error_max;
    r->km_rel_error_max = f->metrics.km_rel_error_max;
    r->bias_error_max = f->metrics.bias_error_max;
    r->coeff_converged_s = f->metrics.coeff_converged_since;
    r->bias_converged_s = f->metrics.bias_converged_since;
    for (int i = 0; i < n; i++) {
        r->true_kf[i] = f->true_kf[i];
        r->true_km[i] = f->true_km[i];
        r->used_kf[i] = f->used_kf[i];
        r->used_km[i] = f->used_km[i];
    }
    propid_get_estimate(&f->filter, &r->estimate);
    propid_get_counters(&f->filter, &r->counters);
    sitl_honesty_finish(&f->honesty);
    r->honesty = f->honesty;
    memcpy(r->faults_injected, f->faults.injected, sizeof(r->faults_injected));
    teardown(f, r);
    r->wall_time_s = wall_seconds() - wall_start;
    return r->exit_code;
}
