/* propid_sitl command-line parsing (see options.h; docs/sitl.md lists everything). */
#include "options.h"

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
    o->physics_rate_hz = 2000.0;
    o->control_rate_hz = 500.0;
    o->coeff_spread = 0.2;
    o->incorrect_random = 0;
    o->incorrect_spread = 0.1;
    sitl_effects_clear(&o->effects);
    o->start_height_m = 1.0;
    o->ground_enabled = 1;
    o->divergence_distance_m = 2.0;
    o->divergence_tilt_deg = 90.0;
    sitl_imu_default_params(&o->imu);
    sitl_esc_default_params(&o->esc);
    o->motor_time_constant = -1.0;
    o->rotor_speed_min = -1.0;
    o->rotor_speed_max = -1.0;
    o->prior_kf_rel_std = -1.0;
    o->prior_km_rel_std = -1.0;
    o->prior_bias_std = -1.0;
    o->prior_rate_std = -1.0;
    o->filter_rate_noise = -1.0;
    o->filter_coeff_walk = -1.0;
    o->filter_bias_walk = -1.0;
}

void sitl_options_print_help(const char *prog)
{
    printf(
        "usage: %s [options]\n"
        "\n"
        "Closed-loop multirotor simulator with the propid filter in the loop.\n"
        "The filter runs in every mode; --mode picks the coefficients the controller's\n"
        "allocation uses. Position/velocity/attitude/rate feedback is the truth.\n"
        "\n"
        "Flight:\n"
        "  --vehicle NAME|FILE.json  crazyflie-plus (default), crazyflie-x, hummingbird-plus,\n"
        "                            hummingbird-x, or a flight-log v1 vehicle file\n"
        "  --trajectory KIND         hover | step | circle | lissajous (default)\n"
        "  --mode MODE               oracle | incorrect | filter (default)\n"
        "  --seed N                  random seed (default 1); same seed -> same log\n"
        "  --duration S              flight time [s] (default 10)\n"
        "  --trajectory-period S     the trajectory's period T [s] (default 10, the paper's;\n"
        "                            independent of --duration)\n"
        "  --yaw-amplitude RAD, --yaw-cycles N   circle/lissajous back-and-forth yaw\n"
        "                            A sin(2 pi N t / T) (default 1.5 rad, 1.5 cycles)\n"
        "  --start-height M          trajectory origin height [m] (default 1)\n"
        "  --start-on-ground         start at rest on the ground, rotors stopped\n"
        "  --start-at-rest           start hovering with zero velocity (default: on the\n"
        "                            trajectory's initial velocity)\n"
        "  --no-ground               no ground plane\n"
        "  --physics-rate HZ         RK4 rate (default 2000, >= control rate)\n"
        "  --control-rate HZ         controller/allocation rate (default 500)\n"
        "  --realtime FACTOR         pace at FACTOR x wall clock (default: as fast as possible)\n"
        "  --divergence-distance M   stop (exit 3) beyond this distance from the reference (2)\n"
        "  --divergence-tilt DEG     stop (exit 3) beyond this tilt (default 90 = upside down)\n"
        "\n"
        "Coefficients:\n"
        "  --coeff-spread S          true kf, km = nominal x U(1-S, 1+S) per rotor (default 0.2)\n"
        "  --incorrect-source SRC    nominal (default: catalogue values) | random\n"
        "  --incorrect-spread S      random: truth x (1 + N(0, S)) (default 0.1)\n"
        "  --prior-kf-std R, --prior-km-std R   filter prior relative std (default: library)\n"
        "  --prior-bias-std RAD_S    filter prior gyro-bias std (default: library)\n"
        "  --prior-rate-std RAD_S    filter prior body-rate std (rate_std0; default: library).\n"
        "                            The filter's rate starts at 0: a small value says the\n"
        "                            vehicle is known to be at rest at the first gyro sample\n"
        "  --filter-rate-noise X     filter rate_process_noise [rad/s^2/sqrt(Hz)] (default: library)\n"
        "  --filter-coeff-walk X     filter kf/km relative random walk [1/sqrt(s)] (default: library)\n"
        "  --filter-bias-walk X      filter gyro-bias random walk [rad/s/sqrt(s)] (default: library)\n"
        "\n"
        "Vehicle overrides:\n"
        "  --motor-tau S, --rotor-speed-min RAD_S, --rotor-speed-max RAD_S\n"
        "\n"
        "Effects (all off by default = the paper's conditions), repeatable:\n"
        "  --effect NAME[=STRENGTH]  rotor_inertia rotor_gyroscopic rotor_drag\n"
        "                            translational_lift ground_effect com_offset inertia_error\n"
        "                            esc_delay thrust_nonlinearity gyro_scale aero_damping\n"
        "\n"
        "Sensors (defaults: Bosch BMI088 IMU, bidirectional-DShot telemetry; docs/sitl.md):\n"
        "  --paper                   the paper's sensors: 500 Hz gyro (noise + constant bias\n"
        "                            only), exact rotor speeds at the control rate\n"
        "  --imu-rate HZ (1000)      --gyro-noise RAD_S_SQRT_HZ   --gyro-bias-max RAD_S\n"
        "  --gyro-bias-walk X        --gyro-range RAD_S (0 = none) --gyro-resolution RAD_S\n"
        "  --accel-noise X           --accel-bias-max M_S2\n"
        "  --imu-sample-at-start     first IMU sample at t = 0 (default: one period later)\n"
        "  --esc-rate HZ (500)       --esc-latency S (0.001)  --esc-phase S (0.00025)\n"
        "  --esc-dropout P (0.01)    --esc-quantisation dshot|none   --esc-pole-pairs N (7)\n"
        "\n"
        "Output:\n"
        "  --log FILE.csv            flight log v1 + FILE.vehicle.json\n"
        "  --log-rate HZ             log rows per second (default: every control step)\n"
        "  --summary-json FILE       final metrics as JSON\n"
        "  --mavlink udp:HOST:PORT   MAVLink 2 telemetry (off unless given)\n"
        "  --quiet                   no live summary\n"
        "  --help\n"
        "\n"
        "Exit codes: 0 ok, 1 run-time error, 2 usage error, 3 flight diverged,\n"
        "130 interrupted (Ctrl-C; the log is kept).\n",
        prog);
}

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

