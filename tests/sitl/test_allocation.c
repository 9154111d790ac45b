/*
 * Allocation: wrench -> rotor speeds -> wrench round trips (plus, X, hexa,
 * distinct per-rotor coefficients), the saturation priority (yaw first, then
 * collective thrust, roll/pitch last) and input checks.
 * Plain C (no framework): prints each failure, exit status = failure count.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "allocation.h"
#include "check.h"

static const double kf_nom = 2.3e-8, km_nom = 7.8e-10, arm = 0.043;
static const double speed_max = 2500.0;

static void symmetric_geometry(sitl_allocation_geometry_t *g, int n, double first_angle)
{
    memset(g, 0, sizeof(*g));
    g->rotor_count = n;
    g->rotor_speed_min = 0.0;
    g->rotor_speed_max = speed_max;
    for (int i = 0; i < n; i++) {
        double a = first_angle + 2.0 * 3.14159265358979323846 * i / n;
        g->position[i][0] = arm * cos(a);
        g->position[i][1] = arm * sin(a);
        g->yaw_sign[i] = (i % 2 == 0) ? 1.0 : -1.0;
    }
}

/* Deterministic spread of coefficients around nominal, like the campaign's truth. */
static void spread(int n, double *kf, double *km, int seed)
{
    for (int i = 0; i < n; i++) {
        double a = 0.8 + 0.4 * fmod(0.618033988749 * (i + 1 + 7 * seed), 1.0);
        double b = 0.8 + 0.4 * fmod(0.414213562373 * (i + 3 + 5 * seed), 1.0);
        kf[i] = kf_nom * a;
        km[i] = km_nom * b;
    }
}

static int rel_close(double a, double b, double scale, double tol) { return fabs(a - b) <= tol * scale; }

static void check_round_trip(int n, double first_angle, int seed)
{
    sitl_allocation_geometry_t g;
    symmetric_geometry(&g, n, first_angle);
    sitl_allocation_t alloc;
    CHECK(sitl_allocation_init(&alloc, &g) == 0, "init n=%d", n);
    double kf[SITL_ALLOC_MAX_ROTORS], km[SITL_ALLOC_MAX_ROTORS];
    spread(n, kf, km, seed);
    CHECK(sitl_allocation_set_coefficients(&alloc, kf, km) == 0, "coefficients n=%d", n);

    /* Hover-ish thrust with moments a controller would ask for. */
    const double thrust = 0.3, moment[3] = {2e-4, -1.5e-4, 3e-5};
    sitl_allocation_result_t r;
    CHECK(sitl_allocation_solve(&alloc, thrust, moment, &r) == 0, "solve n=%d", n);
    CHECK(r.saturation == 0, "n=%d unexpected saturation %u", n, r.saturation);
    double w[4];
    sitl_allocation_wrench(&alloc, r.rotor_speed, w);
    CHECK(rel_close(w[0], thrust, thrust, 1e-9), "n=%d thrust %g vs %g", n, w[0], thrust);
    for (int k = 0; k < 3; k++) {
        CHECK(rel_close(w[k + 1], moment[k], fabs(moment[k]), 1e-9), "n=%d moment %d %g vs %g", n,
              k, w[k + 1], moment[k]);
        CHECK(rel_close(r.achieved[k + 1], moment[k], fabs(moment[k]), 1e-9),
              "n=%d achieved moment %d", n, k);
    }
    /* Check the wrench map against the physics written out independently:
     * tau = sum r_i x (kf_i u_i z) + s_i km_i u_i z */
    double tau[3] = {0, 0, 0}, f = 0.0;
    for (int i = 0; i < n; i++) {
        double u = r.rotor_speed[i] * r.rotor_speed[i];
        f += kf[i] * u;
        tau[0] += g.position[i][1] * kf[i] * u;
        tau[1] -= g.position[i][0] * kf[i] * u;
        tau[2] += g.yaw_sign[i] * km[i] * u;
    }
    CHECK(rel_close(f, thrust, thrust, 1e-9), "n=%d physics thrust %g", n, f);
    for (int k = 0; k < 3; k++) {
        CHECK(rel_close(tau[k], moment[k], fabs(moment[k]), 1e-9), "n=%d physics moment %d", n, k);
    }
}

static void test_round_trips(void)
{
    const double pi = 3.14159265358979323846;
    check_round_trip(4, 0.0, 1);      /* plus */
    check_round_trip(4, pi / 4.0, 2); /* X */
    check_round_trip(6, 0.0, 3);      /* hexa: minimum-norm pseudo-inverse */
    check_round_trip(8, pi / 8.0, 4); /* octo */
}

