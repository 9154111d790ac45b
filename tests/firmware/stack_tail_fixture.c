/*
 * Call-graph check self-test (stack_report.py): two entry points above the
 * same deep callee, one reaching it by a tail call (its own frame released
 * first), one by a call whose result it still uses (both frames stacked).
 * Never linked into anything.
 */
#include <stdint.h>

uint32_t propid_fixture_deep(volatile uint32_t *value);
uint32_t propid_fixture_tail_entry(volatile uint32_t *value);
uint32_t propid_fixture_call_entry(volatile uint32_t *value);

/* A 256 B frame. */
__attribute__((noinline)) uint32_t propid_fixture_deep(volatile uint32_t *value)
{
    volatile uint32_t scratch[64];
    for (uint32_t i = 0; i < 64u; ++i) {
        scratch[i] = *value + i;
    }
    return scratch[*value & 63u];
}

/* A 128 B frame, then a tail call. */
uint32_t propid_fixture_tail_entry(volatile uint32_t *value)
{
    volatile uint32_t scratch[32];
    for (uint32_t i = 0; i < 32u; ++i) {
        scratch[i] = *value ^ i;
    }
    *value = scratch[*value & 31u];
    return propid_fixture_deep(value);
}

/* The same frame, then a call. */
uint32_t propid_fixture_call_entry(volatile uint32_t *value)
{
    volatile uint32_t scratch[32];
    for (uint32_t i = 0; i < 32u; ++i) {
        scratch[i] = *value ^ i;
    }
    *value = scratch[*value & 31u];
    return propid_fixture_deep(value) + scratch[0];
}
