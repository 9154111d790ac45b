/* Honesty metrics of the filter against the truth (see honesty.h). */
#include "honesty.h"

#include <math.h>
#include <string.h>

#include "../../firmware/src/propid_internal.h" /* the coefficient blocks' bases */

#define HONESTY_CONVERGED_TOL 0.05  /* a "converged" coefficient more than this off is a false claim */
#define HONESTY_RECOVERED_TOL 0.10  /* recovered: every coefficient within this of the truth */
#define HONESTY_NEES_EVERY 10      /* control steps between NEES samples (50 Hz at 500 Hz control) */
#define HONESTY_MAX_DOF SITL_HONESTY_MAX_DOF

/* z-quantile of chi-square(k), Wilson-Hilferty. */
static double chi_square_quantile(double k, double z)
{
    const double c = 2.0 / (9.0 * k);
    const double root = 1.0 - c + z * sqrt(c);
    return k * root * root * root;
}

void sitl_honesty_init(sitl_honesty_t *h, const propid_filter_t *filter, const double *true_kf,
                       const double *true_km, double true_torque_scale)
{
    const int rotor_count = filter->config.rotor_count;
    memset(h, 0, sizeof(*h));
    h->nees_dof = 2 * rotor_count + 3 + (filter->derived.layout.torque_scale != PROPID_NO_STATE);
    h->true_torque_scale = true_torque_scale;
    memcpy(h->last_true_kf, true_kf, (size_t)rotor_count * sizeof(double));
    memcpy(h->last_true_km, true_km, (size_t)rotor_count * sizeof(double));
    h->change_time_s = -1.0;
    h->inside_since_s = -1.0;
    h->max_recovery_s = -1.0;
    h->rotor_inside_since_s = -1.0;
    h->max_rotor_recovery_s = -1.0;
    h->last_inside = 1;
    h->last_rotor_inside = ~0u;
    h->first_all_claimed_s = -1.0;
}

/* e^T P^-1 e by Cholesky (double); P's lower triangle by columns,
 * p_col[j][i] = P[i][j] for i >= j, zeros elsewhere (add_nees); returns -1 when
 * P is not positive definite. The divisions by the diagonal
 * are multiplications by its reciprocals (rounding-level difference). Both
 * passes go column by column: every element takes the same operations in the
 * same order as row by row (its sum over k in k order), but the elements of one
 * column do not wait for each other. The factor is kept transposed, lt[k][i] =
 * L[i][k], and the factorisation takes a column's elements four at a time (GCC
 * and Clang vector extensions): the lanes above the diagonal and beyond n hold
 * values nothing reads (each lane its own chain). */
#if defined(__GNUC__)
typedef double honesty_v4d __attribute__((vector_size(32)));
#define HONESTY_LANES 4
_Static_assert(HONESTY_MAX_DOF % HONESTY_LANES == 0, "whole vectors per column");
#endif

