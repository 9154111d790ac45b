/*
 * Internal declarations shared by the filter's source files. Not installed,
 * not part of the API: tests may include it to reach the pieces directly.
 */
#ifndef PROPID_INTERNAL_H
#define PROPID_INTERNAL_H

#include <float.h>
#include <string.h>

#include "propid/propid.h"

/* Marks a filter on which propid_init() succeeded ("PRID"). */
#define PROPID_MAGIC 0x50524944u

/* State count of a quad: the step has an unrolled copy of its loops for it. */
#if PROPID_MAX_ROTORS >= 4
#define PROPID_QUAD_STATES 14u
#else
#define PROPID_QUAD_STATES 0u
#endif

/* Covariance storage: P is symmetric and only its upper triangle is kept,
 * packed row by row (propid.h, propid_cov_index): symmetry is exact by
 * construction and P takes n (n + 1) / 2 floats. Read an element at any (i, j)
 * with propid_cov_at; with constant indices it compiles to one load. */
static inline float propid_cov_at(const float *cov, uint8_t i, uint8_t j)
{
    return cov[propid_cov_index(i, j)];
}

/* Row i of the stored triangle as a pointer `row` with row[j] = P_ij for
 * j >= i (the elements left of the diagonal are other rows' and not P_ij). */
static inline float *propid_cov_row(float *cov, uint8_t i)
{
    return cov + (propid_cov_index(i, i) - i);
}
static inline const float *propid_cov_row_const(const float *cov, uint8_t i)
{
    return cov + (propid_cov_index(i, i) - i);
}

/* Distance from P_jj to P_(j+1)(j+1) in the packed triangle. */
static inline uint32_t propid_cov_diagonal_step(uint8_t j)
{
    return (uint32_t)PROPID_MAX_STATES - j;
}

/* Fixed Jacobian layout of a quad whose rate rows have the structure of a
 * diagonal inertia (derived->quad_layout = 1): row a of G has exactly
 * PROPID_QUAD_JAC_ENTRIES entries, entries 0 and 1 in the two other rate columns
 * (ascending), entries 2..5 in the columns of rotors 0..3's thrust coefficient
 * (rows 0 and 1) or drag coefficient (row 2). Entries that are structurally zero
 * for a given frame (a plus frame's roll row has no thrust from rotors 0 and 2)
 * stay in the layout with a zero torque: fixed straight-line kernels beat index
 * lists. */
#define PROPID_QUAD_JAC_ENTRIES 6u

/* Length of a row of the Jacobian work rows jacobian_dt[3][PROPID_JAC_ROW]
 * (propid_predict_stage): the general path's longest list, or the quad layout's 6. */
#if PROPID_GENERAL_VEHICLES
#define PROPID_JAC_ROW PROPID_MAX_STATES
#define PROPID_JAC_TORQUE_ROW (PROPID_MAX_STATES - 3) /* derived->jac_torque[3][...] */
#else
#define PROPID_JAC_ROW PROPID_QUAD_JAC_ENTRIES
#define PROPID_JAC_TORQUE_ROW 4 /* the quad layout's rotor entries 2..5 only */
#endif
/* The size-lean quad build's Jacobian rows fit the filter's work area (propid_predict_step). */
#if !PROPID_GENERAL_VEHICLES
_Static_assert(3u * PROPID_JAC_ROW <= 2u * PROPID_MAX_STATES, "Jacobian rows fit core.update_vector");
#endif

/* |predicted body rate| bound, 2 config.gyro_range: derived once in the full
 * build; the quad build does not store it (one multiply by 2, exact). */
static inline float propid_rate_limit(const propid_filter_t *filter)
{
#if PROPID_GENERAL_VEHICLES
    return filter->derived.rate_limit;
#else
    return 2.0f * filter->config.gyro_range;
#endif
}

/* config.rotor_delay_us as kept: without the delay buffer (PROPID_DELAY_SLOTS
 * 0) the configuration check admits only 0 and the quad build does not store it. */
static inline int32_t propid_kept_delay_us(const propid_kept_config_t *config)
{
#if PROPID_GENERAL_VEHICLES || PROPID_DELAY_SLOTS > 0
    return config->rotor_delay_us;
#else
    (void)config;
    return 0;
#endif
}

/* Where entry 2 of a quad layout row (rotor 0) is in derived->jac_torque[a]: the
 * general path's lists keep every entry in place, the quad build only the four
 * rotor entries. */
#define PROPID_QUAD_TORQUE_FIRST (PROPID_GENERAL_VEHICLES ? 2u : 0u)

/* State column of entry p of rate row a in the fixed quad layout. */
static inline uint8_t propid_quad_layout_column(uint8_t a, uint8_t p)
{
    if (p < 2u) { /* the two other rate columns, ascending */
        return (uint8_t)(p == 0u ? (a == 0u ? 1u : 0u) : (a == 2u ? 1u : 2u));
    }
    /* thrust columns in the roll and pitch rows, drag columns in the yaw row */
    return (uint8_t)(PROPID_RATE_STATES + (a < 2u ? 0u : 4u) + (p - 2u));
}

/* Entries of rate row a of G, and the state column of entry p: one pair of
 * accessors per build, so every caller reads the same names. */
