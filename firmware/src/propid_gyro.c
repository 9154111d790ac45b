/* The gyro as a measurement (docs/math.md §3): when and how it is fused.
 * y_a = omega_a + b_a + v_a, three scalar updates in the order x, y, z, each
 * through propid_scalar_update() with H_a = e_rate(a) + e_bias(a), gated, and
 * re-anchored after too many gated samples in a row.
 *
 * The usual quad sample (every axis passes, 14 states) takes a straight-line
 * equivalent of the three updates in one pass over P: the later axes' vectors
 * are formed from the P in memory with the earlier axes' pending rank-one terms
 * folded in,
 *   h_a = P H_a^T - sum_{p<a} g_p (h_p . H_a),   g_p = h_p / S_p,
 * (each h_a and S_a equals the sequential one in exact arithmetic), then one
 * sweep over the upper triangle writes
 *   P_ij -= sum_a g_a,i h_a,j,   x_i += sum_a g_a,i nu_a,
 * five rows at a time (fuse_quad_usual, apply_three_quad). Any other sample or
 * vehicle takes the generic scalar update per axis. */
#include <math.h>
#include <string.h>

#include "propid_internal.h"


/* The quad's pending vector h_0 = P H_0^T of axis 0 (the quad step's largest
 * stack object: 14 floats); axes 1 and 2's are core->update_vector[0] and [1],
 * in the filter object (off the stack: the one pass's chain is the step's
 * deepest). Their innovations are the ones recorded in core->innovation. */
typedef struct {
    float h0[PROPID_MAX_STATES];        /* P H^T of pending axis 0 (the gain is h / S) */
    float inv_var[3];                   /* 1 / S: the gain is g = h / S */
} pending_t;

#if PROPID_GENERAL_VEHICLES
/* The general path's three pending vectors (any state count), on the stack. */
typedef struct {
    float h[3][PROPID_MAX_STATES];
    float inv_var[3];
} pending_any_t;
#endif

#if PROPID_SIZE_LEAN
/* The size-lean build's apply_three_quad (below): the same arithmetic per element
 * and per state in the same order, so the same results, row by row over loops
 * (small code, more instructions: the loop control and each element's three
 * vector values loaded per element). Not cloned: GCC's copy specialised for its
 * one caller (fuse_quad_usual's tail call) took 42 instructions more a step. */
static __attribute__((noinline)) PROPID_NO_CLONE uint32_t
apply_three_quad(float *restrict cov, propid_core_t *restrict core, pending_t *restrict pending,
                 const propid_derived_t *restrict derived)
{
    float *state = core->state;
    const float *h0 = pending->h0;
    const float *h1 = core->update_vector[0];
    const float *h2 = core->update_vector[1];
    uint32_t outside = 0u;
    float *row = cov; /* row[j] = P_ij for j >= i: packed row i, shifted back by i */
    for (uint8_t i = 0; i < PROPID_QUAD_STATES; ++i) {
        const float g0 = h0[i] * pending->inv_var[0];
        const float g1 = h1[i] * pending->inv_var[1];
        const float g2 = h2[i] * pending->inv_var[2];
        state[i] = state[i] + g0 * core->innovation[0] + g1 * core->innovation[1] + g2 * core->innovation[2];
        for (uint8_t j = i; j < PROPID_QUAD_STATES; ++j) {
            row[j] = row[j] - g0 * h0[j] - g1 * h1[j] - g2 * h2[j];
        }
        outside |= propid_outside_positive_range(row[i], propid_floor_bits(derived, i), propid_range_bits(derived, i));
        row += PROPID_MAX_STATES - 1u - i;
    }
    return outside;
}
#elif PROPID_HOST_ROW_SWEEP
/* The quad downdate on a 64-bit desktop host (PROPID_HOST_ROW_SWEEP) with the
 * compiler's vector type of 4 floats (GNU C; SSE on x86-64, NEON on AArch64):
 * the gains and states 4 lanes at a time, then each packed row of P in chunks
 * of 4 consecutive elements. A length that is not a multiple of 4 ends with a
 * chunk aligned to the end that overlaps the one before: every chunk is
 * computed from the values as loaded before any is stored, so an overlapped
 * element gets the same value twice. Each lane takes the row groups' operations
 * in their order (g = h (1 / S); x + g0 nu0 + g1 nu1 + g2 nu2; p - g0 h0 - g1 h1
 * - g2 h2, left to right; a scalar times a vector multiplies every lane): the
 * same bits, tested against the row groups in portable C
 * (propid_quad_row_groups_shared, test_quad_build_bits_match_row_groups). */
typedef float propid_f4_t __attribute__((vector_size(16)));
#define PROPID_F4_CHUNKS ((PROPID_QUAD_STATES + 3u) / 4u)
static inline __attribute__((always_inline)) propid_f4_t f4_load(const float *p)
{
    propid_f4_t v;
    memcpy(&v, p, sizeof(v));
    return v;
}
static inline __attribute__((always_inline)) void f4_store(float *p, propid_f4_t v)
{
    memcpy(p, &v, sizeof(v));
}
/* Where chunk c of elements first .. 13 starts (the last one ends at 13). */
static inline __attribute__((always_inline)) uint8_t f4_chunk_at(uint8_t first, uint8_t c)
{
    const uint8_t at = (uint8_t)(first + 4u * c);
    return at + 4u <= PROPID_QUAD_STATES ? at : (uint8_t)(PROPID_QUAD_STATES - 4u);
}

/* Row i of the packed triangle, columns i .. 13 (i constant where inlined). */
static inline __attribute__((always_inline)) void
downdate_row(float *restrict row, const uint8_t i, const float *restrict h0, const float *restrict h1,
             const float *restrict h2, const float g0, const float g1, const float g2)
{
    if (PROPID_QUAD_STATES - i >= 4u) {
        const uint8_t count = (uint8_t)((PROPID_QUAD_STATES - i + 3u) / 4u);
        propid_f4_t chunk[PROPID_F4_CHUNKS];
PROPID_UNROLL(4)
        for (uint8_t c = 0u; c < count; ++c) {
            const uint8_t j = f4_chunk_at(i, c);
            chunk[c] = f4_load(row + j) - g0 * f4_load(h0 + j) - g1 * f4_load(h1 + j) - g2 * f4_load(h2 + j);
        }
PROPID_UNROLL(4)
        for (uint8_t c = 0u; c < count; ++c) {
            f4_store(row + f4_chunk_at(i, c), chunk[c]);
        }
    } else {
PROPID_UNROLL(3)
        for (uint8_t j = i; j < PROPID_QUAD_STATES; ++j) {
            row[j] = row[j] - g0 * h0[j] - g1 * h1[j] - g2 * h2[j];
        }
    }
}

static __attribute__((noinline)) uint32_t
apply_three_quad(float *restrict cov, propid_core_t *restrict core, pending_t *restrict pending,
                 const propid_derived_t *restrict derived)
{
    float *state = core->state;
    const float *h0 = pending->h0;
    const float *h1 = core->update_vector[0];
    const float *h2 = core->update_vector[1];
    const float inv0 = pending->inv_var[0], inv1 = pending->inv_var[1], inv2 = pending->inv_var[2];
    const float nu0 = core->innovation[0], nu1 = core->innovation[1], nu2 = core->innovation[2];
    float gain[3][PROPID_QUAD_STATES];
    propid_f4_t new_state[PROPID_F4_CHUNKS];
PROPID_UNROLL(4)
    for (uint8_t c = 0u; c < PROPID_F4_CHUNKS; ++c) {
        const uint8_t j = f4_chunk_at(0u, c);
        const propid_f4_t g0 = f4_load(h0 + j) * inv0;
        const propid_f4_t g1 = f4_load(h1 + j) * inv1;
        const propid_f4_t g2 = f4_load(h2 + j) * inv2;
        f4_store(&gain[0][j], g0);
        f4_store(&gain[1][j], g1);
        f4_store(&gain[2][j], g2);
        new_state[c] = f4_load(state + j) + g0 * nu0 + g1 * nu1 + g2 * nu2;
    }
PROPID_UNROLL(4)
    for (uint8_t c = 0u; c < PROPID_F4_CHUNKS; ++c) {
        f4_store(state + f4_chunk_at(0u, c), new_state[c]);
    }
PROPID_UNROLL(14)
    for (uint8_t i = 0; i < PROPID_QUAD_STATES; ++i) {
        downdate_row(propid_cov_row(cov, i), i, h0, h1, h2, gain[0][i], gain[1][i], gain[2][i]);
    }
    uint32_t outside = 0u;
PROPID_UNROLL(14)
    for (uint8_t i = 0; i < PROPID_QUAD_STATES; ++i) {
        const uint8_t kind = i < PROPID_QUAD_FIRST_THRUST ? PROPID_KIND_RATE
                             : (i < PROPID_QUAD_FIRST_DRAG ? PROPID_KIND_THRUST
                                : (i < PROPID_QUAD_FIRST_BIAS ? PROPID_KIND_DRAG : PROPID_KIND_BIAS));
        outside |= propid_outside_positive_range(cov[propid_cov_index(i, i)], propid_kind_floor_bits(derived, kind),
                                                 derived->kind_range_bits[kind]);
    }
    return outside;
}
#else
#if PROPID_ARM_BLOCK_MOVES
/* The block-move kernels' registers: the vectors' values of four consecutive
 * columns c = 0..3 in s16+c (h_0), s20+c (h_1), s24+c (h_2), a row's elements
 * of those columns in s28+c; the rows' gains stay where the compiler put them
 * (s0-s15: the kernels clobber s16-s31). Each element takes its three terms in
 * the C loop's order, p - g0 h0 - g1 h1 - g2 h2, each a fused multiply-subtract
 * (vfms: what -ffp-contract=fast makes of the C), so the results are the C
 * loop's to the bit. */
