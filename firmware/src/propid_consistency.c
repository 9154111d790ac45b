/* Model-consistency monitor (docs/reliability.md "Honest sigma"): do the gyro
 * innovations and the coefficient estimates behave the way the filter's own
 * covariance says they should? Two tests per window of one second of gyro
 * samples, each with a bound derived from its distribution under the filter's
 * model for a false-alarm probability of a few 1e-5 per window (a few false
 * windows in 100 h of flight), nothing fitted to a flight:
 *
 * 1. Innovation test (NIS). Every fused axis' nu^2 / S is chi-square(1) and
 *    independent of the others, so their sum over the window's k fused axis
 *    samples is chi-square(k); bound: its upper z = 4 quantile (Wilson-Hilferty).
 *    Catches innovations larger than S says (a gross model error the rate
 *    process noise cannot cover).
 *
 * 2. Drift test. The filter's estimate is the conditional mean, a martingale
 *    under its model: over the window each coefficient's change is
 *    Delta_i = sum_k K_k,i nu_k with variance D_i = sum_k K_k,i^2 S_k, the
 *    variance the updates removed, D_i = P_ii(start) + q_i T - P_ii(end)
 *    (q_i its random-walk PSD). Delta_i^2 / D_i is chi-square(1); bound
 *    z = 4.5 per coefficient (two-sided 6.8e-6, up to 16 coefficients: < 1.1e-4
 *    per window). Catches the usual symptom of an unmodelled effect: the
 *    coefficients absorb it, and wander with the flight condition further than
 *    their tiny sigma allows. An effect that the coefficients absorb exactly
 *    (a constant bias of the same shape) is invisible to any test on these
 *    measurements.
 *
 * The NIS test also runs on the running sum at every eighth of the window (a
 * gross mismatch is then flagged within about 0.1 s, before the coefficients
 * first converge; the partial sums are nested, so this adds at most a factor 8
 * to the false-alarm rate). A window failing either test counts in
 * counters.model_mismatch and raises PROPID_HEALTH_MODEL_MISMATCH, which stays
 * up until PROPID_CONSISTENCY_CLEAR_WINDOWS consistent windows in a row have
 * passed; while it is up no coefficient is reported converged
 * (propid_get_estimate). The monitor only reports: it does not change the
 * state or covariance (widening the coefficients' covariance on mismatch lets
 * them absorb more of the unmodelled effect, which in closed-loop SITL made
 * their error several times larger).
 *
 * The monitor also vouches for "converged" claims (propid_get_estimate): a
 * claim needs passed_windows > 0 (a full window passed since the start or the
 * last inconsistent one) and the coefficient's bit in steady_coeff (its change
 * in the last window within PROPID_CLAIM_DRIFT_Z of the explained std), and
 * no gated axis sample in that window.
 *
 * Gated axes are not counted: they were not fused (faults have their own
 * counters). Cost: three adds and a compare per gyro sample; per window one
 * pass over the coefficients. */
#include <math.h>

#include "propid_internal.h"
#include "propid_consistency.h"

#if PROPID_CONSISTENCY

#define PROPID_CONSISTENCY_WINDOW_S 1.0f
#define PROPID_CONSISTENCY_CLEAR_WINDOWS 10u
#define PROPID_CONSISTENCY_NIS_Z 4.0f
#define PROPID_CONSISTENCY_DRIFT_Z 4.5f
/* A coefficient is "steady" for a converged claim when its change over the last
 * window is within 3 std of the change its updates explain (two-sided 0.27 % of
 * the windows of a consistent filter lose the claim for one window). */
#define PROPID_CLAIM_DRIFT_Z 3.0f

/* Upper z-quantile of chi-square(k), Wilson-Hilferty: k (1 - c + z sqrt(c))^3, c = 2 / (9k). */
static float chi_square_upper(float k, float z)
{
    const float c = 2.0f / (9.0f * k);
    const float root = 1.0f - c + z * sqrtf(c);
    return k * root * root * root;
}

static uint8_t coefficient_count(const propid_filter_t *filter)
{
    return (uint8_t)(2u * filter->config.rotor_count);
}