static inline __attribute__((always_inline)) double
nees_of_inline(const double p_col[HONESTY_MAX_DOF][HONESTY_MAX_DOF], const double *e, int n)
{
    double inv_diag[HONESTY_MAX_DOF];
    double y[HONESTY_MAX_DOF];
#if defined(__GNUC__)
    honesty_v4d lt[HONESTY_MAX_DOF][HONESTY_MAX_DOF / HONESTY_LANES];
    const int vectors = (n + HONESTY_LANES - 1) / HONESTY_LANES;
    for (int j = 0; j < n; j++) {
        /* s[j]: the diagonal's sum, s[i > j]: the column's. */
        const int first = j / HONESTY_LANES;
        honesty_v4d s[HONESTY_MAX_DOF / HONESTY_LANES];
        for (int v = first; v < vectors; v++) {
            memcpy(&s[v], &p_col[j][HONESTY_LANES * v], sizeof(s[v]));
        }
        for (int k = 0; k < j; k++) {
            const double l_jk = lt[k][first][j % HONESTY_LANES];
            for (int v = first; v < vectors; v++) {
                s[v] -= lt[k][v] * l_jk;
            }
        }
        const double d = s[first][j % HONESTY_LANES];
        if (!(d > 0.0)) {
            return -1.0;
        }
        const double l_jj = sqrt(d);
        inv_diag[j] = 1.0 / l_jj;
        for (int v = first; v < vectors; v++) {
            lt[j][v] = s[v] * inv_diag[j];
        }
        lt[j][first][j % HONESTY_LANES] = l_jj;
    }
#define HONESTY_LT(k, i) lt[k][(i) / HONESTY_LANES][(i) % HONESTY_LANES]
#else
    double lt[HONESTY_MAX_DOF][HONESTY_MAX_DOF];
    for (int j = 0; j < n; j++) {
        double s[HONESTY_MAX_DOF];
        for (int i = j; i < n; i++) {
            s[i] = p_col[j][i];
        }
        for (int k = 0; k < j; k++) {
            const double l_jk = lt[k][j];
            for (int i = j; i < n; i++) {
                s[i] -= lt[k][i] * l_jk;
            }
        }
        if (!(s[j] > 0.0)) {
            return -1.0;
        }
        lt[j][j] = sqrt(s[j]);
        inv_diag[j] = 1.0 / lt[j][j];
        for (int i = j + 1; i < n; i++) {
            lt[j][i] = s[i] * inv_diag[j];
        }
    }
#define HONESTY_LT(k, i) lt[k][i]
#endif
    /* Forward substitution: y[i] = (e[i] - sum_k<i l[i][k] y[k]) / l[i][i], each
     * sum taken in k order as y[k] becomes known. */
    double rest[HONESTY_MAX_DOF];
    for (int i = 0; i < n; i++) {
        rest[i] = e[i];
    }
    double nees = 0.0;
    for (int k = 0; k < n; k++) {
        y[k] = rest[k] * inv_diag[k];
        nees += y[k] * y[k];
        for (int i = k + 1; i < n; i++) {
            rest[i] -= HONESTY_LT(k, i) * y[k];
        }
    }
#undef HONESTY_LT
    return nees;
}

/* The quad's sizes (11 states, 12 with the torque scale) as constants, so the
 * loops above compile for them (the same operations in the same order). */
static double nees_of(const double p_col[HONESTY_MAX_DOF][HONESTY_MAX_DOF], const double *e, int n)
{
    switch (n) {
    case 11:
        return nees_of_inline(p_col, e, 11);
    case 12:
        return nees_of_inline(p_col, e, 12);
    default:
        return nees_of_inline(p_col, e, n);
    }
}

/* propid_reflection_flip_column's operations on one column (the same values):
 * inlined, with the reflection's count a constant where the caller has one. */
static inline __attribute__((always_inline)) void
flip_column(const propid_reflection_t *reflection, uint8_t count, propid_core_t *core, uint8_t column_index)
{
    const uint8_t first = reflection->first;
    float column[PROPID_MAX_ROTORS];
    for (uint8_t i = 0; i < count; ++i) {
        column[i] = propid_cov_at(core->cov, (uint8_t)(first + i), column_index);
    }
    propid_reflection_apply(reflection, column);
    for (uint8_t i = 0; i < count; ++i) {
        core->cov[propid_cov_index((uint8_t)(first + i), column_index)] = column[i];
    }
}

/* See honesty.h. A whole flip maps every column of P: 3 % of a flight at one NEES sample
 * per 10 control steps for each of the three reflections. Each column is mapped on its
 * own (propid_reflection_flip_column) and the block apart (flip_block), so the columns
 * the NEES does not read can be left out, the others taking the same operations. */