#define PROPID_FMS(element, value, gain) "vfms.f32 " element ", %[" gain "], " value "\n\t"
#define PROPID_TERMS_C0(g, k) PROPID_FMS("s28", k##0, g)
#define PROPID_TERMS_C1(g, k) PROPID_FMS("s29", k##1, g)
#define PROPID_TERMS_C2(g, k) PROPID_FMS("s30", k##2, g)
#define PROPID_TERMS_C3(g, k) PROPID_FMS("s31", k##3, g)
#define PROPID_H0_0 "s16"
#define PROPID_H0_1 "s17"
#define PROPID_H0_2 "s18"
#define PROPID_H0_3 "s19"
#define PROPID_H1_0 "s20"
#define PROPID_H1_1 "s21"
#define PROPID_H1_2 "s22"
#define PROPID_H1_3 "s23"
#define PROPID_H2_0 "s24"
#define PROPID_H2_1 "s25"
#define PROPID_H2_2 "s26"
#define PROPID_H2_3 "s27"
/* A row's elements of columns c0..3 (4, 3, 2 or 1 of them) at byte offset `at`
 * from cov: one VLDM, 3 x (4 - c0) multiply-subtracts, one VSTM. */
#define PROPID_ROW4(at, g)                                                                           \
    "add ip, %[cov], %[" at "]\n\tvldmia ip, {s28-s31}\n\t"                                          \
    PROPID_TERMS_C0(g "0", PROPID_H0_) PROPID_TERMS_C1(g "0", PROPID_H0_)                            \
    PROPID_TERMS_C2(g "0", PROPID_H0_) PROPID_TERMS_C3(g "0", PROPID_H0_)                            \
    PROPID_TERMS_C0(g "1", PROPID_H1_) PROPID_TERMS_C1(g "1", PROPID_H1_)                            \
    PROPID_TERMS_C2(g "1", PROPID_H1_) PROPID_TERMS_C3(g "1", PROPID_H1_)                            \
    PROPID_TERMS_C0(g "2", PROPID_H2_) PROPID_TERMS_C1(g "2", PROPID_H2_)                            \
    PROPID_TERMS_C2(g "2", PROPID_H2_) PROPID_TERMS_C3(g "2", PROPID_H2_)                            \
    "vstmia ip, {s28-s31}\n\t"
#define PROPID_ROW3(at, g)                                                                           \
    "add ip, %[cov], %[" at "]\n\tvldmia ip, {s29-s31}\n\t"                                          \
    PROPID_TERMS_C1(g "0", PROPID_H0_) PROPID_TERMS_C2(g "0", PROPID_H0_)                            \
    PROPID_TERMS_C3(g "0", PROPID_H0_)                                                               \
    PROPID_TERMS_C1(g "1", PROPID_H1_) PROPID_TERMS_C2(g "1", PROPID_H1_)                            \
    PROPID_TERMS_C3(g "1", PROPID_H1_)                                                               \
    PROPID_TERMS_C1(g "2", PROPID_H2_) PROPID_TERMS_C2(g "2", PROPID_H2_)                            \
    PROPID_TERMS_C3(g "2", PROPID_H2_)                                                               \
    "vstmia ip, {s29-s31}\n\t"
#define PROPID_ROW2(at, g)                                                                           \
    "add ip, %[cov], %[" at "]\n\tvldmia ip, {s30-s31}\n\t"                                          \
    PROPID_TERMS_C2(g "0", PROPID_H0_) PROPID_TERMS_C3(g "0", PROPID_H0_)                            \
    PROPID_TERMS_C2(g "1", PROPID_H1_) PROPID_TERMS_C3(g "1", PROPID_H1_)                            \
    PROPID_TERMS_C2(g "2", PROPID_H2_) PROPID_TERMS_C3(g "2", PROPID_H2_)                            \
    "vstmia ip, {s30-s31}\n\t"
#define PROPID_ROW1(at, g)                                                                           \
    "add ip, %[cov], %[" at "]\n\tvldr s31, [ip]\n\t"                                                \
    PROPID_TERMS_C3(g "0", PROPID_H0_) PROPID_TERMS_C3(g "1", PROPID_H1_)                            \
    PROPID_TERMS_C3(g "2", PROPID_H2_)                                                               \
    "vstr s31, [ip]\n\t"
