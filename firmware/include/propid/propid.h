/*
 * propid — in-flight identification of per-propeller thrust and drag
 * coefficients from gyro and ESC rotor-speed telemetry.
 *
 * The one header an autopilot includes. C11, float32 only, no allocation:
 * the caller owns a propid_filter_t (static or on its own stack) and feeds it
 *
 *   propid_push_rotor_speeds()  whenever ESC telemetry arrives (any rate),
 *   propid_push_gyro()          for every gyro sample (any rate): the filter
 *                               predicts to the gyro time with the rotor
 *                               speeds averaged over the interval (previous
 *                               and latest), then fuses the three axes,
 *
 * and reads propid_get_estimate() whenever it wants the coefficients.
 *
 * Units are SI, body frame FLU (x forward, y left, z up), rotor speeds are
 * positive magnitudes in rad/s, timestamps are microseconds of one monotonic
 * clock shared by both streams.
 *
 * Every function returning propid_status_t leaves the filter bit-for-bit
 * unchanged (core state and covariance) when it returns a negative status;
 * only the rejection counters move.
 */
#ifndef PROPID_H
#define PROPID_H

#include <stdint.h>

#include "propid/propid_config.h"

#ifdef __cplusplus
extern "C" {
#endif

/* ------------------------------------------------------------------------ */
/* Status codes: 0 accepted, > 0 accepted with a note, < 0 rejected.        */
/* ------------------------------------------------------------------------ */
typedef enum {
    PROPID_OK = 0,
    PROPID_OK_GATED = 1,              /* predicted; at least one axis' update was gated out */
    PROPID_OK_QUEUED = 2,             /* valid, held in the telemetry-delay buffer: fused when the
                                         other stream catches up (outcome in counters and health) */

    PROPID_ERR_NULL = -1,             /* a pointer argument was NULL */
    PROPID_ERR_NOT_INITIALISED = -2,  /* propid_init() has not succeeded on this filter */
    PROPID_ERR_CONFIG = -3,           /* configuration rejected (see propid_config_check) */
    PROPID_ERR_NOT_FINITE = -4,       /* NaN or Inf in an input sample */
    PROPID_ERR_ROTOR_SPEED_NEGATIVE = -5,
    PROPID_ERR_ROTOR_SPEED_RANGE = -6, /* above config.max_rotor_speed, or changed since the previous
                                          sample faster than a motor of config.motor_time_constant can;
                                          a motor command outside 0..1 */
    PROPID_ERR_ROTOR_COUNT = -7,      /* sample's rotor count differs from the configuration */
    PROPID_ERR_ROTOR_INDEX = -8,      /* rotor index out of range */
    PROPID_ERR_GYRO_RANGE = -9,       /* |gyro| beyond config.gyro_range (saturated sensor) */
    PROPID_ERR_TIME_BACKWARDS = -10,  /* timestamp not after the previous one of its stream */
    PROPID_ERR_TIME_JUMP = -11,       /* gyro gap longer than config.max_gyro_gap_us: call propid_resync() */
    PROPID_ERR_NO_ROTOR_DATA = -12,   /* gyro sample before any rotor speeds were pushed */
    PROPID_ERR_ROTOR_STALE = -13,     /* latest rotor speeds older than config.rotor_stale_us */
    PROPID_ERR_NUMERIC = -14,         /* the step would have produced a non-finite state */
    PROPID_ERR_ACCEL_RANGE = -15,     /* |specific force| beyond config.accel_range (saturated sensor) */
} propid_status_t;

/* Number of distinct rejection reasons; counters.rejected[] is indexed by -status. */
#define PROPID_REJECT_SLOTS 16

/* Largest rotor_speed_noise_time [s]: a quantised speed at hover can stand on one
 * telemetry code for a whole flight (docs/math.md §14, "Hold time from the telemetry"). */
#define PROPID_ROTOR_SPEED_NOISE_TIME_MAX 600.0f

/* Largest rotor_timing_error [s]: a report older than a second is no rotor speed. */
#define PROPID_ROTOR_TIMING_ERROR_MAX 1.0f

/* ------------------------------------------------------------------------ */
/* Health flags (propid_estimate_t.health)                                  */
/* ------------------------------------------------------------------------ */
#define PROPID_HEALTH_NO_ROTOR_DATA   (1u << 0) /* no rotor speeds yet */
#define PROPID_HEALTH_ROTOR_STALE     (1u << 1) /* last gyro sample found stale rotor data */
#define PROPID_HEALTH_GATED           (1u << 2) /* last gyro sample had a gated axis */
#define PROPID_HEALTH_COV_REPAIRED    (1u << 3) /* covariance repaired since last reset (sticky) */
#define PROPID_HEALTH_STATE_CLAMPED   (1u << 4) /* a coefficient sat on its clamp after the last update, or the
                                                   predicted body rate was bounded to 2 gyro_range */
#define PROPID_HEALTH_GATE_REOPENED   (1u << 5) /* an axis was re-opened after too many gated samples (sticky) */
#define PROPID_HEALTH_ALL_CONVERGED   (1u << 6) /* every kf and km has converged */
#define PROPID_HEALTH_TIME_RESYNCED   (1u << 7) /* propid_resync() was used since last reset (sticky) */
#define PROPID_HEALTH_ROTOR_DAMAGE    (1u << 8) /* propid_damage_step() detected a damaged rotor (sticky) */
#define PROPID_HEALTH_MODEL_MISMATCH  (1u << 9) /* the gyro innovations were inconsistent with their
                                                   variances (windowed NIS above its chi-square bound)
                                                   in one of the last few windows: the model misses
                                                   something; no coefficient is reported converged
                                                   (PROPID_CONSISTENCY builds; docs/reliability.md) */

/* ------------------------------------------------------------------------ */
/* Configuration                                                            */
/* ------------------------------------------------------------------------ */
typedef struct {
    float position_m[3];          /* rotor hub in body FLU relative to the centre of mass [m] */
    float yaw_sign;               /* +1 or -1: sign of the yaw torque its drag puts on the body */
    float thrust_coeff_nominal;   /* kf prior mean [N/(rad/s)^2], > 0 */
    float drag_coeff_nominal;     /* km prior mean [N m/(rad/s)^2], > 0 */
} propid_rotor_config_t;

typedef struct {
    uint8_t rotor_count;                          /* 1..PROPID_MAX_ROTORS */
    propid_rotor_config_t rotor[PROPID_MAX_ROTORS];
    float inertia[3][3];                          /* body inertia [kg m^2], symmetric positive definite */

    /* Prior standard deviations. Coefficients are relative to their nominal. */
    float rate_std0;                  /* body rate [rad/s] */
    float thrust_coeff_rel_std0;      /* e.g. 0.2 = 20 % of nominal */
    float drag_coeff_rel_std0;
    float gyro_bias_std0;             /* [rad/s] */

    /* Noise. Per-sample gyro variance = gyro_noise_density^2 * gyro_sample_rate_hz. */
    float gyro_noise_density;         /* [rad/s/sqrt(Hz)] */
    float gyro_sample_rate_hz;        /* nominal gyro rate the density applies to [Hz] */
    float rate_process_noise;         /* unmodelled angular acceleration [rad/s^2/sqrt(Hz)] */
    float thrust_coeff_rel_walk;      /* random walk of kf/kf_nominal [1/sqrt(s)] */
    float drag_coeff_rel_walk;        /* random walk of km/km_nominal [1/sqrt(s)] */
    float gyro_bias_walk;             /* [rad/s/sqrt(s)] */

    /* Guards. */
    float gate_sigma;                 /* innovation gate in standard deviations, >= 1; <= 0 disables it
                                         (innovations beyond 1e15 sigma are still gated) */
    uint16_t gate_max_consecutive;    /* gated samples in a row before an axis is re-opened */
    uint16_t gyro_stuck_samples;      /* >= 2: a gyro axis whose reading repeats bit for bit this many
                                         samples in a row (a stuck sensor, bus or FIFO) is not fused
                                         from that sample on until it changes (counters.gyro_stuck,
                                         flag GATED): its constant reading would otherwise be explained
                                         by the coefficients (docs/reliability.md "A stuck gyro axis").
                                         0: off. Full build only (the quad build refuses a nonzero
                                         value). (In the padding after gate_max_consecutive.) */
    float max_rotor_speed;            /* larger rotor speeds are absurd [rad/s] */
    float gyro_range;                 /* larger |gyro| is a saturated sensor [rad/s] */
    uint32_t rotor_stale_us;          /* rotor data older than this at a gyro sample is stale */
    uint32_t max_gyro_gap_us;         /* longer gap between gyro samples is a time jump */
    float coeff_rel_min;              /* clamp of kf/kf_nom and km/km_nom, e.g. 0.05 */
    float coeff_rel_max;              /* e.g. 5 */
    float converged_rel_std;          /* relative error a "converged" claim bounds: claimed when 3 x the
                                         relative std is below it and the consistency monitor vouches */

    /* Optional model terms and sensors (docs/math.md §7-9). Each is off at its
     * default: the plain filter is the 6 + 2N state one above. */
    float rotor_inertia[PROPID_MAX_ROTORS]; /* spinning inertia of rotor + motor bell [kg m^2];
                                               0: its yaw reaction and gyroscopic torque not modelled */
    uint8_t disturbance_torque;       /* 1: estimate a slowly varying body torque (3 more states) */
    float disturbance_std0;           /* its prior std, as angular acceleration J^-1 tau [rad/s^2] */
    float disturbance_walk;           /* its random walk [rad/s^2/sqrt(s)] */
    float disturbance_bandwidth;      /* > 0 [Hz]: the walk is 2 pi f rate_process_noise instead, so the
                                         states take the torque residual below f (what a controller of
                                         that bandwidth cancels) and kf/km learn above it (math.md §7) */
    float mass;                       /* vehicle mass [kg]; > 0 enables propid_push_accel()
                                         (1 more state: the accelerometer's z bias) */
    float accel_noise_std;            /* per-sample noise of the z specific force [m/s^2] */
    float accel_bias_std0;            /* [m/s^2] */
    float accel_bias_walk;            /* [m/s^2/sqrt(s)] */
    float accel_range;                /* larger |specific force| is a saturated sensor [m/s^2] */
    uint8_t torque_scale;             /* 1 (needs mass > 0): estimate the scale of the thrust torques
                                         J^-1 (r x z) kf relative to the configured J and arms (1 more
                                         state): kf's scale then comes from the accelerometer alone */
    float torque_scale_std0;          /* prior std of that scale (nominal 1) */
    float torque_scale_walk;          /* its random walk [1/sqrt(s)]; 0: a constant (a pure J or arm
                                         error). > 0 when the torque gain the gyro sees varies during a
                                         flight (errors in the rotor-speed regressor, docs/math.md §9) */
    int32_t rotor_delay_us;           /* telemetry delay [us] (docs/math.md §12): > 0, the rotor speeds
                                         lag the gyro (the speed the body had at t arrives stamped
                                         t + delay): gyro and accelerometer samples are held until
                                         then; < 0, the gyro lags the rotor speeds: rotor samples are
                                         held |delay|. 0: none. Bounded by PROPID_DELAY_SLOTS. */
    float rotor_speed_noise;          /* std of the error of a rotor-speed sample [rad/s] (telemetry
                                         resolution, timing): enters the rate process noise through the
                                         torque Jacobian (docs/math.md §14). 0: exact inputs (off) */
    float rotor_speed_noise_time;     /* correlation time of that error [s]: how long one error stays
                                         in the input (e.g. the telemetry interval; with the hold below
                                         its ceiling); 0: one step. At most
                                         PROPID_ROTOR_SPEED_NOISE_TIME_MAX */

    /* What the data cannot tell (docs/reliability.md "Converged claims"). */
    float inertia_rel_std;            /* relative std of the configured inertia's scale (how well the
                                         vehicle file knows J, e.g. 0.1 from CAD): gyro and rotor speeds
                                         see kf/J and km/J only, so a scale error of J passes 1:1 into kf
                                         and km, invisible to every test. A converged claim counts it
                                         (for kf not when torque_scale separates it). 0: J exact */
    float motor_time_constant;        /* the motors' time constant [s] (speed loop as a first-order lag,
                                         its fastest response): bounds how fast a true rotor speed can
                                         change between two samples; faster changes are refused
                                         (ESC spikes within range, docs/reliability.md) */
    uint8_t input_error_compensation; /* 1 (needs rotor_speed_noise > 0): remove from each gyro update
                                         of the coefficients the part the rotor-speed error explains
                                         on average (errors-in-variables bias, docs/math.md §14).
                                         0: off */
    uint8_t motor_command_instrument; /* 1: the rotor input u_i = Omega_i^2 is the first stage's
                                         projection of the telemetry on the motor commands
                                         (propid_push_motor_command; docs/math.md §16): the
                                         telemetry's error then stays out of the regressor.
                                         0: off, the telemetry as measured */
    uint8_t rotor_speed_noise_hold;   /* 1 (needs rotor_speed_noise > 0, no compensation): the error's
                                         correlation time per rotor from the telemetry itself, how long
                                         the rotor's value has stood (renewed when it changes), with
                                         rotor_speed_noise_time its ceiling (docs/math.md §14). 2: the
                                         same hold with rotor_speed_noise_time its floor and
                                         PROPID_ROTOR_SPEED_NOISE_TIME_MAX its ceiling. 0: the
                                         configured time for every rotor */
    uint8_t rotor_speed_noise_split;  /* 1 (needs rotor_speed_noise > 0, no compensation): the error is
                                         a truncation's (a decode at the code's period), rotor_speed_noise
                                         its root mean square q / sqrt(3): its mean q / 2 is one error
                                         common to every rotor, its spread q / sqrt(12) each rotor's
                                         own, both over each rotor's span (docs/math.md §14, "An error
                                         common to every rotor"; in the padding: the struct's size and
                                         offsets unchanged). 0: independent per rotor */
    float motor_command_lag;          /* [s] first-order lag of the rotor speed behind its command
                                         in the first stage (> 0 with the instrument on) */
    float motor_command_memory;       /* [s] forgetting time of the first stage's fit (battery sag);
                                         > 0 with the instrument on */
    float motor_command_min_f;        /* weak-instrument guard: a rotor's first stage replaces its
                                         telemetry only while the F statistic of its increments' fit
                                         (over the fit's effective sample count) is >= this
                                         (docs/math.md §16). 0: no guard */
    float aero_damping[3];            /* known aerodynamic rate damping [N m s/rad] per body axis: a
                                         body torque -aero_damping[a] omega_a (docs/math.md §17; the
                                         vehicle file's key of that name). 0: not modelled. Full build
                                         only (the quad build refuses a nonzero value) */
    float accel_error_std;            /* > 0 (needs mass > 0): the accelerometer row's slow model error
                                         (vertical forces the row leaves out, the rotor speeds' decode
                                         error) as one more state, a first-order Gauss-Markov process of
                                         this stationary std [m/s^2] beside the z bias (docs/math.md §9,
                                         "The row's model error"). 0: off (the row's error is white) */
    float accel_error_time;           /* its correlation time [s] (> 0 with accel_error_std > 0) */
    float rotor_timing_error;         /* std of a rotor-speed report's age error [s], one error common
                                         to the rotors of a report (latency, hold): while the speeds
                                         change, the report stands for the speed of another instant,
                                         and the step's input is off by that time x du/dt
                                         (docs/math.md §14, "The report's timing"). At most
                                         PROPID_ROTOR_TIMING_ERROR_MAX. Full build only (the quad
                                         build refuses a nonzero value). 0: off */
} propid_config_t;

/* Fill every noise, prior and guard field with documented defaults (docs/design.md)
 * and set rotor_count = 0: the caller then sets geometry, inertia and nominals. */
void propid_config_default(propid_config_t *config);

/* Place rotor_count rotors evenly on a circle of radius arm_m in the body xy-plane,
 * rotor 0 at angle first_angle_rad from +x (0 = plus frame, pi/4 = X frame),
 * counting counter-clockwise seen from above, yaw signs alternating starting with
 * first_yaw_sign, all with the same nominal coefficients. */
propid_status_t propid_config_set_symmetric(propid_config_t *config, uint8_t rotor_count,
                                            float arm_m, float first_angle_rad,
                                            float first_yaw_sign, float thrust_coeff_nominal,
                                            float drag_coeff_nominal);

/* Diagonal inertia convenience. */
void propid_config_set_inertia_diag(propid_config_t *config, float jxx, float jyy, float jzz);

/* PROPID_OK or PROPID_ERR_CONFIG; *bad_field (may be NULL) names the first bad field. */
propid_status_t propid_config_check(const propid_config_t *config, const char **bad_field);

/* ------------------------------------------------------------------------ */
/* Filter object: allocate it yourself; touch it only through the API.      */
/* ------------------------------------------------------------------------ */
/* Covariance storage (private): only the upper triangle of the symmetric P is
 * kept, row by row, P_ij (i <= j) at cov[propid_cov_index(i, j)]: row i holds
 * P_ii .. P_i,(PROPID_MAX_STATES-1) contiguously. */
#define PROPID_COV_SIZE (PROPID_MAX_STATES * (PROPID_MAX_STATES + 1) / 2)
/* Index of P_ij in the packed triangle, for either order of i and j. */
static inline uint32_t propid_cov_index(uint32_t i, uint32_t j)
{
    const uint32_t row = i <= j ? i : j;
    const uint32_t column = i <= j ? j : i;
    return row * (2u * PROPID_MAX_STATES - 1u - row) / 2u + column;
}

typedef struct {
    /* Private: the gyro step's work area, meaningless between calls (off the
     * stack): the one pass's P H^T of the y and z axes, the per-axis update's
     * P H^T (update_vector[0]), and in the quad build the prediction's Jacobian
     * rows. First, so the update kernels reach it and the state from one base
     * register. */
    float update_vector[2][PROPID_MAX_STATES];
    /* Scaled state: body rate [rad/s], kf/kf_nominal in the torque basis (Q kf/kf_nominal),
     * km/km_nominal in the yaw basis (H km/km_nominal; P's coefficient rows too:
     * propid_internal.h, propid_reflection_t), gyro bias [rad/s]. */
    float state[PROPID_MAX_STATES];
    float cov[PROPID_COV_SIZE];                       /* symmetric, kept in the scaled units: the
                                                         packed upper triangle (propid_cov_index) */
    float rotor_speed_sq[PROPID_MAX_ROTORS];          /* latest accepted rotor speeds squared */
    float input_speed_sq[PROPID_MAX_ROTORS];          /* rotor speeds squared in force at time_us
                                                         (start of the next prediction interval) */
    /* (Ordered so the 64-bit stamps need no padding before them.) */
    uint32_t stale_mark;                              /* private: counters.rejected[-ROTOR_STALE] at
                                                         last accepted gyro */
    uint64_t rotor_time_us;                           /* time of the latest accepted rotor speeds */
    uint64_t time_us;                                 /* filter time = last accepted gyro time */
    uint8_t has_rotor_data;
    uint8_t has_time;
    uint16_t gated_run[3];                            /* consecutive gated samples per axis */
#if PROPID_WITH_ACCEL
    uint16_t accel_gated_run;                         /* consecutive gated accelerometer samples */
    uint8_t has_accel;
    uint64_t accel_time_us;                           /* time of the latest accepted accelerometer sample */
#endif
    uint32_t health;                                  /* PROPID_HEALTH_* (sticky and per-step bits) */
    /* Private (not part of the API contract): */
    float innovation[3];                              /* last gyro innovation per axis [rad/s] */
    float innovation_test_ratio[3];                   /* last innovation^2 / (gate^2 * S) */
#if PROPID_WITH_ACCEL
    float accel_innovation;                           /* last accelerometer z innovation [m/s^2] */
    float accel_innovation_test_ratio;
#endif
    uint8_t check_row;                                /* next covariance row of the round-robin integrity check */
#if PROPID_WITH_INPUT_NOISE
    /* Private: the input-error compensation's memory per gyro axis (propid_input_compensation.c),
     * in units of one sample's error variance: E[x^2] and E[x e] of the error x the rate
     * estimate still carries after the update. */
    float input_error_carried[3];
    float input_error_cross[3];
    /* Since init/reset, per axis, dt-weighted means of the information each update draws
     * about the coefficients' common scale, and of the part of it the configured error
     * explains (the compensation's validity test). */
    float input_information[3];
    float input_error_information[3];
    float input_information_time;
    /* Private work area of one gyro step (meaningless between calls; in the filter object,
     * not on the stack): per axis the factors f_a per coefficient column, and the products
     * with the coefficient block, product[0] = P theta, product[1 + a] = P f_a (axis a's
     * correction); the update's rate gain, the step's memory terms, the validity flags. */
    float input_factor[3][2 * PROPID_MAX_ROTORS];
    float input_product[4][2 * PROPID_MAX_ROTORS];
    float input_rate_gain[3];
    float input_step_carried[3];
    float input_step_cross[3];
    uint8_t input_valid[3];
    /* Per rotor, how long its input value has stood before the current step [s]
     * (rotor_speed_noise_hold; 0 after init, reset and a change). */
    float input_hold_age[PROPID_MAX_ROTORS];
#endif
#if PROPID_WITH_GYRO_STUCK_CHECK
    /* Private (config.gyro_stuck_samples): per axis the last reading's bits and
     * how many readings in a row had them. Last: the step's offsets unchanged. */
    uint32_t gyro_last_bits[3];
    uint16_t gyro_repeat_run[3];
#endif
} propid_core_t;

typedef struct {
    uint32_t gyro_accepted;
    uint32_t rotor_accepted;
    uint32_t axis_gated[3];           /* scalar updates skipped by the gate, per axis */
    uint32_t gate_reopened;
    uint32_t cov_repairs;
    uint32_t state_clamps;
    uint32_t resyncs;
    uint32_t rejected[PROPID_REJECT_SLOTS]; /* indexed by -status */
    uint32_t accel_accepted;
    uint32_t accel_gated;             /* accelerometer updates skipped by the gate */
    uint32_t accel_reanchored;        /* z bias re-anchored after too many gated samples */
    uint32_t delay_overflows;         /* samples released early because the delay buffer was full */
    uint32_t model_mismatch;          /* NIS windows above their chi-square bound (0 when
                                         PROPID_CONSISTENCY is 0) */
    uint32_t gyro_stuck;              /* axis-samples not fused as stuck (config.gyro_stuck_samples) */
} propid_counters_t;

/* State layout: the first index of each block of the scaled state. Fixed blocks
 * first (rates, kf, km, gyro biases), then the optional ones the configuration
 * enables (PROPID_NO_STATE when off). */
#define PROPID_NO_STATE 0xFFu
typedef struct {
    uint8_t rate;                                   /* body rate (3) */
    uint8_t thrust;                                 /* kf / kf_nominal (rotor_count); s kf / kf_nominal
                                                       with the torque scale (docs/math.md §9) */
    uint8_t drag;                                   /* km / km_nominal (rotor_count) */
    uint8_t gyro_bias;                              /* gyro bias (3) */
    uint8_t disturbance;                            /* disturbance angular acceleration (3) or none */
    uint8_t accel_bias;                             /* accelerometer z bias (1) or none */
    uint8_t torque_scale;                           /* r = 1/s of the thrust-torque scale (1) or none */
} propid_layout_t;

/* Quantities derived once from the configuration (so the step does no divisions). */
typedef struct {
    uint8_t state_count;                            /* 6 + 2 * rotor_count (+ optional blocks) */
    uint8_t quad_layout;                            /* private: 1 when the step's fixed quad kernels
                                                       apply (jac_* in the fixed layout, see
                                                       propid_internal.h); fills padding */
    uint8_t quad_core;                              /* private: 1 for the plain quad (14 states in
                                                       the fixed order): the gyro's one-pass update */
    propid_layout_t layout;
    uint16_t motor_tau_100us;                       /* private: motor_time_constant in 100 us (the
                                                       rotor-speed slew test, propid_filter.c; 16 bits
                                                       fill the padding after the layout) */
#if PROPID_GENERAL_VEHICLES /* (the quad build needs them at initialisation only) */
    float inertia_inv[3][3];
    float thrust_torque[PROPID_MAX_ROTORS][3];      /* J^-1 (r_i x z) kf_nominal_i */
    float drag_torque[PROPID_MAX_ROTORS][3];        /* J^-1 z yaw_sign_i km_nominal_i */
#endif
    float gyro_var;                                 /* per-sample measurement variance */
    /* Private (not part of the API contract): */
    float gate_sq;                                  /* gate_sigma^2, PROPID_GATE_OFF_SQ when gating is off */
    float inv_gate_sq;                              /* 1 / gate_sq (1 when gating is off) */
    float claim_var;                                /* private: relative variance of a coefficient
                                                       below which it is claimed converged (3 std and
                                                       the inertia's uncertainty: propid_config.c) */
#if PROPID_GENERAL_VEHICLES /* (the quad build: 2 config.gyro_range, propid_rate_limit) */
    float rate_limit;                               /* |predicted body rate| bound: 2 gyro_range */
#endif
    uint32_t innovation_range_bits;                 /* bits(S at which R is loaded) - bits(gyro_var)
                                                       (S range test, on gyro_var's bit pattern) */
    /* Process noise, prior and variance bounds are the same for every state of a
     * kind (rate, thrust, drag, gyro bias and each optional block): one value per
     * kind, state_kind[i] the kind of state i (propid_internal.h: propid_prior_var ...;
     * without the general path the quad layout fixes it: propid_state_kind). */
#if PROPID_GENERAL_VEHICLES
    uint8_t state_kind[PROPID_MAX_STATES];
#endif
    float kind_process_psd[PROPID_STATE_KINDS];     /* Q rate: Q_ii = psd * dt */
    float kind_prior_var[PROPID_STATE_KINDS];       /* prior variance */
    uint32_t kind_floor_bits[PROPID_STATE_KINDS];   /* bit pattern of the variance floor */
    uint32_t kind_range_bits[PROPID_STATE_KINDS];   /* bits(ceiling) - bits(floor): the ceiling's
                                                       value follows (propid_var_ceiling) */
    /* Sparsity of the 3 rate rows of A = df/dx (structurally non-zero entries only,
     * fixed by geometry and inertia): row a has jac_count[a] entries, the first
     * jac_rate_count[a] of them in rate columns, the rest in coefficient columns
     * (the quad layout: 6 entries in fixed columns, propid_internal.h). */
#if PROPID_GENERAL_VEHICLES
    uint8_t jac_count[3];
    uint8_t jac_rate_count[3];
    uint8_t jac_column[3][PROPID_MAX_STATES - 3];   /* state index of each entry */
    uint8_t jac_rotor[3][PROPID_MAX_STATES - 3];    /* coefficient entry: its rotor */
    float jac_torque[3][PROPID_MAX_STATES - 3];     /* coefficient entry: A = jac_torque * u_rotor */
    float gyro_jacobian[3][3][3];                   /* A_ab = sum_c gyro_jacobian[a][b][c] omega_c */
#else
    float jac_torque[3][4];                         /* the quad layout's rotor entries 2..5 */
#endif
    /* Optional terms' data: compiled out with their terms (propid_config.h). */
#if PROPID_WITH_ROTOR_INERTIA
    uint8_t rotor_inertia_on;                       /* any config.rotor_inertia > 0 */
    float rotor_momentum[PROPID_MAX_ROTORS];        /* yaw_sign_i J_r,i: h = sum_i rotor_momentum_i Omega_i */
    float rotor_gyro[3][2];                         /* rotor gyroscopic term: A_ab += rotor_gyro[a][b] h, b < 2 */
    float rotor_reaction[PROPID_MAX_ROTORS][3];     /* J^-1 z yaw_sign_i J_r,i: delta omega per delta Omega_i */
#endif
#if PROPID_WITH_AERO_DAMPING
    uint8_t aero_damping_on;                        /* any config.aero_damping > 0 */
    float aero_damping[3][3];                       /* -J^-1 D: its rate acceleration A_ab omega_b */
#endif
#if PROPID_WITH_ACCEL
    float thrust_per_mass[PROPID_MAX_ROTORS];       /* kf_nominal_i / mass (accelerometer row) */
    float accel_var;                                /* accel_noise_std^2 */
#endif
#if PROPID_WITH_INPUT_NOISE
    float input_noise_var;                          /* 4 rotor_speed_noise^2: Var(u_i) per unit u_i */
    float input_noise_time;                         /* rotor_speed_noise_time */
    float input_timing_error;                       /* config.rotor_timing_error */
    uint8_t input_compensation;                     /* config.input_error_compensation */
    uint8_t input_noise_hold;                       /* config.rotor_speed_noise_hold */
    uint8_t input_noise_split;                      /* config.rotor_speed_noise_split (input_noise_var is
                                                       then the spread's, the common part 3x it; in the
                                                       padding before quad_gyro) */
#endif
#if PROPID_WITH_INPUT_NOISE || PROPID_WITH_GYRO_STUCK_CHECK
    uint8_t rare_gyro_update;                       /* input compensation on or gyro_stuck_samples > 0:
                                                       the step's one test for either (in the padding
                                                       before quad_gyro: the step's offsets unchanged) */
#endif
    float quad_gyro[3];                             /* quad layout only: A_ab = quad_gyro[a] omega_c for
                                                       both other axes b, c of row a (symmetric in b, c) */
    /* Private: the thrust coefficients' torque basis (propid_internal.h,
     * propid_thrust_basis): Q = H_1 H_0, H_k = I - w w^T, H_0's w the first
     * PROPID_MAX_ROTORS entries, H_1's (on elements 1..N-1) the rest. */
    float thrust_basis[2 * PROPID_MAX_ROTORS - 1];
#if PROPID_GENERAL_VEHICLES /* (the quad build: a table in flash, propid_internal.h) */
    /* Private: the drag coefficients' yaw basis (propid_internal.h, propid_drag_basis):
     * the reflection H = I - drag_basis_scale v v^T with v = drag_basis. */
    float drag_basis[PROPID_MAX_ROTORS];
    float drag_basis_scale;
#endif
#if PROPID_WITH_ACCEL /* (last: the step's offsets before it unchanged) */
    float accel_error_rate;                         /* 1 / accel_error_time (its decay per second) */
    uint8_t accel_error;                            /* the row's model-error state: accel_bias + 1, or
                                                       PROPID_NO_STATE (config.accel_error_std 0) */
#endif
} propid_derived_t;

#if PROPID_DELAY_SLOTS > 0
/* Telemetry-delay buffer (private; propid_delay.c): a FIFO of held samples. */
#define PROPID_DELAY_VALUES (PROPID_MAX_ROTORS > 3 ? PROPID_MAX_ROTORS : 3)
typedef struct {
    uint64_t time_us;                               /* release time (rotor) or own stamp (IMU) */
    float value[PROPID_DELAY_VALUES];               /* gyro [rad/s], specific force [m/s^2] or
                                                       rotor speeds squared [(rad/s)^2] */
    uint8_t kind;
} propid_delay_entry_t;
typedef struct {
    propid_delay_entry_t entry[PROPID_DELAY_SLOTS];
    uint8_t head;                                   /* oldest entry */
    uint8_t count;
} propid_delay_t;
#endif

#if PROPID_WITH_INSTRUMENT
/* Private: the motor commands' first stage (propid_instrument.c), per rotor: the
 * held command and its first-order lag, and the exponentially weighted moments of
 * the fit y = u / max_rotor_speed^2 = a + b z + c z^2, z = lagged command - 1/2:
 * sum w {1, z, z^2, y} of the levels, sum w {dz dz, dz dz2, dz2 dz2, dz dy, dz2 dy, dy dy}
 * of the increments between rotor samples (z2 = z^2). */
#define PROPID_INSTRUMENT_MOMENTS 10
typedef struct {
    float command[PROPID_MAX_ROTORS];               /* latest accepted command, held (0..1) */
    float lagged[PROPID_MAX_ROTORS];                /* the lag's output at command_time_us */
    float moment[PROPID_MAX_ROTORS][PROPID_INSTRUMENT_MOMENTS];
    float previous[PROPID_MAX_ROTORS][3];           /* z, z^2, y of the fit's latest sample */
    uint64_t command_time_us;
    uint64_t fit_time_us;                           /* time of the fit's latest rotor sample */
    float weight_sq;                                /* sum w^2 of the fit's weights (effective count) */
    uint32_t fit_samples;                           /* rotor samples in the fit since init/reset */
    uint32_t command_accepted;                      /* motor-command samples accepted (kept by reset) */
    uint32_t inputs;                                /* rotor samples whose input came from the first
                                                       stage for every rotor (kept by reset) */
    uint32_t guarded;                               /* rotor inputs the weak-instrument guard left to
                                                       the telemetry (kept by reset) */
    uint8_t has_command;
} propid_instrument_t;
#endif

/* Private: the model-consistency monitor's window (propid_consistency.c). */
typedef struct {
    float start_coeff[2 * PROPID_MAX_ROTORS];       /* kf, km (scaled) at the window's start */
    float start_var[2 * PROPID_MAX_ROTORS];         /* their variances then */
    uint64_t start_time_us;
    float nis_sum;                                  /* sum of nu^2 / (gate^2 S) over fused axes */
    uint32_t nis_count;                             /* fused axis samples in the window */
    uint32_t samples;                               /* gyro samples in the window */
    uint32_t window;                                /* gyro samples per window */
    uint32_t check_every;                           /* gyro samples between checks of the running NIS */
    uint8_t started;                                /* the window has its start snapshot */
    uint8_t flagged;                                /* PROPID_HEALTH_MODEL_MISMATCH is up */
    uint16_t clean_windows;                         /* consistent windows since the last inconsistent one */
    uint16_t passed_windows;                        /* consistent windows in a row (saturating) */
    uint16_t steady_coeff;                          /* bit c: coefficient c's last-window change within its claim bound */
    float last_mean_nis;                            /* mean nu^2 / S of the last window */
    float last_drift;                               /* largest Delta^2 / D of the last window */
} propid_consistency_t;

/* The configuration the filter keeps (private): all of it, or in a build without
 * the general path (PROPID_GENERAL_VEHICLES 0, the quad build) only the fields
 * its calls read after propid_init, under the same names. */
#if PROPID_GENERAL_VEHICLES
typedef propid_config_t propid_kept_config_t;
#else
typedef struct {
    float thrust_coeff_nominal;
    float drag_coeff_nominal;
} propid_kept_rotor_t;
typedef struct {
    uint8_t rotor_count;
    uint8_t yaw_sign_flips;                         /* bit i: rotor i's yaw sign is rotor 0's opposite
                                                       (the drag coefficients' yaw basis; fills padding) */
    uint16_t gate_max_consecutive;
#if PROPID_DELAY_SLOTS > 0 /* (without the delay buffer the configuration check admits only 0) */
    int32_t rotor_delay_us;
#endif
    uint32_t rotor_stale_us;
    uint32_t max_gyro_gap_us;
    float max_rotor_speed;
    float gyro_range;
    float coeff_rel_min;
    float coeff_rel_max;
    propid_kept_rotor_t rotor[PROPID_MAX_ROTORS];
} propid_kept_config_t;
#endif

/* The counters the filter keeps (private): all of them, or in the quad build only
 * those its calls can move (no accelerometer, delay buffer, consistency monitor
 * or stuck-gyro check there, and no rejection has status 0: propid_get_counters
 * reports those as 0). Rejection `status` is counted in
 * rejected[PROPID_REJECT_SLOT(status)]. */
#if PROPID_GENERAL_VEHICLES
typedef propid_counters_t propid_kept_counters_t;
#define PROPID_REJECT_SLOT(status) (-(int)(status))
#else
#define PROPID_REJECT_SLOT(status) (-(int)(status) - 1)
typedef struct {
    uint32_t gyro_accepted;
    uint32_t rotor_accepted;
    uint32_t axis_gated[3];
    uint32_t gate_reopened;
    uint32_t cov_repairs;
    uint32_t state_clamps;
    uint32_t resyncs;
    uint32_t rejected[PROPID_REJECT_SLOTS - 1];
} propid_kept_counters_t;
#endif

typedef struct {
    propid_kept_config_t config;
    propid_derived_t derived;
#if !PROPID_GENERAL_VEHICLES
    uint32_t magic;                                 /* set by a successful propid_init() (here in the
                                                       quad build: in the padding before the core's
                                                       64-bit stamps, which the object's 1 KiB needs) */
#endif
    propid_core_t core;
    propid_kept_counters_t counters;
#if PROPID_DELAY_SLOTS > 0
    propid_delay_t delay;
#endif
#if PROPID_CONSISTENCY
    propid_consistency_t consistency;
#endif
#if PROPID_WITH_INSTRUMENT
    propid_instrument_t instrument;
#endif
#if PROPID_GENERAL_VEHICLES
    uint32_t magic;                                 /* set by a successful propid_init() */
#endif
} propid_filter_t;

/* ------------------------------------------------------------------------ */
/* Life cycle                                                               */
/* ------------------------------------------------------------------------ */
propid_status_t propid_init(propid_filter_t *filter, const propid_config_t *config);

/* A prepared setup: the configuration's checks and derivation done once, off the
 * step's board or before flight, so that a flight controller that flies one vehicle
 * links neither (docs/design.md, "Prepared setup"). firmware/codegen/setup_blob.py
 * writes one for a vehicle file as a C constant; propid_setup_prepare makes one on
 * the board. A setup holds this build's layout: format and size tell a setup of
 * another build or version, the checksum (CRC-32 of every byte before it, the
 * zlib one) a damaged or hand-edited one. */
#define PROPID_SETUP_VERSION 1u
#define PROPID_SETUP_FORMAT                                                                        \
    (0x50530000u | (PROPID_SETUP_VERSION << 8) | ((uint32_t)PROPID_MAX_ROTORS & 0xFu) |           \
     ((uint32_t)PROPID_GENERAL_VEHICLES << 4) | ((uint32_t)PROPID_WITH_ACCEL << 5) |              \
     ((uint32_t)PROPID_WITH_DISTURBANCE << 6) | ((uint32_t)PROPID_WITH_ROTOR_INERTIA << 7))
typedef struct {
    uint32_t format;                                /* PROPID_SETUP_FORMAT of the build that made it */
    uint32_t size;                                  /* sizeof(propid_setup_t) of that build */
    propid_kept_config_t config;
    propid_derived_t derived;
    uint32_t checksum;                              /* CRC-32 of the bytes before it */
} propid_setup_t;

/* Checks and derives config into setup (PROPID_ERR_CONFIG on a bad config: see
 * propid_config_check; setup then untouched). */
propid_status_t propid_setup_prepare(const propid_config_t *config, propid_setup_t *setup);

/* propid_init from a prepared setup: PROPID_ERR_CONFIG (filter untouched) when its
 * format, size or checksum is not this build's or it fails the structure checks
 * the step relies on. The same filter as propid_init with the config it came from. */
propid_status_t propid_init_prepared(propid_filter_t *filter, const propid_setup_t *setup);

/* Back to the prior (nominal coefficients, prior covariance, no rotor data, no time);
 * counters are kept. */
propid_status_t propid_reset(propid_filter_t *filter);

/* A propeller was swapped: rotor's kf and km back to nominal with prior variance,
 * their cross-covariances zeroed; everything else kept. */
propid_status_t propid_reset_rotor(propid_filter_t *filter, uint8_t rotor);

/* Re-anchor the filter clock after a known gap (e.g. after PROPID_ERR_TIME_JUMP):
 * filter time := time_us, body rates and their variance back to the prior (the
 * next gyro sample sets the rates). Coefficients and biases kept. */
propid_status_t propid_resync(propid_filter_t *filter, uint64_t time_us);

/* ------------------------------------------------------------------------ */
/* Inputs                                                                   */
/* ------------------------------------------------------------------------ */
/* With config.rotor_delay_us != 0 the stream that leads is held in a fixed buffer
 * (docs/math.md §12): its samples are validated at once (a negative status: not
 * held, nothing changed) and return PROPID_OK_QUEUED; each is fused when the
 * other stream's time reaches it, during a later push, and its outcome then shows
 * in the counters and health only. The estimates lag real time by |delay|. */
propid_status_t propid_push_rotor_speeds(propid_filter_t *filter, uint64_t time_us,
                                         const float *rotor_speed_rad_s, uint8_t rotor_count);

propid_status_t propid_push_gyro(propid_filter_t *filter, uint64_t time_us,
                                 const float gyro_rad_s[3]);

/* Motor commands (config.motor_command_instrument = 1, else PROPID_ERR_CONFIG): the
 * commands the flight controller sends the ESCs, normalised 0..1 (0 = stop, 1 = full),
 * any rate, their own time stamps on the gyro's clock. They never enter the model
 * directly: a per-rotor first stage (lag, then a + b z + c z^2, fitted online to the
 * telemetry) turns them into the rotor input the filter uses instead of the measured
 * Omega^2 (docs/math.md §16). Rejected (state untouched): PROPID_ERR_NOT_FINITE,
 * PROPID_ERR_ROTOR_SPEED_RANGE (a command outside 0..1), PROPID_ERR_ROTOR_COUNT,
 * PROPID_ERR_TIME_BACKWARDS (not after the previous command). A command older than
 * config.rotor_stale_us at a rotor sample is stale: that sample's telemetry is used
 * as measured. */
propid_status_t propid_push_motor_command(propid_filter_t *filter, uint64_t time_us,
                                          const float *command, uint8_t rotor_count);

/* Accelerometer aiding (config.mass > 0, else PROPID_ERR_CONFIG): body specific
 * force [m/s^2] (what an accelerometer reads: +g on z at hover), any rate, its
 * own time stamps. Only z is fused: f_z = sum_i kf_i Omega_i^2 / m + b_z, with
 * the latest rotor speeds. PROPID_OK_GATED when the gate skipped it. */
propid_status_t propid_push_accel(propid_filter_t *filter, uint64_t time_us,
                                  const float specific_force[3]);

/* ------------------------------------------------------------------------ */
/* Outputs                                                                  */
/* ------------------------------------------------------------------------ */
typedef struct {
    uint64_t time_us;
    uint8_t rotor_count;
    float body_rate[3];                               /* bias-free body rate [rad/s] */
    float body_rate_std[3];
    float thrust_coeff[PROPID_MAX_ROTORS];            /* kf [N/(rad/s)^2] */
    float thrust_coeff_std[PROPID_MAX_ROTORS];
    float drag_coeff[PROPID_MAX_ROTORS];              /* km [N m/(rad/s)^2] */
    float drag_coeff_std[PROPID_MAX_ROTORS];
    float gyro_bias[3];                               /* [rad/s] */
    float gyro_bias_std[3];
    float innovation[3];                              /* last gyro innovation [rad/s] */
    float innovation_test_ratio[3];                   /* innovation^2 / (gate^2 * S) */
    uint16_t thrust_coeff_converging;                 /* bit i: std below half its prior */
    uint16_t thrust_coeff_converged;                  /* bit i: 3 rel std < converged_rel_std, monitor vouches */
    uint16_t drag_coeff_converging;
    uint16_t drag_coeff_converged;
    uint32_t health;                                  /* PROPID_HEALTH_* */
    /* Optional blocks (zeros when off). */
    float disturbance_torque[3];                      /* J * disturbance state [N m] */
    float disturbance_torque_std[3];                  /* (axes' correlations ignored for a full J) */
    float accel_bias;                                 /* accelerometer z bias [m/s^2] */
    float accel_bias_std;
    float accel_innovation;                           /* last accelerometer z innovation [m/s^2] */
    float accel_innovation_test_ratio;
    float torque_scale;                               /* thrust-torque scale (1 when off) */
    float torque_scale_std;
    int32_t rotor_delay_us;                           /* the configured telemetry delay (docs/math.md §12) */
    uint8_t model_terms;                              /* PROPID_TERM_*: the optional terms configured */
} propid_estimate_t;

/* propid_estimate_t.model_terms: which optional terms the filter runs with. */
#define PROPID_TERM_DISTURBANCE   (1u << 0) /* disturbance-torque states */
#define PROPID_TERM_ACCEL         (1u << 1) /* accelerometer aiding (accel z bias state) */
#define PROPID_TERM_TORQUE_SCALE  (1u << 2) /* thrust-torque scale state */
#define PROPID_TERM_ROTOR_INERTIA (1u << 3) /* rotor inertia: yaw reaction, gyroscopic torque */
#define PROPID_TERM_ESC_DELAY     (1u << 4) /* a nonzero telemetry delay held in the buffer */
#define PROPID_TERM_AERO_DAMPING  (1u << 5) /* a known aerodynamic rate damping (config.aero_damping) */

propid_status_t propid_get_estimate(const propid_filter_t *filter, propid_estimate_t *estimate);
propid_status_t propid_get_counters(const propid_filter_t *filter, propid_counters_t *counters);

/* Short constant name of a status code, e.g. "PROPID_ERR_TIME_JUMP". */
const char *propid_status_name(propid_status_t status);

/* State indices in the scaled state vector (for tests and future measurements). */
static inline uint8_t propid_index_rate(uint8_t axis) { return axis; }
static inline uint8_t propid_index_thrust_coeff(uint8_t rotor) { return (uint8_t)(3u + rotor); }
static inline uint8_t propid_index_drag_coeff(const propid_filter_t *filter, uint8_t rotor)
{
    return (uint8_t)(3u + filter->config.rotor_count + rotor);
}
static inline uint8_t propid_index_gyro_bias(const propid_filter_t *filter, uint8_t axis)
{
    return (uint8_t)(3u + 2u * filter->config.rotor_count + axis);
}
/* PROPID_NO_STATE when the block is not configured. */
static inline uint8_t propid_index_disturbance(const propid_filter_t *filter, uint8_t axis)
{
    const uint8_t first = filter->derived.layout.disturbance;
    return first == PROPID_NO_STATE ? (uint8_t)PROPID_NO_STATE : (uint8_t)(first + axis);
}
static inline uint8_t propid_index_accel_bias(const propid_filter_t *filter)
{
    return filter->derived.layout.accel_bias;
}
/* The accelerometer row's model error (config.accel_error_std > 0), in m/s^2. */
static inline uint8_t propid_index_accel_error(const propid_filter_t *filter)
{
#if PROPID_WITH_ACCEL
    return filter->derived.accel_error;
#else
    (void)filter;
    return (uint8_t)PROPID_NO_STATE;
#endif
}

#ifdef __cplusplus
}
#endif

#endif /* PROPID_H */
