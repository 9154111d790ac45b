/*
 * Is the filter honest? Per control step, against the truth: NEES of the
 * coefficients and gyro biases with the filter's full covariance block (and
 * whether it lies in its 95 % chi-square interval), non-finite estimates,
 * "converged" claims and the false ones (a coefficient flagged converged while
 * more than 5 % off), and the recovery after a change of the true coefficients
 * (rotor loss, damage): the time until every kf and km is back within 10 % of
 * the truth and stays there. Read by `make soak` from the summary JSON.
 */
#ifndef SITL_HONESTY_H
#define SITL_HONESTY_H

#include <stdio.h>

#include "propid/propid.h"
#include "vehicle.h"

typedef struct {
    long steps;                 /* control steps seen */
    int steps_to_nees;          /* control steps before the next NEES sample */
    long nees_samples;          /* NEES samples (every 10th step) with a usable covariance block */
    long nees_in_bounds;        /* ... whose NEES lay in the 95 % chi-square interval */
    long nees_below_bounds;     /* ... below it (sigma too large: underconfident) */
    long nees_above_bounds;     /* ... above it (sigma too small: overconfident) */
    double nees_sum;
    int check_cov;              /* check the whole P for definiteness at every NEES sample (set after
                                   init; --honesty-cov-check: +3 % of a flight's instructions) */
    long cov_checks;            /* full covariance P checked for definiteness (at every NEES sample) */
    long cov_not_pd;            /* ... of them not positive definite (Cholesky in double) */
    int nees_dof;               /* 2 N + 3, 2 N + 4 with the thrust-torque scale state */
    double true_torque_scale;   /* s_true: the torque gain the filter's scale state stands for */
    long nonfinite_estimates;   /* steps with a non-finite estimate or std */
    long converged_claims;      /* coefficient-steps flagged converged */
    long false_converged;       /* ... of them more than 5 % off */
    double first_all_claimed_s; /* first step with every kf and km claimed converged, -1: never */
    int all_claimed_at_end;     /* every kf and km claimed converged at the latest step */
    double last_true_kf[SITL_MAX_ROTORS], last_true_km[SITL_MAX_ROTORS];
    double change_time_s;       /* latest change of the true coefficients, -1: none */
    double inside_since_s;      /* every coefficient within 10 % since then, -1: outside */
    double max_recovery_s;      /* longest completed recovery, -1: none */
    int changes;                /* changes of the true coefficients */
    int unrecovered;            /* changes not recovered by the end (or the next change) */
    /* The same, split by what a recovery can be asked for: */
    int last_inside;            /* every coefficient within 10 % at the latest step */
    int change_from_inside;     /* ... at the step before the latest change */
    int changes_from_inside;    /* changes with every coefficient within 10 % just before */
    int recovered_from_inside;  /* ... of them recovered (every coefficient back within 10 %) */
    unsigned changed_rotors;    /* bit i: rotor i's truth changed at the latest change */
    double rotor_inside_since_s; /* the changed rotors' kf, km within 10 % since then, -1: outside */
    int rotor_recovered;        /* changes whose changed rotors came back within 10 % and stayed */
    unsigned last_rotor_inside; /* bit i: rotor i's kf and km within 10 % at the latest step */
    int change_rotor_from_inside; /* the changed rotors were within 10 % just before the latest change */
    int rotor_changes_from_inside; /* changes whose changed rotors were within 10 % just before */
    int rotor_recovered_from_inside; /* ... of them: the changed rotors came back within 10 % and stayed */
    double max_rotor_recovery_s; /* longest such recovery, -1: none */
    FILE *dump;                 /* --nees-dump: every NEES sample's error and covariance (NULL: none) */
    double dump_time_s;         /* the time of the step add_nees is called at */
    long dump_write_errors;     /* rows the dump could not write */
} sitl_honesty_t;

/* filter: initialised (its configuration gives the states the NEES reads); true_torque_scale:
 * s_true of sitl_honesty_truth, used only when the filter has the scale state. */
void sitl_honesty_init(sitl_honesty_t *h, const propid_filter_t *filter, const double *true_kf,
                       const double *true_km, double true_torque_scale);

/* The states the NEES reads (index) and their true values (truth): kf / kf_nominal,
 * km / km_nominal, the gyro biases, in that order. With the thrust-torque scale state
 * (docs/math.md §9) the thrust states carry g_i = s kf_i / kf_nominal_i and the scale
 * state r = 1/s: their truth is s_true kf_true_i / kf_nominal_i and 1 / s_true, and r
 * is read last. s_true is the gain the true thrust torques have in the filter's model:
 * with the true inertia (1 + e) J_file (inertia_error), s_true = 1 / (1 + e).
 * Returns the count (2 N + 3, or 2 N + 4 with the scale state); arrays of
 * SITL_HONESTY_MAX_DOF. */
#define SITL_HONESTY_MAX_DOF (2 * SITL_MAX_ROTORS + 4)
int sitl_honesty_truth(const propid_filter_t *filter, double true_torque_scale, const double *true_kf,
                       const double *true_km, const double true_bias[3], int *index, double *truth);

/* --nees-dump (docs/reliability.md, "The NEES sample by sample"): open path and write its
 * head: comment lines with the states and the coefficient blocks' bases (each row of the kf
 * basis Q, z = Q kf_rel, and of the km basis H, w = H km_rel, per rotor), then the column
 * names. Every later NEES sample adds a row: t, nees (-1: P not positive definite), the error
 * (estimate - truth) of the NEES states (sitl_honesty_truth's order, per rotor), and the lower
 * triangle of their covariance row by row (p_i_j, j <= i). 0 on success, -1 when the file
 * cannot be written. sitl_honesty_dump_close closes it: 0, or -1 when a row or the close failed. */
int sitl_honesty_dump_open(sitl_honesty_t *h, const propid_filter_t *filter, const char *path);
int sitl_honesty_dump_close(sitl_honesty_t *h);

/* One control step: estimate, the filter (for its covariance), the truth. */
void sitl_honesty_add(sitl_honesty_t *h, double t, const propid_estimate_t *estimate,
                      const propid_filter_t *filter, const double *true_kf, const double *true_km,
                      const double true_bias[3]);

/* Close the recovery of the latest change (at the end of the flight, or at the
 * next change): recovered (inside at that moment) or not. */
void sitl_honesty_finish(sitl_honesty_t *h);

/* core (a copy of filter->core) with its coefficient entries per rotor where the NEES reads
 * them: the states, the two blocks, their cross-covariances and the given columns of P
 * (states outside the two blocks, and the thrust block's for the drag), by
 * propid_reflection_flip's own two parts (flip_column, flip_block), bit for bit as the
 * whole flip; the other columns stay in the kept bases. */
void sitl_honesty_coeff_per_rotor(const propid_filter_t *filter, const uint8_t *columns,
                                 int column_count, propid_core_t *core);

#endif /* SITL_HONESTY_H */