/* The vectors' values of columns c0..3 from h_k + j + c0 (j: column 0's). */
#define PROPID_LOAD_H4 "vldmia %[h0], {s16-s19}\n\tvldmia %[h1], {s20-s23}\n\tvldmia %[h2], {s24-s27}\n\t"
#define PROPID_LOAD_H3 "vldmia %[h0], {s17-s19}\n\tvldmia %[h1], {s21-s23}\n\tvldmia %[h2], {s25-s27}\n\t"
#define PROPID_GAINS(r, g)                                                                           \
    [g##0] "t"(gain[r][0]), [g##1] "t"(gain[r][1]), [g##2] "t"(gain[r][2])
#define PROPID_BLOCK_CLOBBERS                                                                        \
    "s16", "s17", "s18", "s19", "s20", "s21", "s22", "s23", "s24", "s25", "s26", "s27", "s28", "s29",  \
        "s30", "s31", "ip", "memory"
#define PROPID_AT(i, j) "n"(4u * propid_cov_index((i), (j)))

/* Rows first..first+4 (or +3): gains g_k,i = h_k,i (1 / S_k) into registers
 * the compiler chooses (outputs; s0-s15, the block kernels clobber the rest),
 * and the states x_i + g_0,i nu_0 + g_1,i nu_1 + g_2,i nu_2 (three fused
 * multiply-adds in that order, as the C loop contracts), the vectors' values,
 * 1 / S, nu and the states moved by VLDM / VSTM; and the group's first
 * diagonal element (PROPID_FIRST_ELEMENT_*). */
#define PROPID_GAIN(r, k, value, inv) "vmul.f32 %[" r #k "], " value ", " inv "\n\t"
#define PROPID_STATE_ROW(r, x)                                                                       \
    "vfma.f32 " x ", %[" r "0], s29\n\tvfma.f32 " x ", %[" r "1], s30\n\tvfma.f32 " x ", %[" r "2], s31\n\t"
/* The group's first diagonal element P_ff (f = first) in the same kernel, from
 * the vectors' values of column f it has loaded: P_ff - g_0,f h_0,f - g_1,f h_1,f
 * - g_2,f h_2,f, the C loop's three fused multiply-subtracts in its order (the
 * third after h_2 is loaded). */
#define PROPID_FIRST_ELEMENT_01(p, h0f, h1f)                                                         \
    "vldr " p ", [%[cov], %[first]]\n\tvfms.f32 " p ", %[ga0], " h0f "\n\tvfms.f32 " p ", %[ga1], " h1f "\n\t"
#define PROPID_FIRST_ELEMENT_2(p, h2f) "vfms.f32 " p ", %[ga2], " h2f "\n\tvstr " p ", [%[cov], %[first]]\n\t"
#define PROPID_GAIN_OUT(r, g) [g##0] "=&t"(gain[r][0]), [g##1] "=&t"(gain[r][1]), [g##2] "=&t"(gain[r][2])
static inline __attribute__((always_inline)) void
gains_and_states_5(float gain[5][3], float *state, const float *h0, const float *h1, const float *h2,
                   const float *inv_var, const float *innovation, float *cov, const uint32_t first)
{
    __asm__ volatile("vldmia %[inv], {s29-s31}\n\t"
                     "vldmia %[h0], {s16-s20}\n\tvldmia %[h1], {s21-s25}\n\t"
                     PROPID_GAIN("ga", 0, "s16", "s29") PROPID_GAIN("ga", 1, "s21", "s30")
                     PROPID_FIRST_ELEMENT_01("s26", "s16", "s21")
                     PROPID_GAIN("gb", 0, "s17", "s29") PROPID_GAIN("gb", 1, "s22", "s30")
                     PROPID_GAIN("gc", 0, "s18", "s29") PROPID_GAIN("gc", 1, "s23", "s30")
                     PROPID_GAIN("gd", 0, "s19", "s29") PROPID_GAIN("gd", 1, "s24", "s30")
                     PROPID_GAIN("ge", 0, "s20", "s29") PROPID_GAIN("ge", 1, "s25", "s30")
                     "vldmia %[h2], {s16-s20}\n\t"
                     PROPID_GAIN("ga", 2, "s16", "s31") PROPID_FIRST_ELEMENT_2("s26", "s16")
                     PROPID_GAIN("gb", 2, "s17", "s31")
                     PROPID_GAIN("gc", 2, "s18", "s31") PROPID_GAIN("gd", 2, "s19", "s31")
                     PROPID_GAIN("ge", 2, "s20", "s31")
                     "vldmia %[nu], {s29-s31}\n\tvldmia %[x], {s16-s20}\n\t"
                     PROPID_STATE_ROW("ga", "s16") PROPID_STATE_ROW("gb", "s17") PROPID_STATE_ROW("gc", "s18")
                     PROPID_STATE_ROW("gd", "s19") PROPID_STATE_ROW("ge", "s20")
                     "vstmia %[x], {s16-s20}\n\t"
                     : PROPID_GAIN_OUT(0, ga), PROPID_GAIN_OUT(1, gb), PROPID_GAIN_OUT(2, gc), PROPID_GAIN_OUT(3, gd),
                       PROPID_GAIN_OUT(4, ge)
                     : [h0] "r"(h0), [h1] "r"(h1), [h2] "r"(h2), [inv] "r"(inv_var), [nu] "r"(innovation),
                       [x] "r"(state), [cov] "r"(cov), [first] PROPID_AT(first, first)
                     : PROPID_BLOCK_CLOBBERS);
}
static inline __attribute__((always_inline)) void
gains_and_states_4(float gain[5][3], float *state, const float *h0, const float *h1, const float *h2,
                   const float *inv_var, const float *innovation, float *cov, const uint32_t first)
{
    __asm__ volatile("vldmia %[inv], {s29-s31}\n\t"
                     "vldmia %[h0], {s16-s19}\n\tvldmia %[h1], {s20-s23}\n\tvldmia %[h2], {s24-s27}\n\t"
                     PROPID_GAIN("ga", 0, "s16", "s29") PROPID_GAIN("ga", 1, "s20", "s30") PROPID_GAIN("ga", 2, "s24", "s31")
                     PROPID_GAIN("gb", 0, "s17", "s29") PROPID_GAIN("gb", 1, "s21", "s30") PROPID_GAIN("gb", 2, "s25", "s31")
                     PROPID_GAIN("gc", 0, "s18", "s29") PROPID_GAIN("gc", 1, "s22", "s30") PROPID_GAIN("gc", 2, "s26", "s31")
                     PROPID_GAIN("gd", 0, "s19", "s29") PROPID_GAIN("gd", 1, "s23", "s30") PROPID_GAIN("gd", 2, "s27", "s31")
                     PROPID_FIRST_ELEMENT_01("s28", "s16", "s20") PROPID_FIRST_ELEMENT_2("s28", "s24")
                     "vldmia %[nu], {s29-s31}\n\tvldmia %[x], {s16-s19}\n\t"
                     PROPID_STATE_ROW("ga", "s16") PROPID_STATE_ROW("gb", "s17") PROPID_STATE_ROW("gc", "s18")
                     PROPID_STATE_ROW("gd", "s19")
                     "vstmia %[x], {s16-s19}\n\t"
                     : PROPID_GAIN_OUT(0, ga), PROPID_GAIN_OUT(1, gb), PROPID_GAIN_OUT(2, gc), PROPID_GAIN_OUT(3, gd)
                     : [h0] "r"(h0), [h1] "r"(h1), [h2] "r"(h2), [inv] "r"(inv_var), [nu] "r"(innovation),
                       [x] "r"(state), [cov] "r"(cov), [first] PROPID_AT(first, first)
                     : PROPID_BLOCK_CLOBBERS);
}

/* P_ij -= sum_k g_k,i h_k,j for five rows i = first.. (gains in registers) and
 * four consecutive columns j.. right of their diagonal block: the columns' 12
 * vector values in three VLDMs, each row's four elements in one VLDM and one
 * VSTM (the C loop: 12 loads of the values, 20 loads and 20 stores). */
static inline __attribute__((always_inline)) void
downdate_tile_5x4(float *restrict cov, const uint32_t first, const uint32_t j, const float *h0, const float *h1,
                  const float *h2, const float gain[5][3])
{
    __asm__ volatile(PROPID_LOAD_H4
                     PROPID_ROW4("r0", "ga") PROPID_ROW4("r1", "gb") PROPID_ROW4("r2", "gc")
                     PROPID_ROW4("r3", "gd") PROPID_ROW4("r4", "ge")
                     :
                     : [h0] "r"(h0 + j), [h1] "r"(h1 + j), [h2] "r"(h2 + j), [cov] "r"(cov),
                       [r0] PROPID_AT(first, j), [r1] PROPID_AT(first + 1u, j), [r2] PROPID_AT(first + 2u, j),
                       [r3] PROPID_AT(first + 3u, j), [r4] PROPID_AT(first + 4u, j),
                       PROPID_GAINS(0, ga), PROPID_GAINS(1, gb), PROPID_GAINS(2, gc), PROPID_GAINS(3, gd),
                       PROPID_GAINS(4, ge)
                     : PROPID_BLOCK_CLOBBERS);
}

/* The group's diagonal block (upper triangle) but its first element (first,
 * first): columns first+1..first+4 of five rows, each row from its diagonal
 * or column first+1 on (4, 4, 3, 2, 1 elements: a VLDM and a VSTM each). */
static inline __attribute__((always_inline)) void
downdate_triangle_5(float *restrict cov, const uint32_t first, const float *h0, const float *h1, const float *h2,
                    const float gain[5][3])
{
    __asm__ volatile(PROPID_LOAD_H4
                     PROPID_ROW4("r0", "ga") PROPID_ROW4("r1", "gb") PROPID_ROW3("r2", "gc")
                     PROPID_ROW2("r3", "gd") PROPID_ROW1("r4", "ge")
                     :
                     : [h0] "r"(h0 + first + 1u), [h1] "r"(h1 + first + 1u), [h2] "r"(h2 + first + 1u),
                       [cov] "r"(cov), [r0] PROPID_AT(first, first + 1u), [r1] PROPID_AT(first + 1u, first + 1u),
                       [r2] PROPID_AT(first + 2u, first + 2u), [r3] PROPID_AT(first + 3u, first + 3u),
                       [r4] PROPID_AT(first + 4u, first + 4u),
                       PROPID_GAINS(0, ga), PROPID_GAINS(1, gb), PROPID_GAINS(2, gc), PROPID_GAINS(3, gd),
                       PROPID_GAINS(4, ge)
                     : PROPID_BLOCK_CLOBBERS);
}

/* The same for a group of four rows: columns first+1..first+3 (3, 3, 2, 1). */
static inline __attribute__((always_inline)) void
downdate_triangle_4(float *restrict cov, const uint32_t first, const float *h0, const float *h1, const float *h2,
                    const float gain[5][3])
{
    __asm__ volatile(PROPID_LOAD_H3
                     PROPID_ROW3("r0", "ga") PROPID_ROW3("r1", "gb") PROPID_ROW2("r2", "gc")
                     PROPID_ROW1("r3", "gd")
                     :
                     : [h0] "r"(h0 + first + 1u), [h1] "r"(h1 + first + 1u), [h2] "r"(h2 + first + 1u),
                       [cov] "r"(cov), [r0] PROPID_AT(first, first + 1u), [r1] PROPID_AT(first + 1u, first + 1u),
                       [r2] PROPID_AT(first + 2u, first + 2u), [r3] PROPID_AT(first + 3u, first + 3u),
                       PROPID_GAINS(0, ga), PROPID_GAINS(1, gb), PROPID_GAINS(2, gc), PROPID_GAINS(3, gd)
                     : PROPID_BLOCK_CLOBBERS);
}
#endif

/* Rows first .. first + rows - 1 of the quad's three-term pass: their gains
 * g_k,i = h_k,i / S_k and state updates, the upper triangle of their diagonal
 * block, then every column to the right, where each h_j triple is loaded once
 * for all the group's rows (5 rows: 28 instructions per 5 elements, with the 15
 * gains in registers). Returns non-zero when a new variance of the group is
 * outside its [floor, ceiling]. */
static inline __attribute__((always_inline)) uint32_t
apply_row_group(float *restrict cov, propid_core_t *restrict core,
                const pending_t *restrict pending, const propid_derived_t *restrict derived,
                const uint8_t first, const uint8_t rows)
{
    float *state = core->state;
    const float *h0 = pending->h0;
    const float *h1 = core->update_vector[0];
    const float *h2 = core->update_vector[1];
    const float inv0 = pending->inv_var[0];
    const float inv1 = pending->inv_var[1];
    const float inv2 = pending->inv_var[2];
    const float nu0 = core->innovation[0];
    const float nu1 = core->innovation[1];
    const float nu2 = core->innovation[2];
    float gain[5][3];
    uint32_t outside = 0u;
#if PROPID_ARM_BLOCK_MOVES
    (void)inv0, (void)inv1, (void)inv2, (void)nu0, (void)nu1, (void)nu2;
    if (rows == 5u) {
        gains_and_states_5(gain, &state[first], &h0[first], &h1[first], &h2[first], pending->inv_var, core->innovation,
                           cov, first);
    } else {
        gains_and_states_4(gain, &state[first], &h0[first], &h1[first], &h2[first], pending->inv_var, core->innovation,
                           cov, first);
    }
#else
PROPID_UNROLL(5)
    for (uint8_t r = 0; r < rows; ++r) {
        const uint8_t i = (uint8_t)(first + r);
        gain[r][0] = h0[i] * inv0;
        gain[r][1] = h1[i] * inv1;
        gain[r][2] = h2[i] * inv2;
        /* Summed from the state on: three multiply-adds. */
        state[i] = state[i] + gain[r][0] * nu0 + gain[r][1] * nu1 + gain[r][2] * nu2;
    }
#endif
#if PROPID_ARM_BLOCK_MOVES
    /* Block moves (PROPID_ARM_BLOCK_MOVES): the columns right of the group four
     * at a time while only the gains are live, the diagonal block but its first
     * element (done with the gains), the columns left over one at a time; then
     * the variances' tests on their bit patterns read from memory (as floats
     * the compiler would load them early and spill them). */
    uint8_t j = (uint8_t)(first + rows);
    if (rows == 5u) {
PROPID_UNROLL(2)
        for (; j + 4u <= PROPID_QUAD_STATES; j = (uint8_t)(j + 4u)) {
            downdate_tile_5x4(cov, first, j, h0, h1, h2, (const float (*)[3])gain);
        }
        downdate_triangle_5(cov, first, h0, h1, h2, (const float (*)[3])gain);
    } else {
        downdate_triangle_4(cov, first, h0, h1, h2, (const float (*)[3])gain);
    }
PROPID_UNROLL(10)
    for (; j < PROPID_QUAD_STATES; ++j) {
        const float hj0 = h0[j];
        const float hj1 = h1[j];
        const float hj2 = h2[j];
PROPID_UNROLL(5)
        for (uint8_t r = 0; r < rows; ++r) {
            float *p = &cov[propid_cov_index((uint32_t)first + r, j)];
            *p = *p - gain[r][0] * hj0 - gain[r][1] * hj1 - gain[r][2] * hj2;
        }
    }
    (void)derived; /* the variances are tested after the last group (apply_three_quad) */
#else
PROPID_UNROLL(5)
    for (uint8_t r = 0; r < rows; ++r) {
        const uint8_t i = (uint8_t)(first + r);
PROPID_UNROLL(5)
        for (uint8_t c = r; c < rows; ++c) {
            const uint8_t j = (uint8_t)(first + c);
            float *p = &cov[propid_cov_index(i, j)];
            *p = *p - gain[r][0] * h0[j] - gain[r][1] * h1[j] - gain[r][2] * h2[j];
        }
        /* Floors and ceilings are per kind of state (rate, thrust, drag, bias:
         * derived->state_kind); the quad's kinds are known here, so the
         * constants stay in registers across the groups. */
        const uint8_t kind = i < PROPID_QUAD_FIRST_THRUST ? PROPID_KIND_RATE
                             : (i < PROPID_QUAD_FIRST_DRAG ? PROPID_KIND_THRUST
                                : (i < PROPID_QUAD_FIRST_BIAS ? PROPID_KIND_DRAG : PROPID_KIND_BIAS));
        outside |= propid_outside_positive_range(cov[propid_cov_index(i, i)], propid_kind_floor_bits(derived, kind),
                                                 derived->kind_range_bits[kind]);
    }
PROPID_UNROLL(10)
    for (uint8_t j = (uint8_t)(first + rows); j < PROPID_QUAD_STATES; ++j) {
        const float hj0 = h0[j];
        const float hj1 = h1[j];
        const float hj2 = h2[j];
PROPID_UNROLL(5)
        for (uint8_t r = 0; r < rows; ++r) {
            float *p = &cov[propid_cov_index((uint32_t)first + r, j)];
            *p = *p - gain[r][0] * hj0 - gain[r][1] * hj1 - gain[r][2] * hj2;
        }
    }
#endif
    return outside;
}

/* P_ij -= sum_k g_k,i h_k,j on the stored upper triangle, x += sum_k g_k nu_k,
 * for three pending terms of a quad: n constant, fully unrolled, rows in groups
 * of 5 + 5 + 4. Also tests every new variance against its floor and ceiling; returns 0
 * when all are inside (else non-zero: how many are outside, or a flag). Not inlined: with the covariance as its own pointer every
 * element is within the 1 KiB reach of a VFP load (from the filter's base the
 * compiler folds the offsets and needs an address computation per element).
 * Without the scheduling pass before register allocation: it hoists the later
 * groups' loads, which then outlive the registers (measured: 17 instructions
 * more per step with it, every element still one load, three multiply-adds and
 * one store). */
static __attribute__((noinline)) PROPID_NO_EARLY_SCHEDULE uint32_t
apply_three_quad(float *restrict cov, propid_core_t *restrict core, pending_t *restrict pending,
                 const propid_derived_t *restrict derived)
{
    /* Each group loads the vectors' values it needs: without the barriers the
     * compiler keeps the ones an earlier group loaded alive for the later groups
     * and spills them (groups of 4 + 4 + 4 + 2 rows: 77 spill stores and reloads,
     * 80 B of stack, 12 instructions more per step than with the barriers; with
     * them and no spill, 5 + 5 + 4 rows saves 9 more; 7 + 7 spills again, 887). */
    uint32_t outside = apply_row_group(cov, core, pending, derived, 0u, 5u);
    PROPID_RELOAD_BARRIER(pending->h0);
    PROPID_RELOAD_BARRIER(core->update_vector);
    outside |= apply_row_group(cov, core, pending, derived, 5u, 5u);
    PROPID_RELOAD_BARRIER(pending->h0);
    PROPID_RELOAD_BARRIER(core->update_vector);
    outside |= apply_row_group(cov, core, pending, derived, 10u, 4u);
#if PROPID_ARM_BLOCK_MOVES
    /* The new variances' tests, on their bit patterns read from memory (tested
     * inside the groups, the compiler loads them early and spills them): the
     * count of those inside (each test's carry added, no flag per test). */
    uint32_t inside = 0u;
PROPID_UNROLL(14)
    for (uint8_t i = 0; i < PROPID_QUAD_STATES; ++i) {
        const uint8_t kind = i < PROPID_QUAD_FIRST_THRUST ? PROPID_KIND_RATE
                             : (i < PROPID_QUAD_FIRST_DRAG ? PROPID_KIND_THRUST
                                : (i < PROPID_QUAD_FIRST_BIAS ? PROPID_KIND_DRAG : PROPID_KIND_BIAS));
        uint32_t bits;
        memcpy(&bits, &cov[propid_cov_index(i, i)], sizeof(bits));
        inside = propid_count_inside(inside, bits, propid_kind_floor_bits(derived, kind), derived->kind_range_bits[kind]);
    }
    (void)outside;
    return PROPID_QUAD_STATES - inside;
#else
    return outside;
#endif
}
#endif

/* The axis' rate forgets everything and restarts from this sample: rate :=
 * measurement - bias estimate, rate variance := its prior, correlations zeroed
 * (zeroing a row/column and setting a positive diagonal keeps P PSD). */
static void reanchor_rate(propid_filter_t *filter, uint8_t axis, uint8_t bias, float gyro)
{
    propid_core_t *core = &filter->core;
    core->state[axis] = gyro - core->state[bias];
    propid_cov_reset_state(&filter->derived, core, axis);
}

/* One axis through the generic scalar update: gate, and after
 * gate_max_consecutive gated samples in a row the re-anchor. Returns 1 when the
 * axis was gated out. Not inlined into fuse_generic: the two calls' locals stay
 * in one frame per axis (the per-axis path's stack: 32 B less). */
static __attribute__((noinline)) PROPID_RARE uint32_t fuse_axis(propid_filter_t *filter, uint8_t axis, float measured)
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const uint8_t rate = (uint8_t)(derived->layout.rate + axis);
    const uint8_t bias = (uint8_t)(derived->layout.gyro_bias + axis);
    const propid_sparse_row_t row = {2u, {rate, bias}, {1.0f, 1.0f}};
    float innovation = measured - core->state[rate] - core->state[bias];
    float test_ratio = 0.0f;
    propid_scalar_result_t result =
        propid_scalar_update(filter, &row, innovation, derived->gyro_var, derived->gate_sq, &test_ratio);
    core->innovation[axis] = innovation;
    core->innovation_test_ratio[axis] = test_ratio;
    if (result == PROPID_SCALAR_GATED) {
        if (core->gated_run[axis] < filter->config.gate_max_consecutive) {
            core->gated_run[axis]++;
            filter->counters.axis_gated[axis]++;
            return 1u;
        }
        /* Too many rejections in a row: the filter, not the sensor, is probably
         * wrong. Re-anchor this axis' rate on the sample (prior variance, no
         * correlations) and fuse it: the update then has the conditioning of
         * the very first sample, never the P_hh ~ nu^2 of an inflation by the
         * innovation. */
        reanchor_rate(filter, rate, bias, measured);
        innovation = measured - core->state[rate] - core->state[bias];
        (void)propid_scalar_update(filter, &row, innovation, derived->gyro_var, 0.0f, &test_ratio);
        filter->counters.gate_reopened++;
        core->health |= PROPID_HEALTH_GATE_REOPENED;
    }
    core->gated_run[axis] = 0u;
    return 0u;
}

