/* "%.9g" without printf (see number_format.h). */
#include "number_format.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>

/* 10^0 .. 10^22: every one exact in a double. */
static const double exact_power_of_ten[23] = {
    1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
    1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

static int fallback(double x, char out[SITL_G9_MAX])
{
    return snprintf(out, SITL_G9_MAX, "%.9g", x);
}

/* a * 10^k with ONE correctly rounded operation; 0 if 10^|k| is not exact. */
static double scale_by_power_of_ten(double a, int k)
{
    if (k >= 0) {
        return k <= 22 ? a * exact_power_of_ten[k] : 0.0;
    }
    return -k <= 22 ? a / exact_power_of_ten[-k] : 0.0;
}

int sitl_format_g9(double x, char out[SITL_G9_MAX])
{
    const double a = fabs(x);
    if (!(a >= 1e-14 && a < 1e22)) { /* zero, tiny, huge, inf, nan */
        return fallback(x, out);
    }
    /* Nine significant digits: m = a * 10^(8 - e) in [1e8, 1e9). The decimal
     * exponent e from the binary one (log10(2) ~ 0.30103) is off by at most one. */
    int binary_exponent;
    (void)frexp(a, &binary_exponent);
    int e = (int)floor((double)(binary_exponent - 1) * 0.30102999566398120);
    double m = scale_by_power_of_ten(a, 8 - e);
    if (m >= 1e9) {
        e++;
        m = scale_by_power_of_ten(a, 8 - e);
    }
    if (!(m >= 1e8 && m < 1e9)) {
        return fallback(x, out);
    }
    /* m carries at most half an ulp of error (< 1.2e-7 here): unless it lies
     * that close to a rounding tie, rounding it rounds the exact value. */
    const double whole = floor(m);
    const double fraction = m - whole; /* exact: m < 2^30 */
    if (fabs(fraction - 0.5) < 1e-6) {
        return fallback(x, out);
    }
    uint32_t digits = (uint32_t)whole + (fraction > 0.5 ? 1u : 0u);
    if (digits == 1000000000u) {
        digits = 100000000u;
        e++;
    }
    char d[9];
    for (int i = 8; i >= 0; i--) {
        d[i] = (char)('0' + digits % 10u);
        digits /= 10u;
    }
    int last = 8; /* last significant digit kept (trailing zeros go) */
    while (last > 0 && d[last] == '0') {
        last--;
    }
    int len = 0;
    if (x < 0.0) {
        out[len++] = '-';
    }
    if (e >= -4 && e < 9) {
        /* Style f with 8 - e decimals. */
        if (e < 0) {
            out[len++] = '0';
            out[len++] = '.';
            for (int i = 0; i < -e - 1; i++) {
                out[len++] = '0';
            }
            for (int i = 0; i <= last; i++) {
                out[len++] = d[i];
            }
        } else {
            for (int i = 0; i <= e; i++) {
                out[len++] = d[i];
            }
            if (last > e) {
                out[len++] = '.';
                for (int i = e + 1; i <= last; i++) {
                    out[len++] = d[i];
                }
            }
        }
    } else {
        /* Style e: d.dddddddde+XX (at least two exponent digits). */
        out[len++] = d[0];
        if (last > 0) {
            out[len++] = '.';
            for (int i = 1; i <= last; i++) {
                out[len++] = d[i];
            }
        }
        out[len++] = 'e';
        out[len++] = e < 0 ? '-' : '+';
        const int ae = e < 0 ? -e : e;
        if (ae >= 100) {
            out[len++] = (char)('0' + ae / 100);
        }
        out[len++] = (char)('0' + (ae / 10) % 10);
        out[len++] = (char)('0' + ae % 10);
    }
    out[len] = '\0';
    return len;
}
