/* Unity configuration for the target build: output through semihosting. */
#ifndef PROPID_QEMU_UNITY_CONFIG_H
#define PROPID_QEMU_UNITY_CONFIG_H

#define UNITY_OUTPUT_CHAR(c) propid_qemu_putc(c)
#define UNITY_OUTPUT_CHAR_HEADER_DECLARATION propid_qemu_putc(int)
#define UNITY_OUTPUT_FLUSH() propid_qemu_flush()
#define UNITY_OUTPUT_FLUSH_HEADER_DECLARATION propid_qemu_flush(void)

#endif