#if PROPID_ARM_BLOCK_MOVES
/* The one pass's three vectors by block moves. For columns 0..11 the bias
 * values P_(b_a)i = P_i,11..13 are the last three elements of packed row i (one
 * VLDM), for columns 12 and 13 they lie in the bias block (one VLDM for both);
 * the rate values P_ai (a = 0..2) lie on the rate rows, consecutive across the
 * columns right of the row's diagonal: each rate row's four (at the end two)
 * columns in one VLDM (the row's pointer written back), left of the diagonal
 * (columns 0..2) copied from the rows above (P symmetric); each vector's four
 * values in one VSTM. Per element the C loop's operations in its order:
 * h_0 = P_0i + P_b0i, h_1 = (P_1i + P_b1i) - c10 h_0,
 * h_2 = ((P_2i + P_b2i) - c20 h_0) - c21 h_1 (fused multiply-subtracts, what
 * -ffp-contract=fast makes of the C; the first as a fused multiply-add of
 * -c10, the same bits), check summed in column order from h_2,0 (no 0 + h_2,0:
 * only the sign of a zero differs, and check only feeds a finiteness test).
 * Registers: h_0 of four columns in s16-s19, h_1 in s20-s23, h_2 in s24-s27, a
 * column's bias triple in s28-s30. */
