/* Tracking and convergence metrics (see metrics.h). */
#include "metrics.h"

#include <math.h>
#include <string.h>

#include "sitl_math.h"

void sitl_metrics_init(sitl_metrics_t *m, int rotor_count, const double *kf_prior_std,
                       const double *km_prior_std, double bias_prior_std)
{
    memset(m, 0, sizeof(*m));
    m->rotor_count = rotor_count;
    for (int i = 0; i < rotor_count; i++) {
        m->kf_tolerance[i] = 0.1 * kf_prior_std[i];
        m->km_tolerance[i] = 0.1 * km_prior_std[i];
    }
    m->bias_tolerance = 0.1 * bias_prior_std;
    m->coeff_converged_since = -1.0;
    m->bias_converged_since = -1.0;
}

/* fmax(m, x) for m never NaN (a NaN x keeps m, as fmax does) without libm's
 * call: metrics run at every control step. */
static double larger(double m, double x)
{
    return x > m ? x : m;
}

void sitl_metrics_add(sitl_metrics_t *m, double t, const double position[3],
                      const double ref_position[3], double yaw, double ref_yaw,
                      const propid_estimate_t *e, const double *true_kf, const double *true_km,
                      const double true_bias[3])
{
    m->samples++;
    for (int k = 0; k < 3; k++) {
        m->position_error[k] = position[k] - ref_position[k];
        m->sum_sq[k] += m->position_error[k] * m->position_error[k];
    }
    m->yaw_error = sitl_wrap_angle(yaw - ref_yaw);
    m->sum_sq_yaw += m->yaw_error * m->yaw_error;

    int coeff_inside = 1;
    m->kf_rel_error_max = 0.0;
    m->km_rel_error_max = 0.0;
    for (int i = 0; i < m->rotor_count; i++) {
        double dkf = (double)e->thrust_coeff[i] - true_kf[i];
        double dkm = (double)e->drag_coeff[i] - true_km[i];
        coeff_inside &= fabs(dkf) <= m->kf_tolerance[i] && fabs(dkm) <= m->km_tolerance[i];
        m->kf_rel_error_max = larger(m->kf_rel_error_max, fabs(dkf / true_kf[i]));
        m->km_rel_error_max = larger(m->km_rel_error_max, fabs(dkm / true_km[i]));
    }
    int bias_inside = 1;
    m->bias_error_max = 0.0;
    for (int k = 0; k < 3; k++) {
        double db = fabs((double)e->gyro_bias[k] - true_bias[k]);
        bias_inside &= db <= m->bias_tolerance;
        m->bias_error_max = larger(m->bias_error_max, db);
    }
    if (!coeff_inside) {
        m->coeff_converged_since = -1.0;
    } else if (m->coeff_converged_since < 0.0) {
        m->coeff_converged_since = t;
    }
    if (!bias_inside) {
        m->bias_converged_since = -1.0;
    } else if (m->bias_converged_since < 0.0) {
        m->bias_converged_since = t;
    }
}

double sitl_metrics_rmse(const sitl_metrics_t *m, int axis)
{
    return m->samples > 0 ? sqrt(m->sum_sq[axis] / (double)m->samples) : 0.0;
}

double sitl_metrics_rmse_yaw_deg(const sitl_metrics_t *m)
{
    return m->samples > 0 ? sqrt(m->sum_sq_yaw / (double)m->samples) * 180.0 / SITL_PI : 0.0;
}
