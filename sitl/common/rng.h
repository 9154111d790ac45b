/*
 * Deterministic random numbers for the simulator (xoshiro256** seeded through
 * splitmix64). Every consumer (coefficient draw, gyro noise, ESC dropouts...)
 * owns its own stream derived from (seed, stream id), so switching one
 * feature on does not shift the draws of another: same seed, same vehicle.
 */
#ifndef SITL_RNG_H
#define SITL_RNG_H

#include <stdint.h>

typedef struct {
    uint64_t s[4];
    int has_spare;      /* Box-Muller gives two normals per draw */
    double spare;
} sitl_rng_t;

/* Stream ids: fixed forever so logs stay reproducible across versions. */
enum {
    SITL_RNG_COEFFS = 1,
    SITL_RNG_INCORRECT = 2,
    SITL_RNG_GYRO = 3,
    SITL_RNG_ACCEL = 4,
    SITL_RNG_ESC = 5,
    SITL_RNG_GYRO_BIAS = 6,
    SITL_RNG_ACCEL_BIAS = 7,
    SITL_RNG_DISTURBANCE_TORQUE = 8,
};

void sitl_rng_init(sitl_rng_t *rng, uint64_t seed, uint64_t stream);
uint64_t sitl_rng_next(sitl_rng_t *rng);
/* Uniform in [0, 1). */
double sitl_rng_uniform(sitl_rng_t *rng);
/* Uniform in [lo, hi). */
double sitl_rng_range(sitl_rng_t *rng, double lo, double hi);
/* Standard normal. */
double sitl_rng_normal(sitl_rng_t *rng);
/* count standard normals into out: the same values, in the same order and
 * leaving the same stream state, as count calls of sitl_rng_normal; the angles of
 * up to four Box-Muller pairs go through one sitl_sincos4. */
void sitl_rng_normals(sitl_rng_t *rng, double *out, int count);

#endif /* SITL_RNG_H */
