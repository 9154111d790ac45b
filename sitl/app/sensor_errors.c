/* Filter input-error terms from the sensor model (see sensor_errors.h). */
#include "sensor_errors.h"

#include <math.h>
#include <string.h>

#include "propid/propid.h"

int sitl_sensor_errors(const sitl_vehicle_t *v, const sitl_esc_params_t *esc, const double *flown_kf,
                       sitl_sensor_errors_t *out)
{
    memset(out, 0, sizeof(*out));
    double kf_sum = 0.0;
    for (int i = 0; i < v->rotor_count; i++) {
        kf_sum += flown_kf != NULL ? flown_kf[i] : v->rotor[i].thrust_coeff;
    }
    if (!(kf_sum > 0.0) || !(v->mass > 0.0) || esc->pole_pairs < 1) {
        return -1;
    }
    const double hover = sqrt(v->mass * 9.81 / kf_sum);
    out->hover_speed = hover;

    /* Quantisation: the ESC truncates the period, so the true speed lies
     * anywhere within one step of the code, uniform. Decoded at the code's
     * period (the flight controllers' drivers) a speed is too high by a share
     * of the step: mean step / 2, spread step / sqrt(12); the filter's input
     * error has mean 0, so the size that covers it is its root mean square
     * about 0, step / sqrt(3), held 1 s. Decoded at the middle of the code's
     * interval the mean is gone: the spread alone, step / sqrt(12), held as
     * long as the rotor's code stands (the hold from the telemetry, the
     * firmware's largest time its ceiling: at hover a code can stand for the
     * whole flight, a per-rotor coefficient error). No errors-in-variables
     * compensation: that removes the attenuation of a classical error (mean 0,
     * fresh at every sample), which this one is not (docs/math.md §14,
     * "Validity"). Split (--filter-decode-error-split): the period decode's
     * mean step / 2 as one error common to every rotor, its spread per rotor. */
    if (esc->quantise_dshot) {
        const double step = sitl_esc_dshot_step(hover, esc->pole_pairs);
        out->rotor_speed_noise_truncated = !esc->decode_middle;
        if (esc->decode_middle) {
            out->rotor_speed_noise = step / sqrt(12.0);
            out->rotor_speed_noise_time = (double)PROPID_ROTOR_SPEED_NOISE_TIME_MAX;
            out->rotor_speed_noise_hold = 1;
        } else {
            out->rotor_speed_noise = step / sqrt(3.0);
            out->rotor_speed_noise_time = SITL_HELD_STEP_TIME_S;
        }
    }
    out->rotor_delay_s = esc->latency_s;
    return 0;
}

double sitl_report_mean_age(const sitl_esc_params_t *esc, double gyro_rate_hz, double gyro_first_s)
{
    /* Instants in nanoseconds, rounded as the simulator's schedules round them. */
    const double report_ns = 1e9 / esc->rate_hz;
    const double gyro_ns = 1e9 / gyro_rate_hz;
    const double phase_ns = esc->phase_s * 1e9;
    const double latency_ns = llround(esc->latency_s * 1e9);
    const long samples = lround(gyro_rate_hz);
    double age_sum = 0.0;
    long counted = 0;
    for (long k = 0; k < samples; k++) {
        const double reach = (double)llround(gyro_first_s * 1e9 + (double)k * gyro_ns) + latency_ns;
        long long j = (long long)floor((reach - phase_ns) / report_ns) + 1;
        double arrived = (double)llround(phase_ns + (double)j * report_ns);
        while (j >= 0 && arrived > reach) { /* the newest report that arrived by the reach */
            j--;
            arrived = (double)llround(phase_ns + (double)j * report_ns);
        }
        if (j < 0) {
            continue;
        }
        age_sum += reach - arrived; /* the gyro time minus the report's measurement time */
        counted++;
    }
    return counted > 0 ? age_sum / (double)counted * 1e-9 : 0.0;
}
