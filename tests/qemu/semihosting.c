/*
 * ARM semihosting calls: `bkpt 0xAB` with the operation in r0 and its argument
 * in r1 (M-profile). QEMU services them on the host.
 */
#include "semihosting.h"

#include <stdint.h>

enum {
    SEMIHOST_SYS_WRITE0 = 0x04,        /* write a NUL-terminated string */
    SEMIHOST_SYS_EXIT = 0x18,
    SEMIHOST_SYS_EXIT_EXTENDED = 0x20, /* exit with a status code (32-bit ABI) */
};

/* Reason code meaning "the application finished"; the subcode is its status. */
#define SEMIHOST_ADP_STOPPED_APPLICATION_EXIT 0x20026u

static int semihost_call(int operation, const void *argument)
{
    register int r0 __asm__("r0") = operation;
    register const void *r1 __asm__("r1") = argument;
    __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

/* One trap per line rather than per character keeps Unity's output fast. */
static char line_buffer[128];
static unsigned line_length;

void propid_qemu_flush(void)
{
    if (line_length == 0u) {
        return;
    }
    line_buffer[line_length] = '\0';
    (void)semihost_call(SEMIHOST_SYS_WRITE0, line_buffer);
    line_length = 0u;
}

void propid_qemu_putc(int c)
{
    line_buffer[line_length++] = (char)c;
    if (c == '\n' || line_length == sizeof line_buffer - 1u) {
        propid_qemu_flush();
    }
}

void propid_qemu_puts(const char *text)
{
    while (*text != '\0') {
        propid_qemu_putc(*text++);
    }
}

void propid_qemu_exit(int status)
{
    /* A status that does not fit QEMU's 8-bit exit code must not wrap to 0. */
    uint32_t code = (status < 0) ? 1u : (status > 255) ? 255u : (uint32_t)status;
    uint32_t block[2] = {SEMIHOST_ADP_STOPPED_APPLICATION_EXIT, code};
    propid_qemu_flush();
    (void)semihost_call(SEMIHOST_SYS_EXIT_EXTENDED, block);
    /* Hosts without SYS_EXIT_EXTENDED: plain exit still stops the emulator
     * (status 0 only for success). */
    (void)semihost_call(SEMIHOST_SYS_EXIT,
                        (const void *)(uintptr_t)(code == 0u ? SEMIHOST_ADP_STOPPED_APPLICATION_EXIT : 0u));
    for (;;) {
    }
}

/* newlib hooks, so printf/puts/abort/exit in a test behave under QEMU. */
int _write(int fd, const char *data, int length);
void _exit(int status);

int _write(int fd, const char *data, int length)
{
    (void)fd;
    for (int i = 0; i < length; ++i) {
        propid_qemu_putc(data[i]);
    }
    return length;
}

void _exit(int status)
{
    propid_qemu_exit(status);
}
