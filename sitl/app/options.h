/*
 * propid_sitl command line: every run setting in one struct, defaults,
 * parser and --help text.
 */
#ifndef SITL_OPTIONS_H
#define SITL_OPTIONS_H

#include <stdint.h>

#include "effects.h"
#include "faults.h"
#include "esc_telemetry.h"
#include "imu.h"
#include "trajectory.h"

#define SITL_PATH_MAX 1024
#define SITL_MAX_DAMAGE 8

/* A propeller damage: at time_s rotor's kf and km lose fraction of their value. */
typedef struct {
    int rotor;                          /* 0-based */
    double time_s;
    double fraction;                    /* 0 < fraction < 1 */
} sitl_damage_t;

typedef enum {
    SITL_MODE_ORACLE = 0,    /* controller allocation uses the true coefficients */
    SITL_MODE_INCORRECT = 1, /* fixed wrong coefficients */
    SITL_MODE_FILTER = 2,    /* the filter's current estimates */
} sitl_mode_t;

/* Exit codes of propid_sitl (docs/sitl.md). */
enum {
    SITL_EXIT_OK = 0,
    SITL_EXIT_ERROR = 1,      /* run-time failure: file I/O, link, filter set-up */
    SITL_EXIT_USAGE = 2,      /* bad command line or vehicle file */
    SITL_EXIT_DIVERGED = 3,   /* the flight diverged and was stopped */
    SITL_EXIT_INTERRUPTED = 130, /* stopped by SIGINT/SIGTERM (log kept) */
};

