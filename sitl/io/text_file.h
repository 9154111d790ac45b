/*
 * Read a whole (small) file into memory: the vehicle file before JSON
 * parsing, and logs the tests compare. Desktop only (uses malloc).
 */
#ifndef SITL_TEXT_FILE_H
#define SITL_TEXT_FILE_H

#include <stddef.h>

/* Read a whole file into a NUL-terminated buffer (caller frees), or NULL when
 * it cannot be read or is longer than max_bytes. */
char *sitl_read_file(const char *path, size_t max_bytes);

#endif /* SITL_TEXT_FILE_H */