#if PROPID_GENERAL_VEHICLES
/* General vehicles: the lists propid_init derived from the configuration. */
static inline uint8_t propid_jacobian_entries(const propid_derived_t *derived, uint8_t a)
{
    return derived->jac_count[a];
}
static inline uint8_t propid_jacobian_column(const propid_derived_t *derived, uint8_t a, uint8_t p)
{
    return derived->jac_column[a][p];
}
#else
/* Quad build: the fixed quad layout above; there are no lists to read. */
static inline uint8_t propid_jacobian_entries(const propid_derived_t *derived, uint8_t a)
{
    (void)derived;
    (void)a;
    return (uint8_t)PROPID_QUAD_JAC_ENTRIES;
}
static inline uint8_t propid_jacobian_column(const propid_derived_t *derived, uint8_t a, uint8_t p)
{
    (void)derived;
    return propid_quad_layout_column(a, p);
}
#endif

/*
 * Scheduling hints for the unrolled kernels. They change which instructions
 * the compiler emits, never a result: a compiler without them builds the same
 * filter, with a different instruction count than docs/performance.md's (which
 * is measured with arm-none-eabi-gcc).
 *
 * PROPID_SCHEDULE_BARRIER(): keeps the instruction scheduler from hoisting the
 * loads of later iterations of a fully unrolled kernel above this point:
 * hoisted loads outlive the 32 FPU registers and are spilled to the stack
 * (measured: ~100 extra instructions per kernel). No instruction is emitted.
 * GNU inline assembly (GCC, clang and the clang-based Arm Compiler 6);
 * nothing elsewhere.
 *
 * PROPID_RELOAD_BARRIER(object): `object` (a local array or struct) counts as
 * rewritten here, no instruction emitted: values loaded from it before are
 * loaded again after it, and values stored into it stay in memory, instead of
 * being held in registers across it. For kernels that need more values than
 * the 32 FPU registers hold: what the compiler would otherwise keep alive
 * costs a spill store and reload (and stack) each. GNU inline assembly, as
 * above; nothing elsewhere.
 *
 * PROPID_NO_EARLY_SCHEDULE: a whole kernel compiled without GCC's scheduling
 * pass before register allocation (-fschedule-insns), for straight-line
 * kernels whose hoisted loads outlive the FPU registers. GCC only: clang
 * defines __GNUC__ too but has no per-function switch for its scheduler and
 * warns on the unknown `optimize` attribute, so it is empty there (and on any
 * other compiler).
 */
#if defined(__GNUC__)
#define PROPID_SCHEDULE_BARRIER() __asm__ volatile("" ::: "memory")
#define PROPID_RELOAD_BARRIER(object) __asm__ volatile("" : "+m"(object))
#else
#define PROPID_SCHEDULE_BARRIER() ((void)0)
#define PROPID_RELOAD_BARRIER(object) ((void)0)
#endif
/* PROPID_ARM_BLOCK_MOVES: the quad downdate's rectangular tiles move their
 * rows' consecutive P elements and the vectors' consecutive values with the
 * Cortex-M4's VLDM/VSTM (GNU inline assembly: C has no way to ask for them, and
 * GCC emits them only for register saves), with the same fused multiply-
 * subtracts in the same order as the C loop compiled with -ffp-contract=fast
 * (the target build's flag): the same bits (propid_gyro.c, apply_row_group).
 * Only where the instructions exist (Thumb-2, a single-precision FPU with fused
 * multiply-add) and only for straight-line kernels (not in the size-lean build);
 * -DPROPID_NO_ARM_ASM keeps the portable C everywhere. */
#if !defined(PROPID_NO_ARM_ASM) && defined(__GNUC__) && defined(__thumb2__) && defined(__ARM_FP) && \
    ((__ARM_FP & 4) != 0) && defined(__ARM_FEATURE_FMA) && !PROPID_SIZE_LEAN
#define PROPID_ARM_BLOCK_MOVES 1
#else
#define PROPID_ARM_BLOCK_MOVES 0
#endif
/* PROPID_REGISTER_ORDER3(a, b, c): three float variables count as read and
 * rewritten here, no instruction emitted (GNU inline assembly on the FPU
 * registers, with the block moves; nothing elsewhere). The generated prediction
 * kernel forms two sums' first products of an element before the sum that starts
 * from that element: ordered so, the sum accumulates in the element's own
 * register, where GCC otherwise copies it first (propid_quad_predict.h). */
#if PROPID_ARM_BLOCK_MOVES
#define PROPID_REGISTER_ORDER3(a, b, c) __asm__("" : "+t"(a), "+t"(b), "+t"(c))
#else
#define PROPID_REGISTER_ORDER3(a, b, c) ((void)0)
#endif
/* PROPID_HOST_ROW_SWEEP: on 64-bit desktop hosts (x86-64, AArch64: the SITL, the
 * host tests, the Python binding) the quad downdate sweeps P one packed row at a
 * time in chunks of 4 consecutive floats (GNU C vector type: SSE, NEON), each
 * element with the row groups' operations in their order, so the same bits
 * (propid_gyro.c). The Cortex-M4 has no float SIMD: its row groups stay.
 * -DPROPID_NO_HOST_ROW_SWEEP keeps the row groups on the host too. */
#if !defined(PROPID_NO_HOST_ROW_SWEEP) && defined(__GNUC__) && (defined(__x86_64__) || defined(__aarch64__)) && \
    !PROPID_SIZE_LEAN
#define PROPID_HOST_ROW_SWEEP 1
#else
#define PROPID_HOST_ROW_SWEEP 0
#endif
/* PROPID_UNROLL(n): the pragma before a kernel's loop that asks for it fully
 * unrolled (straight-line code: fewer instructions per step, ~4 B of flash per
 * instruction); empty in the size-lean build (PROPID_SIZE_LEAN), whose loops stay
 * loops. Same arithmetic in the same order either way. */
