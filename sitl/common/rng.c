/* xoshiro256** (Blackman & Vigna) with a splitmix64 seeder; see rng.h. */
#include "rng.h"

#include <math.h>

#include "sitl_sincos.h"

static uint64_t splitmix64(uint64_t *x)
{
    uint64_t z = (*x += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static uint64_t rotl(uint64_t x, int k)
{
    return (x << k) | (x >> (64 - k));
}

void sitl_rng_init(sitl_rng_t *rng, uint64_t seed, uint64_t stream)
{
    uint64_t x = seed ^ (stream * 0xD1B54A32D192ED03ull);
    for (int i = 0; i < 4; i++) {
        rng->s[i] = splitmix64(&x);
    }
    rng->has_spare = 0;
    rng->spare = 0.0;
}

uint64_t sitl_rng_next(sitl_rng_t *rng)
{
    uint64_t *s = rng->s;
    uint64_t result = rotl(s[1] * 5, 7) * 9;
    uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = rotl(s[3], 45);
    return result;
}

double sitl_rng_uniform(sitl_rng_t *rng)
{
    /* 53 random bits -> [0, 1) */
    return (double)(sitl_rng_next(rng) >> 11) * (1.0 / 9007199254740992.0);
}

double sitl_rng_range(sitl_rng_t *rng, double lo, double hi)
{
    return lo + (hi - lo) * sitl_rng_uniform(rng);
}

/* One Box-Muller pair's radius and angle from the next two uniforms. */
static void box_muller_draw(sitl_rng_t *rng, double *radius, double *angle)
{
    double u1 = sitl_rng_uniform(rng);
    double u2 = sitl_rng_uniform(rng);
    if (u1 < 1e-300) {
        u1 = 1e-300;
    }
    *radius = sqrt(-2.0 * log(u1));
    *angle = 2.0 * 3.14159265358979323846 * u2;
}

double sitl_rng_normal(sitl_rng_t *rng)
{
    if (rng->has_spare) {
        rng->has_spare = 0;
        return rng->spare;
    }
    double r, angle, s, c;
    box_muller_draw(rng, &r, &angle);
    sitl_sincos(angle, &s, &c);
    rng->spare = r * s;
    rng->has_spare = 1;
    return r * c;
}

void sitl_rng_normals(sitl_rng_t *rng, double *out, int count)
{
    int done = 0;
    if (count > 0 && rng->has_spare) {
        rng->has_spare = 0;
        out[done++] = rng->spare;
    }
    while (done < count) {
        /* Pairs in draw order: pair p gives out[done + 2p] (cosine) and the one
         * after it (sine), which is the spare when count runs out first. */
        const int pairs_left = (count - done + 1) / 2;
        const int pairs = pairs_left < 4 ? pairs_left : 4;
        double r[4], angle[4] = {0.0, 0.0, 0.0, 0.0}, s[4], c[4];
        for (int p = 0; p < pairs; p++) {
            box_muller_draw(rng, &r[p], &angle[p]);
        }
        sitl_sincos4(angle, s, c);
        for (int p = 0; p < pairs; p++) {
            out[done++] = r[p] * c[p];
            if (done < count) {
                out[done++] = r[p] * s[p];
            } else {
                rng->spare = r[p] * s[p];
                rng->has_spare = 1;
            }
        }
    }
}
