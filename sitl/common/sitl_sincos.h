/*
 * sin and cos of one angle together, for the simulator's per-step angles (the
 * reference trajectory, the Box-Muller normals, the controller's yaw).
 * libm's sincos costs ~ 150-190 x86 instructions per call (it saves and
 * restores the floating-point control state); these ~ 45 give the same
 * values to within 2 units in the last place (tests/sitl/test_sitl_sincos.c
 * compares them with libm), so a flight changes only at rounding level.
 */
#ifndef SITL_SINCOS_H
#define SITL_SINCOS_H

/* *s = sin(x), *c = cos(x). Exact-reduction range |x| <= 2^19 (the angles
 * here are below 1e4 rad); beyond it, and for non-finite x, libm answers. */
void sitl_sincos(double x, double *s, double *c);
/* sitl_sincos of four angles at once, each value the same bit for bit (one
 * 4-wide polynomial instead of four calls: the Box-Muller normals of an IMU
 * sample, the reference trajectory's angles). */
void sitl_sincos4(const double x[4], double s[4], double c[4]);

#endif
