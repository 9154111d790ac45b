/* sin and cos together by quadrant reduction and Taylor polynomials (see sitl_sincos.h). */
#include "sitl_sincos.h"

#include <math.h>
#include <stdint.h>

/* pi/2 in three parts: the first two have 33 significant bits, so k * part is
 * exact for |k| < 2^20 and x - k pi/2 loses nothing to cancellation. */
static const double half_pi_1 = 0x1.921fb544p+0;
static const double half_pi_2 = 0x1.0b4611a6p-34;
static const double half_pi_3 = 0x1.3198a2e037073p-69;
static const double two_over_pi = 0.63661977236758134308;

/* Bound on |x| for the reduction above: |k| <= 2^19 * 2 / pi < 2^20. */
static const double reduction_limit = 524288.0;

void sitl_sincos(double x, double *s, double *c)
{
    if (!(fabs(x) <= reduction_limit)) {
        *s = sin(x);
        *c = cos(x);
        return;
    }
    /* k = x / (pi/2) rounded to the nearest integer (ties either way: the
     * polynomials below are accurate a little beyond pi/4). */
    const int64_t k = (int64_t)(x * two_over_pi + (x >= 0.0 ? 0.5 : -0.5));
    const double kd = (double)k;
    const double r = ((x - kd * half_pi_1) - kd * half_pi_2) - kd * half_pi_3;
    const double r2 = r * r;

    /* Taylor series to r^15 / r^16: for |r| <= pi/4 the first omitted term
     * is below 5e-17, under half a unit in the last place. The tails are
     * summed in pairs (Estrin's scheme) to shorten the dependent chain. */
    const double r4 = r2 * r2, r8 = r4 * r4;
    const double sin_tail = (-1.0 / 6.0 + r2 * (1.0 / 120.0)) +
                            r4 * (-1.0 / 5040.0 + r2 * (1.0 / 362880.0)) +
                            r8 * ((-1.0 / 39916800.0 + r2 * (1.0 / 6227020800.0)) +
                                  r4 * (-1.0 / 1307674368000.0));
    const double cos_tail = (1.0 / 24.0 + r2 * (-1.0 / 720.0)) +
                            r4 * (1.0 / 40320.0 + r2 * (-1.0 / 3628800.0)) +
                            r8 * ((1.0 / 479001600.0 + r2 * (-1.0 / 87178291200.0)) +
                                  r4 * (1.0 / 20922789888000.0));
    const double sin_r = r + (r * r2) * sin_tail;
    const double cos_r = (1.0 - 0.5 * r2) + r4 * cos_tail;
    switch (k & 3) {
    case 0:
        *s = sin_r;
        *c = cos_r;
        break;
    case 1:
        *s = cos_r;
        *c = -sin_r;
        break;
    case 2:
        *s = -sin_r;
        *c = -cos_r;
        break;
    default:
        *s = -cos_r;
        *c = sin_r;
        break;
    }
}

/* Four angles at once (see sitl_sincos.h): each lane takes sitl_sincos's
 * operations in its order, so every value is the same bit for bit; the range
 * test, the reduction, both polynomials and the quadrant's swap and signs run as
 * 4-wide vectors (GCC and Clang vector extensions: AVX registers in the
 * x86-64-v3 build, SSE2 pairs in the portable one; with -ffp-contract=off no
 * multiply-add is fused). The quadrant's integer fits 32 bits in the range
 * (|k| < 2^20), so the truncation to it is the same as to 64 bits. */
#if defined(__GNUC__)
typedef double sitl_v4d __attribute__((vector_size(32)));
typedef int64_t sitl_v4l __attribute__((vector_size(32)));
typedef int32_t sitl_v4i __attribute__((vector_size(16)));

/* The lanes of a (mask all ones) or of b (mask zero), bit for bit. A macro: a
 * function taking or returning a 32-byte vector changes the ABI without AVX
 * (GCC's -Wpsabi, the portable and sanitizer builds). */
