/* propid_sitl command-line parsing (see options.h; docs/sitl.md lists everything).
 * Every option is described once, in the table below: getopt_long's table and
 * the --help text are built from it. */
#define _GNU_SOURCE /* getopt_long */
#include "options.h"

#include <getopt.h>
#include <stddef.h>

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "sitl_math.h"

static const char *const mode_names[] = {"oracle", "incorrect", "filter"};

const char *sitl_mode_name(sitl_mode_t mode)
{
    if ((int)mode < 0 || (int)mode > 2) {
        return "?";
    }
    return mode_names[mode];
}

uint64_t sitl_options_vehicle_seed(const sitl_options_t *o)
{
    return o->vehicle_seed_set ? o->vehicle_seed : o->seed;
}

void sitl_options_default(sitl_options_t *o)
{
    memset(o, 0, sizeof(*o));
    snprintf(o->vehicle, sizeof(o->vehicle), "crazyflie-plus");
    o->trajectory = SITL_TRAJ_LISSAJOUS;
    o->mode = SITL_MODE_FILTER;
    o->seed = 1;
    o->duration_s = 10.0;
    o->trajectory_period_s = SITL_TRAJ_DEFAULT_PERIOD_S;
    o->yaw_amplitude_rad = -1.0;
    o->yaw_cycles = -1.0;
    o->lissajous_climb_m = -1.0;
    o->physics_rate_hz = 0.0; /* derived from the vehicle (physics_rate.h) */
    o->control_rate_hz = 500.0;
    o->coeff_spread = 0.2;
    o->incorrect_random = 0;
    o->incorrect_spread = 0.1;
    sitl_effects_clear(&o->effects);
    memset(&o->faults, 0, sizeof(o->faults));
    o->start_height_m = 1.0;
    o->ground_enabled = 1;
    o->divergence_distance_m = 2.0;
    o->divergence_tilt_deg = 90.0;
    sitl_imu_default_params(&o->imu);
    sitl_esc_default_params(&o->esc);
    o->motor_time_constant = -1.0;
    o->disturbance_torque_time = 0.5;
    o->rotor_speed_min = -1.0;
    o->rotor_speed_max = -1.0;
    o->prior_kf_rel_std = -1.0;
    o->prior_km_rel_std = -1.0;
    o->prior_bias_std = -1.0;
    o->prior_rate_std = -1.0;
    o->prior_accel_bias_std = -1.0;
    o->filter_accel_noise = -1.0;
    o->filter_accel_error_std = 0.0;
    o->filter_accel_error_time = 0.0;
    o->filter_rate_noise = -1.0;
    o->filter_coeff_walk = -1.0;
    o->filter_bias_walk = -1.0;
    o->damage_false_alarms_per_hour = -1.0;
    o->damage_design_loss = -1.0;
}


/* How an option's value is stored. */
typedef enum {
    OPT_SET_INT,  /* no value: the int at `offset` becomes `flag_value` */
    OPT_DOUBLE,   /* number in [lo, hi] into the double at `offset` */
    OPT_PATH,     /* string into the SITL_PATH_MAX buffer at `offset` */
    OPT_CUSTOM,   /* `parse` handles the value */
} opt_kind_t;

typedef struct {
    const char *section;  /* non-NULL: a --help heading printed before this option */
    const char *name;     /* long name without "--" */
    opt_kind_t kind;
    size_t offset;        /* offsetof(sitl_options_t, ...) for all but OPT_CUSTOM */
    double lo, hi;        /* OPT_DOUBLE range */
    int flag_value;       /* OPT_SET_INT */
    int (*parse)(sitl_options_t *o, const char *opt, const char *val); /* OPT_CUSTOM */
    const char *metavar;  /* value placeholder in --help, NULL for flags */
    const char *help;     /* may hold '\n' for continuation lines */
    void (*names)(char *out, int out_size, const char *separator); /* registry to list */
} opt_t;

static int parse_double(const char *opt, const char *text, double lo, double hi, double *out)
{
    char *end = NULL;
    errno = 0;
    double v = strtod(text, &end);
    if (end == text || *end != '\0' || errno != 0 || !isfinite(v) || v < lo || v > hi) {
        fprintf(stderr, "propid_sitl: %s: '%s' is not a number in [%g, %g]\n", opt, text, lo, hi);
        return -1;
    }
    *out = v;
    return 0;
}

static int parse_path(const char *opt, const char *text, char *out)
{
    if (strlen(text) >= SITL_PATH_MAX || text[0] == '\0') {
        fprintf(stderr, "propid_sitl: %s: bad value '%s'\n", opt, text);
        return -1;
    }
    snprintf(out, SITL_PATH_MAX, "%s", text);
    return 0;
}