#define PROPID_VECTOR_COLUMN(at, v0, v1, v2, check)                                                  \
    "add ip, %[cov], %[" at "]\n\tvldmia ip, {s28-s30}\n\t"                                          \
    "vadd.f32 " v0 ", " v0 ", s28\n\t"                                                               \
    "vadd.f32 " v1 ", " v1 ", s29\n\tvfma.f32 " v1 ", %[neg_c10], " v0 "\n\t"                         \
    "vadd.f32 " v2 ", " v2 ", s30\n\tvfms.f32 " v2 ", %[c20], " v0 "\n\tvfms.f32 " v2 ", %[c21], " v1 "\n\t" \
    check(v2)
#define PROPID_CHECK_FIRST(v2) "vmov.f32 %[check], " v2 "\n\t"
#define PROPID_CHECK_ADD(v2) "vadd.f32 %[check], %[check], " v2 "\n\t"
#define PROPID_VECTOR_COLUMNS(a0, a1, a2, a3, check0)                                                \
    PROPID_VECTOR_COLUMN(a0, "s16", "s20", "s24", check0)                                            \
    PROPID_VECTOR_COLUMN(a1, "s17", "s21", "s25", PROPID_CHECK_ADD)                                  \
    PROPID_VECTOR_COLUMN(a2, "s18", "s22", "s26", PROPID_CHECK_ADD)                                  \
    PROPID_VECTOR_COLUMN(a3, "s19", "s23", "s27", PROPID_CHECK_ADD)                                  \
    "vstmia %[h0]!, {s16-s19}\n\tvstmia %[h1]!, {s20-s23}\n\tvstmia %[h2]!, {s24-s27}\n\t"
/* Columns 0..3: row 0 from column 0, row 1 from its diagonal (P_10 = P_01),
 * row 2 from its diagonal (P_20 = P_02, P_21 = P_12). */
#define PROPID_VECTOR_FIRST_CHUNK                                                                    \
    "vldmia %[p0]!, {s16-s19}\n\tvldmia %[p1]!, {s21-s23}\n\tvldmia %[p2]!, {s26-s27}\n\t"          \
    "vmov.f32 s20, s17\n\tvmov.f32 s24, s18\n\tvmov.f32 s25, s22\n\t"                                 \
    PROPID_VECTOR_COLUMNS("b0", "b1", "b2", "b3", PROPID_CHECK_FIRST)
#define PROPID_VECTOR_CHUNK(a0, a1, a2, a3)                                                          \
    "vldmia %[p0]!, {s16-s19}\n\tvldmia %[p1]!, {s20-s23}\n\tvldmia %[p2]!, {s24-s27}\n\t"          \
    PROPID_VECTOR_COLUMNS(a0, a1, a2, a3, PROPID_CHECK_ADD)
/* Columns 12 and 13: each rate row's two in one VLDM, the bias block (rows
 * 11..13 from their diagonals: P_11,11 P_11,12 P_11,13 P_12,12 P_12,13 P_13,13)
 * into s26-s31, column 12's triple s27 s29 s30, column 13's s28 s30 s31. In the
 * quad build (14 states) the block is consecutive, one VLDM; in the full build
 * (longer packed rows) the three rows' parts apart. */
