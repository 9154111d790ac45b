/* JSON document tree and its printer (see json.h); the parser is json_parse.c. */
#include "json.h"

#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static char *copy_text(const char *s)
{
    size_t n = strlen(s) + 1;
    char *c = malloc(n);
    if (c != NULL) {
        memcpy(c, s, n);
    }
    return c;
}

static sitl_json_t *new_item(sitl_json_type_t type)
{
    sitl_json_t *item = calloc(1, sizeof *item);
    if (item != NULL) {
        item->type = type;
    }
    return item;
}

sitl_json_t *sitl_json_object(void) { return new_item(SITL_JSON_OBJECT); }
sitl_json_t *sitl_json_array(void) { return new_item(SITL_JSON_ARRAY); }
sitl_json_t *sitl_json_null(void) { return new_item(SITL_JSON_NULL); }
sitl_json_t *sitl_json_bool(int value) { return new_item(value ? SITL_JSON_TRUE : SITL_JSON_FALSE); }

sitl_json_t *sitl_json_number(double value)
{
    sitl_json_t *item = new_item(SITL_JSON_NUMBER);
    if (item != NULL) {
        item->number = value;
    }
    return item;
}

static sitl_json_t *text_item(sitl_json_type_t type, const char *text)
{
    sitl_json_t *item = new_item(type);
    if (item != NULL && (item->text = copy_text(text != NULL ? text : "")) == NULL) {
        free(item);
        item = NULL;
    }
    return item;
}

sitl_json_t *sitl_json_string(const char *value) { return text_item(SITL_JSON_STRING, value); }
sitl_json_t *sitl_json_raw(const char *text) { return text_item(SITL_JSON_RAW, text); }

void sitl_json_free(sitl_json_t *item)
{
    /* Siblings by iteration; children by recursion, as deep as the document
     * (the parser refuses nesting deeper than 64). */
    while (item != NULL) {
        sitl_json_t *next = item->next;
        sitl_json_free(item->child);
        free(item->text);
        free(item->key);
        free(item);
        item = next;
    }
}

static void append_child(sitl_json_t *parent, sitl_json_t *item)
{
    sitl_json_t **tail = &parent->child;
    while (*tail != NULL) {
        tail = &(*tail)->next;
    }
    *tail = item;
}

sitl_json_t *sitl_json_add(sitl_json_t *object, const char *key, sitl_json_t *item)
{
    if (object == NULL || item == NULL || object->type != SITL_JSON_OBJECT ||
        (item->key = copy_text(key)) == NULL) {
        sitl_json_free(item);
        return NULL;
    }
    append_child(object, item);
    return item;
}

sitl_json_t *sitl_json_append(sitl_json_t *array, sitl_json_t *item)
{
    if (array == NULL || item == NULL || array->type != SITL_JSON_ARRAY) {
        sitl_json_free(item);
        return NULL;
    }
    append_child(array, item);
    return item;
}

int sitl_json_is(const sitl_json_t *item, sitl_json_type_t type)
{
    return item != NULL && item->type == type;
}

const sitl_json_t *sitl_json_member(const sitl_json_t *object, const char *key)
{
    if (object == NULL || object->type != SITL_JSON_OBJECT) {
        return NULL;
    }
    for (const sitl_json_t *c = object->child; c != NULL; c = c->next) {
        if (c->key != NULL && strcmp(c->key, key) == 0) {
            return c;
        }
    }
    return NULL;
}

const sitl_json_t *sitl_json_item(const sitl_json_t *array, int index)
{
    if (array == NULL || array->type != SITL_JSON_ARRAY || index < 0) {
        return NULL;
    }
    const sitl_json_t *c = array->child;
    for (int i = 0; c != NULL && i < index; i++) {
        c = c->next;
    }
    return c;
}

int sitl_json_size(const sitl_json_t *array)
{
    if (array == NULL || (array->type != SITL_JSON_ARRAY && array->type != SITL_JSON_OBJECT)) {
        return 0;
    }
    int n = 0;
    for (const sitl_json_t *c = array->child; c != NULL; c = c->next) {
        n++;
    }
    return n;
}