static int parse_physics_rate(sitl_options_t *o, const char *opt, const char *val)
{
    if (strcmp(val, "auto") == 0) {
        o->physics_rate_hz = 0.0;
        return 0;
    }
    char *end = NULL;
    errno = 0;
    double v = strtod(val, &end);
    if (end == val || *end != '\0' || errno != 0 || !isfinite(v) || v < 1.0 || v > 1e6) {
        fprintf(stderr, "propid_sitl: %s: '%s' is neither auto nor a rate in [1, 1e6] Hz\n", opt, val);
        return -1;
    }
    o->physics_rate_hz = v;
    return 0;
}

static int parse_trajectory(sitl_options_t *o, const char *opt, const char *val)
{
    if (sitl_trajectory_from_name(val, &o->trajectory) != 0) {
        char names[256];
        sitl_trajectory_names(names, (int)sizeof(names), "|");
        fprintf(stderr, "propid_sitl: %s: unknown '%s' (%s)\n", opt, val, names);
        return -1;
    }
    return 0;
}

static int parse_mode(sitl_options_t *o, const char *opt, const char *val)
{
    for (int i = 0; i < 3; i++) {
        if (strcmp(val, mode_names[i]) == 0) {
            o->mode = (sitl_mode_t)i;
            return 0;
        }
    }
    fprintf(stderr, "propid_sitl: %s: unknown '%s' (oracle|incorrect|filter)\n", opt, val);
    return -1;
}

static int parse_seed(sitl_options_t *o, const char *opt, const char *val)
{
    char *end = NULL;
    errno = 0;
    unsigned long long s = strtoull(val, &end, 10);
    if (end == val || *end != '\0' || errno != 0 || val[0] == '-') {
        fprintf(stderr, "propid_sitl: %s: '%s' is not a non-negative integer\n", opt, val);
        return -1;
    }
    o->seed = (uint64_t)s;
    return 0;
}

static int parse_vehicle_seed(sitl_options_t *o, const char *opt, const char *val)
{
    const uint64_t flight_seed = o->seed;
    if (parse_seed(o, opt, val) != 0) {
        return -1;
    }
    o->vehicle_seed = o->seed;
    o->vehicle_seed_set = 1;
    o->seed = flight_seed;
    return 0;
}

static int parse_incorrect_source(sitl_options_t *o, const char *opt, const char *val)
{
    if (strcmp(val, "nominal") == 0) {
        o->incorrect_random = 0;
    } else if (strcmp(val, "random") == 0) {
        o->incorrect_random = 1;
    } else {
        fprintf(stderr, "propid_sitl: %s: '%s' (nominal|random)\n", opt, val);
        return -1;
    }
    return 0;
}

static int parse_effect(sitl_options_t *o, const char *opt, const char *val)
{
    (void)opt;
    char err[512];
    if (sitl_effects_parse(&o->effects, val, err, (int)sizeof(err)) != 0) {
        fprintf(stderr, "propid_sitl: %s\n", err);
        return -1;
    }
    return 0;
}

/* ROTOR@TIME=FRACTION, rotor 1-based: e.g. 2@3.5=0.3 */
static int parse_damage(sitl_options_t *o, const char *opt, const char *val)
{
    int rotor = 0;
    double time_s = 0.0, fraction = 0.0;
    int used = 0;
    if (sscanf(val, "%d@%lf=%lf%n", &rotor, &time_s, &fraction, &used) != 3 ||
        val[used] != '\0' || rotor < 1 || rotor > SITL_MAX_ROTORS || !(time_s >= 0.0) ||
        !(fraction > 0.0) || !(fraction < 1.0)) {
        fprintf(stderr, "propid_sitl: %s: '%s' is not ROTOR@TIME=FRACTION "
                        "(rotor 1..%d, time >= 0 s, 0 < fraction < 1)\n", opt, val, SITL_MAX_ROTORS);
        return -1;
    }
    if (o->damage_count >= SITL_MAX_DAMAGE) {
        fprintf(stderr, "propid_sitl: %s: at most %d damages\n", opt, SITL_MAX_DAMAGE);
        return -1;
    }
    sitl_damage_t *d = &o->damage[o->damage_count++];
    d->rotor = rotor - 1;
    d->time_s = time_s;
    d->fraction = fraction;
    return 0;
}

static int parse_fault(sitl_options_t *o, const char *opt, const char *val)
{
    (void)opt;
    char err[256];
    if (sitl_faults_parse(&o->faults, val, err, (int)sizeof(err)) != 0) {
        fprintf(stderr, "propid_sitl: %s\n", err);
        return -1;
    }
    return 0;
}

static int parse_esc_quantisation(sitl_options_t *o, const char *opt, const char *val)
{
    if (strcmp(val, "dshot") == 0) {
        o->esc.quantise_dshot = 1;
    } else if (strcmp(val, "none") == 0) {
        o->esc.quantise_dshot = 0;
    } else {
        fprintf(stderr, "propid_sitl: %s: '%s' (dshot|none)\n", opt, val);
        return -1;
    }
    return 0;
}

