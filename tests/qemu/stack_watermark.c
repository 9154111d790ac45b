#include "stack_watermark.h"

extern uint32_t __stack_top;
extern uint32_t __stack_limit;

#define STACK_PAINT 0xC0FFEE11u

void propid_qemu_stack_paint(void)
{
    uintptr_t sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    /* Leave this function's own frame (and some margin) untouched. */
    for (volatile uint32_t *word = &__stack_limit; (uintptr_t)word + 64u < sp; ++word) {
        *word = STACK_PAINT;
    }
}

uint32_t propid_qemu_stack_used(void)
{
    const volatile uint32_t *word = &__stack_limit;
    while (word < &__stack_top && *word == STACK_PAINT) {
        ++word;
    }
    return (uint32_t)((uintptr_t)&__stack_top - (uintptr_t)word);
}

uint32_t propid_qemu_stack_size(void)
{
    return (uint32_t)((uintptr_t)&__stack_top - (uintptr_t)&__stack_limit);
}
