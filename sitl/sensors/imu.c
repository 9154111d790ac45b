/* Gyro + accelerometer model (see imu.h). */
#include "imu.h"

#include <math.h>
#include <string.h>

#include "sitl_math.h"

#define DEG (SITL_PI / 180.0)
#define G0 9.80665

void sitl_imu_default_params(sitl_imu_params_t *p)
{
    memset(p, 0, sizeof(*p));
    p->rate_hz = 1000.0;                    /* BMI088 gyro ODR 1000 Hz (one of 100..2000) */
    p->gyro.noise_density = 0.014 * DEG;    /* 0.014 deg/s/sqrt(Hz), BMI088 typ. */
    p->gyro.bias_max = 1.0 * DEG;           /* zero-rate offset +-1 deg/s, BMI088 typ. */
    p->gyro.bias_walk = 1.0e-4;             /* in-run drift, consumer MEMS order (docs) */
    p->gyro.range = 2000.0 * DEG;           /* +-2000 deg/s range */
    p->gyro.resolution = 2000.0 * DEG / 32768.0; /* 16-bit: 0.061 deg/s LSB */
    p->accel.noise_density = 175e-6 * G0;   /* 175 ug/sqrt(Hz), BMI088 accel typ. */
    p->accel.bias_max = 20e-3 * G0;         /* zero-g offset +-20 mg */
    p->accel.bias_walk = 1.0e-4;
    p->accel.range = 24.0 * G0;             /* +-24 g range */
    p->accel.resolution = 24.0 * G0 / 32768.0;
}

void sitl_imu_paper_params(sitl_imu_params_t *p)
{
    sitl_imu_default_params(p);
    p->rate_hz = 500.0;
    p->gyro.bias_walk = 0.0;
    p->gyro.range = 0.0;
    p->gyro.resolution = 0.0;
    p->accel.bias_walk = 0.0;
    p->accel.range = 0.0;
    p->accel.resolution = 0.0;
}

void sitl_imu_init(sitl_imu_t *imu, const sitl_imu_params_t *params, uint64_t bias_seed,
                   uint64_t noise_seed, const sitl_effects_t *effects)
{
    memset(imu, 0, sizeof(*imu));
    imu->params = *params;
    imu->gyro_sigma = params->gyro.noise_density * sqrt(params->rate_hz);
    imu->accel_sigma = params->accel.noise_density * sqrt(params->rate_hz);
    sitl_rng_t bias_rng;
    sitl_rng_init(&bias_rng, bias_seed, SITL_RNG_GYRO_BIAS);
    for (int i = 0; i < 3; i++) {
        imu->gyro_bias[i] = sitl_rng_range(&bias_rng, -params->gyro.bias_max,
                                           params->gyro.bias_max);
    }
    sitl_rng_init(&bias_rng, bias_seed, SITL_RNG_ACCEL_BIAS);
    for (int i = 0; i < 3; i++) {
        imu->accel_bias[i] = sitl_rng_range(&bias_rng, -params->accel.bias_max,
                                            params->accel.bias_max);
    }
    sitl_rng_init(&imu->gyro_rng, noise_seed, SITL_RNG_GYRO);
    sitl_rng_init(&imu->accel_rng, noise_seed, SITL_RNG_ACCEL);
    imu->gyro_draws_used = SITL_IMU_DRAWS_AHEAD;
    imu->accel_draws_used = SITL_IMU_DRAWS_AHEAD;
    sitl_effects_gyro_matrix(effects, imu->gyro_matrix);
}

static double finish(const sitl_inertial_params_t *p, double x)
{
    if (p->range > 0.0) {
        x = x > p->range ? p->range : (x < -p->range ? -p->range : x);
    }
    if (p->resolution > 0.0) {
        x = p->resolution * floor(x / p->resolution + 0.5);
    }
    return x;
}

/* The stream's next six normals, refilling its buffer when spent. */
static const double *next_six(sitl_rng_t *rng, double *draws, int *used)
{
    if (*used > SITL_IMU_DRAWS_AHEAD - 6) {
        sitl_rng_normals(rng, draws, SITL_IMU_DRAWS_AHEAD);
        *used = 0;
    }
    const double *six = draws + *used;
    *used += 6;
    return six;
}

void sitl_imu_sample(sitl_imu_t *imu, const double true_rate[3],
                     const double specific_force[3], double dt, double gyro_out[3],
                     double accel_out[3])
{
    const sitl_imu_params_t *p = &imu->params;
    const double sigma_g = imu->gyro_sigma, sigma_a = imu->accel_sigma;
    double walk_g = p->gyro.bias_walk * sqrt(dt > 0.0 ? dt : 0.0);
    double walk_a = p->accel.bias_walk * sqrt(dt > 0.0 ? dt : 0.0);
    double scaled[3];
    sitl_mat3_mul_vec(scaled, imu->gyro_matrix, true_rate);
    /* Draw order is fixed (per axis: noise, then walk) so runs stay reproducible;
     * the six draws of each stream come from its buffer, the same values in that order
     * as drawn one sample at a time. */
    const double *gyro_draws = next_six(&imu->gyro_rng, imu->gyro_draws, &imu->gyro_draws_used);
    const double *accel_draws = NULL;
    if (accel_out != NULL) {
        accel_draws = next_six(&imu->accel_rng, imu->accel_draws, &imu->accel_draws_used);
    }
    for (int i = 0; i < 3; i++) {
        const double ng = gyro_draws[2 * i], wg = gyro_draws[2 * i + 1];
        imu->gyro_bias[i] += walk_g * wg;
        gyro_out[i] = finish(&p->gyro, scaled[i] + imu->gyro_bias[i] + sigma_g * ng);
        if (accel_out != NULL) {
            const double na = accel_draws[2 * i], wa = accel_draws[2 * i + 1];
            imu->accel_bias[i] += walk_a * wa;
            accel_out[i] =
                finish(&p->accel, specific_force[i] + imu->accel_bias[i] + sigma_a * na);
        }
    }
}