static int parse_esc_decode(sitl_options_t *o, const char *opt, const char *val)
{
    if (strcmp(val, "period") == 0) {
        o->esc.decode_middle = 0;
    } else if (strcmp(val, "middle") == 0) {
        o->esc.decode_middle = 1;
    } else {
        fprintf(stderr, "propid_sitl: %s: '%s' (period|middle)\n", opt, val);
        return -1;
    }
    return 0;
}

static int parse_pole_pairs(sitl_options_t *o, const char *opt, const char *val)
{
    double d;
    if (parse_double(opt, val, 1.0, 100.0, &d) != 0) {
        return -1;
    }
    o->esc.pole_pairs = (int)d;
    return 0;
}

#define OFF(field) offsetof(sitl_options_t, field)
#define FLAG(sec, name, field, value, help) {sec, name, OPT_SET_INT, OFF(field), 0, 0, value, NULL, NULL, help, NULL}
#define NUMBER(sec, name, field, lo, hi, metavar, help) \
    {sec, name, OPT_DOUBLE, OFF(field), lo, hi, 0, NULL, metavar, help, NULL}
#define PATH(sec, name, field, metavar, help) {sec, name, OPT_PATH, OFF(field), 0, 0, 0, NULL, metavar, help, NULL}
#define CUSTOM(sec, name, fn, metavar, help) {sec, name, OPT_CUSTOM, 0, 0, 0, 0, fn, metavar, help, NULL}

