/* The vehicle most firmware tests configure: propid_config_default, then a
 * symmetric frame of `rotor_count` rotors on `arm_m` arms, the first at
 * `first_angle` rad, with the nominal coefficients (kf 5.57e-6, km 1.36e-7 in
 * the filter's units) and the diagonal inertia (3.65, 3.68, 7.03) x 1e-3 kg m^2
 * the tests share. Include after unity.h and propid.h. */
#ifndef TEST_VEHICLE_H
#define TEST_VEHICLE_H

static inline void test_vehicle_config(propid_config_t *config, uint8_t rotor_count, float arm_m,
                                       float first_angle)
{
    propid_config_default(config);
    TEST_ASSERT_EQUAL_INT(PROPID_OK, propid_config_set_symmetric(config, rotor_count, arm_m, first_angle, 1.0f,
                                                                 5.57e-6f, 1.36e-7f));
    propid_config_set_inertia_diag(config, 3.65e-3f, 3.68e-3f, 7.03e-3f);
}

#endif
