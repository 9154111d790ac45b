/*
 * Vehicles: preset layouts (plus: rotor 1 on +x, counter-clockwise, yaw signs
 * +,-,+,-; X rotated 45 degrees), the flight-log v1 vehicle JSON round trip,
 * and clear errors for files the SITL cannot fly.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "sitl_math.h"
#include "unity.h"
#include "vehicle.h"

void setUp(void)
{
}

void tearDown(void)
{
}

static const char *tmp_path(const char *name)
{
    static char buf[1024];
    snprintf(buf, sizeof(buf), "%s/%s", PROPID_SITL_TEST_TMP, name);
    return buf;
}

static void write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    TEST_ASSERT_NOT_NULL(f);
    fputs(text, f);
    fclose(f);
}

static void test_plus_preset_layout(void)
{
    sitl_vehicle_t v;
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset("hummingbird-plus", &v));
    const double expect[4][2] = {{0.17, 0}, {0, 0.17}, {-0.17, 0}, {0, -0.17}};
    const double signs[4] = {1, -1, 1, -1};
    for (int i = 0; i < 4; i++) {
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, expect[i][0], v.rotor[i].position[0]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, expect[i][1], v.rotor[i].position[1]);
        TEST_ASSERT_EQUAL_DOUBLE(signs[i], v.rotor[i].yaw_sign);
        TEST_ASSERT_EQUAL_DOUBLE(5.57e-6, v.rotor[i].thrust_coeff);
        TEST_ASSERT_EQUAL_DOUBLE(1.36e-7, v.rotor[i].drag_coeff);
    }
    TEST_ASSERT_EQUAL_DOUBLE(0.5, v.mass);
    TEST_ASSERT_EQUAL_DOUBLE(0.005, v.motor_time_constant);
    TEST_ASSERT_EQUAL_DOUBLE(1500.0, v.rotor_speed_max);
    TEST_ASSERT_EQUAL_INT(-1, sitl_vehicle_preset("no-such-quad", &v));
}

static void test_x_preset_is_rotated_45_degrees(void)
{
    sitl_vehicle_t plus, x;
    sitl_vehicle_preset("crazyflie-plus", &plus);
    sitl_vehicle_preset("crazyflie-x", &x);
    double c = cos(SITL_PI / 4), s = sin(SITL_PI / 4);
    for (int i = 0; i < 4; i++) {
        double px = plus.rotor[i].position[0], py = plus.rotor[i].position[1];
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, c * px - s * py, x.rotor[i].position[0]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, s * px + c * py, x.rotor[i].position[1]);
        TEST_ASSERT_EQUAL_DOUBLE(plus.rotor[i].yaw_sign, x.rotor[i].yaw_sign);
    }
    TEST_ASSERT_EQUAL_DOUBLE(1.43e-5, x.inertia[0][0]);
    TEST_ASSERT_EQUAL_DOUBLE(2.89e-5, x.inertia[2][2]);
    TEST_ASSERT_EQUAL_DOUBLE(0.072, x.motor_time_constant);
}

/* Hexa and octo presets: same hover speed as the quad (mass x N/4), balanced
 * yaw signs, propellers that do not overlap, a valid vehicle. */