/* Solve on a plus quad with nominal coefficients. */
static void setup_plus(sitl_allocation_t *alloc)
{
    sitl_allocation_geometry_t g;
    symmetric_geometry(&g, 4, 0.0);
    sitl_allocation_init(alloc, &g);
    double kf[4] = {kf_nom, kf_nom, kf_nom, kf_nom}, km[4] = {km_nom, km_nom, km_nom, km_nom};
    sitl_allocation_set_coefficients(alloc, kf, km);
}

static int within_bounds(const sitl_allocation_result_t *r, int n)
{
    for (int i = 0; i < n; i++) {
        if (!(r->rotor_speed[i] >= 0.0 && r->rotor_speed[i] <= speed_max * (1.0 + 1e-12))) {
            return 0;
        }
    }
    return 1;
}

static void test_yaw_sacrificed_first(void)
{
    sitl_allocation_t alloc;
    setup_plus(&alloc);
    const double thrust = 0.3, moment[3] = {1e-4, -5e-5, 5e-2}; /* ~5x the achievable yaw */
    sitl_allocation_result_t r;
    sitl_allocation_solve(&alloc, thrust, moment, &r);
    CHECK(within_bounds(&r, 4), "speeds out of bounds");
    CHECK(r.saturation == SITL_ALLOC_SAT_YAW, "flags %u, expected yaw only", r.saturation);
    CHECK(r.yaw_fraction > 0.0 && r.yaw_fraction < 1.0, "yaw fraction %g", r.yaw_fraction);
    CHECK(rel_close(r.achieved[0], thrust, thrust, 1e-9), "thrust not kept: %g", r.achieved[0]);
    CHECK(rel_close(r.achieved[1], moment[0], fabs(moment[0]), 1e-9), "roll not kept");
    CHECK(rel_close(r.achieved[2], moment[1], fabs(moment[1]), 1e-9), "pitch not kept");
    CHECK(rel_close(r.achieved[3], r.yaw_fraction * moment[2], fabs(moment[2]), 1e-9),
          "yaw achieved %g vs fraction %g", r.achieved[3], r.yaw_fraction);
    CHECK(r.achieved[3] > 0.0, "yaw moment kept its sign");
    /* the reduced yaw saturates at least one rotor (largest feasible fraction) */
    int at_bound = 0;
    for (int i = 0; i < 4; i++) {
        at_bound |= fabs(r.rotor_speed[i] - speed_max) < 1e-6 || r.rotor_speed[i] < 1e-3;
    }
    CHECK(at_bound, "yaw reduced more than needed");
}

static void test_thrust_moved_before_roll_pitch(void)
{
    sitl_allocation_t alloc;
    setup_plus(&alloc);
    /* More thrust than four rotors at full speed give, plus a roll moment. */
    const double thrust_max = 4.0 * kf_nom * speed_max * speed_max;
    const double thrust = 1.2 * thrust_max, moment[3] = {2e-3, 0.0, 1e-5};
    sitl_allocation_result_t r;
    sitl_allocation_solve(&alloc, thrust, moment, &r);
    CHECK(within_bounds(&r, 4), "speeds out of bounds");
    CHECK((r.saturation & SITL_ALLOC_SAT_THRUST) && !(r.saturation & SITL_ALLOC_SAT_ROLL_PITCH),
          "flags %u", r.saturation);
    CHECK(rel_close(r.achieved[1], moment[0], fabs(moment[0]), 1e-9), "roll not kept: %g",
          r.achieved[1]);
    CHECK(r.achieved[0] < thrust && r.achieved[0] > 0.8 * thrust_max, "thrust %g", r.achieved[0]);
    CHECK(fabs(r.achieved[3]) < 1e-12, "yaw should be dropped before thrust moves");

    /* Roll moment larger than the rotors can make at any thrust: scaled, sign kept. */
    const double huge[3] = {1.0, 0.0, 0.0};
    sitl_allocation_solve(&alloc, 0.3, huge, &r);
    CHECK(within_bounds(&r, 4), "speeds out of bounds (huge roll)");
    CHECK(r.saturation & SITL_ALLOC_SAT_ROLL_PITCH, "flags %u", r.saturation);
    CHECK(r.achieved[1] > 0.0, "roll sign lost");
    const double roll_max = arm * kf_nom * speed_max * speed_max; /* one side full, other off */
    CHECK(r.achieved[1] > 0.99 * roll_max, "roll %g far below the achievable %g", r.achieved[1],
          roll_max);

    /* Negative thrust: clipped to zero speeds, no NaN. */
    const double none[3] = {0.0, 0.0, 0.0};
    sitl_allocation_solve(&alloc, -1.0, none, &r);
    CHECK(within_bounds(&r, 4) && r.rotor_speed[0] == 0.0, "negative thrust -> %g",
          r.rotor_speed[0]);
}