/* Coefficient c (kf of every rotor, then km) and its variance, per rotor (the
 * coefficient blocks are kept in their bases: propid_internal.h). */
static void per_rotor_coefficients(const propid_filter_t *filter, float *value, float *var)
{
    const propid_core_t *core = &filter->core;
    const uint8_t rotor_count = filter->config.rotor_count;
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, &filter->config);
    propid_thrust_per_rotor(&thrust, core, value, var);
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, &filter->config);
    propid_drag_per_rotor(&basis, core, value + rotor_count, var + rotor_count);
}

/* The window starts now: coefficients and their variances as they are (value,
 * var: per_rotor_coefficients of this step, or NULL to form them). */
static void start_window(propid_filter_t *filter, const float *value, const float *var)
{
    propid_consistency_t *monitor = &filter->consistency;
    const propid_core_t *core = &filter->core;
    if (value == NULL || var == NULL) {
        per_rotor_coefficients(filter, monitor->start_coeff, monitor->start_var);
    } else {
        memcpy(monitor->start_coeff, value, sizeof(monitor->start_coeff));
        memcpy(monitor->start_var, var, sizeof(monitor->start_var));
    }
    monitor->start_time_us = core->time_us;
    monitor->nis_sum = 0.0f;
    monitor->nis_count = 0u;
    monitor->samples = 0u;
    monitor->started = 1u;
}

void propid_consistency_reset(propid_filter_t *filter)
{
    propid_consistency_t *monitor = &filter->consistency;
    float per_axis = filter->config.gyro_sample_rate_hz * PROPID_CONSISTENCY_WINDOW_S;
    per_axis = per_axis < 10.0f ? 10.0f : (per_axis > 1.0e6f ? 1.0e6f : per_axis);
    monitor->window = (uint32_t)per_axis;
    monitor->check_every = monitor->window / 8u;
    monitor->samples = 0u;
    monitor->nis_sum = 0.0f;
    monitor->nis_count = 0u;
    monitor->started = 0u;
    monitor->clean_windows = 0u;
    monitor->passed_windows = 0u;
    monitor->steady_coeff = 0u;
    monitor->flagged = 0u;
    monitor->last_mean_nis = 0.0f;
    monitor->last_drift = 0.0f;
    filter->core.health &= ~PROPID_HEALTH_MODEL_MISMATCH;
}

void propid_consistency_restart(propid_filter_t *filter)
{
    filter->consistency.started = 0u;
    filter->consistency.passed_windows = 0u;
    filter->consistency.steady_coeff = 0u;
}

/* End of a window: both tests and the flag (value, var: per_rotor_coefficients
 * of this step). */
