/*
 * Minimal ARM semihosting for bare-metal programs run under qemu-system-arm
 * (-semihosting-config enable=on,target=native): console output and exit
 * status. Used by the Unity tests and the port example in the target build.
 */
#ifndef PROPID_QEMU_SEMIHOSTING_H
#define PROPID_QEMU_SEMIHOSTING_H

/* Buffered console output; a line is written when '\n' arrives or the buffer fills. */
void propid_qemu_putc(int c);
void propid_qemu_puts(const char *text);
void propid_qemu_flush(void);

/* Flush, then stop QEMU with this exit status (0..255; anything else -> 255 or 1). */
void propid_qemu_exit(int status) __attribute__((noreturn));

#endif /* PROPID_QEMU_SEMIHOSTING_H */