#if PROPID_MAX_STATES == 14
#define PROPID_LOAD_BIAS_BLOCK "add ip, %[cov], %[b11]\n\tvldmia ip, {s26-s31}\n\t"
#else
#define PROPID_LOAD_BIAS_BLOCK                                                                       \
    "add ip, %[cov], %[b11]\n\tvldmia ip, {s26-s28}\n\tadd ip, %[cov], %[b12]\n\tvldmia ip, {s29-s30}\n\t" \
    "add ip, %[cov], %[b13]\n\tvldr s31, [ip]\n\t"
#endif
#define PROPID_VECTOR_LAST_COLUMN(v0, v1, v2, b0, b1, b2)                                            \
    "vadd.f32 " v0 ", " v0 ", " b0 "\n\t"                                                               \
    "vadd.f32 " v1 ", " v1 ", " b1 "\n\tvfma.f32 " v1 ", %[neg_c10], " v0 "\n\t"                      \
    "vadd.f32 " v2 ", " v2 ", " b2 "\n\tvfms.f32 " v2 ", %[c20], " v0 "\n\tvfms.f32 " v2 ", %[c21], " v1 "\n\t" \
    "vadd.f32 %[check], %[check], " v2 "\n\t"
#define PROPID_VECTOR_LAST_CHUNK                                                                     \
    "vldmia %[p0]!, {s16-s17}\n\tvldmia %[p1]!, {s20-s21}\n\tvldmia %[p2]!, {s24-s25}\n\t"          \
    PROPID_LOAD_BIAS_BLOCK                                                                           \
    PROPID_VECTOR_LAST_COLUMN("s16", "s20", "s24", "s27", "s29", "s30")                              \
    PROPID_VECTOR_LAST_COLUMN("s17", "s21", "s25", "s28", "s30", "s31")                              \
    "vstmia %[h0]!, {s16-s17}\n\tvstmia %[h1]!, {s20-s21}\n\tvstmia %[h2]!, {s24-s25}\n\t"
#define PROPID_BIAS_AT(i) "n"(4u * propid_cov_index((i), PROPID_QUAD_FIRST_BIAS))
/* Returns check (the sum of h_2,0..13). */
static inline __attribute__((always_inline)) float
quad_vectors(const float *cov, float *h0, float *h1, float *h2, const float c10, const float c20,
                       const float c21)
{
    const float *p0 = cov + propid_cov_index(0u, 0u);
    const float *p1 = cov + propid_cov_index(1u, 1u);
    const float *p2 = cov + propid_cov_index(2u, 2u);
    float check;
    __asm__ volatile(PROPID_VECTOR_FIRST_CHUNK PROPID_VECTOR_CHUNK("b4", "b5", "b6", "b7")
                     PROPID_VECTOR_CHUNK("b8", "b9", "b10", "b11")
                     : [p0] "+&r"(p0), [p1] "+&r"(p1), [p2] "+&r"(p2), [h0] "+&r"(h0), [h1] "+&r"(h1),
                       [h2] "+&r"(h2), [check] "=&t"(check)
                     : [cov] "r"(cov), [neg_c10] "t"(-c10), [c20] "t"(c20), [c21] "t"(c21),
                       [b0] PROPID_BIAS_AT(0u), [b1] PROPID_BIAS_AT(1u), [b2] PROPID_BIAS_AT(2u),
                       [b3] PROPID_BIAS_AT(3u), [b4] PROPID_BIAS_AT(4u), [b5] PROPID_BIAS_AT(5u),
                       [b6] PROPID_BIAS_AT(6u), [b7] PROPID_BIAS_AT(7u), [b8] PROPID_BIAS_AT(8u),
                       [b9] PROPID_BIAS_AT(9u), [b10] PROPID_BIAS_AT(10u), [b11] PROPID_BIAS_AT(11u)
                     : "s16", "s17", "s18", "s19", "s20", "s21", "s22", "s23", "s24", "s25", "s26", "s27", "s28",
                       "s29", "s30", "ip", "memory");
    /* (The last chunk apart: an asm statement takes at most 30 operands.) */
    __asm__ volatile(PROPID_VECTOR_LAST_CHUNK
                     : [p0] "+&r"(p0), [p1] "+&r"(p1), [p2] "+&r"(p2), [h0] "+&r"(h0), [h1] "+&r"(h1),
                       [h2] "+&r"(h2), [check] "+t"(check)
                     : [cov] "r"(cov), [neg_c10] "t"(-c10), [c20] "t"(c20), [c21] "t"(c21),
                       [b11] PROPID_BIAS_AT(11u),
                       [b12] PROPID_AT(PROPID_QUAD_FIRST_BIAS + 1u, PROPID_QUAD_FIRST_BIAS + 1u),
                       [b13] PROPID_AT(PROPID_QUAD_FIRST_BIAS + 2u, PROPID_QUAD_FIRST_BIAS + 2u)
                     : "s16", "s17", "s20", "s21", "s24", "s25", "s26", "s27", "s28", "s29", "s30", "s31", "ip",
                       "memory");
    return check;
}
#endif

/* fuse_quad_usual's result when it has written nothing (apply_three_quad's are
 * 0 when every variance is inside its bounds, else how many are outside, at
 * most 14, or a flag below this). */
#define PROPID_NOT_FUSED UINT32_MAX

/* The usual quad sample, straight-line: all three axes pass the gate, every
 * S >= R and the vectors are finite. Same arithmetic in the same order as
 * fuse_axis (the scalars S, innovation and projections are formed from the few
 * vector entries they need before the vectors themselves). With the three axes
 * queued in `pending` and their innovations recorded, it ends in their
 * downdate (apply_three_quad, a tail call: its frame replaces this one) and
 * returns its result; else PROPID_NOT_FUSED without writing anything: the
 * general path then handles the sample. Not inlined, and given the covariance
 * as its own pointer: offsets from the filter's base exceed the 1 KiB reach of
 * a VFP load. */
