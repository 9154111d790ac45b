/*
 * Output paths of propid_sitl (--log, --summary-json): checked before the
 * flight so a bad path fails at once, not after minutes of flying, and their
 * missing parent directories created when the file is written (the host
 * tools' rule: `mkdir -p` and write). Desktop only (POSIX).
 */
#ifndef SITL_OUTPUT_PATH_H
#define SITL_OUTPUT_PATH_H

#include <stddef.h>

/* 0 when `path` can be written once its missing parents are created: no
 * component of it is an existing non-directory, it is not itself a directory,
 * and the nearest existing directory above it is writable. Otherwise -1 with
 * the reason in `why` (one line). Creates nothing. */
int sitl_output_path_check(const char *path, char *why, size_t why_size);

/* Create the missing parent directories of `path` (mkdir -p of its
 * directory). 0 on success, -1 with the reason in `why`. */
int sitl_output_path_make_parents(const char *path, char *why, size_t why_size);

#endif /* SITL_OUTPUT_PATH_H */
