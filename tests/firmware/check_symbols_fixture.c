/*
 * Deliberately bad object for the forbidden-symbol check's self-test: it uses
 * the heap and double-precision arithmetic, so check_symbols.sh must reject it.
 * Never linked into anything.
 */
#include <stdlib.h>

float propid_fixture_double_math(float value);
void *propid_fixture_heap(size_t bytes);

float propid_fixture_double_math(float value)
{
    double widened = value; /* __aeabi_f2d */
    return (float)(widened * 1.000001); /* __aeabi_dmul, __aeabi_d2f */
}

void *propid_fixture_heap(size_t bytes)
{
    return malloc(bytes);
}

/* Recursion: the call-graph check must report it. Two calls, so the compiler
 * cannot turn it into a loop. */
unsigned propid_fixture_recursive(unsigned depth);

unsigned propid_fixture_recursive(unsigned depth)
{
    if (depth < 2u) {
        return depth;
    }
    return propid_fixture_recursive(depth - 1u) + propid_fixture_recursive(depth - 2u);
}
