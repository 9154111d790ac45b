/* A coefficient beyond its bound: the estimate projected onto the bound, P kept
 * (docs/math.md §15). Setting x_k to the bound alone (the plain clamp) undoes
 * part of the update while the states the update moved together with x_k (the
 * body rates, the other rotors' coefficients) keep their part: the torque the
 * filter then predicts is off by an amount its covariance does not hold, and its
 * innovations ramp.
 *
 * Here the whole estimate moves to the nearest point on the bound in P's metric
 * (the mean of N(x, P) conditioned on x_k = bound):
 *
 *   x_j += P_jk / P_kk * (bound - x_k)       (x_k itself lands on the bound)
 *
 * P is left as it is: the bound says where the model's signs or scale stop, it
 * is not a measurement. Counting it as one (truncating the Gaussian) shrinks
 * P_kk at every sample a coefficient rides the bound, and the coefficient then
 * sticks there (docs/damage.md). Only on a sample whose update left a
 * coefficient outside its range: not on the usual step.
 *
 * The bounds are per rotor while the filter keeps the coefficient blocks in
 * their bases: the caller passes the state per rotor and P's column k per rotor
 * (propid_coeff_per_rotor_column), so P itself is neither flipped nor touched. */
#include <float.h>
#include <math.h>

#include "propid_internal.h"

int propid_project_onto_bound(uint8_t state_count, const float *column, float *state, uint8_t k, float bound)
{
    const float pkk = column[k];
    const float shift = bound - state[k];
    if (!(pkk > 0.0f && pkk <= FLT_MAX) || !(fabsf(shift) <= FLT_MAX)) { /* NaN fails both */
        state[k] = bound; /* no usable P_kk: the plain clamp */
        return 0;
    }
    const float step = shift / pkk;
    for (uint8_t i = 0; i < state_count; ++i) {
        state[i] += column[i] * step;
    }
    state[k] = bound; /* exactly (the loop's x_k += P_kk shift / P_kk rounds) */
    return 1;
}