typedef struct {
    char vehicle[SITL_PATH_MAX];        /* preset name or JSON path */
    sitl_trajectory_kind_t trajectory;
    sitl_mode_t mode;
    uint64_t seed;
    uint64_t vehicle_seed;              /* the airframe's draws (--vehicle-seed) */
    int vehicle_seed_set;               /* 0: the vehicle is drawn from seed */
    double duration_s;                  /* how long the flight lasts */
    double trajectory_period_s;         /* the trajectory's period T (independent of it) */
    double yaw_amplitude_rad;           /* < 0 = the trajectory's default */
    double yaw_cycles;                  /* < 0 = the trajectory's default */
    double lissajous_climb_m;           /* vertical amplitude of the fast Lissajous; < 0 = default (0) */
    char log_path[SITL_PATH_MAX];       /* "" = no log */
    double log_rate_hz;                 /* 0 = every control step */
    char mavlink_url[SITL_PATH_MAX];    /* "" = no link */
    double realtime;                    /* 0 = as fast as possible */
    double physics_rate_hz;             /* 0 = derived from the vehicle (physics_rate.h) */
    double control_rate_hz;
    double coeff_spread;                /* true = nominal * U(1-s, 1+s) */
    int incorrect_random;               /* 0: Incorrect uses nominal; 1: random around truth */
    double incorrect_spread;            /* relative std of the random Incorrect draw */
    sitl_effects_t effects;
    sitl_fault_config_t faults;         /* --fault (all off by default) */
    int quiet;
    char summary_json[SITL_PATH_MAX];   /* "" = none */
    char nees_dump[SITL_PATH_MAX];      /* "" = none: every NEES sample's error and covariance */
    int paper;                          /* --paper was given */
    int help;                           /* --help or -h was given */
    double start_height_m;              /* trajectory origin z */
    int start_on_ground;                /* start at rest on the ground below the origin */
    int start_at_rest;                  /* start at the origin with zero velocity */
    int start_trimmed;                  /* start on the trajectory's attitude, rate and thrust */
    int honesty_cov_check;              /* the whole P checked for definiteness (summary cov_checks) */
    int esc_split_steps;                /* end a physics step at every ESC report (the earlier loop) */
    int imu_split_steps;                /* end a physics step at every IMU sample (the earlier loop) */
    int ground_enabled;
    double divergence_distance_m;       /* stop when farther than this from the reference */
    double divergence_tilt_deg;         /* stop when tilted more than this */

    sitl_imu_params_t imu;
    int imu_sample_at_start;            /* first IMU sample at t = 0, not after one period */
    sitl_esc_params_t esc;

    /* Vehicle overrides (< 0 = keep the vehicle's value). */
    double motor_time_constant;
    double disturbance_torque_std;      /* random body torque [N m] per axis, 0: none */
    double disturbance_torque_time;     /* its correlation time [s] */
    double rotor_speed_min;
    double rotor_speed_max;

    /* Filter prior overrides (< 0 = propid_config_default). */
    double prior_kf_rel_std;
    double prior_km_rel_std;
    double prior_bias_std;
    double prior_rate_std;              /* rate_std0 [rad/s] */
    double prior_accel_bias_std;        /* accel_bias_std0 [m/s^2], with filter_accel */
    double filter_accel_noise;          /* accel_noise_std [m/s^2 per sample], with filter_accel */
    double filter_accel_error_std;      /* accel_error_std [m/s^2] (0: off), with filter_accel */
    double filter_accel_error_time;     /* accel_error_time [s], with filter_accel_error_std */
    /* Filter tuning overrides (< 0 = propid_config_default). */
    double filter_rate_noise;           /* rate_process_noise [rad/s^2/sqrt(Hz)] */
    double filter_coeff_walk;           /* thrust_ and drag_coeff_rel_walk [1/sqrt(s)] */
    double filter_bias_walk;            /* gyro_bias_walk [rad/s/sqrt(s)] */
    /* The filter's optional model terms and sensors (docs/math.md §7-9, §12). */
    int filter_disturbance;             /* 1: disturbance-torque states */
    double filter_disturbance_bandwidth; /* their bandwidth [Hz] (docs/math.md §7); 0: the library's walk */
    int filter_accel;                   /* 1: accelerometer aiding with the vehicle's mass */
    int filter_torque_scale;            /* 1: with filter_accel, the thrust-torque scale state */
    int filter_rotor_inertia;           /* 1: the vehicle's rotor inertia in the filter's model */
    double filter_esc_delay_s;          /* telemetry delay the filter holds [s]: > 0 rotor speeds lag */
    double filter_rotor_speed_noise;    /* rotor_speed_noise [rad/s] (docs/math.md §14); 0: off */
    double filter_rotor_speed_noise_time; /* rotor_speed_noise_time [s] */
    double filter_gyro_stuck_samples;   /* gyro_stuck_samples (whole number; 0: off) */
    double filter_inertia_rel_std;      /* inertia_rel_std: the vehicle file's inertia scale std; 0: exact */
    int filter_rotor_speed_noise_hold;    /* rotor_speed_noise_hold (docs/math.md §14); 0: off */
    int filter_decode_error_split;      /* with --filter-sensor-errors: the decode's error as its common mean and
                                           independent spread (sensor_errors.h) */
    int filter_input_error_compensation;  /* input_error_compensation (docs/math.md §14); 0: off */
    int filter_instrument;                /* motor_command_instrument: the commands pushed to the filter
                                             as its rotor input's instrument (docs/math.md §16); 0: off */
    int filter_aero_damping;              /* 1: the airframe's rate damping (its aero_damping effect at
                                             hover speed) in the filter's model (docs/math.md §17) */
    int filter_sensor_errors;           /* input-error terms from the sensor model (sensor_errors.h) */
    int filter_report_age;              /* delay + the fused report's mean age in whole gyro periods (sensor_errors.h) */

    /* Propeller damage scenario and the firmware's damage detector. */
    sitl_damage_t damage[SITL_MAX_DAMAGE];
    int damage_count;
    int detect_damage;                  /* run propid_damage_step after every gyro sample */
    double damage_false_alarms_per_hour; /* detector design rate (< 0 = library default) */
    double damage_design_loss;          /* detector's derived design loss (< 0 = library default: off) */
    int damage_landed_input;            /* the plant's ground contact to propid_damage_set_landed */
    double oracle_damage_delay_s;       /* Oracle mode: the allocation learns a loss this late (0 = at once) */
    double null_dither;                 /* null-space excitation, fraction of mean Omega^2 (0 = off) */
} sitl_options_t;

void sitl_options_default(sitl_options_t *opts);

/* Parse argv. Returns 0 to run, 1 if --help was printed, or SITL_EXIT_USAGE
 * after printing the reason to stderr. */
int sitl_options_parse(sitl_options_t *opts, int argc, char **argv);

void sitl_options_print_help(const char *prog);

const char *sitl_mode_name(sitl_mode_t mode);

/* The seed of the vehicle's own draws (true coefficients, a random Incorrect mixer,
 * the IMU's constant biases): --vehicle-seed when given, else --seed. */
uint64_t sitl_options_vehicle_seed(const sitl_options_t *opts);

#endif /* SITL_OPTIONS_H */