/* Options that take a value, for the "--opt value" / "--opt=value" split. */
static const char *const valued[] = {
    "--vehicle", "--trajectory", "--mode", "--seed", "--duration", "--log", "--log-rate",
    "--mavlink", "--realtime", "--physics-rate", "--control-rate", "--coeff-spread",
    "--incorrect-source", "--incorrect-spread", "--gyro-bias-max", "--effect", "--summary-json",
    "--start-height", "--divergence-distance", "--divergence-tilt", "--imu-rate", "--gyro-noise",
    "--gyro-bias-walk", "--gyro-range", "--gyro-resolution", "--accel-noise", "--accel-bias-max",
    "--esc-rate", "--esc-latency", "--esc-phase", "--esc-dropout", "--esc-quantisation",
    "--esc-pole-pairs", "--motor-tau", "--rotor-speed-min", "--rotor-speed-max",
    "--prior-kf-std", "--prior-km-std", "--prior-bias-std", "--prior-rate-std",
    "--filter-rate-noise", "--trajectory-period", "--yaw-amplitude", "--yaw-cycles",
    "--filter-coeff-walk", "--filter-bias-walk", NULL};

static int takes_value(const char *name)
{
    for (int i = 0; valued[i] != NULL; i++) {
        if (strcmp(name, valued[i]) == 0) {
            return 1;
        }
    }
    return 0;
}