#define PROPID_PRAGMA(text) _Pragma(#text)
#if PROPID_SIZE_LEAN || !defined(__GNUC__)
#define PROPID_UNROLL(n)
#else
#define PROPID_UNROLL(n) PROPID_PRAGMA(GCC unroll n)
#endif
/* PROPID_QUAD_INLINE: a quad kernel (or the one pass) that the quad build, which
 * has no general path, inlines into its only caller, the dispatcher between it and
 * the general path: a call, its argument passing and a frame less per step (the
 * quad build's filter object is within the 1 KiB reach of a VFP load from its
 * base, so its offsets cost nothing). The full build keeps it apart, with its
 * own base registers, and so does the size-lean build (inlined there its frame
 * put the prediction's stack chain at 264 B, over the 256 B budget, for 9
 * instructions more). */
#if PROPID_GENERAL_VEHICLES || PROPID_SIZE_LEAN
#define PROPID_QUAD_INLINE __attribute__((noinline))
#else
#define PROPID_QUAD_INLINE inline __attribute__((always_inline))
#endif
/* PROPID_RARE: a function the usual gyro step never runs (repairs, the per-axis
 * path, re-anchoring): compiled for size, its calls laid out as unlikely. */
#if defined(__GNUC__)
#define PROPID_RARE __attribute__((cold))
#else
#define PROPID_RARE
#endif
#if defined(__GNUC__) && !defined(__clang__)
#define PROPID_NO_EARLY_SCHEDULE __attribute__((optimize("no-schedule-insns")))
#else
#define PROPID_NO_EARLY_SCHEDULE
#endif
/* PROPID_NO_CLONE: a function GCC must not copy into a version specialised for
 * its caller (GCC only, as above). */
#if defined(__GNUC__) && !defined(__clang__)
#define PROPID_NO_CLONE __attribute__((noclone))
#else
#define PROPID_NO_CLONE
#endif

/* Covariance health in float32 (docs/math.md §2 "Rounding loading", design.md
 * §12). The prediction multiplies a variance by (1 + PROPID_VAR_LOADING): a PSD
 * diagonal term of one float32 epsilon of the variance, the size of one
 * rounding, so P stays positive definite where the exact P is nearly singular
 * (constant coefficients: correlations -> 1). Every step, but the drag
 * coefficients (km) every second step (chosen when they were kept per rotor,
 * where a loading of each km's own, far larger, variance re-opened their
 * best-determined combination, the yaw torque, every step; every second step
 * needed no covariance repair on the design flights, every fourth did:
 * math.md). In the drag block's yaw basis (below) that combination is loaded
 * by its own variance; the schedule was kept. The thrust coefficients are kept
 * in a torque basis (below) for the same reason: their roll- and pitch-torque
 * combinations are loaded by their own variances. A fraction of epsilon per step
 * is no option: 1 + eps/2 rounds to 1 in float32.
 * PROPID_ROUNDING_TOL is the rounding of the integrity tests themselves (a
 * product or a three-term sum of float32 values): differences within it are
 * not faults. */
#define PROPID_VAR_LOADING 1.1920929e-7f /* FLT_EPSILON = 2^-23 */
#define PROPID_ROUNDING_TOL (2.0f * PROPID_VAR_LOADING)

/* Rate loading (docs/math.md §2 "The rate block's loading"): the body rates'
 * predicted variances get PROPID_RATE_LOADING of their rounding scale
 * m (P_aa + sum_p G_ap^2 P_pp) instead (m = 1 + the row's Jacobian entries, 7 in
 * the quad layout; the general path takes max(8, m) eps for a longer row), which
 * is also above what the prediction's own rounding can take. A gyro update cuts a rate
 * variance by its cancellation factor f = P_pred / P_post and rounds the rate
 * block by up to ~6 eps f relative to the result; a loading of l eps before the
 * update leaves a gap of about l eps f in the rate block's correlation after it,
 * so a fixed l > 6 keeps rates that the gyroscopic coupling has correlated to
 * float32 resolution definite, whatever f. */
#define PROPID_RATE_LOADING (8.0f * PROPID_VAR_LOADING) /* 1 + 2^-20: exact in float32 */

/* Update loading: a gyro update computes the new variance of omega + b as
 * P_hh - P_hh^2 / S, exact only to ~epsilon P_hh in float32; when R is below
 * PROPID_UPDATE_LOADING P_hh that rounding is a sizable part of the result and
 * P loses its definiteness. The update then uses R_eff = PROPID_UPDATE_LOADING
 * P_hh (S += R_eff - R): float32 rounding treated as measurement noise. */
#define PROPID_UPDATE_LOADING (64.0f * PROPID_VAR_LOADING)

/* A "converged" claim (docs/reliability.md "Converged claims"): the coefficient's
 * relative error is below converged_rel_std. With an honest Gaussian std that
 * holds with 99.73 % when PROPID_CLAIM_SIGMAS std < converged_rel_std (the old
 * rule, 1 std, failed 32 % of the claims it could make at the threshold). */
#define PROPID_CLAIM_SIGMAS 3.0f

