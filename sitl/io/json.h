/*
 * JSON documents of the simulator: the vehicle file it reads and writes, the
 * flight summary it writes. A small tree of values with a parser and an
 * indented printer, written for the simulator so that propid_sitl links no
 * shared library besides the C library (and can link statically; see
 * docs/performance.md "SITL").
 *
 * The printer's layout: objects one member per line, indented by tabs, a tab
 * after the colon; arrays on one line, ", " between items. Numbers made with
 * sitl_json_number print as integers when they are one (within int range),
 * else with the fewest of 15 or 17 significant digits that read back to the
 * same double; non-finite numbers print as null. Numbers that must read back
 * exactly in another form are raw items formatted by the caller.
 */
#ifndef SITL_JSON_H
#define SITL_JSON_H

typedef enum {
    SITL_JSON_NULL,
    SITL_JSON_FALSE,
    SITL_JSON_TRUE,
    SITL_JSON_NUMBER,
    SITL_JSON_STRING,
    SITL_JSON_RAW, /* text printed as it is (a number formatted by the caller) */
    SITL_JSON_ARRAY,
    SITL_JSON_OBJECT
} sitl_json_type_t;

typedef struct sitl_json {
    struct sitl_json *next;  /* next item of the enclosing array or object */
    struct sitl_json *child; /* first item of an array or object */
    sitl_json_type_t type;
    double number;           /* SITL_JSON_NUMBER */
    char *text;              /* SITL_JSON_STRING (decoded) or SITL_JSON_RAW */
    char *key;               /* member name when inside an object */
} sitl_json_t;

/* Constructors: a new item, or NULL when memory runs out. */
sitl_json_t *sitl_json_object(void);
sitl_json_t *sitl_json_array(void);
sitl_json_t *sitl_json_null(void);
sitl_json_t *sitl_json_bool(int value);
sitl_json_t *sitl_json_number(double value);
sitl_json_t *sitl_json_string(const char *value);
sitl_json_t *sitl_json_raw(const char *text);

/* Append item to an object under key, or to an array. Returns item; when
 * either is NULL (an allocation failed) or the key cannot be copied, item is
 * freed and NULL returned (the document then lacks that item). */
sitl_json_t *sitl_json_add(sitl_json_t *object, const char *key, sitl_json_t *item);
sitl_json_t *sitl_json_append(sitl_json_t *array, sitl_json_t *item);

/* Free item and everything below it (NULL is allowed). */
void sitl_json_free(sitl_json_t *item);

/* Whether item exists and has that type. */
int sitl_json_is(const sitl_json_t *item, sitl_json_type_t type);

/* Lookups; NULL when absent or when the container has the wrong type. The
 * first member with the exact key. */
const sitl_json_t *sitl_json_member(const sitl_json_t *object, const char *key);
const sitl_json_t *sitl_json_item(const sitl_json_t *array, int index);
int sitl_json_size(const sitl_json_t *array); /* items of an array or object, else 0 */

/* Parse a whole NUL-terminated text (one value, surrounding white space
 * allowed). Returns the tree, or NULL with *error_at (if given) at the first
 * byte that is not valid JSON. Nesting deeper than 64 is refused. */
sitl_json_t *sitl_json_parse(const char *text, const char **error_at);

/* The indented text of root (malloc'd, NUL-terminated), or NULL when root is
 * NULL or memory runs out. */
char *sitl_json_print(const sitl_json_t *root);

#endif /* SITL_JSON_H */
