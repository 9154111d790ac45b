/*
 * printf("%.9g") for doubles, fast: the flight log writes ~ 75 numbers per
 * row at the control rate, and glibc's exact printf was most of a logged
 * flight's time. The output is byte for byte what snprintf(out, n, "%.9g", x)
 * writes (tests/sitl/test_number_format.c compares them).
 */
#ifndef SITL_NUMBER_FORMAT_H
#define SITL_NUMBER_FORMAT_H

/* Longest text: "-1.23456789e-308" + NUL. */
#define SITL_G9_MAX 24

/* Writes x as "%.9g" does into out (SITL_G9_MAX bytes) and returns its length. */
int sitl_format_g9(double x, char out[SITL_G9_MAX]);

#endif /* SITL_NUMBER_FORMAT_H */
