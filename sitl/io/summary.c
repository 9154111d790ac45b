/* Final summary on the terminal and as JSON (see sim.h). */
#include <math.h>
#include <stdio.h>

#include "json_file.h"
#include "number_format.h"
#include "sim.h"

/* %.9g (the log's formatter, byte for byte printf's): every float estimate
 * reads back exactly; non-finite -> null. */
static cJSON *number9(double x)
{
    char buf[SITL_G9_MAX];
    if (!isfinite(x)) {
        return cJSON_CreateNull();
    }
    sitl_format_g9(x, buf);
    return cJSON_CreateRaw(buf);
}

static void add_number(cJSON *object, const char *name, double value)
{
    cJSON_AddItemToObject(object, name, number9(value));
}

/* A convergence time; "never" (< 0) -> null. */
static void add_time(cJSON *object, const char *name, double t)
{
    cJSON_AddItemToObject(object, name, t >= 0.0 ? number9(t) : cJSON_CreateNull());
}

void sitl_print_final_summary(FILE *out, const sitl_options_t *o, const sitl_result_t *r)
{
    char fx[256];
    sitl_effects_describe(&o->effects, fx, (int)sizeof(fx));
    fprintf(out, "---- propid_sitl: %s, %s, mode %s, seed %llu, effects %s\n", o->vehicle,
            sitl_trajectory_name(o->trajectory), sitl_mode_name(o->mode),
            (unsigned long long)o->seed, fx);
    if (o->vehicle_seed_set) {
        fprintf(out, "vehicle seed %llu\n", (unsigned long long)o->vehicle_seed);
    }
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
    cJSON *root = cJSON_CreateObject();
    cJSON_AddStringToObject(root, "vehicle", o->vehicle);
    cJSON_AddStringToObject(root, "trajectory", sitl_trajectory_name(o->trajectory));
    cJSON_AddStringToObject(root, "mode", sitl_mode_name(o->mode));
    snprintf(text, sizeof(text), "%llu", (unsigned long long)o->seed); /* exact beyond 2^53 */
    cJSON_AddRawToObject(root, "seed", text);
    if (o->vehicle_seed_set) { /* absent by default: the default summary stays as it was */
        snprintf(text, sizeof(text), "%llu", (unsigned long long)o->vehicle_seed);
        cJSON_AddRawToObject(root, "vehicle_seed", text);
    }
    cJSON_AddStringToObject(root, "effects", fx);
    cJSON_AddBoolToObject(root, "paper_sensors", o->paper);
    add_number(root, "duration_s", o->duration_s);
    add_number(root, "trajectory_period_s", o->trajectory_period_s);
    add_number(root, "physics_rate_hz", r->physics_rate_hz);
    add_number(root, "flown_s", r->flown_s);
    cJSON_AddNumberToObject(root, "exit_code", r->exit_code);
    cJSON_AddBoolToObject(root, "stable", !r->diverged);
    cJSON_AddItemToObject(root, "diverged_at_s",
                          r->diverged ? number9(r->diverged_at_s) : cJSON_CreateNull());
    cJSON_AddItemToObject(root, "touchdown_at_s",
                          r->touchdown_at_s >= 0.0 ? number9(r->touchdown_at_s) : cJSON_CreateNull());
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
    cJSON_AddNumberToObject(root, "health", (double)r->estimate.health);
    const char *names[4] = {"true_kf", "est_kf", "true_km", "est_km"};
    for (int k = 0; k < 4; k++) {
        cJSON *list = cJSON_AddArrayToObject(root, names[k]);
        for (int i = 0; i < r->rotor_count; i++) {
            double v = k == 0   ? r->true_kf[i]
                       : k == 1 ? (double)r->estimate.thrust_coeff[i]
                       : k == 2 ? r->true_km[i]
                                : (double)r->estimate.drag_coeff[i];
            cJSON_AddItemToArray(list, number9(v));
        }
    }
    cJSON *true_bias = cJSON_AddArrayToObject(root, "true_bias");
    cJSON *est_bias = cJSON_AddArrayToObject(root, "est_bias");
    for (int a = 0; a < 3; a++) {
        cJSON_AddItemToArray(true_bias, number9(r->true_bias[a]));
        cJSON_AddItemToArray(est_bias, number9((double)r->estimate.gyro_bias[a]));
    }
    if (r->estimate.model_terms & PROPID_TERM_ACCEL) {
        /* The accelerometer aiding (--filter-accel): what its z bias state holds against the
         * sensor's, and how often the gate held samples off or re-anchored the bias
         * (a collective thrust loss it absorbs would show here, docs/damage.md). */
        cJSON *accel = cJSON_AddObjectToObject(root, "accel");
        add_number(accel, "true_bias_z", r->true_accel_bias_z);
        add_number(accel, "est_bias_z", (double)r->estimate.accel_bias);
        add_number(accel, "est_bias_std_z", (double)r->estimate.accel_bias_std);
        cJSON_AddNumberToObject(accel, "accepted", (double)r->counters.accel_accepted);
        cJSON_AddNumberToObject(accel, "gated", (double)r->counters.accel_gated);
        cJSON_AddNumberToObject(accel, "reanchored", (double)r->counters.accel_reanchored);
    }
    cJSON *damages = cJSON_AddArrayToObject(root, "damage");
    for (int k = 0; k < o->damage_count; k++) {
        cJSON *item = cJSON_CreateObject();
        cJSON_AddNumberToObject(item, "rotor", o->damage[k].rotor + 1);
        add_number(item, "time_s", o->damage[k].time_s);
        add_number(item, "fraction", o->damage[k].fraction);
        cJSON_AddBoolToObject(item, "on_ground", r->damage_on_ground[k] != 0);
        cJSON_AddBoolToObject(item, "after_touchdown", r->damage_after_touchdown[k] != 0);
        cJSON_AddItemToArray(damages, item);
    }
    cJSON *detections = cJSON_AddArrayToObject(root, "detections");
    for (int k = 0; k < r->detection_count; k++) {
        cJSON *item = cJSON_CreateObject();
        cJSON_AddNumberToObject(item, "rotor", r->detection_rotor[k] + 1);
        add_number(item, "time_s", r->detection_time_s[k]);
        cJSON_AddItemToArray(detections, item);
    }
    cJSON_AddNumberToObject(root, "gyro_accepted", (double)r->counters.gyro_accepted);
    cJSON_AddNumberToObject(root, "rotor_accepted", (double)r->counters.rotor_accepted);
    cJSON_AddNumberToObject(root, "control_steps", (double)r->control_steps);
    cJSON *faults = cJSON_AddObjectToObject(root, "faults_injected");
    for (int k = 0; k < SITL_FAULT_COUNT; k++) {
        cJSON_AddNumberToObject(faults, sitl_fault_name((sitl_fault_class_t)k), (double)r->faults_injected[k]);
    }
    cJSON *rejected = cJSON_AddObjectToObject(root, "rejected");
    for (int k = 1; k < PROPID_REJECT_SLOTS; k++) {
        if (r->counters.rejected[k] != 0u) {
            cJSON_AddNumberToObject(rejected, propid_status_name((propid_status_t)(-k)), (double)r->counters.rejected[k]);
        }
    }
    cJSON_AddNumberToObject(root, "axis_gated", (double)(r->counters.axis_gated[0] + r->counters.axis_gated[1] +
                                                        r->counters.axis_gated[2]));
    cJSON_AddNumberToObject(root, "gate_reopened", (double)r->counters.gate_reopened);
    cJSON_AddNumberToObject(root, "gyro_stuck", (double)r->counters.gyro_stuck);
    cJSON_AddNumberToObject(root, "cov_repairs", (double)r->counters.cov_repairs);
    cJSON_AddNumberToObject(root, "resyncs", (double)r->counters.resyncs);
    cJSON_AddNumberToObject(root, "model_mismatch_windows", (double)r->counters.model_mismatch);
    const sitl_honesty_t *h = &r->honesty;
    cJSON *honesty = cJSON_AddObjectToObject(root, "honesty");
    cJSON_AddNumberToObject(honesty, "nees_dof", h->nees_dof);
    cJSON_AddNumberToObject(honesty, "nees_samples", (double)h->nees_samples);
    cJSON_AddNumberToObject(honesty, "cov_checks", (double)h->cov_checks);
    cJSON_AddNumberToObject(honesty, "cov_not_pd", (double)h->cov_not_pd);
    cJSON_AddNumberToObject(honesty, "nees_in_bounds", (double)h->nees_in_bounds);
    cJSON_AddNumberToObject(honesty, "nees_below_bounds", (double)h->nees_below_bounds);
    cJSON_AddNumberToObject(honesty, "nees_above_bounds", (double)h->nees_above_bounds);
    add_number(honesty, "nees_mean", h->nees_samples > 0 ? h->nees_sum / (double)h->nees_samples : 0.0);
    cJSON_AddNumberToObject(honesty, "nonfinite_estimates", (double)h->nonfinite_estimates);
    cJSON_AddNumberToObject(honesty, "converged_claims", (double)h->converged_claims);
    cJSON_AddNumberToObject(honesty, "false_converged", (double)h->false_converged);
    add_time(honesty, "first_all_claimed_s", h->first_all_claimed_s);
    cJSON_AddNumberToObject(honesty, "all_claimed_at_end", h->all_claimed_at_end);
    cJSON_AddNumberToObject(honesty, "coefficient_changes", h->changes);
    cJSON_AddNumberToObject(honesty, "unrecovered", h->unrecovered);
    add_time(honesty, "max_recovery_s", h->max_recovery_s);
    cJSON_AddNumberToObject(honesty, "changes_from_inside", h->changes_from_inside);
    cJSON_AddNumberToObject(honesty, "recovered_from_inside", h->recovered_from_inside);
    cJSON_AddNumberToObject(honesty, "changed_rotor_recovered", h->rotor_recovered);
    cJSON_AddNumberToObject(honesty, "changed_rotor_from_inside", h->rotor_changes_from_inside);
    cJSON_AddNumberToObject(honesty, "changed_rotor_recovered_from_inside", h->rotor_recovered_from_inside);
    add_time(honesty, "max_changed_rotor_recovery_s", h->max_rotor_recovery_s);
    snprintf(text, sizeof(text), "%.6g", r->wall_time_s);
    cJSON_AddRawToObject(root, "wall_time_s", text);
    snprintf(text, sizeof(text), "%.6g", r->flight_cpu_s);
    cJSON_AddRawToObject(root, "flight_cpu_time_s", text);
    return sitl_write_json_file(path, root);
}
