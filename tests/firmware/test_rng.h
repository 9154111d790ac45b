/* Deterministic xorshift32 for the firmware tests: same numbers on the host and
 * on the Cortex-M4, no libc rand(), no double. */
#ifndef PROPID_TEST_RNG_H
#define PROPID_TEST_RNG_H

#include <math.h>
#include <stdint.h>

typedef struct {
    uint32_t state; /* non-zero seed */
} rng_t;

static inline uint32_t rng_next(rng_t *rng)
{
    uint32_t x = rng->state;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    rng->state = x;
    return x;
}

/* Uniform in [lo, hi), 24-bit resolution. */
static inline float rng_range(rng_t *rng, float lo, float hi)
{
    return lo + (hi - lo) * ((float)(rng_next(rng) >> 8) * (1.0f / 16777216.0f));
}

/* Uniform in (0, 1): never 0, so its logarithm is finite. */
static inline float rng_open_unit(rng_t *rng)
{
    return ((float)(rng_next(rng) >> 8) + 0.5f) * (1.0f / 16777216.0f);
}

/* Standard normal by Box-Muller (one of the pair). */
static inline float rng_normal(rng_t *rng)
{
    const float u1 = rng_open_unit(rng);
    const float u2 = rng_open_unit(rng);
    return sqrtf(-2.0f * logf(u1)) * cosf(2.0f * 3.14159265358979f * u2);
}

#endif /* PROPID_TEST_RNG_H */