static int apply(sitl_options_t *o, const char *name, const char *val)
{
    double d;
    const double big = 1e9;
#define NUM(lo, hi, field)                                      \
    do {                                                        \
        if (parse_double(name, val, (lo), (hi), &d) != 0) {     \
            return -1;                                          \
        }                                                       \
        (field) = d;                                            \
    } while (0)

    if (strcmp(name, "--vehicle") == 0) {
        return parse_path(name, val, o->vehicle);
    } else if (strcmp(name, "--trajectory") == 0) {
        if (sitl_trajectory_from_name(val, &o->trajectory) != 0) {
            fprintf(stderr, "propid_sitl: --trajectory: unknown '%s' (hover|step|circle|lissajous)\n",
                    val);
            return -1;
        }
    } else if (strcmp(name, "--mode") == 0) {
        int found = 0;
        for (int i = 0; i < 3; i++) {
            if (strcmp(val, mode_names[i]) == 0) {
                o->mode = (sitl_mode_t)i;
                found = 1;
            }
        }
        if (!found) {
            fprintf(stderr, "propid_sitl: --mode: unknown '%s' (oracle|incorrect|filter)\n", val);
            return -1;
        }
    } else if (strcmp(name, "--seed") == 0) {
        char *end = NULL;
        errno = 0;
        unsigned long long s = strtoull(val, &end, 10);
        if (end == val || *end != '\0' || errno != 0 || val[0] == '-') {
            fprintf(stderr, "propid_sitl: --seed: '%s' is not a non-negative integer\n", val);
            return -1;
        }
        o->seed = (uint64_t)s;
    } else if (strcmp(name, "--duration") == 0) {
        NUM(1e-3, 1e6, o->duration_s);
    } else if (strcmp(name, "--trajectory-period") == 0) {
        NUM(1e-2, 1e6, o->trajectory_period_s);
    } else if (strcmp(name, "--yaw-amplitude") == 0) {
        NUM(0.0, 3.0, o->yaw_amplitude_rad);
    } else if (strcmp(name, "--yaw-cycles") == 0) {
        NUM(0.0, 1e3, o->yaw_cycles);
    } else if (strcmp(name, "--log") == 0) {
        return parse_path(name, val, o->log_path);
    } else if (strcmp(name, "--log-rate") == 0) {
        NUM(0.0, 1e6, o->log_rate_hz);
    } else if (strcmp(name, "--mavlink") == 0) {
        return parse_path(name, val, o->mavlink_url);
    } else if (strcmp(name, "--realtime") == 0) {
        NUM(0.0, 1e6, o->realtime);
    } else if (strcmp(name, "--physics-rate") == 0) {
        NUM(1.0, 1e6, o->physics_rate_hz);
    } else if (strcmp(name, "--control-rate") == 0) {
        NUM(1.0, 1e5, o->control_rate_hz);
    } else if (strcmp(name, "--coeff-spread") == 0) {
        NUM(0.0, 0.95, o->coeff_spread);
    } else if (strcmp(name, "--incorrect-source") == 0) {
        if (strcmp(val, "nominal") == 0) {
            o->incorrect_random = 0;
        } else if (strcmp(val, "random") == 0) {
            o->incorrect_random = 1;
        } else {
            fprintf(stderr, "propid_sitl: --incorrect-source: '%s' (nominal|random)\n", val);
            return -1;
        }
    } else if (strcmp(name, "--incorrect-spread") == 0) {
        NUM(0.0, 0.9, o->incorrect_spread);
    } else if (strcmp(name, "--gyro-bias-max") == 0) {
        NUM(0.0, 10.0, o->imu.gyro.bias_max);
    } else if (strcmp(name, "--effect") == 0) {
        char err[512];
        if (sitl_effects_parse(&o->effects, val, err, (int)sizeof(err)) != 0) {
            fprintf(stderr, "propid_sitl: %s\n", err);
            return -1;
        }
    } else if (strcmp(name, "--summary-json") == 0) {
        return parse_path(name, val, o->summary_json);
    } else if (strcmp(name, "--start-height") == 0) {
        NUM(0.0, 1e4, o->start_height_m);
    } else if (strcmp(name, "--divergence-distance") == 0) {
        NUM(1e-3, big, o->divergence_distance_m);
    } else if (strcmp(name, "--divergence-tilt") == 0) {
        NUM(1.0, 180.0, o->divergence_tilt_deg);
    } else if (strcmp(name, "--imu-rate") == 0) {
        NUM(1.0, 1e5, o->imu.rate_hz);
    } else if (strcmp(name, "--gyro-noise") == 0) {
        NUM(0.0, 1.0, o->imu.gyro.noise_density);
    } else if (strcmp(name, "--gyro-bias-walk") == 0) {
        NUM(0.0, 1.0, o->imu.gyro.bias_walk);
    } else if (strcmp(name, "--gyro-range") == 0) {
        NUM(0.0, 1e3, o->imu.gyro.range);
    } else if (strcmp(name, "--gyro-resolution") == 0) {
        NUM(0.0, 1.0, o->imu.gyro.resolution);
    } else if (strcmp(name, "--accel-noise") == 0) {
        NUM(0.0, 10.0, o->imu.accel.noise_density);
    } else if (strcmp(name, "--accel-bias-max") == 0) {
        NUM(0.0, 10.0, o->imu.accel.bias_max);
    } else if (strcmp(name, "--esc-rate") == 0) {
        NUM(1.0, 1e5, o->esc.rate_hz);
    } else if (strcmp(name, "--esc-latency") == 0) {
        NUM(0.0, 0.5, o->esc.latency_s);
    } else if (strcmp(name, "--esc-phase") == 0) {
        NUM(0.0, 1.0, o->esc.phase_s);
    } else if (strcmp(name, "--esc-dropout") == 0) {
        NUM(0.0, 1.0, o->esc.dropout_prob);
    } else if (strcmp(name, "--esc-quantisation") == 0) {
        if (strcmp(val, "dshot") == 0) {
            o->esc.quantise_dshot = 1;
        } else if (strcmp(val, "none") == 0) {
            o->esc.quantise_dshot = 0;
        } else {
            fprintf(stderr, "propid_sitl: --esc-quantisation: '%s' (dshot|none)\n", val);
            return -1;
        }
    } else if (strcmp(name, "--esc-pole-pairs") == 0) {
        NUM(1.0, 100.0, d);
        o->esc.pole_pairs = (int)d;
    } else if (strcmp(name, "--motor-tau") == 0) {
        NUM(1e-5, 10.0, o->motor_time_constant);
    } else if (strcmp(name, "--rotor-speed-min") == 0) {
        NUM(0.0, 1e5, o->rotor_speed_min);
    } else if (strcmp(name, "--rotor-speed-max") == 0) {
        NUM(1.0, 1e5, o->rotor_speed_max);
    } else if (strcmp(name, "--prior-kf-std") == 0) {
        NUM(1e-6, 10.0, o->prior_kf_rel_std);
    } else if (strcmp(name, "--prior-km-std") == 0) {
        NUM(1e-6, 10.0, o->prior_km_rel_std);
    } else if (strcmp(name, "--prior-bias-std") == 0) {
        NUM(1e-9, 10.0, o->prior_bias_std);
    } else if (strcmp(name, "--prior-rate-std") == 0) {
        NUM(1e-9, 100.0, o->prior_rate_std);
    } else if (strcmp(name, "--filter-rate-noise") == 0) {
        NUM(0.0, 1e4, o->filter_rate_noise);
    } else if (strcmp(name, "--filter-coeff-walk") == 0) {
        NUM(0.0, 10.0, o->filter_coeff_walk);
    } else if (strcmp(name, "--filter-bias-walk") == 0) {
        NUM(0.0, 10.0, o->filter_bias_walk);
    } else {
        fprintf(stderr, "propid_sitl: unknown option '%s' (see --help)\n", name);
        return -1;
    }
#undef NUM
    return 0;
}

