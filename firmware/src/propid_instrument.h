/*
 * The motor commands as an instrument for the rotor input (docs/math.md §16),
 * internal. With config.motor_command_instrument the input u_i = Omega_i^2 the
 * model integrates is the first stage's projection of the telemetry on the
 * commands, not the telemetry itself; without it (or compiled out) the
 * telemetry squared, bit for bit as before.
 */
#ifndef PROPID_INSTRUMENT_H
#define PROPID_INSTRUMENT_H

#include "propid_internal.h"

#if PROPID_WITH_INSTRUMENT
/* Forget the commands and the fit (init, reset). */
void propid_instrument_clear(propid_filter_t *filter);
/* The rotor input of a validated rotor sample stamped time_us (gyro clock):
 * speed_sq[i] = the first stage's value where it is valid, else the speed
 * squared; the sample then joins the fit (after its own projection, so the value
 * never contains this sample's telemetry error). */
void propid_instrument_input(propid_filter_t *filter, uint64_t time_us, const float *speed_rad_s,
                             float *speed_sq);
#endif

#endif /* PROPID_INSTRUMENT_H */