/* Variance floors per kind of state (docs/design.md "Variance floors"): they keep
 * rounding from driving a variance to zero. The thrust coefficients' is far below
 * the drag coefficients': their torque basis' roll and pitch elements are learnt
 * to std ~1e-6 on agile flights, and a floor above that is a loading of them
 * (docs/math.md §2); 1e-14 is about float32's resolution of a relative
 * coefficient near 1 (2^-24 ~ 6e-8), squared. */
#define PROPID_FLOOR_RATE 1.0e-12f
#define PROPID_FLOOR_THRUST 1.0e-14f
#define PROPID_FLOOR_DRAG 1.0e-10f
#define PROPID_FLOOR_BIAS 1.0e-14f

/* Rotor-speed slew test (propid_filter.c): the motor is taken up to this many
 * times faster than its configured time constant says (spread between motors
 * and with the battery's voltage, the stamps' jitter, an ESC's own filter). */
#define PROPID_MOTOR_SPEEDUP 2.0f
/* Changes below this fraction of max_rotor_speed are never refused by it: the
 * telemetry's resolution near standstill (a DShot eRPM frame reads 0 below its
 * longest period, some ESCs report whole hundreds of rpm). */
#define PROPID_SLEW_FLOOR 0.02f

/* Gate constant when gating is off (gate_sigma <= 0): a 1e15-sigma innovation
 * is never data; the gate test then also needs no "gating on" branch. */
#define PROPID_GATE_OFF_SQ 1.0e30f

/* propid_predict_stage's note that it bounded a predicted rate to
 * derived->rate_limit (not a public status: the step was accepted). */
#define PROPID_PREDICT_CLAMPED ((propid_status_t)2)


/* The rotor-inertia terms' data: one pair of accessors per build. */
#if PROPID_WITH_ROTOR_INERTIA
static inline int propid_rotor_inertia_on(const propid_derived_t *derived)
{
    return derived->rotor_inertia_on != 0u;
}
static inline float propid_rotor_gyro(const propid_derived_t *derived, uint8_t a, uint8_t b)
{
    return derived->rotor_gyro[a][b];
}
#else
/* Compiled out (propid_config.h): off, and every term 0. */
static inline int propid_rotor_inertia_on(const propid_derived_t *derived)
{
    (void)derived;
    return 0;
}
static inline float propid_rotor_gyro(const propid_derived_t *derived, uint8_t a, uint8_t b)
{
    (void)derived;
    (void)a;
    (void)b;
    return 0.0f;
}
#endif

/* The aerodynamic damping's rate-block entries A_ab = -(J^-1 D)_ab (docs/math.md
 * §17), one pair of accessors per build. */
#if PROPID_WITH_AERO_DAMPING
static inline int propid_aero_damping_on(const propid_derived_t *derived)
{
    return derived->aero_damping_on != 0u;
}
static inline float propid_aero_damping_entry(const propid_derived_t *derived, uint8_t a, uint8_t b)
{
    return derived->aero_damping[a][b];
}
#else
/* Compiled out (propid_config.h): off, and every entry 0. */
static inline int propid_aero_damping_on(const propid_derived_t *derived)
{
    (void)derived;
    return 0;
}
static inline float propid_aero_damping_entry(const propid_derived_t *derived, uint8_t a, uint8_t b)
{
    (void)derived;
    (void)a;
    (void)b;
    return 0.0f;
}
#endif

/* Index of the first thrust coefficient, first drag coefficient, first bias. */
static inline uint8_t propid_first_thrust(void) { return PROPID_RATE_STATES; }
static inline uint8_t propid_first_drag(uint8_t rotor_count)
{
    return (uint8_t)(PROPID_RATE_STATES + rotor_count);
}
static inline uint8_t propid_first_bias(uint8_t rotor_count)
{
    return (uint8_t)(PROPID_RATE_STATES + 2u * rotor_count);
}

/* The coefficients' bases (docs/math.md §2, "The drag coefficients' basis" and
 * "The thrust coefficients' basis"). The
 * state and P keep each coefficient block in an orthonormal basis whose first
 * elements are the torque combinations the gyro measures best, so those are
 * rounded (and loaded) relative to their own variances instead of the
 * individual coefficients' far larger ones:
 * - km: z = H km_rel, H the reflection I - scale v v^T with v = e_0 + s_0 s /
 *   sqrt(N), s the yaw signs: its first row is -s_0 s / sqrt(N), the yaw torque;
 * - kf: z = Q kf_rel, Q = H_1 H_0 two reflections, H_0 on the whole block with
 *   first row the roll-torque direction, H_1 on elements 1..N-1 with (H_1 H_0)'s
 *   second row the pitch-torque direction orthogonalised against it (the thrust
 *   torques per unit kf_rel at equal rotor speeds: propid_config.c).
 * Every reader of a per-rotor coefficient maps at the boundary; the rate rows'
 * coefficient entries are multiplied by the basis (a row times an orthonormal
 * matrix is again a row over the same N columns).
 *
 * One reflection H = I - scale v v^T (symmetric, orthogonal, its own inverse)
 * acting on the `count` states from `first` (v = 0: the identity). The general
 * build derives the vectors at init; the quad build reads the km's from a table
 * in flash by the relative yaw signs (config.yaw_sign_flips: v = (3/2, +-1/2,
 * +-1/2, +-1/2), scale 2/3) and the kf's from its derived data (theirs with the
 * scale folded into v: scale 1). */
typedef struct {
    const float *vector; /* v, count entries */
    float scale;         /* 2 / v.v (1 for a folded kf vector) */
    uint8_t first;       /* state index of v[0] */
    uint8_t count;
} propid_reflection_t;