static __attribute__((noinline)) uint32_t
fuse_quad_usual(float *restrict cov, propid_core_t *restrict core,
                const propid_derived_t *restrict derived, pending_t *restrict pending,
                const float *restrict gyro)
{
#define PROPID_P(i, j) propid_cov_at(cov, (i), (j))
    const float *state = core->state;
    const float noise_var = derived->gyro_var;
    const float gate_sq = derived->gate_sq;
    /* S outside [R, R + R / loading] (or NaN) leaves the fast path: below, the
     * generic path decides about rounding; above, it loads R. */
    uint32_t var_bits; /* gyro_var's bit pattern */
    memcpy(&var_bits, &derived->gyro_var, sizeof(var_bits));
    const uint32_t var_range_bits = derived->innovation_range_bits;
    const uint8_t b0 = PROPID_QUAD_FIRST_BIAS; /* the three gyro-bias states */
    const uint8_t b1 = PROPID_QUAD_FIRST_BIAS + 1u;
    const uint8_t b2 = PROPID_QUAD_FIRST_BIAS + 2u;

    /* x axis: h_0 = P_:,0 + P_:,11 */
    const float h0_r0 = PROPID_P(0, 0) + PROPID_P(b0, 0);
    const float h0_b0 = PROPID_P(0, b0) + PROPID_P(b0, b0);
    const float var0 = h0_r0 + h0_b0 + noise_var;
    const float nu0 = gyro[0] - state[0] - state[b0];
    const float nu0_sq = nu0 * nu0;
    /* S < R (even within rounding: fuse_axis decides) leaves the fast path. */
    if (propid_outside_positive_range(var0, var_bits, var_range_bits) || !(nu0_sq <= gate_sq * var0)) {
        return PROPID_NOT_FUSED;
    }
    const float inv0 = 1.0f / var0;
    const float step0 = nu0 * inv0;

    /* y axis: h_1 = P_:,1 + P_:,12 - c10 h_0 */
    const float h0_r1 = PROPID_P(0, 1) + PROPID_P(b0, 1);
    const float h0_b1 = PROPID_P(0, b1) + PROPID_P(b0, b1);
    const float c10 = (h0_r1 + h0_b1) * inv0;
    const float h1_r1 = PROPID_P(1, 1) + PROPID_P(b1, 1) - c10 * h0_r1;
    const float h1_b1 = PROPID_P(1, b1) + PROPID_P(b1, b1) - c10 * h0_b1;
    const float var1 = h1_r1 + h1_b1 + noise_var;
    const float nu1 = gyro[1] - (state[1] + h0_r1 * step0) - (state[b1] + h0_b1 * step0);
    const float nu1_sq = nu1 * nu1;
    if (propid_outside_positive_range(var1, var_bits, var_range_bits) || !(nu1_sq <= gate_sq * var1)) {
        return PROPID_NOT_FUSED;
    }
    const float inv1 = 1.0f / var1;
    const float step1 = nu1 * inv1;

    /* z axis: h_2 = P_:,2 + P_:,13 - c20 h_0 - c21 h_1 */
    const float h0_r2 = PROPID_P(0, 2) + PROPID_P(b0, 2);
    const float h0_b2 = PROPID_P(0, b2) + PROPID_P(b0, b2);
    const float h1_r2 = PROPID_P(1, 2) + PROPID_P(b1, 2) - c10 * h0_r2;
    const float h1_b2 = PROPID_P(1, b2) + PROPID_P(b1, b2) - c10 * h0_b2;
    const float c20 = (h0_r2 + h0_b2) * inv0;
    const float c21 = (h1_r2 + h1_b2) * inv1;
    const float h2_r2 = PROPID_P(2, 2) + PROPID_P(b2, 2) - c20 * h0_r2 - c21 * h1_r2;
    const float h2_b2 = PROPID_P(2, b2) + PROPID_P(b2, b2) - c20 * h0_b2 - c21 * h1_b2;
    const float var2 = h2_r2 + h2_b2 + noise_var;
    const float shift_r2 = h0_r2 * step0 + h1_r2 * step1;
    const float shift_b2 = h0_b2 * step0 + h1_b2 * step1;
    const float nu2 = gyro[2] - (state[2] + shift_r2) - (state[b2] + shift_b2);
    const float nu2_sq = nu2 * nu2;
    if (propid_outside_positive_range(var2, var_bits, var_range_bits) || !(nu2_sq <= gate_sq * var2)) {
        return PROPID_NOT_FUSED;
    }
    const float inv2 = 1.0f / var2;

    /* The three vectors, with one finiteness test over all of them: h_2 folds in
     * h_0 and h_1 (c * Inf is Inf, or NaN when c = 0), so a non-finite element of
     * any of the three makes that element of h_2 non-finite; summing h_2 covers all. */
    float *h0 = pending->h0;
    float *h1 = core->update_vector[0];
    float *h2 = core->update_vector[1];
    /* The vectors' elements 0..2 and 11..13 sum P values the scalars above
     * loaded already: loaded again here, not kept alive through the loop
     * (spilled, that was 60 B more stack for 5 instructions fewer). */
    PROPID_SCHEDULE_BARRIER();
#if PROPID_SIZE_LEAN
    /* The loop's P_ai and P_(b_a),i walked through the packed triangle (down
     * their columns while i is above the diagonal, then along their rows):
     * no index arithmetic per element. */
    uint32_t at[6] = {0u, 1u, 2u, b0, b1, b2};
#endif
#if PROPID_ARM_BLOCK_MOVES
    /* By block moves (the same operations per element in the same order; check
     * summed in column order). */
    const float check = quad_vectors(cov, h0, h1, h2, c10, c20, c21);
#else
    float check = 0.0f;
PROPID_UNROLL(14)
    for (uint8_t i = 0; i < PROPID_QUAD_STATES; ++i) {
#if PROPID_SIZE_LEAN
        float p[6];
#pragma GCC unroll 6
        for (uint8_t k = 0; k < 6u; ++k) {
            const uint8_t row = (uint8_t)(k < 3u ? k : PROPID_QUAD_FIRST_BIAS + k - 3u);
            p[k] = cov[at[k]];
            at[k] += i < row ? (uint32_t)PROPID_MAX_STATES - 1u - i : 1u;
        }
        const float value0 = p[0] + p[3];
        const float value1 = p[1] + p[4] - c10 * value0;
        const float value2 = p[2] + p[5] - c20 * value0 - c21 * value1;
#else
        const float value0 = PROPID_P(0, i) + PROPID_P(b0, i);
        const float value1 = PROPID_P(1, i) + PROPID_P(b1, i) - c10 * value0;
        const float value2 = PROPID_P(2, i) + PROPID_P(b2, i) - c20 * value0 - c21 * value1;
#endif
        h0[i] = value0;
        h1[i] = value1;
        h2[i] = value2;
        check += value2;
    }
#endif
#undef PROPID_P
    if (!isfinite(check)) {
        return PROPID_NOT_FUSED;
    }
    const float inv_gate_sq = derived->inv_gate_sq;
    core->innovation[0] = nu0;
    core->innovation[1] = nu1;
    core->innovation[2] = nu2;
    core->innovation_test_ratio[0] = nu0_sq * inv0 * inv_gate_sq;
    core->innovation_test_ratio[1] = nu1_sq * inv1 * inv_gate_sq;
    core->innovation_test_ratio[2] = nu2_sq * inv2 * inv_gate_sq;
    core->gated_run[0] = 0u;
    core->gated_run[1] = 0u;
    core->gated_run[2] = 0u;
    pending->inv_var[0] = inv0;
    pending->inv_var[1] = inv1;
    pending->inv_var[2] = inv2;
    return apply_three_quad(cov, core, pending, derived);
}

#if PROPID_GENERAL_VEHICLES
/* The usual sample of any other vehicle (hexa, octo, optional states): the same
 * one pass as the quad's (fuse_quad_usual, apply_three_quad) over loops, for any
 * state count n and the layout's bias block. Returns 1 with the three axes
 * queued in `pending` and their innovations recorded, or 0 without writing
 * anything (the per-axis path then handles the sample). */
static __attribute__((noinline)) int
fuse_usual_any(const float *restrict cov, propid_core_t *restrict core,
               const propid_derived_t *restrict derived, pending_any_t *restrict pending,
               const float *restrict gyro)
{
    const uint8_t n = derived->state_count;
    const uint8_t first_bias = derived->layout.gyro_bias;
    const float *state = core->state;
    const float noise_var = derived->gyro_var;
    const float gate_sq = derived->gate_sq;
    uint32_t var_bits; /* gyro_var's bit pattern */
    memcpy(&var_bits, &derived->gyro_var, sizeof(var_bits));
    const uint32_t var_range_bits = derived->innovation_range_bits;
    /* Rows 0 and 1 are written (axes 0 and 1) before they are read (axes 1 and 2). */
    // cppcheck-suppress [uninitvar,ctuuninitvar]
    const float *h0 = pending->h[0];
    const float *h1 = pending->h[1];
    /* The three vectors h_a = P H_a^T - sum_{p<a} c_ap h_p, c_ap = (h_p . H_a) / S_p,
     * axis by axis (each needs the previous axes' S). */
    float inv[3] = {0.0f, 0.0f, 0.0f};
    float nu[3] = {0.0f, 0.0f, 0.0f};
    float nu_sq[3] = {0.0f, 0.0f, 0.0f};
    for (uint8_t a = 0; a < 3u; ++a) {
        const uint8_t bias = (uint8_t)(first_bias + a);
        const float c0 = a > 0u ? (h0[a] + h0[bias]) * inv[0] : 0.0f;
        const float c1 = a > 1u ? (h1[a] + h1[bias]) * inv[1] : 0.0f;
        float check = 0.0f;
        /* P_ia and P_i,bias walked through the packed triangle: down the column
         * while i is above the diagonal (the step shrinks by one per row), then
         * along the row. */
        uint32_t at_rate = a;
        uint32_t at_bias = bias;
        for (uint8_t i = 0; i < n; ++i) {
            float value = cov[at_rate] + cov[at_bias];
            at_rate += i < a ? (uint32_t)PROPID_MAX_STATES - 1u - i : 1u;
            at_bias += i < bias ? (uint32_t)PROPID_MAX_STATES - 1u - i : 1u;
            if (a > 0u) {
                value -= c0 * h0[i];
            }
            if (a > 1u) {
                value -= c1 * h1[i];
            }
            pending->h[a][i] = value;
            check += value;
        }
        const float var = pending->h[a][a] + pending->h[a][bias] + noise_var;
        /* The earlier axes' state updates shift this axis' prediction. */
        float predicted = state[a] + state[bias];
        for (uint8_t p = 0; p < a; ++p) {
            predicted += (pending->h[p][a] + pending->h[p][bias]) * (nu[p] * inv[p]);
        }
        nu[a] = gyro[a] - predicted;
        nu_sq[a] = nu[a] * nu[a];
        if (!isfinite(check) || propid_outside_positive_range(var, var_bits, var_range_bits) ||
            !(nu_sq[a] <= gate_sq * var)) {
            return 0;
        }
        inv[a] = 1.0f / var;
    }
    for (uint8_t a = 0; a < 3u; ++a) {
        core->innovation[a] = nu[a];
        core->innovation_test_ratio[a] = nu_sq[a] * inv[a] * derived->inv_gate_sq;
        core->gated_run[a] = 0u;
        pending->inv_var[a] = inv[a];
    }
    return 1;
}

