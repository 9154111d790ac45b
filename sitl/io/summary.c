/* Final summary on the terminal and as JSON (see sim.h). */
#include <math.h>
#include <stdio.h>

#include "sim.h"

static void json_number(FILE *f, double x)
{
    if (isfinite(x)) {
        fprintf(f, "%.9g", x);
    } else {
        fprintf(f, "null");
    }
}

/* One `,\n  "name": number` member of the summary object. */
static void json_field(FILE *f, const char *name, double value)
{
    fprintf(f, ",\n  \"%s\": ", name);
    json_number(f, value);
}


static void json_time(FILE *f, double t)
{
    if (t >= 0.0) {
        fprintf(f, "%.9g", t);
    } else {
        fprintf(f, "null");
    }
}

void sitl_print_final_summary(FILE *out, const sitl_options_t *o, const sitl_result_t *r)
{
    char fx[256];
    sitl_effects_describe(&o->effects, fx, (int)sizeof(fx));
    fprintf(out, "---- propid_sitl: %s, %s, mode %s, seed %llu, effects %s\n", o->vehicle,
            sitl_trajectory_name(o->trajectory), sitl_mode_name(o->mode),
            (unsigned long long)o->seed, fx);
    if (r->diverged) {
        fprintf(out, "DIVERGED: %s\n", r->message);
    }
    fprintf(out, "flown %.3f s in %.3f s wall (%.1fx real time)\n", r->flown_s, r->wall_time_s,
            r->wall_time_s > 0.0 ? r->flown_s / r->wall_time_s : 0.0);
    fprintf(out, "tracking RMSE  x %.4f m  y %.4f m  z %.4f m  yaw %.3f deg\n", r->rmse[0],
            r->rmse[1], r->rmse[2], r->rmse_yaw_deg);
    fprintf(out, "final errors   position %.4f m  yaw %.3f deg\n", r->final_position_error_m,
            r->final_yaw_error_deg);
    fprintf(out, "filter final   max|kf/kf_true-1| %.2f%%  max|km/km_true-1| %.2f%%  "
                 "max|bias err| %.5f rad/s  health 0x%02lx\n",
            100.0 * r->kf_rel_error_max, 100.0 * r->km_rel_error_max, r->bias_error_max,
            (unsigned long)r->estimate.health);
    fprintf(out, "convergence    kf&km ");
    if (r->coeff_converged_s >= 0.0) {
        fprintf(out, "%.3f s", r->coeff_converged_s);
    } else {
        fprintf(out, "not converged");
    }
    fprintf(out, "   b_g ");
    if (r->bias_converged_s >= 0.0) {
        fprintf(out, "%.3f s\n", r->bias_converged_s);
    } else {
        fprintf(out, "not converged\n");
    }
    fprintf(out, "rotor   true kf    est kf     true km    est km\n");
    for (int i = 0; i < r->rotor_count; i++) {
        fprintf(out, "%5d   %.4e %.4e %.4e %.4e\n", i + 1, r->true_kf[i],
                (double)r->estimate.thrust_coeff[i], r->true_km[i],
                (double)r->estimate.drag_coeff[i]);
    }
    fflush(out);
}

int sitl_write_summary_json(const char *path, const sitl_options_t *o, const sitl_result_t *r)
{
    FILE *f = fopen(path, "w");
    if (f == NULL) {
        return -1;
    }
    char fx[256];
    sitl_effects_describe(&o->effects, fx, (int)sizeof(fx));
    fprintf(f, "{\n  \"vehicle\": \"%s\",\n  \"trajectory\": \"%s\",\n  \"mode\": \"%s\",\n",
            o->vehicle, sitl_trajectory_name(o->trajectory), sitl_mode_name(o->mode));
    fprintf(f, "  \"seed\": %llu,\n  \"effects\": \"%s\",\n  \"paper_sensors\": %s,\n",
            (unsigned long long)o->seed, fx, o->paper ? "true" : "false");
    fprintf(f, "  \"duration_s\": ");
    json_number(f, o->duration_s);
    json_field(f, "trajectory_period_s", o->trajectory_period_s);
    json_field(f, "flown_s", r->flown_s);
    fprintf(f, ",\n  \"exit_code\": %d,\n  \"stable\": %s,\n", r->exit_code,
            r->diverged ? "false" : "true");
    fprintf(f, "  \"diverged_at_s\": ");
    if (r->diverged) {
        json_number(f, r->diverged_at_s);
    } else {
        fprintf(f, "null");
    }
    json_field(f, "rmse_x_m", r->rmse[0]);
    json_field(f, "rmse_y_m", r->rmse[1]);
    json_field(f, "rmse_z_m", r->rmse[2]);
    json_field(f, "rmse_yaw_deg", r->rmse_yaw_deg);
    json_field(f, "final_position_error_m", r->final_position_error_m);
    json_field(f, "final_yaw_error_deg", r->final_yaw_error_deg);
    json_field(f, "kf_rel_error_max", r->kf_rel_error_max);
    json_field(f, "km_rel_error_max", r->km_rel_error_max);
    json_field(f, "bias_error_max_rad_s", r->bias_error_max);
    fprintf(f, ",\n  \"convergence_coeff_s\": ");
    json_time(f, r->coeff_converged_s);
    fprintf(f, ",\n  \"convergence_bias_s\": ");
    json_time(f, r->bias_converged_s);
    fprintf(f, ",\n  \"health\": %lu,\n", (unsigned long)r->estimate.health);
    const char *names[4] = {"true_kf", "est_kf", "true_km", "est_km"};
    for (int k = 0; k < 4; k++) {
        fprintf(f, "  \"%s\": [", names[k]);
        for (int i = 0; i < r->rotor_count; i++) {
            double v = k == 0   ? r->true_kf[i]
                       : k == 1 ? (double)r->estimate.thrust_coeff[i]
                       : k == 2 ? r->true_km[i]
                                : (double)r->estimate.drag_coeff[i];
            fprintf(f, "%s", i ? ", " : "");
            json_number(f, v);
        }
        fprintf(f, "],\n");
    }
    fprintf(f, "  \"true_bias\": [%.9g, %.9g, %.9g],\n", r->true_bias[0], r->true_bias[1],
            r->true_bias[2]);
    fprintf(f, "  \"est_bias\": [%.9g, %.9g, %.9g],\n", (double)r->estimate.gyro_bias[0],
            (double)r->estimate.gyro_bias[1], (double)r->estimate.gyro_bias[2]);
    fprintf(f, "  \"gyro_accepted\": %lu,\n  \"rotor_accepted\": %lu,\n",
            (unsigned long)r->counters.gyro_accepted, (unsigned long)r->counters.rotor_accepted);
    fprintf(f, "  \"control_steps\": %ld,\n  \"wall_time_s\": %.6g\n}\n", r->control_steps,
            r->wall_time_s);
    return fclose(f) == 0 ? 0 : -1;
}