void sitl_honesty_coeff_per_rotor(const propid_filter_t *filter, const uint8_t *columns,
                                 int column_count, propid_core_t *core)
{
    const uint8_t rotors = filter->config.rotor_count;
    const propid_reflection_t basis = propid_drag_basis(&filter->derived, &filter->config);
    /* The columns the thrust block's reflections map: the asked ones, the drag block's
     * (its cross-covariances with the thrust block) and the thrust block's own outside
     * a reflection (H_1 leaves element 0 out). */
    uint8_t read[PROPID_MAX_STATES] = {0};
    for (int c = 0; c < column_count; c++) {
        read[columns[c]] = 1;
    }
    for (uint8_t i = 0; i < rotors; ++i) {
        read[basis.first + i] = 1;
        read[propid_first_thrust() + i] = 1;
    }
    /* The thrust block (state, those columns, block: its two reflections, H_1 first). */
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, &filter->config);
    for (uint8_t r = 2; r-- > 0;) {
        const propid_reflection_t reflection = propid_thrust_reflection(&thrust, r);
        const uint8_t end = (uint8_t)(reflection.first + reflection.count);
        propid_reflection_apply(&reflection, &core->state[reflection.first]);
        for (uint8_t j = 0; j < PROPID_MAX_STATES; ++j) {
            if (read[j] && (j < reflection.first || j >= end)) {
                if (reflection.count == 4u) {
                    flip_column(&reflection, 4u, core, j);
                } else if (reflection.count == 3u) {
                    flip_column(&reflection, 3u, core, j);
                } else {
                    flip_column(&reflection, reflection.count, core, j);
                }
            }
        }
        propid_reflection_flip_block(&reflection, core);
    }
    propid_reflection_apply(&basis, &core->state[basis.first]);
    for (int c = 0; c < column_count; c++) {
        if (basis.count == 4u) {
            flip_column(&basis, 4u, core, columns[c]);
        } else {
            flip_column(&basis, basis.count, core, columns[c]);
        }
    }
    propid_reflection_flip_block(&basis, core);
}

int sitl_honesty_truth(const propid_filter_t *filter, double true_torque_scale, const double *true_kf,
                       const double *true_km, const double true_bias[3], int *index, double *truth)
{
    const propid_config_t *config = &filter->config;
    const propid_layout_t *layout = &filter->derived.layout;
    const int n_rotor = config->rotor_count;
    const int has_scale = layout->torque_scale != PROPID_NO_STATE;
    /* Without the scale state the thrust states are kf / kf_nominal itself. */
    const double gain = has_scale ? true_torque_scale : 1.0;
    for (int i = 0; i < n_rotor; i++) {
        index[i] = layout->thrust + i;
        truth[i] = gain * (true_kf[i] / (double)config->rotor[i].thrust_coeff_nominal);
        index[n_rotor + i] = layout->drag + i;
        truth[n_rotor + i] = true_km[i] / (double)config->rotor[i].drag_coeff_nominal;
    }
    for (int a = 0; a < 3; a++) {
        index[2 * n_rotor + a] = layout->gyro_bias + a;
        truth[2 * n_rotor + a] = true_bias[a];
    }
    if (!has_scale) {
        return 2 * n_rotor + 3;
    }
    index[2 * n_rotor + 3] = layout->torque_scale;
    truth[2 * n_rotor + 3] = 1.0 / true_torque_scale;
    return 2 * n_rotor + 4;
}

/* 1 when the filter's whole stored P (every state, in its own basis: a
 * reflection of the drag block does not change definiteness) is positive
 * definite: Cholesky in double of the stored upper triangle. */