static const opt_t options[] = {
    PATH("Flight", "vehicle", vehicle, "NAME|FILE.json",
         "crazyflie-plus (default), crazyflie-x, hummingbird-plus,\n"
         "hummingbird-x, hexa-plus, hexa-x, octo-plus, octo-x (Crazyflie\n"
         "rotors), or a flight-log v1 vehicle file"),
    {NULL, "trajectory", OPT_CUSTOM, 0, 0, 0, 0, parse_trajectory, "KIND",
     "one of (default lissajous):", sitl_trajectory_names},
    CUSTOM(NULL, "mode", parse_mode, "MODE", "oracle | incorrect | filter (default)"),
    CUSTOM(NULL, "seed", parse_seed, "N", "random seed (default 1); same seed -> same log"),
    CUSTOM(NULL, "vehicle-seed", parse_vehicle_seed, "N",
           "seed of the vehicle's own draws (true kf/km, a random Incorrect\n"
           "mixer, the IMU's constant biases; default --seed): another --seed\n"
           "with the same N is another flight of the same vehicle"),
    NUMBER(NULL, "duration", duration_s, 1e-3, 1e6, "S", "flight time [s] (default 10)"),
    NUMBER(NULL, "trajectory-period", trajectory_period_s, 1e-2, 1e6, "S",
           "the trajectory's period T [s] (default 10, the paper's;\n"
           "independent of --duration)"),
    NUMBER(NULL, "yaw-amplitude", yaw_amplitude_rad, 0.0, 3.0, "RAD",
           "circle/lissajous back-and-forth yaw A sin(2 pi N t / T)\n(default 1.5 rad)"),
    NUMBER(NULL, "yaw-cycles", yaw_cycles, 0.0, 1e3, "N", "N of that yaw (default 1.5 cycles)"),
    NUMBER(NULL, "lissajous-climb", lissajous_climb_m, 0.0, 1.0, "M",
           "lissajous: vertical amplitude of its fast part (8 cycles per T;\n"
           "default 0): climb and descent for the thrust's climb term"),
    NUMBER(NULL, "start-height", start_height_m, 0.0, 1e4, "M",
           "trajectory origin height [m] (default 1)"),
    FLAG(NULL, "start-on-ground", start_on_ground, 1, "start at rest on the ground, rotors stopped"),
    FLAG(NULL, "start-at-rest", start_at_rest, 1,
         "start hovering with zero velocity (default: on the\n"
         "trajectory's initial velocity)"),
    FLAG(NULL, "start-trimmed", start_trimmed, 1,
         "start on the trajectory's trim: the attitude, body rate\nand thrust its feed-forward asks "
         "for at t = 0\n(default: level, hover rotor speeds)"),
    FLAG(NULL, "no-ground", ground_enabled, 0, "no ground plane"),
    FLAG(NULL, "honesty-cov-check", honesty_cov_check, 1,
         "check the filter's whole covariance for positive\ndefiniteness at every NEES sample (summary honesty.\n"
         "cov_checks / cov_not_pd; make soak sets it; ~ 3 % of\nthe flight's instructions)"),
    CUSTOM(NULL, "physics-rate", parse_physics_rate, "HZ|auto",
           "RK4 rate, >= control rate (default auto: the smallest\n"
           "multiple of the control rate with a step <= tau_m / 10\n"
           "and <= 0.1 / (2000 deg/s); 500 Hz for the Crazyflie\n"
           "presets, 2000 Hz for the Hummingbird)"),
    NUMBER(NULL, "control-rate", control_rate_hz, 1.0, 1e5, "HZ", "controller/allocation rate (default 500)"),
    NUMBER(NULL, "realtime", realtime, 0.0, 1e6, "FACTOR",
           "pace at FACTOR x wall clock (default: as fast as possible)"),
    NUMBER(NULL, "divergence-distance", divergence_distance_m, 1e-3, 1e9, "M",
           "stop (exit 3) beyond this distance from the reference (2)"),
    NUMBER(NULL, "divergence-tilt", divergence_tilt_deg, 1.0, 180.0, "DEG",
           "stop (exit 3) beyond this tilt (default 90 = upside down)"),

    NUMBER("Coefficients", "coeff-spread", coeff_spread, 0.0, 0.95, "S",
           "true kf, km = nominal x U(1-S, 1+S) per rotor (default 0.2)"),
    CUSTOM(NULL, "incorrect-source", parse_incorrect_source, "SRC",
           "nominal (default: catalogue values) | random"),
    NUMBER(NULL, "incorrect-spread", incorrect_spread, 0.0, 0.9, "S",
           "random: truth x (1 + N(0, S)) (default 0.1)"),
    NUMBER(NULL, "prior-kf-std", prior_kf_rel_std, 1e-6, 10.0, "R",
           "filter prior relative std of kf (default: library)"),
    NUMBER(NULL, "prior-km-std", prior_km_rel_std, 1e-6, 10.0, "R",
           "filter prior relative std of km (default: library)"),
    NUMBER(NULL, "prior-bias-std", prior_bias_std, 1e-9, 10.0, "RAD_S",
           "filter prior gyro-bias std (default: library)"),
    NUMBER(NULL, "prior-rate-std", prior_rate_std, 1e-9, 100.0, "RAD_S",
           "filter prior body-rate std (rate_std0; default: library).\n"
           "The filter's rate starts at 0: a small value says the\n"
           "vehicle is known to be at rest at the first gyro sample"),
    NUMBER(NULL, "prior-accel-bias-std", prior_accel_bias_std, 1e-6, 10.0, "M_S2",
           "filter prior accelerometer z-bias std (accel_bias_std0; with\n"
           "--filter-accel; default: library), e.g. the IMU datasheet's\n"
           "zero-g offset"),
    NUMBER(NULL, "filter-accel-noise", filter_accel_noise, 1e-6, 100.0, "M_S2",
           "filter accelerometer z noise std per sample (accel_noise_std;\n"
           "with --filter-accel; default: library), e.g. the IMU datasheet's\n"
           "noise density x sqrt(sample rate)"),
    NUMBER(NULL, "filter-accel-error-std", filter_accel_error_std, 1e-6, 100.0, "M_S2",
           "the accelerometer row's slow model error as a Gauss-Markov state\n"
           "of this std (accel_error_std; with --filter-accel and\n"
           "--filter-accel-error-time; default: off, docs/math.md §9)"),
    NUMBER(NULL, "filter-accel-error-time", filter_accel_error_time, 1e-3, 1e6, "S",
           "its correlation time (accel_error_time)"),
    NUMBER(NULL, "filter-rate-noise", filter_rate_noise, 0.0, 1e4, "X",
           "filter rate_process_noise [rad/s^2/sqrt(Hz)] (default: library)"),
    NUMBER(NULL, "filter-coeff-walk", filter_coeff_walk, 0.0, 10.0, "X",
           "filter kf/km relative random walk [1/sqrt(s)] (default: library)"),
    NUMBER(NULL, "filter-bias-walk", filter_bias_walk, 0.0, 10.0, "X",
           "filter gyro-bias random walk [rad/s/sqrt(s)] (default: library)"),
    FLAG(NULL, "filter-disturbance", filter_disturbance, 1,
         "filter: disturbance-torque states (docs/math.md §7)"),
    NUMBER(NULL, "filter-disturbance-bandwidth", filter_disturbance_bandwidth, 0.0, 1e3, "HZ",
           "filter: with --filter-disturbance, the states' bandwidth: they\n"
           "take the torque residual below it (what the controller cancels)\n"
           "and kf/km learn above it (docs/math.md §7). Default 0: slow walk"),
    FLAG(NULL, "filter-accel", filter_accel, 1,
         "filter: fuse the accelerometer's z specific force with the\n"
         "vehicle's mass (docs/math.md §9)"),
    FLAG(NULL, "filter-torque-scale", filter_torque_scale, 1,
         "filter: with --filter-accel, the thrust-torque scale state"),
    FLAG(NULL, "filter-rotor-inertia", filter_rotor_inertia, 1,
         "filter: the vehicle's rotor inertia (yaw reaction, gyroscopic\n"
         "torque) in its model (docs/math.md §8)"),
    NUMBER(NULL, "filter-esc-delay", filter_esc_delay_s, -1.0, 1.0, "S",
           "filter: telemetry delay it holds [s] (> 0: rotor speeds lag the\n"
           "gyro; docs/math.md §12). Default 0. The ESC telemetry lags by\n"
           "--esc-latency plus the esc_delay effect"),
    NUMBER(NULL, "filter-rotor-speed-noise", filter_rotor_speed_noise, 0.0, 1e4, "RAD_S",
           "filter: std of a rotor-speed sample's error, carried into the\n"
           "rate process noise (docs/math.md §14). Default 0 (exact)"),
    NUMBER(NULL, "filter-rotor-speed-noise-time", filter_rotor_speed_noise_time, 0.0, 600.0, "S",
           "filter: correlation time of that error [s] (default 0: one step)"),
    FLAG(NULL, "filter-rotor-speed-noise-hold", filter_rotor_speed_noise_hold, 1,
         "filter: that error's correlation time per rotor from the telemetry,\n"
         "how long the rotor's value has stood (the configured time its\n"
         "ceiling; docs/math.md §14). Also with --filter-sensor-errors"),
    FLAG(NULL, "filter-rotor-speed-noise-hold-floor", filter_rotor_speed_noise_hold, 2,
         "filter: the same hold with the configured time as its floor, the\n"
         "firmware's largest time its ceiling (rotor_speed_noise_hold = 2,\n"
         "docs/math.md §14). Also with --filter-sensor-errors"),
    FLAG(NULL, "filter-decode-error-split", filter_decode_error_split, 1,
         "filter: with --filter-sensor-errors, the truncating decode's error\n"
         "as its mean, half the step, common to every rotor and its spread\n"
         "step / sqrt(12) per rotor, instead of step / sqrt(3) per rotor\n"
         "(rotor_speed_noise_split, docs/math.md §14; the middle decode has\n"
         "the spread alone)"),
    NUMBER(NULL, "filter-inertia-std", filter_inertia_rel_std, 0.0, 1.0, "R",
           "filter: relative std of the vehicle file's inertia scale\n"
           "(inertia_rel_std): the data cannot see it, converged claims\n"
           "count it. Default 0 (the file's inertia is exact)"),
    NUMBER(NULL, "filter-gyro-stuck", filter_gyro_stuck_samples, 0.0, 65535.0, "N",
           "filter: a gyro axis whose reading repeats bit for bit N samples\n"
           "in a row is not fused until it changes (gyro_stuck_samples,\n"
           "docs/reliability.md). Default 0 (off); >= 2 when on"),
    FLAG(NULL, "filter-input-error-compensation", filter_input_error_compensation, 1,
         "filter: with --filter-rotor-speed-noise, remove the average part of\n"
         "each coefficient update that error explains (errors in variables,\n"
         "docs/math.md §14)"),
    FLAG(NULL, "filter-aero-damping", filter_aero_damping, 1,
         "filter: the airframe's aerodynamic rate damping in its model\n"
         "(config aero_damping, docs/math.md §17): the aero_damping effect's\n"
         "torque per unit body rate at hover speed, diagonal; 0 without\n"
         "that effect"),
    FLAG(NULL, "filter-instrument", filter_instrument, 1,
         "filter: push each control step's rotor commands\n"
         "(propid_push_motor_command, normalised by the vehicle's top speed)\n"
         "and use their first stage as the rotor input, so the telemetry's\n"
         "error stays out of the regressor (docs/math.md §16); lag: the\n"
         "vehicle's motor time constant"),
    FLAG(NULL, "filter-sensor-errors", filter_sensor_errors, 1,
         "filter: input-error terms from the sensor model (docs/sitl.md):\n"
         "rotor-speed noise = the telemetry step at the hover speed the\n"
         "rotors fly / sqrt(3) (RMS of a truncation), held 1 s (with\n"
         "--esc-decode middle: / sqrt(12), held while the code stands), no\n"
         "compensation; delay = the ESC latency.\n"
         "Replaces --filter-rotor-speed-noise(-time), --filter-esc-delay\n"
         "and --filter-input-error-compensation"),
    FLAG(NULL, "filter-report-age", filter_report_age, 1,
         "filter: add to its delay the mean age of the newest report at the\n"
         "gyro samples, in whole gyro periods (reports slower than the gyro:\n"
         "the trapezoid input lags the step by that age; docs/math.md §2)"),

    NUMBER("Disturbance", "disturbance-torque", disturbance_torque_std, 0.0, 10.0, "NM",
           "a random body torque outside every model, std per axis [N m]:\n"
           "first-order Gauss-Markov, updated at the control rate; the\n"
           "controller cancels it inside its bandwidth (docs/math.md §7).\n"
           "Default 0 (none)"),
    NUMBER(NULL, "disturbance-torque-time", disturbance_torque_time, 1e-3, 100.0, "S",
           "its correlation time [s] (default 0.5)"),
    NUMBER("Vehicle overrides", "motor-tau", motor_time_constant, 1e-5, 10.0, "S",
           "motor time constant [s]"),
    NUMBER(NULL, "rotor-speed-min", rotor_speed_min, 0.0, 1e5, "RAD_S", "minimum rotor speed"),
    NUMBER(NULL, "rotor-speed-max", rotor_speed_max, 1.0, 1e5, "RAD_S", "maximum rotor speed"),

    {"Effects (all off by default = the paper's conditions), repeatable", "effect", OPT_CUSTOM,
     0, 0, 0, 0, parse_effect, "NAME[=STRENGTH]", "NAME one of (none = all off):",
     sitl_effects_names},
    {"Faults between sensors and filter (all off by default; docs/sitl.md \"Faults\"), repeatable",
     "fault", OPT_CUSTOM, 0, 0, 0, 0, parse_fault, "NAME=RATE",
     "RATE per sample of its stream (time_jitter: std [us];\n"
     "rotor_loss: time [s] at which rotor 0 loses 30 % of its thrust);\n"
     "NAME one of (none = all off):",
     sitl_faults_names},

    CUSTOM("Propeller damage (docs/damage.md)", "damage", parse_damage, "ROTOR@TIME=FRACTION",
           "at TIME [s] rotor ROTOR (1-based) loses FRACTION of its\n"
           "kf and km (repeatable)"),
    FLAG(NULL, "detect-damage", detect_damage, 1,
         "run the firmware damage detector (propid_damage) after\n"
         "every gyro sample; a detection re-opens the rotor's\n"
         "coefficients"),
    NUMBER(NULL, "damage-false-alarm-rate", damage_false_alarms_per_hour, 1e-12, 1e6, "PER_H",
           "detector design false alarms per flight hour (default 1e-3)"),
    NUMBER(NULL, "damage-design-loss", damage_design_loss, 0.0, 0.99, "FRACTION",
           "detector tuned per rotor for a loss of FRACTION, variance\n"
           "floor at the gyro noise's share (docs/math.md 4); 0: the\n"
           "fixed design (default)"),
    FLAG(NULL, "damage-landed-input", damage_landed_input, 1,
         "tell the detector when the vehicle is on the ground (the\n"
         "plant's contact, an ideal land detector): no test there"),
    NUMBER(NULL, "oracle-damage-delay", oracle_damage_delay_s, 0.0, 10.0, "S",
           "Oracle mode: the allocation learns each loss S after it\n"
           "strikes (default 0: at once), the best a detector that\n"
           "takes S could give"),
    NUMBER("Excitation (docs/results.md, \"Extended campaign\")", "null-dither", null_dither, 0.0, 0.5,
           "FRACTION",
           "more than 4 rotors: excite the allocation's null space\n"
           "(wrench unchanged) with FRACTION of the mean Omega^2, so\n"
           "the individual coefficients become observable (default 0)"),

    FLAG("Sensors (defaults: Bosch BMI088 IMU, bidirectional-DShot telemetry; docs/sitl.md)",
         "paper", paper, 1,
         "the paper's sensors: 500 Hz gyro (noise + constant bias\n"
         "only), exact rotor speeds at the control rate"),
    NUMBER(NULL, "imu-rate", imu.rate_hz, 1.0, 1e5, "HZ", "IMU sample rate (1000)"),
    NUMBER(NULL, "gyro-noise", imu.gyro.noise_density, 0.0, 1.0, "RAD_S_SQRT_HZ", "gyro noise density"),
    NUMBER(NULL, "gyro-bias-max", imu.gyro.bias_max, 0.0, 10.0, "RAD_S",
           "gyro bias drawn from U(-X, X) per axis"),
    NUMBER(NULL, "gyro-bias-walk", imu.gyro.bias_walk, 0.0, 1.0, "X", "gyro bias random walk"),
    NUMBER(NULL, "gyro-range", imu.gyro.range, 0.0, 1e3, "RAD_S", "gyro full scale (0 = none)"),
    NUMBER(NULL, "gyro-resolution", imu.gyro.resolution, 0.0, 1.0, "RAD_S", "gyro LSB (0 = none)"),
    NUMBER(NULL, "accel-noise", imu.accel.noise_density, 0.0, 10.0, "X", "accelerometer noise density"),
    NUMBER(NULL, "accel-bias-max", imu.accel.bias_max, 0.0, 10.0, "M_S2",
           "accelerometer bias drawn from U(-X, X) per axis"),
    FLAG(NULL, "imu-sample-at-start", imu_sample_at_start, 1,
         "first IMU sample at t = 0 (default: one period later)"),
    NUMBER(NULL, "esc-rate", esc.rate_hz, 1.0, 1e5, "HZ", "ESC telemetry rate (500)"),
    NUMBER(NULL, "esc-latency", esc.latency_s, 0.0, 0.5, "S", "ESC telemetry latency (0.001)"),
    NUMBER(NULL, "esc-phase", esc.phase_s, 0.0, 1.0, "S", "time of the first report (0.00025)"),
    FLAG(NULL, "imu-split-steps", imu_split_steps, 1,
         "end a physics step at every IMU sample (default: the sample is read inside\nthe step from its stages)"),
    FLAG(NULL, "esc-split-steps", esc_split_steps, 1,
         "end a physics step at every ESC report (default: only\nwhere the report's reading is not yet in the history)"),
    NUMBER(NULL, "esc-dropout", esc.dropout_prob, 0.0, 1.0, "P", "probability a report is lost (0.01)"),
    CUSTOM(NULL, "esc-quantisation", parse_esc_quantisation, "dshot|none",
           "DShot eRPM quantisation (default dshot)"),
    CUSTOM(NULL, "esc-decode", parse_esc_decode, "period|middle",
           "DShot code to speed: at the code's period, as flight controllers do (default), or at the\n"
           "middle of its period interval (unbiased)"),
    CUSTOM(NULL, "esc-pole-pairs", parse_pole_pairs, "N", "motor pole pairs (7)"),

    PATH("Output", "log", log_path, "FILE.csv", "flight log v1 + FILE.vehicle.json"),
    NUMBER(NULL, "log-rate", log_rate_hz, 0.0, 1e6, "HZ",
           "log rows per second (default: every control step)"),
    PATH(NULL, "summary-json", summary_json, "FILE", "final metrics as JSON"),
    PATH(NULL, "nees-dump", nees_dump, "FILE.csv",
         "every NEES sample (50 Hz): time, NEES, the error and covariance of\n"
         "kf, km and biases, with the coefficient bases (docs/reliability.md)"),
    PATH(NULL, "mavlink", mavlink_url, "udp:HOST:PORT", "MAVLink 2 telemetry (off unless given)"),
    FLAG(NULL, "quiet", quiet, 1, "no live summary"),
    FLAG(NULL, "help", help, 1, "this text (also -h)"),
};