/* P_ij -= sum_k g_k,i h_k,j on the stored upper triangle, x += sum_k g_k nu_k, for
 * any n; returns 1 when every new variance is inside its floor and ceiling. */
static __attribute__((noinline)) int
apply_three_any(float *restrict cov, propid_core_t *restrict core,
                const pending_any_t *restrict pending, const propid_derived_t *restrict derived)
{
    float *state = core->state;
    const float nu0 = core->innovation[0];
    const float nu1 = core->innovation[1];
    const float nu2 = core->innovation[2];
    const uint8_t n = derived->state_count;
    const float *h0 = pending->h[0];
    const float *h1 = pending->h[1];
    const float *h2 = pending->h[2];
    uint32_t outside = 0u;
    float *diagonal = cov; /* P_ii; the next diagonal is PROPID_MAX_STATES - i further */
    for (uint8_t i = 0; i < n; ++i) {
        const float g0 = h0[i] * pending->inv_var[0];
        const float g1 = h1[i] * pending->inv_var[1];
        const float g2 = h2[i] * pending->inv_var[2];
        state[i] += g0 * nu0 + g1 * nu1 + g2 * nu2;
        float *row = diagonal - i; /* row[j] = P_ij, j >= i */
        for (uint8_t j = i; j < n; ++j) {
            row[j] = row[j] - g0 * h0[j] - g1 * h1[j] - g2 * h2[j];
        }
        outside |= propid_outside_positive_range(row[i], propid_floor_bits(derived, i), propid_range_bits(derived, i));
        diagonal += PROPID_MAX_STATES - i;
    }
    return outside == 0u;
}
#endif

/* Every sample the one pass does not take (a gated axis, S < R, a non-finite
 * vector): the generic scalar update per axis. Not inlined: its callees' frames
 * stay off the one pass's stack. */
static __attribute__((noinline)) PROPID_RARE uint32_t fuse_generic(propid_filter_t *filter, const float gyro[3])
{
    /* A prediction across a long gap at high rates can inflate the rate
     * variances by orders of magnitude: the ceilings first (they keep P PSD),
     * so no update sees an S that float32 cannot downdate. */
    if (propid_cov_enforce_bounds(&filter->derived, &filter->core)) {
        filter->core.health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    uint32_t gated_mask = 0u;
    for (uint8_t axis = 0; axis < 3u; ++axis) {
        gated_mask |= fuse_axis(filter, axis, gyro[axis]) << axis;
    }
    return gated_mask;
}

/* 1 when every rate variance is inside its [floor, ceiling]. The one pass tests
 * each axis' S after the earlier axes' terms are folded in, so a rate variance
 * far above its ceiling passes when a correlation of ~1 with an earlier axis
 * takes it back below; its rounding (~epsilon P_omega) then stays in the rate
 * rows, beyond R (fuzz finding: a gyroscopic coupling (Ixx - Iyy) omega_x /
 * Izz of 5e5 /s inflated P_zz to 7e4, 4 500 times its ceiling, in one step,
 * correlated with omega_x through omega_y, and P lost definiteness). Such a
 * sample takes the generic path, which applies the ceilings first. */
static inline int rate_variances_inside(const propid_derived_t *derived, const float *cov)
{
    /* (The rates are the first three states of every layout: fixed offsets.) */
    const uint32_t floor_bits = propid_kind_floor_bits(derived, PROPID_KIND_RATE);
    const uint32_t range_bits = derived->kind_range_bits[PROPID_KIND_RATE];
    return (propid_outside_positive_range(cov[propid_cov_index(0u, 0u)], floor_bits, range_bits) |
            propid_outside_positive_range(cov[propid_cov_index(1u, 1u)], floor_bits, range_bits) |
            propid_outside_positive_range(cov[propid_cov_index(2u, 2u)], floor_bits, range_bits)) == 0u;
}

/* The one pass over P for the usual sample (every axis inside its gate): the
 * quad's straight-line kernels or the loops for any other vehicle. Returns 1
 * when it fused the sample, 0 with nothing written. Its frame (`pending`) is not
 * under the per-axis path's: the full build keeps it apart; the quad build
 * inlines it into propid_update_gyro, which releases that frame before it
 * branches to fuse_generic (a tail call). */
static PROPID_QUAD_INLINE int fuse_one_pass(propid_filter_t *filter, const float gyro[3])
{
    propid_core_t *core = &filter->core;
    const propid_derived_t *derived = &filter->derived;
    const float *cov = core->cov;
    if (!rate_variances_inside(derived, cov)) {
        return 0;
    }
    int inside;
#if PROPID_GENERAL_VEHICLES
    if (!derived->quad_core) {
        pending_any_t pending;
        if (!fuse_usual_any(cov, core, derived, &pending, gyro)) {
            return 0;
        }
        inside = apply_three_any(core->cov, core, &pending, derived);
    } else
#endif
    {
        pending_t pending;
        const uint32_t outside = fuse_quad_usual(core->cov, core, derived, &pending, gyro);
        if (outside == PROPID_NOT_FUSED) {
            return 0;
        }
        inside = outside == 0u;
    }
    /* Variance floors and ceilings: tested inside the pass; the full pass (which
     * also repairs) only when one is outside. */
    if (!inside && propid_cov_enforce_bounds(derived, core)) {
        core->health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    return 1;
}

uint32_t propid_update_gyro(propid_filter_t *filter, const float gyro[3])
{
    if (fuse_one_pass(filter, gyro)) {
        return 0u;
    }
    return fuse_generic(filter, gyro);
}

#if PROPID_WITH_GYRO_STUCK_CHECK
uint32_t propid_gyro_stuck_mask(propid_filter_t *filter, const float gyro[3])
{
    propid_core_t *core = &filter->core;
    const uint16_t limit = filter->config.gyro_stuck_samples; /* (the full build keeps the whole config) */
    uint32_t mask = 0u;
    for (uint8_t a = 0; a < 3u; ++a) {
        /* Bits, not values: a stuck source repeats its word exactly. */
        uint32_t bits;
        memcpy(&bits, &gyro[a], sizeof(bits));
        if (bits == core->gyro_last_bits[a] && core->gyro_repeat_run[a] != 0u) {
            if (core->gyro_repeat_run[a] < UINT16_MAX) {
                core->gyro_repeat_run[a]++;
            }
        } else {
            core->gyro_last_bits[a] = bits;
            core->gyro_repeat_run[a] = 1u;
        }
        if (core->gyro_repeat_run[a] >= limit) {
            mask |= 1u << a;
        }
    }
    return mask;
}

uint32_t propid_update_gyro_skipping(propid_filter_t *filter, const float gyro[3], uint32_t skip_mask)
{
    if (skip_mask == 0u) {
        return propid_update_gyro(filter, gyro);
    }
    /* As fuse_generic, with the stuck axes left out: their reading says nothing
     * about the rate, so neither the gate nor its re-anchor may see it. */
    if (propid_cov_enforce_bounds(&filter->derived, &filter->core)) {
        filter->core.health |= PROPID_HEALTH_COV_REPAIRED;
        filter->counters.cov_repairs++;
    }
    uint32_t not_fused = skip_mask;
    for (uint8_t axis = 0; axis < 3u; ++axis) {
        if ((skip_mask >> axis) & 1u) {
            filter->core.innovation_test_ratio[axis] = 0.0f;
            filter->counters.gyro_stuck++;
        } else {
            not_fused |= fuse_axis(filter, axis, gyro[axis]) << axis;
        }
    }
    return not_fused;
}
#endif