/* ---- printer ---- */

typedef struct {
    char *text;
    size_t length;
    size_t capacity;
    int failed;
} out_t;

static void put(out_t *o, const char *s, size_t n)
{
    if (o->failed) {
        return;
    }
    if (o->length + n + 1 > o->capacity) {
        size_t capacity = o->capacity * 2 > o->length + n + 1 ? o->capacity * 2 : o->length + n + 1;
        char *grown = realloc(o->text, capacity);
        if (grown == NULL) {
            o->failed = 1;
            return;
        }
        o->text = grown;
        o->capacity = capacity;
    }
    memcpy(o->text + o->length, s, n);
    o->length += n;
    o->text[o->length] = '\0';
}

static void put_str(out_t *o, const char *s) { put(o, s, strlen(s)); }

static void put_tabs(out_t *o, int depth)
{
    for (int i = 0; i < depth; i++) {
        put(o, "\t", 1);
    }
}

static void put_quoted(out_t *o, const char *s)
{
    put(o, "\"", 1);
    for (const unsigned char *p = (const unsigned char *)s; *p != '\0'; p++) {
        char esc[8];
        switch (*p) {
        case '"': put_str(o, "\\\""); break;
        case '\\': put_str(o, "\\\\"); break;
        case '\b': put_str(o, "\\b"); break;
        case '\f': put_str(o, "\\f"); break;
        case '\n': put_str(o, "\\n"); break;
        case '\r': put_str(o, "\\r"); break;
        case '\t': put_str(o, "\\t"); break;
        default:
            if (*p < 0x20) {
                snprintf(esc, sizeof esc, "\\u%04x", (unsigned)*p);
                put_str(o, esc);
            } else {
                put(o, (const char *)p, 1);
            }
        }
    }
    put(o, "\"", 1);
}

static void put_number(out_t *o, double x)
{
    char buf[32];
    if (!isfinite(x)) {
        put_str(o, "null");
        return;
    }
    if (x > (double)INT_MIN && x < (double)INT_MAX && x == (double)(int)x) {
        snprintf(buf, sizeof buf, "%d", (int)x);
    } else {
        snprintf(buf, sizeof buf, "%1.15g", x);
        if (strtod(buf, NULL) != x) {
            snprintf(buf, sizeof buf, "%1.17g", x);
        }
    }
    put_str(o, buf);
}

/* depth: the nesting level of item's own members (1 for the root's). */
static void put_value(out_t *o, const sitl_json_t *item, int depth)
{
    switch (item->type) {
    case SITL_JSON_NULL: put_str(o, "null"); break;
    case SITL_JSON_FALSE: put_str(o, "false"); break;
    case SITL_JSON_TRUE: put_str(o, "true"); break;
    case SITL_JSON_NUMBER: put_number(o, item->number); break;
    case SITL_JSON_STRING: put_quoted(o, item->text); break;
    case SITL_JSON_RAW: put_str(o, item->text); break;
    case SITL_JSON_ARRAY:
        put(o, "[", 1);
        for (const sitl_json_t *c = item->child; c != NULL; c = c->next) {
            put_value(o, c, depth + 1);
            if (c->next != NULL) {
                put(o, ", ", 2);
            }
        }
        put(o, "]", 1);
        break;
    case SITL_JSON_OBJECT:
        put(o, "{\n", 2);
        for (const sitl_json_t *c = item->child; c != NULL; c = c->next) {
            put_tabs(o, depth);
            put_quoted(o, c->key != NULL ? c->key : "");
            put(o, ":\t", 2);
            put_value(o, c, depth + 1);
            put_str(o, c->next != NULL ? ",\n" : "\n");
        }
        put_tabs(o, depth - 1);
        put(o, "}", 1);
        break;
    }
}

char *sitl_json_print(const sitl_json_t *root)
{
    if (root == NULL) {
        return NULL;
    }
    out_t o = {NULL, 0, 0, 0};
    put_value(&o, root, 1);
    put(&o, "", 0);
    if (o.failed) {
        free(o.text);
        return NULL;
    }
    return o.text;
}
