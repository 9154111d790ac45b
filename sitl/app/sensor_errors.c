/* Filter input-error terms from the sensor model (see sensor_errors.h). */
#include "sensor_errors.h"

#include <math.h>
#include <string.h>

int sitl_sensor_errors(const sitl_vehicle_t *v, const sitl_esc_params_t *esc,
                       sitl_sensor_errors_t *out)
{
    memset(out, 0, sizeof(*out));
    double kf_sum = 0.0;
    for (int i = 0; i < v->rotor_count; i++) {
        kf_sum += v->rotor[i].thrust_coeff;
    }
    if (!(kf_sum > 0.0) || !(v->mass > 0.0) || esc->pole_pairs < 1) {
        return -1;
    }
    const double hover = sqrt(v->mass * 9.81 / kf_sum);
    out->hover_speed = hover;

    /* Quantisation: the error of a speed within one code is uniform over the
     * step, std step / sqrt(12); it holds while the speed stays on the code. */
    if (esc->quantise_dshot) {
        out->rotor_speed_noise = sitl_esc_dshot_step(hover, esc->pole_pairs) / sqrt(12.0);
        out->rotor_speed_noise_time = SITL_HELD_STEP_TIME_S;
    }
    out->rotor_delay_s = esc->latency_s;
    return 0;
}