#define SITL_SELECT_LANES(mask, a, b) \
    ((sitl_v4d)(((sitl_v4l)(a) & (mask)) | ((sitl_v4l)(b) & ~(mask))))
#endif

void sitl_sincos4(const double x[4], double s[4], double c[4])
{
#if defined(__GNUC__)
    sitl_v4d xv;
    for (int i = 0; i < 4; i++) {
        xv[i] = x[i];
    }
    const sitl_v4d limit = {reduction_limit, reduction_limit, reduction_limit, reduction_limit};
    const sitl_v4l sign_bit = {INT64_MIN, INT64_MIN, INT64_MIN, INT64_MIN};
    const sitl_v4d magnitude = (sitl_v4d)((sitl_v4l)xv & ~sign_bit); /* fabs */
    const sitl_v4l in_range = magnitude <= limit; /* false for NaN */
    if (!(in_range[0] & in_range[1] & in_range[2] & in_range[3])) {
        for (int j = 0; j < 4; j++) {
            sitl_sincos(x[j], &s[j], &c[j]);
        }
        return;
    }
    const sitl_v4d zero = {0.0, 0.0, 0.0, 0.0};
    const sitl_v4d plus_half = {0.5, 0.5, 0.5, 0.5}, minus_half = {-0.5, -0.5, -0.5, -0.5};
    const sitl_v4d half = SITL_SELECT_LANES(xv >= zero, plus_half, minus_half);
    const sitl_v4i k32 = __builtin_convertvector(xv * two_over_pi + half, sitl_v4i);
    const sitl_v4d kd = __builtin_convertvector(k32, sitl_v4d);
    const sitl_v4l k = __builtin_convertvector(k32, sitl_v4l);
    const sitl_v4d r = ((xv - kd * half_pi_1) - kd * half_pi_2) - kd * half_pi_3;
    const sitl_v4d r2 = r * r;
    const sitl_v4d r4 = r2 * r2, r8 = r4 * r4;
    const sitl_v4d sin_tail = (-1.0 / 6.0 + r2 * (1.0 / 120.0)) +
                              r4 * (-1.0 / 5040.0 + r2 * (1.0 / 362880.0)) +
                              r8 * ((-1.0 / 39916800.0 + r2 * (1.0 / 6227020800.0)) +
                                    r4 * (-1.0 / 1307674368000.0));
    const sitl_v4d cos_tail = (1.0 / 24.0 + r2 * (-1.0 / 720.0)) +
                              r4 * (1.0 / 40320.0 + r2 * (-1.0 / 3628800.0)) +
                              r8 * ((1.0 / 479001600.0 + r2 * (-1.0 / 87178291200.0)) +
                                    r4 * (1.0 / 20922789888000.0));
    const sitl_v4d sin_r = r + (r * r2) * sin_tail;
    const sitl_v4d cos_r = (1.0 - 0.5 * r2) + r4 * cos_tail;
    /* The quadrant as in sitl_sincos: odd swaps sine and cosine; the sine is
     * negated in quadrants 2 and 3, the cosine in 1 and 2 (negation is exact: the
     * sign bit flipped). */
    const sitl_v4l odd = (k & 1) != 0;
    const sitl_v4l sin_negative = (k & 2) != 0;
    const sitl_v4l cos_negative = ((k + 1) & 2) != 0;
    const sitl_v4d sv = SITL_SELECT_LANES(odd, cos_r, sin_r);
    const sitl_v4d cv = SITL_SELECT_LANES(odd, sin_r, cos_r);
    const sitl_v4d so = (sitl_v4d)((sitl_v4l)sv ^ (sin_negative & sign_bit));
    const sitl_v4d co = (sitl_v4d)((sitl_v4l)cv ^ (cos_negative & sign_bit));
    for (int i = 0; i < 4; i++) {
        s[i] = so[i];
        c[i] = co[i];
    }
#else
    for (int i = 0; i < 4; i++) {
        sitl_sincos(x[i], &s[i], &c[i]);
    }
#endif
}