static void test_bad_input(void)
{
    sitl_allocation_geometry_t g;
    symmetric_geometry(&g, 4, 0.0);
    sitl_allocation_t alloc;
    g.rotor_speed_max = 0.0;
    CHECK(sitl_allocation_init(&alloc, &g) == -1, "max speed 0 accepted");
    symmetric_geometry(&g, 4, 0.0);
    g.yaw_sign[2] = 0.5;
    CHECK(sitl_allocation_init(&alloc, &g) == -1, "yaw sign 0.5 accepted");
    symmetric_geometry(&g, 4, 0.0);
    g.rotor_count = 9;
    CHECK(sitl_allocation_init(&alloc, &g) == -1, "9 rotors accepted");

    symmetric_geometry(&g, 4, 0.0);
    CHECK(sitl_allocation_init(&alloc, &g) == 0, "init");
    sitl_allocation_result_t r;
    const double m[3] = {0, 0, 0};
    CHECK(sitl_allocation_solve(&alloc, 0.3, m, &r) == -1, "solve before coefficients");
    double kf[4] = {kf_nom, -kf_nom, kf_nom, kf_nom}, km[4] = {km_nom, km_nom, km_nom, km_nom};
    CHECK(sitl_allocation_set_coefficients(&alloc, kf, km) == -1, "negative kf accepted");
    kf[1] = kf_nom;
    km[3] = NAN;
    CHECK(sitl_allocation_set_coefficients(&alloc, kf, km) == -1, "NaN km accepted");

    /* Singular: all rotors on the x axis cannot make a roll moment. */
    for (int i = 0; i < 4; i++) {
        g.position[i][1] = 0.0;
    }
    sitl_allocation_init(&alloc, &g);
    km[3] = km_nom;
    CHECK(sitl_allocation_set_coefficients(&alloc, kf, km) == -1, "singular map accepted");
    CHECK(!alloc.ready, "singular map marked ready");
    const double bad_moment[3] = {NAN, 0, 0};
    setup_plus(&alloc);
    CHECK(sitl_allocation_solve(&alloc, 0.3, bad_moment, &r) == -1, "NaN moment accepted");
}

/* The null-space dither moves every rotor of a hexa and an octo without moving
 * the wrench; on a quad (no null space) it changes nothing; at a speed bound it
 * shrinks instead of clipping one rotor (which would move the wrench). */
static void test_null_dither_keeps_the_wrench(void)
{
    const double thrust_per_rotor = 0.075, moment[3] = {2e-4, -1.5e-4, 3e-5};
    for (int n = 4; n <= 8; n += 2) {
        sitl_allocation_geometry_t g;
        symmetric_geometry(&g, n, 0.3);
        sitl_allocation_t alloc;
        sitl_allocation_init(&alloc, &g);
        double kf[SITL_ALLOC_MAX_ROTORS], km[SITL_ALLOC_MAX_ROTORS];
        spread(n, kf, km, n);
        CHECK(sitl_allocation_set_coefficients(&alloc, kf, km) == 0, "coefficients n=%d", n);
        double largest_move = 0.0;
        for (int k = 0; k < 50; k++) {
            const double t = 0.037 * k;
            sitl_allocation_result_t plain, dithered;
            sitl_allocation_solve(&alloc, thrust_per_rotor * n, moment, &plain);
            dithered = plain;
            CHECK(sitl_allocation_add_null_dither(&alloc, 0.1, t, &dithered) == 0, "dither n=%d", n);
            double w0[4], w1[4];
            sitl_allocation_wrench(&alloc, plain.rotor_speed, w0);
            sitl_allocation_wrench(&alloc, dithered.rotor_speed, w1);
            for (int a = 0; a < 4; a++) {
                const double scale = a == 0 ? w0[0] : (a == 3 ? 1e-5 : 1e-4);
                CHECK(rel_close(w1[a], w0[a], scale, 1e-9), "n=%d t=%g wrench %d moved: %g -> %g", n, t,
                      a, w0[a], w1[a]);
            }
            for (int i = 0; i < n; i++) {
                const double u0 = plain.rotor_speed[i] * plain.rotor_speed[i];
                const double u1 = dithered.rotor_speed[i] * dithered.rotor_speed[i];
                largest_move = fmax(largest_move, fabs(u1 / u0 - 1.0));
            }
        }
        if (n == 4) {
            CHECK(largest_move < 1e-12, "quad: the dither moved a rotor (%g)", largest_move);
        } else {
            CHECK(largest_move > 0.03 && largest_move < 0.3, "n=%d: dither moved rotors by %g", n,
                  largest_move);
        }
    }
    /* near the top speed: scaled down, every rotor inside its bounds, wrench kept */
    sitl_allocation_geometry_t g;
    symmetric_geometry(&g, 6, 0.0);
    sitl_allocation_t alloc;
    sitl_allocation_init(&alloc, &g);
    double kf[SITL_ALLOC_MAX_ROTORS], km[SITL_ALLOC_MAX_ROTORS];
    spread(6, kf, km, 1);
    sitl_allocation_set_coefficients(&alloc, kf, km);
    sitl_allocation_result_t r;
    sitl_allocation_solve(&alloc, 6 * kf_nom * 0.99 * speed_max * speed_max, moment, &r);
    double w0[4], w1[4];
    sitl_allocation_wrench(&alloc, r.rotor_speed, w0);
    CHECK(sitl_allocation_add_null_dither(&alloc, 0.2, 0.4, &r) == 0, "dither at the top");
    sitl_allocation_wrench(&alloc, r.rotor_speed, w1);
    for (int i = 0; i < 6; i++) {
        CHECK(r.rotor_speed[i] <= speed_max * (1.0 + 1e-12), "rotor %d above the top speed", i);
    }
    CHECK(rel_close(w1[0], w0[0], w0[0], 1e-9), "thrust moved at the top");
    CHECK(sitl_allocation_add_null_dither(&alloc, -0.1, 0.0, &r) == -1, "negative fraction accepted");
    CHECK(sitl_allocation_add_null_dither(&alloc, NAN, 0.0, &r) == -1, "NaN fraction accepted");
}

