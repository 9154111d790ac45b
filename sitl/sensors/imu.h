/*
 * IMU model: gyroscope and accelerometer sampled together at the IMU rate.
 *   gyro  = Q(sat(M w + b + n)),  b = b0 + random walk, b0 ~ U(-bias_max, bias_max)
 *   accel = Q(sat(f + b_a + n_a)), f = specific force in the body frame
 * n white with standard deviation noise_density * sqrt(rate) per sample,
 * M the gyro_scale effect matrix (identity unless enabled), Q quantisation to
 * the LSB (0 = off), sat the full-scale range (0 = off).
 * Defaults (sitl_imu_default_params) follow the Bosch BMI088 datasheet; see
 * docs/sitl.md.
 */
#ifndef SITL_IMU_H
#define SITL_IMU_H

#include "effects.h"
#include "rng.h"

typedef struct {
    double noise_density;   /* [unit/sqrt(Hz)] */
    double bias_max;        /* constant bias per axis ~ U(-max, max) [unit] */
    double bias_walk;       /* bias random walk [unit/sqrt(s)] */
    double range;           /* full scale [unit], 0 = no saturation */
    double resolution;      /* LSB [unit], 0 = no quantisation */
} sitl_inertial_params_t;

typedef struct {
    double rate_hz;                 /* IMU output data rate */
    sitl_inertial_params_t gyro;    /* rad/s units */
    sitl_inertial_params_t accel;   /* m/s^2 units */
} sitl_imu_params_t;

/* 4 samples' six normals: 12 Box-Muller pairs, three 4-wide sincos calls. */
#define SITL_IMU_DRAWS_AHEAD 24

typedef struct {
    sitl_imu_params_t params;
    double gyro_sigma, accel_sigma; /* white-noise std per sample: density x sqrt(rate) */
    double gyro_bias[3];
    double accel_bias[3];
    double gyro_matrix[3][3];
    sitl_rng_t gyro_rng;
    sitl_rng_t accel_rng;
    /* Each stream's normals drawn ahead, SITL_IMU_DRAWS_AHEAD at a time (whole groups of
     * four Box-Muller pairs: no sincos lane idle), taken in their order; *_used: how many
     * of the buffer are spent. */
    double gyro_draws[SITL_IMU_DRAWS_AHEAD], accel_draws[SITL_IMU_DRAWS_AHEAD];
    int gyro_draws_used, accel_draws_used;
} sitl_imu_t;

void sitl_imu_default_params(sitl_imu_params_t *params);

/* The paper's conditions: 500 Hz, white noise + constant bias, no walk,
 * no saturation, no quantisation. */
void sitl_imu_paper_params(sitl_imu_params_t *params);

/* Draw the constant biases from bias_seed (the airframe's) and seed the noise and
 * bias-walk streams from noise_seed (the flight's); own streams each. */
void sitl_imu_init(sitl_imu_t *imu, const sitl_imu_params_t *params, uint64_t bias_seed,
                   uint64_t noise_seed, const sitl_effects_t *effects);

/* One sample; dt = time since the previous sample (bias walk). With
 * accel_out NULL only the gyro is sampled (specific_force may be NULL too):
 * the accelerometer has its own noise stream, so the gyro's draws are the
 * same either way. */
void sitl_imu_sample(sitl_imu_t *imu, const double true_rate[3],
                     const double specific_force[3], double dt, double gyro_out[3],
                     double accel_out[3]);

#endif /* SITL_IMU_H */