static int full_cov_positive_definite(const propid_filter_t *filter)
{
    const int n = filter->derived.state_count;
    double l[PROPID_MAX_STATES][PROPID_MAX_STATES];
    for (int j = 0; j < n; j++) {
        double d = (double)filter->core.cov[propid_cov_index((uint8_t)j, (uint8_t)j)];
        for (int k = 0; k < j; k++) {
            d -= l[j][k] * l[j][k];
        }
        if (!(d > 0.0)) {
            return 0;
        }
        l[j][j] = sqrt(d);
        for (int i = j + 1; i < n; i++) {
            double v = (double)filter->core.cov[propid_cov_index((uint8_t)j, (uint8_t)i)];
            for (int k = 0; k < j; k++) {
                v -= l[i][k] * l[j][k];
            }
            l[i][j] = v / l[j][j];
        }
    }
    return 1;
}

int sitl_honesty_dump_open(sitl_honesty_t *h, const propid_filter_t *filter, const char *path)
{
    h->dump = fopen(path, "w");
    if (h->dump == NULL) {
        return -1;
    }
    const int n_rotor = filter->config.rotor_count;
    const int n = h->nees_dof;
    fprintf(h->dump, "# propid_sitl NEES samples (docs/reliability.md, \"The NEES sample by sample\"): "
                     "%d rotors, %d states: kf_rel per rotor, km_rel per rotor, gyro bias x y z%s\n",
            n_rotor, n, n > 2 * n_rotor + 3 ? ", torque scale" : "");
    propid_thrust_basis_t thrust;
    propid_thrust_basis_init(&thrust, &filter->derived, &filter->config);
    const propid_reflection_t drag = propid_drag_basis(&filter->derived, &filter->config);
    /* Row k of each basis: its matrix applied to the unit vectors, transposed (H is symmetric). */
    for (int block = 0; block < 2; block++) {
        float rows[PROPID_MAX_ROTORS][PROPID_MAX_ROTORS];
        for (int j = 0; j < n_rotor; j++) {
            float x[PROPID_MAX_ROTORS] = {0.0f};
            x[j] = 1.0f;
            if (block == 0) {
                propid_thrust_to_basis(&thrust, x);
            } else {
                propid_reflection_transform(&drag, x);
            }
            for (int k = 0; k < n_rotor; k++) {
                rows[k][j] = x[k];
            }
        }
        for (int k = 0; k < n_rotor; k++) {
            fprintf(h->dump, "# %s_basis_%d", block == 0 ? "kf" : "km", k);
            for (int j = 0; j < n_rotor; j++) {
                fprintf(h->dump, ",%.9g", (double)rows[k][j]);
            }
            fputc('\n', h->dump);
        }
    }
    fprintf(h->dump, "t,nees");
    for (int i = 0; i < n; i++) {
        fprintf(h->dump, ",e_%d", i);
    }
    for (int i = 0; i < n; i++) {
        for (int j = 0; j <= i; j++) {
            fprintf(h->dump, ",p_%d_%d", i, j);
        }
    }
    return fputc('\n', h->dump) == EOF ? -1 : 0;
}

int sitl_honesty_dump_close(sitl_honesty_t *h)
{
    if (h->dump == NULL) {
        return 0;
    }
    const int closed = fclose(h->dump);
    h->dump = NULL;
    return closed != 0 || h->dump_write_errors > 0 ? -1 : 0;
}

static void dump_sample(sitl_honesty_t *h, double nees, const double *e,
                        const double p_col[HONESTY_MAX_DOF][HONESTY_MAX_DOF], int n)
{
    int failed = fprintf(h->dump, "%.6f,%.9g", h->dump_time_s, nees) < 0;
    for (int i = 0; i < n; i++) {
        failed |= fprintf(h->dump, ",%.9g", e[i]) < 0;
    }
    for (int i = 0; i < n; i++) {
        for (int j = 0; j <= i; j++) {
            failed |= fprintf(h->dump, ",%.9g", p_col[j][i]) < 0;
        }
    }
    failed |= fputc('\n', h->dump) == EOF;
    h->dump_write_errors += failed;
}

