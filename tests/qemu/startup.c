/*
 * Cortex-M4F start-up for QEMU's mps2-an386 board: vector table, reset handler
 * (FPU on, .data copied, .bss zeroed, main called) and fault handlers. main's
 * return value leaves through semihosting as QEMU's exit status, so a ctest of
 * the ELF passes exactly when the program returned 0.
 */
#include <stdint.h>

#include "semihosting.h"
#include "stack_watermark.h"

int main(void);

/* Symbols from the linker script. */
extern uint32_t __stack_top;
extern uint32_t __data_load;
extern uint32_t __data_start;
extern uint32_t __data_end;
extern uint32_t __bss_start;
extern uint32_t __bss_end;

void propid_qemu_reset(void);
void propid_qemu_start(void);
void propid_qemu_fault(void);
void propid_qemu_unexpected(void);

typedef void (*propid_qemu_vector_t)(void);

/* Core exceptions only; the tests use no peripheral interrupts. */
__attribute__((section(".vectors"), used))
const propid_qemu_vector_t propid_qemu_vectors[16] = {
    (propid_qemu_vector_t)&__stack_top,
    propid_qemu_reset,       /* Reset */
    propid_qemu_unexpected,  /* NMI */
    propid_qemu_fault,       /* HardFault */
    propid_qemu_fault,       /* MemManage */
    propid_qemu_fault,       /* BusFault */
    propid_qemu_fault,       /* UsageFault */
    0, 0, 0, 0,
    propid_qemu_unexpected,  /* SVCall */
    propid_qemu_unexpected,  /* DebugMonitor */
    0,
    propid_qemu_unexpected,  /* PendSV */
    propid_qemu_unexpected,  /* SysTick */
};

/* The FPU must be on before the first floating-point instruction, and the
 * compiler may emit one anywhere in C code, so this part is assembly:
 * CPACR (0xE000ED88) bits 20..23 give CP10/CP11 full access. */
__attribute__((naked, noreturn)) void propid_qemu_reset(void)
{
    __asm__ volatile(
        "ldr r0, =0xE000ED88\n"
        "ldr r1, [r0]\n"
        "orr r1, r1, #(0xF << 20)\n"
        "str r1, [r0]\n"
        "dsb\n"
        "isb\n"
        "b propid_qemu_start\n");
}

__attribute__((noreturn)) void propid_qemu_start(void)
{
    /* volatile: keep these loops from being turned into memcpy/memset calls. */
    const uint32_t *source = &__data_load;
    for (volatile uint32_t *word = &__data_start; word < &__data_end; ++word) {
        *word = *source++;
    }
    for (volatile uint32_t *word = &__bss_start; word < &__bss_end; ++word) {
        *word = 0u;
    }
    propid_qemu_stack_paint();
    propid_qemu_exit(main());
}

static void print_hex(const char *label, uint32_t value)
{
    static const char digits[] = "0123456789abcdef";
    propid_qemu_puts(label);
    propid_qemu_puts("0x");
    for (int shift = 28; shift >= 0; shift -= 4) {
        propid_qemu_putc(digits[(value >> (unsigned)shift) & 0xFu]);
    }
    propid_qemu_putc('\n');
}

/* A fault ends the run with a non-zero status (and says where) instead of hanging
 * until the ctest timeout. */
void propid_qemu_fault(void)
{
    volatile const uint32_t *scb = (volatile const uint32_t *)0xE000ED00u;
    propid_qemu_puts("\n*** FAULT\n");
    print_hex("CFSR  ", scb[0x28 / 4]);
    print_hex("HFSR  ", scb[0x2C / 4]);
    print_hex("MMFAR ", scb[0x34 / 4]);
    print_hex("BFAR  ", scb[0x38 / 4]);
    propid_qemu_exit(3);
}

void propid_qemu_unexpected(void)
{
    propid_qemu_puts("\n*** unexpected exception\n");
    propid_qemu_exit(4);
}