#if !PROPID_GENERAL_VEHICLES
/* v for each pattern of rotors 1..3's yaw signs relative to rotor 0's (propid_coeff_basis.c). */
extern const float propid_quad_drag_basis[8][4];
#endif

/* The km block's reflection. */
static inline propid_reflection_t propid_drag_basis(const propid_derived_t *derived,
                                                    const propid_kept_config_t *config)
{
    propid_reflection_t basis;
#if PROPID_GENERAL_VEHICLES
    basis.vector = derived->drag_basis;
    basis.scale = derived->drag_basis_scale;
#else
    (void)derived;
    basis.vector = propid_quad_drag_basis[(config->yaw_sign_flips >> 1) & 7u];
    basis.scale = 2.0f / 3.0f;
#endif
    basis.first = propid_first_drag(config->rotor_count);
    basis.count = config->rotor_count;
    return basis;
}

/* The kf block's two reflections H_k = I - w w^T (w = v sqrt(2 / v.v): the
 * scale folded in, |w|^2 = 2, or w = 0 for the identity), H_0 over the whole
 * block, H_1 over elements 1..N-1 (vector[1][0] is element 1's), derived at
 * init (derived->thrust_basis; the quad build's room for them: its kept
 * counters, propid.h). */
typedef struct {
    const float *vector[2]; /* w of H_0 (N entries), of H_1 (N - 1 entries) */
    uint8_t rotor_count;
} propid_thrust_basis_t;

static inline void propid_thrust_basis_init(propid_thrust_basis_t *basis, const propid_derived_t *derived,
                                            const propid_kept_config_t *config)
{
    basis->rotor_count = config->rotor_count;
    basis->vector[0] = derived->thrust_basis;
    basis->vector[1] = derived->thrust_basis + PROPID_MAX_ROTORS;
}

/* Reflection k (0: H_0, 1: H_1) of the kf basis. */
static inline propid_reflection_t propid_thrust_reflection(const propid_thrust_basis_t *basis, uint8_t k)
{
    propid_reflection_t reflection;
    reflection.vector = basis->vector[k];
    reflection.scale = 1.0f;
    reflection.first = (uint8_t)(propid_first_thrust() + k);
    reflection.count = basis->rotor_count > k ? (uint8_t)(basis->rotor_count - k) : 0u;
    return reflection;
}

/* x := H x for the reflection's `count` values from x[0]. */
static inline void propid_reflection_apply(const propid_reflection_t *basis, float *x)
{
    const float *v = basis->vector;
    float dot = 0.0f;
    for (uint8_t i = 0; i < basis->count; ++i) {
        dot += v[i] * x[i];
    }
    dot *= basis->scale;
    for (uint8_t i = 0; i < basis->count; ++i) {
        x[i] -= dot * v[i];
    }
}
/* The same, as one out-of-line function (propid_coeff_basis.c) for the callers
 * outside the prediction's loops: the files that call it from several places
 * share this copy instead of each keeping its own (80 B of flash each). */
void propid_reflection_transform(const propid_reflection_t *basis, float *x);

/* An N-vector over the kf block, rotor order (x[0] is rotor 0's): into the basis
 * (z = Q x) or back per rotor (x = Q^T z). */
void propid_thrust_to_basis(const propid_thrust_basis_t *basis, float *x);
void propid_thrust_to_rotor(const propid_thrust_basis_t *basis, float *x);

/* propid_coeff_basis.c. The state's and P's block of one reflection between its
 * two bases (either way: H is its own inverse). */
PROPID_RARE void propid_reflection_flip(const propid_reflection_t *basis, propid_core_t *core);
/* Its two parts: one cross-covariance column j (a state outside the block), and the
 * block itself, both sides (H B H). The SITL's NEES maps only the columns it reads. */
PROPID_RARE void propid_reflection_flip_column(const propid_reflection_t *basis, propid_core_t *core,
                                               uint8_t column_index);
PROPID_RARE void propid_reflection_flip_block(const propid_reflection_t *basis, propid_core_t *core);
/* Both coefficient blocks of the state and P per rotor (to_rotor 1) or into the
 * kept bases (to_rotor 0). */
PROPID_RARE void propid_coeff_flip(const propid_derived_t *derived, const propid_kept_config_t *config,
                                   propid_core_t *core, int to_rotor);
/* Per-rotor km_rel (H z) and, when km_var is not NULL, their variances (H P_zz H)_ii. */
void propid_drag_per_rotor(const propid_reflection_t *basis, const propid_core_t *core, float *km_rel,
                           float *km_var);
/* Per-rotor kf_rel (Q^T z) and, when kf_var is not NULL, their variances
 * (Q^T P_zz Q)_ii. */
void propid_thrust_per_rotor(const propid_thrust_basis_t *basis, const propid_core_t *core, float *kf_rel,
                             float *kf_var);
/* Column k of P as the per-rotor state's (T^T P T e_k, T the kept bases on the
 * coefficient blocks and the identity elsewhere; state_count entries), P left in
 * the kept bases; `scratch` holds state_count values. */
PROPID_RARE void propid_coeff_per_rotor_column(const propid_derived_t *derived, const propid_kept_config_t *config,
                                               const propid_core_t *core, uint8_t state_count, uint8_t k,
                                               float *scratch, float *column);
/* Rotor `rotor`'s coefficients back to their prior variance, uncorrelated, and
 * with to_nominal also their value to nominal (per-rotor meaning: the bases are
 * flipped around the reset). */