#define OPTION_COUNT ((int)(sizeof(options) / sizeof(options[0])))

/* A registry's names as help continuation lines, wrapped at 80 columns. */
static void print_names(void (*names)(char *out, int out_size, const char *separator))
{
    char all[1024];
    names(all, (int)sizeof(all), " ");
    const char *word = all;
    int column = 0;
    while (*word != '\0') {
        const char *end = strchr(word, ' ');
        int len = end != NULL ? (int)(end - word) : (int)strlen(word);
        if (column > 0 && column + 1 + len > 80) {
            printf("\n");
            column = 0;
        }
        if (column == 0) {
            column = printf("%-28s%.*s", "", len, word);
        } else {
            column += printf(" %.*s", len, word);
        }
        word += len;
        while (*word == ' ') {
            word++;
        }
    }
    if (column > 0) {
        printf("\n");
    }
}

void sitl_options_print_help(const char *prog)
{
    printf("usage: %s [options]\n"
           "\n"
           "Closed-loop multirotor simulator with the propid filter in the loop.\n"
           "The filter runs in every mode; --mode picks the coefficients the controller's\n"
           "allocation uses. Position/velocity/attitude/rate feedback is the truth.\n"
           "Every option also takes its value as --option=VALUE.\n",
           prog);
    for (int i = 0; i < OPTION_COUNT; i++) {
        const opt_t *opt = &options[i];
        if (opt->section != NULL) {
            printf("\n%s:\n", opt->section);
        }
        char left[64];
        int n = snprintf(left, sizeof(left), "  --%s%s%s", opt->name, opt->metavar ? " " : "",
                         opt->metavar ? opt->metavar : "");
        const char *line = opt->help;
        int first = 1;
        while (line != NULL && *line != '\0') {
            const char *nl = strchr(line, '\n');
            int len = nl != NULL ? (int)(nl - line) : (int)strlen(line);
            if (first && n < 28) {
                printf("%-28s%.*s\n", left, len, line);
            } else {
                if (first) {
                    printf("%s\n", left);
                }
                printf("%-28s%.*s\n", "", len, line);
            }
            first = 0;
            line = nl != NULL ? nl + 1 : NULL;
        }
        if (opt->names != NULL) {
            print_names(opt->names);
        }
    }
    printf("\nExit codes: 0 ok, 1 run-time error, 2 usage error, 3 flight diverged,\n"
           "130 interrupted (Ctrl-C; the log is kept).\n");
}

