/* Filter input-error terms from the sensor model (see sensor_errors.h). */
#include "sensor_errors.h"

#include <math.h>
#include <string.h>

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

    /* Quantisation: the ESC truncates the period, so a decoded speed is too
     * high by a share of one step, uniform over [0, step): mean step / 2, std
     * step / sqrt(12). The filter's input error has mean 0; the size that
     * covers this error is its root mean square about 0, step / sqrt(3) (the
     * mean is no smaller a part of it than the spread). It holds while the speed
     * stays on the code. No errors-in-variables compensation: that removes the
     * attenuation of a classical error (mean 0, fresh at every sample), which
     * this one is not (docs/math.md §14, "Validity"). */
    if (esc->quantise_dshot) {
        out->rotor_speed_noise = sitl_esc_dshot_step(hover, esc->pole_pairs) / sqrt(3.0);
        out->rotor_speed_noise_time = SITL_HELD_STEP_TIME_S;
    }
    out->rotor_delay_s = esc->latency_s;
    return 0;
}
