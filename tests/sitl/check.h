/*
 * Minimal assertion helper shared by the plain-C SITL tests (no framework):
 * CHECK(cond, printf-style message) prints each failure with its location and
 * counts it in `failures`; the test's main() returns non-zero when any failed.
 * Include once per test executable (it defines the file-local counter).
 */
#ifndef PROPID_TESTS_SITL_CHECK_H
#define PROPID_TESTS_SITL_CHECK_H

#include <stdio.h>

static int failures;

#define CHECK(cond, ...)                                                                           \
    do {                                                                                           \
        if (!(cond)) {                                                                             \
            failures++;                                                                            \
            printf("FAIL %s:%d: ", __FILE__, __LINE__);                                            \
            printf(__VA_ARGS__);                                                                   \
            printf("\n");                                                                          \
        }                                                                                          \
    } while (0)

#endif