static void close_window(propid_filter_t *filter, const float *value, const float *var)
{
    propid_consistency_t *monitor = &filter->consistency;
    const propid_derived_t *derived = &filter->derived;
    const propid_core_t *core = &filter->core;
    const uint8_t first = derived->layout.thrust;
    const uint8_t count = coefficient_count(filter);
    int inconsistent = 0;
    if (monitor->nis_count > 0u) {
        /* nis_sum is in test-ratio units, nu^2 / (gate^2 S): back to nu^2 / S. */
        const float nis = monitor->nis_sum / derived->inv_gate_sq;
        const float k = (float)monitor->nis_count;
        monitor->last_mean_nis = nis / k;
        inconsistent = !(nis <= chi_square_upper(k, PROPID_CONSISTENCY_NIS_Z)); /* NaN: inconsistent */
    }

    const float elapsed_s = (float)(uint32_t)(core->time_us - monitor->start_time_us) * 1.0e-6f;
    const float drift_bound = PROPID_CONSISTENCY_DRIFT_Z * PROPID_CONSISTENCY_DRIFT_Z;
    const float steady_bound = PROPID_CLAIM_DRIFT_Z * PROPID_CLAIM_DRIFT_Z;
    uint16_t steady = 0u;
    float worst = 0.0f;
#if PROPID_WITH_ACCEL
    /* A walking thrust-torque scale walks the thrust states too (g = s kf: by
     * kf ds, docs/math.md §9), at the current kf. */
    const uint8_t scale = derived->layout.torque_scale;
    const float scale_walk = scale != PROPID_NO_STATE
                                 ? propid_process_psd(derived, scale) * core->state[scale] * core->state[scale]
                                 : 0.0f;
#endif
    for (uint8_t c = 0; c < count; ++c) {
        const uint8_t k = (uint8_t)(first + c);
        const float var_end = var[c];
        float psd = propid_process_psd(derived, k);
#if PROPID_WITH_ACCEL
        if (k < derived->layout.drag) {
            psd += scale_walk * value[c] * value[c];
        }
#endif
        const float removed = monitor->start_var[c] + psd * elapsed_s - var_end;
        const float change = value[c] - monitor->start_coeff[c];
        /* Steady (for a claim): within 3 explained std; down to the variance floor
         * (the resolution of P) when the window explained less: a coefficient
         * about which nothing was learnt should not move. */
        const float floor = propid_var_floor(derived, k);
        const float explained = removed > floor ? removed : floor;
        if (change * change <= steady_bound * explained) {
            steady |= (uint16_t)(1u << c);
        }
        if (!(removed > floor)) {
            continue; /* nothing learnt about it (or its variance was reset): no test */
        }
        const float drift = change * change / removed;
        worst = drift > worst ? drift : worst;
        if (drift > drift_bound) {
            inconsistent = 1;
        }
    }
    monitor->last_drift = worst;
    /* A gated axis sample in the window: the stream carried data the filter had
     * to refuse, and the fault that sent it may have let others through that
     * were not refused; claims wait for a window without one. */
    if (monitor->nis_count < 3u * monitor->samples) {
        steady = 0u;
    }
    monitor->steady_coeff = steady;

    if (inconsistent) {
        filter->counters.model_mismatch++;
        monitor->flagged = 1u;
        monitor->clean_windows = 0u;
        monitor->passed_windows = 0u;
        filter->core.health |= PROPID_HEALTH_MODEL_MISMATCH;
    } else {
        monitor->passed_windows = (uint16_t)(monitor->passed_windows < 0xFFFFu ? monitor->passed_windows + 1u : 0xFFFFu);
    }
    if (!inconsistent && monitor->flagged) {
        monitor->clean_windows++;
        if (monitor->clean_windows >= PROPID_CONSISTENCY_CLEAR_WINDOWS) {
            monitor->flagged = 0u;
            filter->core.health &= ~PROPID_HEALTH_MODEL_MISMATCH;
        }
    }
}

void propid_consistency_observe(propid_filter_t *filter, uint32_t gated_mask)
{
    propid_consistency_t *monitor = &filter->consistency;
    if (!monitor->started) {
        start_window(filter, NULL, NULL);
        return;
    }
    const propid_core_t *core = &filter->core;
    for (uint8_t a = 0; a < 3u; ++a) {
        if ((gated_mask & (1u << a)) == 0u) {
            monitor->nis_sum += core->innovation_test_ratio[a];
            monitor->nis_count++;
        }
    }
    ++monitor->samples;
    /* The NIS test also on the running sum at every eighth of the window, so a
     * gross mismatch is flagged within a fraction of a second (before the
     * coefficients' first convergence); the drift test needs the whole window. */
    if (monitor->samples < monitor->window) {
        if (monitor->samples % monitor->check_every != 0u || monitor->nis_count == 0u ||
            monitor->nis_sum <= chi_square_upper((float)monitor->nis_count, PROPID_CONSISTENCY_NIS_Z) *
                                     filter->derived.inv_gate_sq) {
            return;
        }
    }
    /* The coefficients per rotor once for both (the blocks are kept in their bases). */
    float value[2u * PROPID_MAX_ROTORS];
    float var[2u * PROPID_MAX_ROTORS];
    per_rotor_coefficients(filter, value, var);
    close_window(filter, value, var);
    start_window(filter, value, var);
}

#endif /* PROPID_CONSISTENCY */
