/* Flight log v1 CSV writer (see flight_log.h). */
#include "flight_log.h"

#include <math.h>
#include <string.h>

#include "number_format.h"

/* One row is built in memory, then written at once. */
typedef struct {
    char text[8192];
    int len;
} row_text_t;

/* ",value" (",%.9g"), or "," alone for a missing value. */
static void put(row_text_t *row, double x)
{
    row->text[row->len++] = ',';
    if (isfinite(x)) {
        row->len += sitl_format_g9(x, row->text + row->len);
    }
}

static void header_indexed(FILE *f, const char *prefix, int n)
{
    for (int i = 1; i <= n; i++) {
        fprintf(f, ",%s%d", prefix, i);
    }
}

int sitl_flight_log_open(sitl_flight_log_t *log, const char *path, int rotor_count)
{
    log->rotor_count = rotor_count;
    log->file = fopen(path, "w");
    if (log->file == NULL) {
        return -1;
    }
    setvbuf(log->file, NULL, _IOFBF, 1 << 16); /* rows are ~ 1 kB */
    FILE *f = log->file;
    const int n = rotor_count;
    fprintf(f, "t,gyro_x,gyro_y,gyro_z");
    header_indexed(f, "omega_", n);
    fprintf(f, ",acc_x,acc_y,acc_z,qw,qx,qy,qz,vx,vy,vz,px,py,pz");
    header_indexed(f, "cmd_", n);
    fprintf(f, ",ref_px,ref_py,ref_pz,ref_yaw");
    header_indexed(f, "true_kf_", n);
    header_indexed(f, "true_km_", n);
    fprintf(f, ",true_bg_x,true_bg_y,true_bg_z,true_wx,true_wy,true_wz");
    for (int i = 1; i <= n; i++) {
        fprintf(f, ",est_kf_%d,std_kf_%d", i, i);
    }
    for (int i = 1; i <= n; i++) {
        fprintf(f, ",est_km_%d,std_km_%d", i, i);
    }
    fprintf(f, ",est_bg_x,est_bg_y,est_bg_z,std_bg_x,std_bg_y,std_bg_z,est_wx,est_wy,est_wz");
    fprintf(f, ",health,status");
    header_indexed(f, "true_omega_", n);
    fputc('\n', f);
    return ferror(f) ? -1 : 0;
}

int sitl_flight_log_write(sitl_flight_log_t *log, const sitl_log_row_t *r)
{
    FILE *f = log->file;
    const int n = log->rotor_count;
    const propid_estimate_t *e = &r->estimate;
    row_text_t row_text;
    row_text_t *row = &row_text;
    row->len = sitl_format_g9(r->t, row->text);
    for (int k = 0; k < 3; k++) {
        put(row, r->gyro[k]);
    }
    for (int i = 0; i < n; i++) {
        put(row, r->omega[i]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, r->acc[k]);
    }
    for (int k = 0; k < 4; k++) {
        put(row, r->quat[k]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, r->velocity[k]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, r->position[k]);
    }
    for (int i = 0; i < n; i++) {
        put(row, r->cmd[i]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, r->ref_position[k]);
    }
    put(row, r->ref_yaw);
    for (int i = 0; i < n; i++) {
        put(row, r->true_kf[i]);
    }
    for (int i = 0; i < n; i++) {
        put(row, r->true_km[i]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, r->true_bias[k]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, r->true_rate[k]);
    }
    for (int i = 0; i < n; i++) {
        put(row, (double)e->thrust_coeff[i]);
        put(row, (double)e->thrust_coeff_std[i]);
    }
    for (int i = 0; i < n; i++) {
        put(row, (double)e->drag_coeff[i]);
        put(row, (double)e->drag_coeff_std[i]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, (double)e->gyro_bias[k]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, (double)e->gyro_bias_std[k]);
    }
    for (int k = 0; k < 3; k++) {
        put(row, (double)e->body_rate[k]);
    }
    row->len += snprintf(row->text + row->len, sizeof(row->text) - (size_t)row->len, ",%lu,%d",
                         (unsigned long)e->health, r->status);
    for (int i = 0; i < n; i++) {
        put(row, r->true_omega[i]);
    }
    row->text[row->len++] = '\n';
    fwrite(row->text, 1, (size_t)row->len, f);
    return ferror(f) ? -1 : 0;
}

int sitl_flight_log_close(sitl_flight_log_t *log)
{
    if (log->file == NULL) {
        return 0;
    }
    int bad = ferror(log->file);
    bad |= fclose(log->file) != 0;
    log->file = NULL;
    return bad ? -1 : 0;
}

void sitl_flight_log_vehicle_path(const char *csv_path, char *out, size_t out_size)
{
    size_t len = strlen(csv_path);
    if (len >= 4 && strcmp(csv_path + len - 4, ".csv") == 0) {
        snprintf(out, out_size, "%.*s.vehicle.json", (int)(len - 4), csv_path);
    } else {
        snprintf(out, out_size, "%s.vehicle.json", csv_path);
    }
}
