/*
 * Writing a JSON document (json.h) to a file (vehicle file, summary). Numbers
 * that must read back exactly are raw items formatted by the caller.
 */
#ifndef SITL_JSON_FILE_H
#define SITL_JSON_FILE_H

#include "json.h"

/* Print root (indented) into path followed by a newline, then free root.
 * Returns 0, or -1 when root is NULL (an allocation failed) or the file
 * cannot be written. */
int sitl_write_json_file(const char *path, sitl_json_t *root);

#endif /* SITL_JSON_FILE_H */