static void test_multirotor_presets(void)
{
    const char *names[] = {"hexa-plus", "hexa-x", "octo-plus", "octo-x"};
    const int counts[] = {6, 6, 8, 8};
    sitl_vehicle_t quad;
    sitl_vehicle_preset("crazyflie-plus", &quad);
    for (int k = 0; k < 4; k++) {
        sitl_vehicle_t v;
        char err[128];
        TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_preset(names[k], &v));
        TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_vehicle_check(&v, err, (int)sizeof(err)), err);
        TEST_ASSERT_EQUAL_INT(counts[k], v.rotor_count);
        TEST_ASSERT_DOUBLE_WITHIN(1e-15, quad.mass * counts[k] / 4.0, v.mass);
        double yaw_sum = 0.0;
        for (int i = 0; i < v.rotor_count; i++) {
            yaw_sum += v.rotor[i].yaw_sign;
            const sitl_rotor_t *a = &v.rotor[i], *b = &v.rotor[(i + 1) % v.rotor_count];
            double gap = hypot(a->position[0] - b->position[0], a->position[1] - b->position[1]);
            TEST_ASSERT_TRUE(gap > 2.0 * v.rotor_radius);
        }
        TEST_ASSERT_EQUAL_DOUBLE(0.0, yaw_sum);
        /* plus: rotor 1 on +x; X: rotated by half the rotor spacing */
        double angle = atan2(v.rotor[0].position[1], v.rotor[0].position[0]);
        TEST_ASSERT_DOUBLE_WITHIN(1e-12, (k % 2) ? SITL_PI / counts[k] : 0.0, angle);
    }
}

static void test_json_round_trip(void)
{
    sitl_vehicle_t v, w;
    sitl_vehicle_preset("hummingbird-x", &v);
    v.rotor[2].thrust_coeff = 6e-6; /* per-rotor list */
    const char *path = tmp_path("roundtrip.vehicle.json");
    TEST_ASSERT_EQUAL_INT(0, sitl_vehicle_write_json(path, &v, "note with \"quotes\"\n"));
    memset(&w, 0, sizeof(w));
    w.motor_time_constant = 0.01;
    w.rotor_speed_max = 1000.0;
    char err[256];
    TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_vehicle_load_json(path, &w, err, 256), err);
    TEST_ASSERT_EQUAL_STRING("hummingbird-x", w.name);
    TEST_ASSERT_EQUAL_INT(4, w.rotor_count);
    TEST_ASSERT_EQUAL_DOUBLE(v.mass, w.mass);
    for (int i = 0; i < 4; i++) {
        for (int k = 0; k < 3; k++) {
            TEST_ASSERT_DOUBLE_WITHIN(1e-12, v.rotor[i].position[k], w.rotor[i].position[k]);
        }
        TEST_ASSERT_EQUAL_DOUBLE(v.rotor[i].yaw_sign, w.rotor[i].yaw_sign);
        TEST_ASSERT_DOUBLE_WITHIN(1e-18, v.rotor[i].thrust_coeff, w.rotor[i].thrust_coeff);
        TEST_ASSERT_DOUBLE_WITHIN(1e-18, v.rotor[i].drag_coeff, w.rotor[i].drag_coeff);
    }
    TEST_ASSERT_DOUBLE_WITHIN(1e-12, v.inertia[1][1], w.inertia[1][1]);
    TEST_ASSERT_DOUBLE_WITHIN(1e-15, v.rotor_inertia, w.rotor_inertia);
    TEST_ASSERT_EQUAL_DOUBLE(0.01, w.motor_time_constant); /* not in the format: kept */
}