PROPID_RARE void propid_cov_reset_rotor(const propid_derived_t *derived, const propid_kept_config_t *config,
                                        propid_core_t *core, uint8_t rotor, int to_nominal);

/* The fixed indices of the plain quad (4 rotors, no optional state): the
 * straight-line kernels are written for this layout. */
#define PROPID_QUAD_FIRST_THRUST PROPID_RATE_STATES
#define PROPID_QUAD_FIRST_DRAG (PROPID_RATE_STATES + 4u)
#define PROPID_QUAD_FIRST_BIAS (PROPID_RATE_STATES + 8u)

/* One scalar measurement y = H x + v with a sparse H (propid_scalar_update.c):
 * H has `count` non-zero entries, value[k] in column index[k]. The longest row
 * is the accelerometer's (every thrust coefficient, the torque scale, its bias
 * and its model error), else the gyro's two (a rate and its bias). */
#define PROPID_SPARSE_MAX (PROPID_WITH_ACCEL ? PROPID_MAX_ROTORS + 3u : 2u)
typedef struct {
    uint8_t count;
    uint8_t index[PROPID_SPARSE_MAX];
    float value[PROPID_SPARSE_MAX];
} propid_sparse_row_t;

typedef enum {
    PROPID_SCALAR_FUSED = 0,   /* state and covariance updated */
    PROPID_SCALAR_GATED = 1,   /* innovation outside the gate: nothing changed */
    PROPID_SCALAR_NUMERIC = 2, /* non-finite covariance even after repair: nothing changed */
} propid_scalar_result_t;

/* propid_scalar_update.c: the one measurement update every sensor calls.
 * innovation = y - h(x); noise_var = R; gate_sq = gate^2 in S units (0: no gate).
 * Writes innovation^2 / (gate^2 S) to *test_ratio (inv_gate_sq scaling of the
 * derived data). Gate, symmetric rank-one downdate P -= (P h)(P h)^T / S on the
 * stored triangle (the Joseph form's result for the optimal gain, with the
 * variance floors/ceilings and the repair below keeping it PSD in float32),
 * coefficient-independent: clamps are the caller's. */
#if !PROPID_WITH_ACCEL /* (with the accelerometer it is that sensor's usual update) */
PROPID_RARE
#endif
propid_scalar_result_t propid_scalar_update(propid_filter_t *filter, const propid_sparse_row_t *row,
                                            float innovation, float noise_var, float gate_sq,
                                            float *test_ratio);

/* propid_config.c: the configuration the filter keeps (propid.h, propid_kept_config_t). */
void propid_config_keep(const propid_config_t *config, propid_kept_config_t *kept);
/* Prepared setup (propid_setup.c): the CRC-32 its checksum field holds, and
 * 1 when format, size, checksum and the indices the step uses are this build's. */
uint32_t propid_setup_checksum(const propid_setup_t *setup);
int propid_setup_usable(const propid_setup_t *setup);

/* propid_config.c: validate a configuration and compute its derived quantities.
 * Writes *derived only when the configuration is valid. */
propid_status_t propid_config_derive(const propid_config_t *config, propid_derived_t *derived,
                                     const char **bad_field);

/* propid_covariance.c */
/* State to nominal, covariance to the diagonal prior. */
PROPID_RARE void propid_cov_set_prior(const propid_derived_t *derived, const propid_kept_config_t *config,
                                      propid_core_t *core);
/* Zero row and column `index`, put its prior variance on the diagonal. */
PROPID_RARE void propid_cov_reset_state(const propid_derived_t *derived, propid_core_t *core, uint8_t index);
/* Floors and ceilings on every variance; returns 1 if a diagonal was bad and the
 * covariance had to be repaired. */
PROPID_RARE int propid_cov_enforce_bounds(const propid_derived_t *derived, propid_core_t *core);
/* Full repair: bad diagonals back to the prior (row/column zeroed), non-finite
 * off-diagonals to 0, correlations above 1 pulled inside. Returns 1 if anything changed. */
PROPID_RARE int propid_cov_repair(const propid_derived_t *derived, propid_core_t *core);
/* Integrity of one row (finite, |Pij| <= sqrt(Pii Pjj)); repairs the whole matrix
 * and returns 1 when the row is bad. The fast quad build inlines it into the
 * step's prediction (a call, its frame and a reload of the row index less); the
 * anchor step and the other builds call propid_cov_check_row (their prediction
 * chains' frames stay as small as before). */
int propid_cov_check_row(const propid_derived_t *derived, propid_core_t *core, uint8_t row);
static inline __attribute__((always_inline)) int
propid_cov_check_row_inline(const propid_derived_t *derived, propid_core_t *core, uint8_t row)
{
    const uint8_t n = derived->state_count;
    if (row >= n) {
        return 0;
    }
    /* The diagonal and the part of the row right of it (the stored triangle):
     * over n samples every element (i, j), i <= j, is visited once. */
    const float pii = core->cov[propid_cov_index(row, row)];
    int bad = !(pii > 0.0f && pii <= FLT_MAX);
    /* |P_ij| <= sqrt(P_ii P_jj) up to the rounding of the two products (a
     * correlation of 1 within float32 is not a fault; propid_internal.h). */
    const float pii_tol = pii * (1.0f + PROPID_ROUNDING_TOL);
    /* Walk P_ij along the row and P_jj down the diagonal with pointers (no index
     * arithmetic per element: the diagonal's step shrinks by one per row). */
    const float *pij = &core->cov[propid_cov_index(row, row)];
    const float *pjj = pij;
    uint32_t diagonal_step = propid_cov_diagonal_step(row);
    for (uint32_t count = (uint32_t)(n - 1u - row); count > 0u; --count) {
        pij += 1;
        pjj += diagonal_step--;
        /* A NaN fails the comparison, so it is caught too. */
        bad |= !(*pij * *pij <= pii_tol * *pjj);
    }
    if (bad) {
        return propid_cov_repair(derived, core);
    }
    return 0;
}