static void add_nees(sitl_honesty_t *h, const propid_filter_t *filter, const double *true_kf,
                     const double *true_km, const double true_bias[3])
{
    const int n_rotor = filter->config.rotor_count;
    int index[HONESTY_MAX_DOF];
    double truth[HONESTY_MAX_DOF];
    const int n = sitl_honesty_truth(filter, h->true_torque_scale, true_kf, true_km, true_bias, index, truth);
    /* The filter keeps its coefficient blocks in their bases (propid_internal.h): per rotor
     * here, the drag block's for the entries read below only. */
    propid_core_t core = filter->core;
    uint8_t columns[HONESTY_MAX_DOF];
    for (int i = 0; i < n_rotor; i++) {
        columns[i] = (uint8_t)index[i];
    }
    for (int a = 2 * n_rotor; a < n; a++) { /* the biases, and the scale when there is one */
        columns[a - n_rotor] = (uint8_t)index[a];
    }
    sitl_honesty_coeff_per_rotor(filter, columns, n - n_rotor, &core);
    double p_col[HONESTY_MAX_DOF][HONESTY_MAX_DOF] = {{0.0}}; /* nees_of's layout */
    double e[HONESTY_MAX_DOF];
    for (int i = 0; i < n; i++) {
        e[i] = (double)core.state[index[i]] - truth[i];
        for (int j = 0; j <= i; j++) {
            const int a = index[i] < index[j] ? index[i] : index[j];
            const int b = index[i] < index[j] ? index[j] : index[i];
            p_col[j][i] = (double)core.cov[propid_cov_index(a, b)]; /* the filter keeps the upper triangle */
        }
    }
    const double nees = nees_of(p_col, e, n);
    if (h->dump != NULL) {
        dump_sample(h, nees, e, p_col, n);
    }
    if (nees < 0.0 || !isfinite(nees)) {
        return;
    }
    h->nees_samples++;
    h->nees_sum += nees;
    /* Below the interval the filter's sigma is too large (underconfident, the safe side);
     * above it too small (overconfident). */
    if (nees < chi_square_quantile(n, -1.959964)) {
        h->nees_below_bounds++;
    } else if (nees > chi_square_quantile(n, 1.959964)) {
        h->nees_above_bounds++;
    } else {
        h->nees_in_bounds++;
    }
}