static void test_json_full_inertia_and_hexa(void)
{
    const char *path = tmp_path("hexa.vehicle.json");
    write_text(path,
               "{\"name\": \"hexa\", \"mass\": 1.2,\n"
               " \"inertia\": [[0.01, 0.0001, 0], [0.0001, 0.012, 0], [0, 0, 0.02]],\n"
               " \"rotors\": [\n"
               "  {\"position\": [0.25, 0, 0], \"yaw_sign\": 1},\n"
               "  {\"position\": [0.125, 0.2165, 0], \"yaw_sign\": -1},\n"
               "  {\"position\": [-0.125, 0.2165, 0], \"yaw_sign\": 1},\n"
               "  {\"position\": [-0.25, 0, 0], \"yaw_sign\": -1},\n"
               "  {\"position\": [-0.125, -0.2165, 0], \"yaw_sign\": 1},\n"
               "  {\"position\": [0.125, -0.2165, 0], \"yaw_sign\": -1}],\n"
               " \"kf_nominal\": 1e-5, \"km_nominal\": [2e-7, 2e-7, 2e-7, 2e-7, 2e-7, 2.1e-7],\n"
               " \"rotor_radius\": null, \"rotor_inertia\": null, \"notes\": \"\\u00e9t\\u00e9\"}\n");
    sitl_vehicle_t v;
    memset(&v, 0, sizeof(v));
    v.motor_time_constant = 0.03;
    v.rotor_speed_max = 1e6;
    char err[256];
    TEST_ASSERT_EQUAL_INT_MESSAGE(0, sitl_vehicle_load_json(path, &v, err, 256), err);
    TEST_ASSERT_EQUAL_INT(6, v.rotor_count);
    TEST_ASSERT_EQUAL_DOUBLE(0.0001, v.inertia[0][1]);
    TEST_ASSERT_EQUAL_DOUBLE(2.1e-7, v.rotor[5].drag_coeff);
    TEST_ASSERT_DOUBLE_WITHIN(1e-4, 0.25, v.arm_length);
}

static void expect_error(const char *name, const char *text, const char *needle)
{
    const char *path = tmp_path(name);
    write_text(path, text);
    sitl_vehicle_t v;
    memset(&v, 0, sizeof(v));
    v.motor_time_constant = 0.03;
    v.rotor_speed_max = 1e6;
    char err[256] = "";
    TEST_ASSERT_EQUAL_INT(-1, sitl_vehicle_load_json(path, &v, err, 256));
    TEST_ASSERT_NOT_NULL_MESSAGE(strstr(err, needle), err);
}

static void test_json_errors_are_clear(void)
{
    const char *rotors = "\"rotors\": [{\"position\": [0.1, 0, 0], \"yaw_sign\": 1}]";
    char text[512];
    snprintf(text, sizeof(text),
             "{\"mass\": null, \"inertia\": [1e-3, 1e-3, 2e-3], %s, \"kf_nominal\": 1e-6, "
             "\"km_nominal\": 1e-8}", rotors);
    expect_error("nomass.json", text, "'mass' is missing or null");
    snprintf(text, sizeof(text),
             "{\"mass\": 0.5, \"inertia\": [1e-3, 1e-3, 2e-3], %s, \"km_nominal\": 1e-8}", rotors);
    expect_error("nokf.json", text, "'kf_nominal'");
    snprintf(text, sizeof(text),
             "{\"mass\": 0.5, \"inertia\": null, %s, \"kf_nominal\": 1e-6, \"km_nominal\": 1e-8}",
             rotors);
    expect_error("noinertia.json", text, "'inertia'");
    expect_error("broken.json", "{\"mass\": 0.5,\n \"inertia\": [1, 2,, 3]}", "JSON line 2");
    expect_error("missing.json", "{\"mass\": 0.5, \"inertia\": [1e-3, 1e-3, 2e-3], "
                                 "\"rotors\": [{\"position\": [0.1, 0, 0], \"yaw_sign\": 2}], "
                                 "\"kf_nominal\": 1e-6, \"km_nominal\": 1e-8}",
                 "yaw_sign");
    sitl_vehicle_t v;
    char err[256];
    TEST_ASSERT_EQUAL_INT(-1, sitl_vehicle_load_json(tmp_path("does-not-exist.json"), &v, err,
                                                     256));
    TEST_ASSERT_NOT_NULL(strstr(err, "cannot read"));
}

int main(void)
{
    UNITY_BEGIN();
    RUN_TEST(test_plus_preset_layout);
    RUN_TEST(test_x_preset_is_rotated_45_degrees);
    RUN_TEST(test_multirotor_presets);
    RUN_TEST(test_json_round_trip);
    RUN_TEST(test_json_full_inertia_and_hexa);
    RUN_TEST(test_json_errors_are_clear);
    return UNITY_END();
}