static int apply(sitl_options_t *o, const opt_t *opt, const char *val)
{
    char name[64];
    snprintf(name, sizeof(name), "--%s", opt->name);
    char *field = (char *)o + opt->offset;
    switch (opt->kind) {
    case OPT_SET_INT:
        *(int *)(void *)field = opt->flag_value;
        return 0;
    case OPT_DOUBLE:
        return parse_double(name, val, opt->lo, opt->hi, (double *)(void *)field);
    case OPT_PATH:
        return parse_path(name, val, field);
    case OPT_CUSTOM:
        return opt->parse(o, name, val);
    }
    return -1;
}

/* One getopt_long pass over argv. paper_pass: only --help and --paper are
 * acted on, errors are left to the full pass. */
static int scan(sitl_options_t *o, int argc, char **argv, const struct option *longopts,
                int paper_pass)
{
    optind = 0; /* full re-initialisation (GNU): the parser may run more than once */
    opterr = 0;
    for (;;) {
        int index = -1;
        int c = getopt_long(argc, argv, ":h", longopts, &index);
        if (c == -1) {
            break;
        }
        if (c == 'h') {
            o->help = 1;
            continue;
        }
        if (c == '?' || c == ':') {
            if (paper_pass) {
                continue;
            }
            const char *arg = argv[optind - 1];
            if (c == ':') {
                fprintf(stderr, "propid_sitl: %s needs a value\n", arg);
            } else {
                fprintf(stderr, "propid_sitl: unknown option '%s' (see --help)\n", arg);
            }
            return SITL_EXIT_USAGE;
        }
        const opt_t *opt = &options[c - 256];
        int is_paper_or_help = opt->kind == OPT_SET_INT &&
                               (opt->offset == OFF(paper) || opt->offset == OFF(help));
        if (paper_pass != is_paper_or_help) {
            continue;
        }
        if (apply(o, opt, optarg) != 0) {
            return SITL_EXIT_USAGE;
        }
    }
    if (!paper_pass && optind < argc) {
        fprintf(stderr, "propid_sitl: unexpected argument '%s' (see --help)\n", argv[optind]);
        return SITL_EXIT_USAGE;
    }
    return 0;
}

