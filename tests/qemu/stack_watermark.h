/*
 * Stack high-water mark of a bare-metal run: the start-up code paints the free
 * stack with a pattern before main; the deepest overwritten word tells how much
 * stack the program really used (all call chains it exercised, interrupts included).
 */
#ifndef PROPID_QEMU_STACK_WATERMARK_H
#define PROPID_QEMU_STACK_WATERMARK_H

#include <stdint.h>

void propid_qemu_stack_paint(void);
uint32_t propid_qemu_stack_used(void);   /* bytes below the initial stack top */
uint32_t propid_qemu_stack_size(void);   /* bytes reserved for the stack */

#endif