/* sitl_allocation_solve_speeds (the flight loop's) gives sitl_allocation_solve's speeds,
 * saturation and yaw fraction bit for bit, with achieved left 0, in every saturation
 * branch: inside, yaw cut, thrust moved, roll/pitch cut, nothing fits. */
static void test_solve_speeds_same_as_solve(void)
{
    const double hover = kf_nom * 1500.0 * 1500.0;
    const double cases[][4] = {
        {4.0 * hover, 2e-4, -1.5e-4, 3e-6},   /* inside */
        {4.0 * hover, 1e-4, 0.0, 5e-3},       /* yaw cut */
        {20.0 * hover, 3e-3, 0.0, 0.0},       /* thrust moved */
        {4.0 * hover, 5e-2, -5e-2, 1e-3},     /* roll/pitch cut */
        {-1.0, 0.0, 0.0, 0.0},                /* nothing fits */
    };
    for (int n = 4; n <= 8; n += 2) {
        sitl_allocation_geometry_t g;
        symmetric_geometry(&g, n, 0.3);
        g.rotor_speed_min = 200.0;
        sitl_allocation_t alloc;
        sitl_allocation_init(&alloc, &g);
        double kf[SITL_ALLOC_MAX_ROTORS], km[SITL_ALLOC_MAX_ROTORS];
        spread(n, kf, km, n);
        CHECK(sitl_allocation_set_coefficients(&alloc, kf, km) == 0, "coefficients n=%d", n);
        unsigned saturations_seen = 0u;
        for (size_t c = 0; c < sizeof(cases) / sizeof(cases[0]); c++) {
            const double thrust = cases[c][0] * n / 4.0, moment[3] = {cases[c][1], cases[c][2], cases[c][3]};
            sitl_allocation_result_t full, speeds;
            memset(&speeds, 0xab, sizeof(speeds));
            CHECK(sitl_allocation_solve(&alloc, thrust, moment, &full) == 0, "solve n=%d case %zu", n, c);
            CHECK(sitl_allocation_solve_speeds(&alloc, thrust, moment, &speeds) == 0,
                  "solve_speeds n=%d case %zu", n, c);
            CHECK(memcmp(full.rotor_speed, speeds.rotor_speed, sizeof(full.rotor_speed)) == 0,
                  "n=%d case %zu: speeds differ", n, c);
            CHECK(full.saturation == speeds.saturation && full.yaw_fraction == speeds.yaw_fraction,
                  "n=%d case %zu: saturation %u/%u, yaw fraction %g/%g", n, c, full.saturation,
                  speeds.saturation, full.yaw_fraction, speeds.yaw_fraction);
            for (int k = 0; k < 4; k++) {
                CHECK(speeds.achieved[k] == 0.0, "n=%d case %zu: achieved %d not cleared", n, c, k);
            }
            saturations_seen |= 1u << (full.saturation & 7u);
        }
        CHECK(saturations_seen != 1u, "n=%d: no case saturated", n);
    }
    sitl_allocation_t not_ready;
    memset(&not_ready, 0, sizeof(not_ready));
    sitl_allocation_result_t r;
    const double m[3] = {0.0, 0.0, 0.0};
    CHECK(sitl_allocation_solve_speeds(&not_ready, 0.3, m, &r) == -1, "solve_speeds before coefficients");
}

int main(void)
{
    test_round_trips();
    test_null_dither_keeps_the_wrench();
    test_yaw_sacrificed_first();
    test_thrust_moved_before_roll_pitch();
    test_bad_input();
    test_solve_speeds_same_as_solve();
    printf("test_allocation: %d failure(s)\n", failures);
    return failures == 0 ? 0 : 1;
}
