/* Final summary on the terminal and as JSON (see sim.h). */
#include <math.h>
#include <stdio.h>

#include "json_file.h"
#include "sim.h"

/* %.9g: every float estimate reads back exactly; non-finite -> null. */
static sitl_json_t *number9(double x)
{
    char buf[32];
    if (!isfinite(x)) {
        return sitl_json_null();
    }
    snprintf(buf, sizeof(buf), "%.9g", x);
    return sitl_json_raw(buf);
}

static void add_number(sitl_json_t *object, const char *name, double value)
{
    sitl_json_add(object, name, number9(value));
}

/* A convergence time; "never" (< 0) -> null. */
static void add_time(sitl_json_t *object, const char *name, double t)
{
    sitl_json_add(object, name, t >= 0.0 ? number9(t) : sitl_json_null());
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
    char fx[256], text[32];
    sitl_effects_describe(&o->effects, fx, (int)sizeof(fx));
    sitl_json_t *root = sitl_json_object();
    sitl_json_add(root, "vehicle", sitl_json_string(o->vehicle));
    sitl_json_add(root, "trajectory", sitl_json_string(sitl_trajectory_name(o->trajectory)));
    sitl_json_add(root, "mode", sitl_json_string(sitl_mode_name(o->mode)));
    snprintf(text, sizeof(text), "%llu", (unsigned long long)o->seed); /* exact beyond 2^53 */
    sitl_json_add(root, "seed", sitl_json_raw(text));
    sitl_json_add(root, "effects", sitl_json_string(fx));
    sitl_json_add(root, "paper_sensors", sitl_json_bool(o->paper));
    add_number(root, "duration_s", o->duration_s);
    add_number(root, "trajectory_period_s", o->trajectory_period_s);
    add_number(root, "flown_s", r->flown_s);
    sitl_json_add(root, "exit_code", sitl_json_number(r->exit_code));
    sitl_json_add(root, "stable", sitl_json_bool(!r->diverged));
    sitl_json_add(root, "diverged_at_s",
                  r->diverged ? number9(r->diverged_at_s) : sitl_json_null());
    add_number(root, "rmse_x_m", r->rmse[0]);
    add_number(root, "rmse_y_m", r->rmse[1]);
    add_number(root, "rmse_z_m", r->rmse[2]);
    add_number(root, "rmse_yaw_deg", r->rmse_yaw_deg);
    add_number(root, "final_position_error_m", r->final_position_error_m);
    add_number(root, "final_yaw_error_deg", r->final_yaw_error_deg);
    add_number(root, "kf_rel_error_max", r->kf_rel_error_max);
    add_number(root, "km_rel_error_max", r->km_rel_error_max);
    add_number(root, "bias_error_max_rad_s", r->bias_error_max);
    add_time(root, "convergence_coeff_s", r->coeff_converged_s);
    add_time(root, "convergence_bias_s", r->bias_converged_s);
    sitl_json_add(root, "health", sitl_json_number((double)r->estimate.health));
    const char *names[4] = {"true_kf", "est_kf", "true_km", "est_km"};
    for (int k = 0; k < 4; k++) {
        sitl_json_t *list = sitl_json_add(root, names[k], sitl_json_array());
        for (int i = 0; i < r->rotor_count; i++) {
            double v = k == 0   ? r->true_kf[i]
                       : k == 1 ? (double)r->estimate.thrust_coeff[i]
                       : k == 2 ? r->true_km[i]
                                : (double)r->estimate.drag_coeff[i];
            sitl_json_append(list, number9(v));
        }
    }
    sitl_json_t *true_bias = sitl_json_add(root, "true_bias", sitl_json_array());
    sitl_json_t *est_bias = sitl_json_add(root, "est_bias", sitl_json_array());
    for (int a = 0; a < 3; a++) {
        sitl_json_append(true_bias, number9(r->true_bias[a]));
        sitl_json_append(est_bias, number9((double)r->estimate.gyro_bias[a]));
    }
    sitl_json_t *damages = sitl_json_add(root, "damage", sitl_json_array());
    for (int k = 0; k < o->damage_count; k++) {
        sitl_json_t *item = sitl_json_object();
        sitl_json_add(item, "rotor", sitl_json_number(o->damage[k].rotor + 1));
        add_number(item, "time_s", o->damage[k].time_s);
        add_number(item, "fraction", o->damage[k].fraction);
        sitl_json_add(item, "on_ground", sitl_json_bool(r->damage_on_ground[k] != 0));
        sitl_json_append(damages, item);
    }
    sitl_json_t *detections = sitl_json_add(root, "detections", sitl_json_array());
    for (int k = 0; k < r->detection_count; k++) {
        sitl_json_t *item = sitl_json_object();
        sitl_json_add(item, "rotor", sitl_json_number(r->detection_rotor[k] + 1));
        add_number(item, "time_s", r->detection_time_s[k]);
        sitl_json_append(detections, item);
    }
    sitl_json_add(root, "gyro_accepted", sitl_json_number((double)r->counters.gyro_accepted));
    sitl_json_add(root, "rotor_accepted", sitl_json_number((double)r->counters.rotor_accepted));
    sitl_json_add(root, "control_steps", sitl_json_number((double)r->control_steps));
    sitl_json_t *faults = sitl_json_add(root, "faults_injected", sitl_json_object());
    for (int k = 0; k < SITL_FAULT_COUNT; k++) {
        sitl_json_add(faults, sitl_fault_name((sitl_fault_class_t)k), sitl_json_number((double)r->faults_injected[k]));
    }
    sitl_json_t *rejected = sitl_json_add(root, "rejected", sitl_json_object());
    for (int k = 1; k < PROPID_REJECT_SLOTS; k++) {
        if (r->counters.rejected[k] != 0u) {
            sitl_json_add(rejected, propid_status_name((propid_status_t)(-k)), sitl_json_number((double)r->counters.rejected[k]));
        }
    }
    sitl_json_add(root, "axis_gated", sitl_json_number((double)(r->counters.axis_gated[0] + r->counters.axis_gated[1] +
                                                        r->counters.axis_gated[2])));
    sitl_json_add(root, "gate_reopened", sitl_json_number((double)r->counters.gate_reopened));
    sitl_json_add(root, "cov_repairs", sitl_json_number((double)r->counters.cov_repairs));
    sitl_json_add(root, "resyncs", sitl_json_number((double)r->counters.resyncs));
    sitl_json_add(root, "model_mismatch_windows", sitl_json_number((double)r->counters.model_mismatch));
    const sitl_honesty_t *h = &r->honesty;
    sitl_json_t *honesty = sitl_json_add(root, "honesty", sitl_json_object());
    sitl_json_add(honesty, "nees_dof", sitl_json_number(h->nees_dof));
    sitl_json_add(honesty, "nees_samples", sitl_json_number((double)h->nees_samples));
    sitl_json_add(honesty, "nees_in_bounds", sitl_json_number((double)h->nees_in_bounds));
    add_number(honesty, "nees_mean", h->nees_samples > 0 ? h->nees_sum / (double)h->nees_samples : 0.0);
    sitl_json_add(honesty, "nonfinite_estimates", sitl_json_number((double)h->nonfinite_estimates));
    sitl_json_add(honesty, "converged_claims", sitl_json_number((double)h->converged_claims));
    sitl_json_add(honesty, "false_converged", sitl_json_number((double)h->false_converged));
    add_time(honesty, "first_all_claimed_s", h->first_all_claimed_s);
    sitl_json_add(honesty, "all_claimed_at_end", sitl_json_number(h->all_claimed_at_end));
    sitl_json_add(honesty, "coefficient_changes", sitl_json_number(h->changes));
    sitl_json_add(honesty, "unrecovered", sitl_json_number(h->unrecovered));
    add_time(honesty, "max_recovery_s", h->max_recovery_s);
    sitl_json_add(honesty, "changes_from_inside", sitl_json_number(h->changes_from_inside));
    sitl_json_add(honesty, "recovered_from_inside", sitl_json_number(h->recovered_from_inside));
    sitl_json_add(honesty, "changed_rotor_recovered", sitl_json_number(h->rotor_recovered));
    add_time(honesty, "max_changed_rotor_recovery_s", h->max_rotor_recovery_s);
    snprintf(text, sizeof(text), "%.6g", r->wall_time_s);
    sitl_json_add(root, "wall_time_s", sitl_json_raw(text));
    snprintf(text, sizeof(text), "%.6g", r->flight_cpu_s);
    sitl_json_add(root, "flight_cpu_time_s", sitl_json_raw(text));
    return sitl_write_json_file(path, root);
}