int sitl_options_parse(sitl_options_t *o, int argc, char **argv)
{
    const char *prog = argc > 0 ? argv[0] : "propid_sitl";
    /* --paper first: it resets the sensor models, later options refine them. */
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
            sitl_options_print_help(prog);
            return 1;
        }
        if (strcmp(argv[i], "--paper") == 0) {
            o->paper = 1;
        }
    }
    double paper_bias_max = o->imu.gyro.bias_max;
    if (o->paper) {
        sitl_imu_paper_params(&o->imu);
        o->imu.gyro.bias_max = paper_bias_max;
        sitl_esc_paper_params(&o->esc, 0.0); /* rate 0 = the control rate, set below */
    }
    for (int i = 1; i < argc; i++) {
        char name[64];
        const char *arg = argv[i];
        const char *val = NULL;
        if (strncmp(arg, "--", 2) != 0) {
            fprintf(stderr, "propid_sitl: unexpected argument '%s' (see --help)\n", arg);
            return SITL_EXIT_USAGE;
        }
        const char *eq = strchr(arg, '=');
        size_t len = eq != NULL ? (size_t)(eq - arg) : strlen(arg);
        if (len >= sizeof(name)) {
            fprintf(stderr, "propid_sitl: unknown option '%s'\n", arg);
            return SITL_EXIT_USAGE;
        }
        memcpy(name, arg, len);
        name[len] = '\0';
        if (strcmp(name, "--paper") == 0) {
            continue;
        }
        if (strcmp(name, "--quiet") == 0) {
            o->quiet = 1;
            continue;
        }
        if (strcmp(name, "--start-on-ground") == 0) {
            o->start_on_ground = 1;
            continue;
        }
        if (strcmp(name, "--start-at-rest") == 0) {
            o->start_at_rest = 1;
            continue;
        }
        if (strcmp(name, "--imu-sample-at-start") == 0) {
            o->imu_sample_at_start = 1;
            continue;
        }
        if (strcmp(name, "--no-ground") == 0) {
            o->ground_enabled = 0;
            continue;
        }
        if (!takes_value(name)) {
            fprintf(stderr, "propid_sitl: unknown option '%s' (see --help)\n", name);
            return SITL_EXIT_USAGE;
        }
        if (eq != NULL) {
            val = eq + 1;
        } else if (i + 1 < argc) {
            val = argv[++i];
        } else {
            fprintf(stderr, "propid_sitl: %s needs a value\n", name);
            return SITL_EXIT_USAGE;
        }
        if (apply(o, name, val) != 0) {
            return SITL_EXIT_USAGE;
        }
    }
    if (o->esc.rate_hz == 0.0) {
        o->esc.rate_hz = o->control_rate_hz;
    }
    if (o->physics_rate_hz < o->control_rate_hz) {
        fprintf(stderr, "propid_sitl: --physics-rate (%g) must be >= --control-rate (%g)\n",
                o->physics_rate_hz, o->control_rate_hz);
        return SITL_EXIT_USAGE;
    }
    if (o->start_on_ground && !o->ground_enabled) {
        fprintf(stderr, "propid_sitl: --start-on-ground needs the ground (drop --no-ground)\n");
        return SITL_EXIT_USAGE;
    }
    return 0;
}
