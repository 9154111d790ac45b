/* Deterministic xorshift32 for the firmware tests: same numbers on the host and
 * on the Cortex-M4, no libc rand(), no double. */
#ifndef PROPID_TEST_RNG_H
#define PROPID_TEST_RNG_H

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

#endif /* PROPID_TEST_RNG_H */