/* propid_predict.c */
/* The rate step (trapezoid input, Heun on the gyroscopic term: docs/math.md §2)
 * into rate_next and the rate rows of F - I (dt * the structurally non-zero
 * Jacobian entries, the gyroscopic ones at the midpoint of omega and the Euler
 * predictor) into jacobian_dt[a][p], entry p of row a
 * being column propid_jacobian_column(derived, a, p), without touching the filter. Returns
 * PROPID_ERR_NUMERIC when either (or a state) would be non-finite, and
 * PROPID_PREDICT_CLAMPED when a finite rate_next beyond +-derived->rate_limit was
 * bounded to it (an unobserved rate integrating the gyroscopic term can run away:
 * the gyro cannot measure beyond gyro_range anyway). */
propid_status_t propid_predict_stage(const propid_filter_t *filter, float dt, float rate_next[3],
                                     float jacobian_dt[3][PROPID_JAC_ROW]);
/* P := F P F^T + Q dt + PROPID_VAR_LOADING diag, F = I + G, G the sparse rows from propid_predict_stage
 * (only the 3 rate rows differ from I). */
void propid_predict_covariance(const propid_derived_t *derived, propid_core_t *core, float dt,
                               const float jacobian_dt[3][PROPID_JAC_ROW]);
/* The accepted gyro sample's prediction over dt: the rate step (decided first:
 * a non-finite step returns PROPID_ERR_NUMERIC with nothing written), then the
 * integrity check of one covariance row (propid_check_next_row) and the
 * covariance propagation; health and counters as for an accepted sample. */
propid_status_t propid_predict_step(propid_filter_t *filter, float dt);

/* Round-robin integrity check: one covariance row per accepted gyro sample
 * (inlined: a call level less on every step). `inline_check`: the row test
 * inlined too (the fast quad build's prediction; a constant at each call). */
static inline __attribute__((always_inline)) void propid_check_next_row(propid_filter_t *filter, int inline_check)
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const int repaired = inline_check ? propid_cov_check_row_inline(derived, core, core->check_row)
                                      : propid_cov_check_row(derived, core, core->check_row);
    if (repaired) {
        core->health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    core->check_row = (uint8_t)(core->check_row + 1u >= derived->state_count ? 0u : core->check_row + 1u);
}

/* propid_gyro.c: fuse one gyro sample, three scalar updates (x, y, z; H = e_rate +
 * e_bias each). Returns the mask of axes gated out (bit a). */
uint32_t propid_update_gyro(propid_filter_t *filter, const float gyro[3]);
#if PROPID_WITH_GYRO_STUCK_CHECK
/* config.gyro_stuck_samples: counts each axis' bit-identical readings in a row and
 * returns the mask of the axes whose reading has repeated gyro_stuck_samples times
 * or more (docs/reliability.md "A stuck gyro axis"). */
uint32_t propid_gyro_stuck_mask(propid_filter_t *filter, const float gyro[3]);
/* propid_update_gyro with the axes of skip_mask not fused (counted in
 * counters.gyro_stuck); returns the mask of the axes not fused (skipped or gated). */
uint32_t propid_update_gyro_skipping(propid_filter_t *filter, const float gyro[3], uint32_t skip_mask);
#endif
#if PROPID_WITH_INPUT_NOISE
/* propid_input_compensation.c (config.input_error_compensation, docs/math.md §14):
 * each axis' correction of the coefficients, formed from the predicted P before
 * the gyro update (into core.input_*), added after it for the axes it fused. */
void propid_input_compensation_prepare(propid_filter_t *filter, float dt);
void propid_input_compensation_apply(propid_filter_t *filter, uint32_t gated_mask);
#endif
/* At most this share of the information about the coefficients' common scale may be
 * the error's for the compensation to apply (the attenuation it removes is then at most
 * 1 / (1 - 0.5) = 2). */
#define PROPID_INPUT_ERROR_MAX_SHARE 0.5f

/* propid_covariance.c: keep the coefficients in [coeff_rel_min, coeff_rel_max],
 * each one found beyond a bound by projecting the estimate onto it (P kept);
 * returns how many were beyond. */
uint32_t propid_clamp_coefficients(propid_filter_t *filter);
/* propid_bound_projection.c: the estimate moved to the mean of N(x, P) given
 * x_k = bound (x_k beyond it), P unchanged; `state` and P's column k (`column`)
 * in one basis. Returns 0 when P_kk was unusable and x_k was only set to the bound. */
int propid_project_onto_bound(uint8_t state_count, const float *column, float *state, uint8_t k, float bound);

#if PROPID_WITH_ACCEL
/* The thrust-torque scale's state r = 1/s (docs/math.md §9) kept where s is in the
 * coefficients' range: at or below zero the thrust torques would vanish or change
 * sign, and a walking scale can be carried there by an update. Returns 1 when it
 * clamped. */
