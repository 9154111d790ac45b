/*
 * Writing a cJSON document to a file (vehicle file, summary). The documents
 * are built with cJSON; numbers that must read back exactly are raw items
 * formatted by the caller.
 */
#ifndef SITL_JSON_FILE_H
#define SITL_JSON_FILE_H

#include <cjson/cJSON.h>

/* Print root (indented) into path followed by a newline, then free root.
 * Returns 0, or -1 when root is NULL (an allocation failed) or the file
 * cannot be written. */
int sitl_write_json_file(const char *path, cJSON *root);

#endif /* SITL_JSON_FILE_H */
