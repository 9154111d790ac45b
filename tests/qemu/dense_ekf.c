/*
 * Dense baseline of the propid gyro step (benchmark only, see dense_ekf.h).
 *
 * Written the way a generic small-EKF library does it: the model supplies the
 * predicted state and the Jacobian (here propid's own model code, so both
 * filters see the same model), the library does everything else with generic
 * N x N matrix products of run-time size, a transposed copy per product, a
 * Gauss-Jordan matrix inverse of the innovation covariance and the Joseph
 * form of the covariance update. No sparsity, no symmetry is exploited.
 */
#include "dense_ekf.h"

#include <math.h>
#include <string.h>

#include "propid_internal.h"

typedef float matrix_t[DENSE_MAX][DENSE_MAX];

/* out (r x c) = a (r x k) b (k x c) */
static void mat_mul(const matrix_t a, const matrix_t b, matrix_t out, int r, int k, int c)
{
    for (int i = 0; i < r; ++i) {
        for (int j = 0; j < c; ++j) {
            float sum = 0.0f;
            for (int m = 0; m < k; ++m) {
                sum += a[i][m] * b[m][j];
            }
            out[i][j] = sum;
        }
    }
}

/* out (c x r) = a (r x c) transposed */
static void transpose(const matrix_t a, matrix_t out, int r, int c)
{
    for (int i = 0; i < r; ++i) {
        for (int j = 0; j < c; ++j) {
            out[j][i] = a[i][j];
        }
    }
}

static void identity(matrix_t out, int n)
{
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
            out[i][j] = i == j ? 1.0f : 0.0f;
        }
    }
}

/* In-place n x n inverse by Gauss-Jordan with partial pivoting; -1 if singular. */
static int invert(matrix_t a, matrix_t inv, int n)
{
    identity(inv, n);
    for (int col = 0; col < n; ++col) {
        int pivot = col;
        for (int r = col + 1; r < n; ++r) {
            if (fabsf(a[r][col]) > fabsf(a[pivot][col])) {
                pivot = r;
            }
        }
        if (!(fabsf(a[pivot][col]) > 0.0f)) {
            return -1;
        }
        for (int j = 0; j < n; ++j) {
            float t = a[col][j];
            a[col][j] = a[pivot][j];
            a[pivot][j] = t;
            t = inv[col][j];
            inv[col][j] = inv[pivot][j];
            inv[pivot][j] = t;
        }
        const float scale = 1.0f / a[col][col];
        for (int j = 0; j < n; ++j) {
            a[col][j] *= scale;
            inv[col][j] *= scale;
        }
        for (int r = 0; r < n; ++r) {
            if (r != col) {
                const float f = a[r][col];
                for (int j = 0; j < n; ++j) {
                    a[r][j] -= f * a[col][j];
                    inv[r][j] -= f * inv[col][j];
                }
            }
        }
    }
    return 0;
}

/* Work matrices: static, as a generic library on a microcontroller keeps them. */
static matrix_t f_mat, f_t, tmp, tmp2, h, h_t, p_ht, s, s_inv, gain, gain_t, r_mat;

void dense_ekf_load(dense_ekf_t *dense, const propid_filter_t *model)
{
    const int n = model->derived.state_count;
    dense->n = n;
    for (int i = 0; i < n; ++i) {
        dense->x[i] = model->core.state[i];
        for (int j = 0; j < n; ++j) {
            dense->p[i][j] = propid_cov_at(model->core.cov, (uint8_t)i, (uint8_t)j);
        }
    }
}

int dense_ekf_step(dense_ekf_t *dense, propid_filter_t *model, uint64_t time_us,
                   const float gyro[3])
{
    const int n = dense->n;
    const propid_derived_t *derived = &model->derived;
    const float dt = (float)(uint32_t)(time_us - model->core.time_us) * 1.0e-6f;

    /* Model: predicted rates and the rate rows of F - I. */
    memcpy(model->core.state, dense->x, sizeof(float) * (size_t)n);
    float rate_next[3];
    float jacobian_dt[3][PROPID_JAC_ROW];
    if (propid_predict_stage(model, dt, rate_next, jacobian_dt) != PROPID_OK) {
        return -1;
    }
    identity(f_mat, n);
    for (int a = 0; a < 3; ++a) {
        for (uint8_t p = 0; p < propid_jacobian_entries(derived, (uint8_t)a); ++p) {
            f_mat[a][propid_jacobian_column(derived, (uint8_t)a, p)] += jacobian_dt[a][p];
        }
    }

    /* Prediction: x = f(x), P = F P F^T + Q (+ the same rounding loading). */
    for (int a = 0; a < 3; ++a) {
        dense->x[a] = rate_next[a];
    }
    mat_mul(f_mat, dense->p, tmp, n, n, n);
    transpose(f_mat, f_t, n, n);
    mat_mul(tmp, f_t, dense->p, n, n, n);
    for (int i = 0; i < n; ++i) {
        dense->p[i][i] += PROPID_VAR_LOADING * dense->p[i][i] + propid_process_psd(derived, (uint8_t)i) * dt;
    }

    /* Update with z = gyro, H = [I_3 0 I_3], R = gyro_var I_3. */
    const int bias = n - 3;
    for (int a = 0; a < 3; ++a) {
        for (int j = 0; j < n; ++j) {
            h[a][j] = (j == a || j == bias + a) ? 1.0f : 0.0f;
        }
        for (int b = 0; b < 3; ++b) {
            r_mat[a][b] = a == b ? derived->gyro_var : 0.0f;
        }
    }
    float innovation[3];
    for (int a = 0; a < 3; ++a) {
        float predicted = 0.0f;
        for (int j = 0; j < n; ++j) {
            predicted += h[a][j] * dense->x[j];
        }
        innovation[a] = gyro[a] - predicted;
    }
    transpose(h, h_t, 3, n);
    mat_mul(dense->p, h_t, p_ht, n, n, 3);
    mat_mul(h, p_ht, s, 3, n, 3);
    for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) {
            s[a][b] += r_mat[a][b];
        }
    }
    if (invert(s, s_inv, 3) != 0) {
        return -1;
    }
    mat_mul(p_ht, s_inv, gain, n, 3, 3);
    for (int i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            dense->x[i] += gain[i][a] * innovation[a];
        }
    }
    /* Joseph form: P = (I - K H) P (I - K H)^T + K R K^T. */
    mat_mul(gain, h, tmp, n, 3, n);
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
            tmp[i][j] = (i == j ? 1.0f : 0.0f) - tmp[i][j];
        }
    }
    mat_mul(tmp, dense->p, tmp2, n, n, n);
    transpose(tmp, f_t, n, n);
    mat_mul(tmp2, f_t, dense->p, n, n, n);
    mat_mul(gain, r_mat, tmp, n, 3, 3);
    transpose(gain, gain_t, n, 3);
    mat_mul(tmp, gain_t, tmp2, n, 3, n);
    for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) {
            dense->p[i][j] += tmp2[i][j];
        }
    }

    /* The model's bookkeeping for the next interval. */
    memcpy(model->core.input_speed_sq, model->core.rotor_speed_sq, sizeof(model->core.input_speed_sq));
    model->core.time_us = time_us;
    return 0;
}