static inline uint32_t propid_clamp_torque_scale(const propid_kept_config_t *config, const propid_derived_t *derived,
                                                 propid_core_t *core)
{
    const uint8_t scale = derived->layout.torque_scale;
    if (scale == PROPID_NO_STATE) {
        return 0u;
    }
    float *value = &core->state[scale];
    const float low = 1.0f / config->coeff_rel_max;
    const float high = 1.0f / config->coeff_rel_min;
    if (*value < low) {
        *value = low;
        return 1u;
    }
    if (*value > high) {
        *value = high;
        return 1u;
    }
    return 0u;
}
#endif

/* 1 when a value is outside [floor, ceiling] (or negative, or not finite): for
 * non-negative floats the bit patterns are ordered like the values, so one
 * unsigned comparison of (bits - floor_bits) with (ceiling_bits - floor_bits)
 * tests both bounds; negative values and NaN land far above the range. */
static inline uint32_t propid_outside_positive_range(float value, uint32_t floor_bits, uint32_t range_bits)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof(bits));
    return (uint32_t)(bits - floor_bits) > range_bits ? 1u : 0u;
}

/* count + 1 when bits is inside [floor_bits, floor_bits + range_bits] (the
 * inverse of propid_outside_positive_range's test on a value's bit pattern),
 * for straight-line kernels that count the values inside: on the Cortex-M4 the
 * test's carry added (SUB, CMP, ADC; the compiler makes a compare, a
 * conditional block and an add of it), the same test in C elsewhere. */
static inline __attribute__((always_inline)) uint32_t propid_count_inside(uint32_t count, uint32_t bits,
                                                                        uint32_t floor_bits, uint32_t range_bits)
{
#if PROPID_ARM_BLOCK_MOVES
    uint32_t above_floor;
    __asm__("sub %[above], %[bits], %[floor]\n\tcmp %[range], %[above]\n\tadc %[count], %[count], #0"
            : [count] "+r"(count), [above] "=&r"(above_floor)
            : [bits] "r"(bits), [floor] "r"(floor_bits), [range] "r"(range_bits)
            : "cc");
    return count;
#else
    return count + ((uint32_t)(bits - floor_bits) <= range_bits ? 1u : 0u);
#endif
}
static inline __attribute__((always_inline)) uint32_t propid_float_bits(float value)
{
    uint32_t bits;
    memcpy(&bits, &value, sizeof(bits));
    return bits;
}

/* Kinds of state (derived->state_kind; propid_config.h PROPID_STATE_KINDS). */
#define PROPID_KIND_RATE 0u
#define PROPID_KIND_THRUST 1u
#define PROPID_KIND_DRAG 2u
#define PROPID_KIND_BIAS 3u
#define PROPID_KIND_DISTURBANCE 4u
#define PROPID_KIND_ACCEL_BIAS (4u + PROPID_WITH_DISTURBANCE)
#define PROPID_KIND_TORQUE_SCALE (5u + PROPID_WITH_DISTURBANCE)
#define PROPID_KIND_ACCEL_ERROR (6u + PROPID_WITH_DISTURBANCE)

#if !PROPID_GENERAL_VEHICLES
/* The fixed quad layout's rate, thrust, drag and bias blocks (propid_covariance.c):
 * one table in flash for every file that reads it (a static copy per file cost
 * 14 B each). */
extern const uint8_t propid_quad_state_kind[PROPID_MAX_STATES];
#endif

/* Kind of state i: derived->state_kind, or without the general path (the quad
 * build) propid_quad_state_kind (one load, like the RAM copy; compares cost
 * ~100 B of code). */
static inline uint8_t propid_state_kind(const propid_derived_t *derived, uint8_t i)
{
#if PROPID_GENERAL_VEHICLES
    return derived->state_kind[i];
#else
    (void)derived;
    return propid_quad_state_kind[i];
#endif
}

/* Per-state process noise rate, prior variance and variance bounds (stored once
 * per kind of state). */
static inline float propid_process_psd(const propid_derived_t *derived, uint8_t i)
{
    return derived->kind_process_psd[propid_state_kind(derived, i)];
}
static inline float propid_prior_var(const propid_derived_t *derived, uint8_t i)
{
    return derived->kind_prior_var[propid_state_kind(derived, i)];
}
static inline uint32_t propid_kind_floor_bits(const propid_derived_t *derived, uint8_t kind)
{
    return derived->kind_floor_bits[kind];
}
static inline uint32_t propid_floor_bits(const propid_derived_t *derived, uint8_t i)
{
    return propid_kind_floor_bits(derived, propid_state_kind(derived, i));
}
static inline uint32_t propid_range_bits(const propid_derived_t *derived, uint8_t i)
{
    return derived->kind_range_bits[propid_state_kind(derived, i)];
}

/* The per-state variance floor and ceiling, kept only as bit patterns (positive
 * floats: the patterns are ordered like the values). */
static inline float propid_var_floor(const propid_derived_t *derived, uint8_t i)
{
    const uint32_t bits = propid_floor_bits(derived, i);
    float value;
    memcpy(&value, &bits, sizeof(value));
    return value;
}
static inline float propid_var_ceiling(const propid_derived_t *derived, uint8_t i)
{
    const uint32_t bits = propid_floor_bits(derived, i) + propid_range_bits(derived, i);
    float value;
    memcpy(&value, &bits, sizeof(value));
    return value;
}

#endif /* PROPID_INTERNAL_H */
