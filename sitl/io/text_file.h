/*
 * A small strict JSON reader (RFC 8259) for vehicle files: parses a whole
 * document into a tree of nodes. Desktop only (uses malloc).
 */
#ifndef SITL_JSON_H
#define SITL_JSON_H

#include <stddef.h>

typedef enum {
    SITL_JSON_NULL,
    SITL_JSON_BOOL,
    SITL_JSON_NUMBER,
    SITL_JSON_STRING,
    SITL_JSON_ARRAY,
    SITL_JSON_OBJECT,
} sitl_json_type_t;

typedef struct sitl_json sitl_json_t;
struct sitl_json {
    sitl_json_type_t type;
    double number;           /* NUMBER; BOOL as 0/1 */
    char *string;            /* STRING value (UTF-8, unescaped) */
    char *key;               /* member name when inside an object */
    sitl_json_t *children;   /* ARRAY / OBJECT members */
    size_t count;
};

/* Parse text; returns the root or NULL with a message (with line number) in err. */
sitl_json_t *sitl_json_parse(const char *text, char *err, int err_size);
void sitl_json_free(sitl_json_t *root);

/* Member of an object by name, or NULL. */
const sitl_json_t *sitl_json_get(const sitl_json_t *object, const char *key);

/* Read a whole file into a NUL-terminated buffer (caller frees), or NULL. */
char *sitl_read_file(const char *path, size_t max_bytes);

#endif /* SITL_JSON_H */
