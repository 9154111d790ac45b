/* ESC telemetry model (see esc_telemetry.h). */
#include "esc_telemetry.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "sitl_math.h"

void sitl_esc_default_params(sitl_esc_params_t *p)
{
    /* Bidirectional DShot: one eRPM report per motor command frame (here the
     * 500 Hz control loop), measured over the last electrical revolutions and
     * returned ~30 us after the frame: ~1 ms effective latency. */
    p->rate_hz = 500.0;
    p->phase_s = 0.00025;
    p->latency_s = 0.001;
    p->dropout_prob = 0.01;
    p->quantise_dshot = 1;
    p->decode_middle = 0;
    p->pole_pairs = 7;
}

void sitl_esc_paper_params(sitl_esc_params_t *p, double control_rate_hz)
{
    p->rate_hz = control_rate_hz;
    p->phase_s = 0.0;
    p->latency_s = 0.0;
    p->dropout_prob = 0.0;
    p->quantise_dshot = 0;
    p->decode_middle = 0;
    p->pole_pairs = 7;
}

int sitl_esc_init(sitl_esc_telemetry_t *esc, const sitl_esc_params_t *params, int rotor_count,
                  double extra_delay_s, double history_rate_hz, uint64_t seed)
{
    memset(esc, 0, sizeof(*esc));
    if (!(params->rate_hz > 0.0) || !(params->latency_s >= 0.0) || !(extra_delay_s >= 0.0) ||
        !(params->dropout_prob >= 0.0 && params->dropout_prob <= 1.0) ||
        params->pole_pairs < 1 || rotor_count < 1 || rotor_count > SITL_MAX_ROTORS ||
        !(history_rate_hz > 0.0)) {
        return -1;
    }
    esc->params = *params;
    esc->extra_delay_s = extra_delay_s;
    esc->rotor_count = rotor_count;
    double span = params->latency_s + extra_delay_s + 0.01;
    double cap = ceil(span * history_rate_hz) + 64.0;
    if (cap > 1e7) {
        return -1;
    }
    esc->capacity = (int)cap;
    esc->history = calloc((size_t)esc->capacity, sizeof(*esc->history));
    if (esc->history == NULL) {
        return -1;
    }
    sitl_rng_init(&esc->rng, seed, SITL_RNG_ESC);
    return 0;
}

void sitl_esc_free(sitl_esc_telemetry_t *esc)
{
    free(esc->history);
    esc->history = NULL;
}

void sitl_esc_record(sitl_esc_telemetry_t *esc, double t, const double *speed)
{
    sitl_speed_sample_t *s = &esc->history[esc->head];
    s->time = t;
    memcpy(s->speed, speed, (size_t)esc->rotor_count * sizeof(double));
    /* After every RK4 step: a compare, not an integer division. */
    esc->head = esc->head + 1 < esc->capacity ? esc->head + 1 : 0;
    if (esc->size < esc->capacity) {
        esc->size++;
    }
}

static const sitl_speed_sample_t *at(const sitl_esc_telemetry_t *esc, int age)
{
    /* age 0 = newest; 0 <= age < size <= capacity, so one wrap at most (a compare,
     * not an integer division: two or three per report). */
    int idx = esc->head - 1 - age;
    if (idx < 0) {
        idx += esc->capacity;
    }
    return &esc->history[idx];
}

/* True speeds at time t by linear interpolation in the history. */
static void lookup(const sitl_esc_telemetry_t *esc, double t, double *out)
{
    const sitl_speed_sample_t *newer = at(esc, 0);
    if (t >= newer->time || esc->size == 1) {
        memcpy(out, newer->speed, (size_t)esc->rotor_count * sizeof(double));
        return;
    }
    for (int age = 1; age < esc->size; age++) {
        const sitl_speed_sample_t *older = at(esc, age);
        if (older->time <= t) {
            double span = newer->time - older->time;
            double a = span > 0.0 ? (t - older->time) / span : 1.0;
            for (int i = 0; i < esc->rotor_count; i++) {
                out[i] = older->speed[i] + a * (newer->speed[i] - older->speed[i]);
            }
            return;
        }
        newer = older;
    }
    memcpy(out, newer->speed, (size_t)esc->rotor_count * sizeof(double)); /* oldest kept */
}

/* The e-period code of a speed: the ESC counts the electrical period in whole
 * microseconds and keeps its top 9 bits (mantissa) with a 3-bit shift, both by
 * dropping bits (a truncation). 0 when the period is too long to code (stopped). */
static int dshot_code(double speed, int pole_pairs, unsigned long *mantissa, unsigned *shift)
{
    if (!(speed > 0.0) || pole_pairs < 1) {
        return 0;
    }
    double period_us = 2.0 * SITL_PI * 1e6 / (speed * (double)pole_pairs);
    if (period_us >= 511.0 * 128.0) {
        return 0;
    }
    unsigned long period = (unsigned long)period_us; /* the ESC's timer truncates */
    unsigned s = 0;
    while ((period >> s) > 511u) {
        s++;
    }
    *mantissa = period >> s;
    *shift = s;
    return *mantissa != 0;
}

static double speed_of_period(double period_us, int pole_pairs)
{
    return 2.0 * SITL_PI * 1e6 / (period_us * (double)pole_pairs);
}

double sitl_esc_quantise_dshot(double speed, int pole_pairs, int decode_middle)
{
    unsigned long mantissa;
    unsigned shift;
    if (!dshot_code(speed, pole_pairs, &mantissa, &shift)) {
        return 0.0;
    }
    /* The true period lies in [m, m + 1) << shift: the flight controllers'
     * drivers take m << shift (a speed too high by a share of one step); its
     * middle is the unbiased decode. */
    double code_us = (double)mantissa + (decode_middle ? 0.5 : 0.0);
    /* times 2^shift: exact, and without a libm call on the 4-rotor x 500 Hz path */
    return speed_of_period(code_us * (double)(1ul << shift), pole_pairs);
}

double sitl_esc_dshot_step(double speed, int pole_pairs)
{
    unsigned long mantissa;
    unsigned shift;
    if (!dshot_code(speed, pole_pairs, &mantissa, &shift)) {
        return 0.0;
    }
    /* The speeds of the code's two period edges. */
    return speed_of_period((double)(mantissa << shift), pole_pairs) -
           speed_of_period((double)((mantissa + 1u) << shift), pole_pairs);
}

int sitl_esc_report(sitl_esc_telemetry_t *esc, double t, double *speed_out)
{
    /* Always draw, so the loss pattern does not depend on anything else. */
    double u = sitl_rng_uniform(&esc->rng);
    if (esc->size == 0 || u < esc->params.dropout_prob) {
        return 0;
    }
    lookup(esc, t - esc->params.latency_s - esc->extra_delay_s, speed_out);
    if (esc->params.quantise_dshot) {
        for (int i = 0; i < esc->rotor_count; i++) {
            speed_out[i] = sitl_esc_quantise_dshot(speed_out[i], esc->params.pole_pairs,
                                                  esc->params.decode_middle);
        }
    }
    return 1;
}