void sitl_honesty_add(sitl_honesty_t *h, double t, const propid_estimate_t *estimate,
                      const propid_filter_t *filter, const double *true_kf, const double *true_km,
                      const double true_bias[3])
{
    const int n = estimate->rotor_count;
    int inside = 1;
    int rotors_inside = 1;
    int all_claimed = n > 0;
    unsigned changed = 0u;
    unsigned rotor_inside_bits = 0u;
    /* Every reported value finite: their sum in double is (floats cannot overflow it;
     * an Inf or NaN makes it Inf or NaN), one test instead of one per value. */
    double reported_sum = 0.0;
    for (int i = 0; i < n; i++) {
        reported_sum += ((double)estimate->thrust_coeff[i] + (double)estimate->thrust_coeff_std[i]) +
                        ((double)estimate->drag_coeff[i] + (double)estimate->drag_coeff_std[i]);
        const double kf_err = fabs((double)estimate->thrust_coeff[i] / true_kf[i] - 1.0);
        const double km_err = fabs((double)estimate->drag_coeff[i] / true_km[i] - 1.0);
        if ((estimate->thrust_coeff_converged >> i) & 1u) {
            h->converged_claims++;
            h->false_converged += kf_err > HONESTY_CONVERGED_TOL;
        }
        if ((estimate->drag_coeff_converged >> i) & 1u) {
            h->converged_claims++;
            h->false_converged += km_err > HONESTY_CONVERGED_TOL;
        }
        all_claimed &= (int)((estimate->thrust_coeff_converged >> i) & (estimate->drag_coeff_converged >> i) & 1u);
        const int rotor_inside = kf_err <= HONESTY_RECOVERED_TOL && km_err <= HONESTY_RECOVERED_TOL;
        inside &= rotor_inside;
        const unsigned bit = 1u << i;
        rotor_inside_bits |= rotor_inside ? bit : 0u;
        if (true_kf[i] != h->last_true_kf[i] || true_km[i] != h->last_true_km[i]) {
            changed |= bit;
        }
        if ((h->changed_rotors | changed) & bit) {
            rotors_inside &= rotor_inside;
        }
        h->last_true_kf[i] = true_kf[i];
        h->last_true_km[i] = true_km[i];
    }
    for (int a = 0; a < 3; a++) {
        reported_sum += ((double)estimate->gyro_bias[a] + (double)estimate->gyro_bias_std[a]) +
                        ((double)estimate->body_rate[a] + (double)estimate->body_rate_std[a]);
    }
    const int finite = isfinite(reported_sum);
    if (!finite) {
        h->nonfinite_estimates++;
    }
    if (all_claimed && h->first_all_claimed_s < 0.0) {
        h->first_all_claimed_s = t;
    }
    h->all_claimed_at_end = all_claimed;
    if (changed) {
        sitl_honesty_finish(h); /* the previous change, if any: recovered or not */
        h->changes++;
        h->change_time_s = t;
        h->inside_since_s = -1.0;
        h->rotor_inside_since_s = -1.0;
        h->change_from_inside = h->last_inside;
        /* Against the estimate of the step before, and the truth before the change. */
        h->change_rotor_from_inside = (h->last_rotor_inside & changed) == changed;
        h->changed_rotors = changed;
    }
    h->last_inside = inside;
    h->last_rotor_inside = rotor_inside_bits;
    if (h->change_time_s >= 0.0) {
        if (!inside) {
            h->inside_since_s = -1.0;
        } else if (h->inside_since_s < 0.0) {
            h->inside_since_s = t;
        }
        if (!rotors_inside) {
            h->rotor_inside_since_s = -1.0;
        } else if (h->rotor_inside_since_s < 0.0) {
            h->rotor_inside_since_s = t;
        }
    }
    /* NEES every HONESTY_NEES_EVERY control steps: a Cholesky per sample would
     * cost the simulator several per cent, and 50 Hz samples a 10 s flight
     * 500 times. A countdown, not steps % HONESTY_NEES_EVERY (the same steps:
     * 0, 10, 20, ...): GCC had compiled that as a 64-bit division. */
    h->steps++;
    if (h->steps_to_nees-- == 0) {
        h->steps_to_nees = HONESTY_NEES_EVERY - 1;
        h->dump_time_s = t;
        if (h->check_cov) {
            h->cov_checks++;
            h->cov_not_pd += !full_cov_positive_definite(filter);
        }
        add_nees(h, filter, true_kf, true_km, true_bias);
    }
}

void sitl_honesty_finish(sitl_honesty_t *h)
{
    if (h->change_time_s < 0.0) {
        return;
    }
    if (h->inside_since_s >= 0.0) {
        const double recovery = h->inside_since_s - h->change_time_s;
        h->max_recovery_s = recovery > h->max_recovery_s ? recovery : h->max_recovery_s;
    } else {
        h->unrecovered++;
    }
    if (h->change_from_inside) {
        h->changes_from_inside++;
        h->recovered_from_inside += h->inside_since_s >= 0.0;
    }
    if (h->rotor_inside_since_s >= 0.0) {
        const double recovery = h->rotor_inside_since_s - h->change_time_s;
        h->max_rotor_recovery_s = recovery > h->max_rotor_recovery_s ? recovery : h->max_rotor_recovery_s;
        h->rotor_recovered++;
    }
    if (h->change_rotor_from_inside) {
        h->rotor_changes_from_inside++;
        h->rotor_recovered_from_inside += h->rotor_inside_since_s >= 0.0;
    }
    h->change_time_s = -1.0;
    h->inside_since_s = -1.0;
    h->rotor_inside_since_s = -1.0;
}