int sitl_options_parse(sitl_options_t *o, int argc, char **argv)
{
    const char *prog = argc > 0 ? argv[0] : "propid_sitl";
    struct option longopts[OPTION_COUNT + 1];
    for (int i = 0; i < OPTION_COUNT; i++) {
        longopts[i].name = options[i].name;
        longopts[i].has_arg = options[i].kind == OPT_SET_INT ? no_argument : required_argument;
        longopts[i].flag = NULL;
        longopts[i].val = 256 + i;
    }
    memset(&longopts[OPTION_COUNT], 0, sizeof(longopts[OPTION_COUNT]));

    /* --paper first: it resets the sensor models, later options refine them. */
    scan(o, argc, argv, longopts, 1);
    if (o->help) {
        sitl_options_print_help(prog);
        return 1;
    }
    double paper_bias_max = o->imu.gyro.bias_max;
    if (o->paper) {
        sitl_imu_paper_params(&o->imu);
        o->imu.gyro.bias_max = paper_bias_max;
        sitl_esc_paper_params(&o->esc, 0.0); /* rate 0 = the control rate, set below */
    }
    int status = scan(o, argc, argv, longopts, 0);
    if (status != 0) {
        return status;
    }
    if (o->esc.rate_hz == 0.0) {
        o->esc.rate_hz = o->control_rate_hz;
    }
    if (o->physics_rate_hz > 0.0 && o->physics_rate_hz < o->control_rate_hz) {
        fprintf(stderr, "propid_sitl: --physics-rate (%g) must be >= --control-rate (%g)\n",
                o->physics_rate_hz, o->control_rate_hz);
        return SITL_EXIT_USAGE;
    }
    if (o->start_trimmed && o->start_on_ground) {
        fprintf(stderr, "propid_sitl: --start-trimmed and --start-on-ground exclude each other\n");
        return SITL_EXIT_USAGE;
    }
    if (o->start_on_ground && !o->ground_enabled) {
        fprintf(stderr, "propid_sitl: --start-on-ground needs the ground (drop --no-ground)\n");
        return SITL_EXIT_USAGE;
    }
    if (o->oracle_damage_delay_s > 0.0 && o->mode != SITL_MODE_ORACLE) {
        fprintf(stderr, "propid_sitl: --oracle-damage-delay needs --mode oracle\n");
        return SITL_EXIT_USAGE;
    }
    if (o->prior_accel_bias_std > 0.0 && !o->filter_accel) {
        /* The filter has no accelerometer bias state without the aiding: the prior would go unused. */
        fprintf(stderr, "propid_sitl: --prior-accel-bias-std needs --filter-accel\n");
        return SITL_EXIT_USAGE;
    }
    if (o->filter_accel_noise > 0.0 && !o->filter_accel) {
        /* Without the aiding no accelerometer sample is fused: the noise would go unused. */
        fprintf(stderr, "propid_sitl: --filter-accel-noise needs --filter-accel\n");
        return SITL_EXIT_USAGE;
    }
    if ((o->filter_accel_error_std > 0.0) != (o->filter_accel_error_time > 0.0)) {
        fprintf(stderr, "propid_sitl: --filter-accel-error-std and --filter-accel-error-time go together\n");
        return SITL_EXIT_USAGE;
    }
    if (o->filter_accel_error_std > 0.0 && !o->filter_accel) {
        /* The row's model error is a term of the accelerometer's row. */
        fprintf(stderr, "propid_sitl: --filter-accel-error-std needs --filter-accel\n");
        return SITL_EXIT_USAGE;
    }
    return 0;
}
