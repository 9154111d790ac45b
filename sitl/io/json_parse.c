/* JSON text -> sitl_json_t tree (RFC 8259; see json.h). */
#include "json.h"

#include <stdlib.h>
#include <string.h>

#define MAX_DEPTH 64

typedef struct {
    const char *p;
    const char *error_at;
} parser_t;

static sitl_json_t *fail(parser_t *s, sitl_json_t *partial)
{
    if (s->error_at == NULL) {
        s->error_at = s->p;
    }
    sitl_json_free(partial);
    return NULL;
}

static void skip_space(parser_t *s)
{
    while (*s->p == ' ' || *s->p == '\t' || *s->p == '\n' || *s->p == '\r') {
        s->p++;
    }
}

static int hex4(const char *p, unsigned *out)
{
    unsigned v = 0;
    for (int i = 0; i < 4; i++) {
        char c = p[i];
        v <<= 4;
        if (c >= '0' && c <= '9') {
            v |= (unsigned)(c - '0');
        } else if (c >= 'a' && c <= 'f') {
            v |= (unsigned)(c - 'a' + 10);
        } else if (c >= 'A' && c <= 'F') {
            v |= (unsigned)(c - 'A' + 10);
        } else {
            return 0;
        }
    }
    *out = v;
    return 1;
}

static size_t put_utf8(char *out, unsigned cp)
{
    if (cp < 0x80) {
        out[0] = (char)cp;
        return 1;
    }
    if (cp < 0x800) {
        out[0] = (char)(0xC0 | (cp >> 6));
        out[1] = (char)(0x80 | (cp & 0x3F));
        return 2;
    }
    if (cp < 0x10000) {
        out[0] = (char)(0xE0 | (cp >> 12));
        out[1] = (char)(0x80 | ((cp >> 6) & 0x3F));
        out[2] = (char)(0x80 | (cp & 0x3F));
        return 3;
    }
    out[0] = (char)(0xF0 | (cp >> 18));
    out[1] = (char)(0x80 | ((cp >> 12) & 0x3F));
    out[2] = (char)(0x80 | ((cp >> 6) & 0x3F));
    out[3] = (char)(0x80 | (cp & 0x3F));
    return 4;
}

/* A quoted string at s->p, decoded into a new buffer (no longer than the
 * quoted text: every escape is at least as long as what it decodes to). */
static char *parse_string(parser_t *s)
{
    const char *start = ++s->p;
    const char *end = start;
    while (*end != '"') {
        if (*end == '\0' || (unsigned char)*end < 0x20) {
            s->p = end;
            return NULL;
        }
        end += *end == '\\' && end[1] != '\0' ? 2 : 1;
    }
    char *out = malloc((size_t)(end - start) + 1);
    if (out == NULL) {
        return NULL;
    }
    size_t n = 0;
    const char *p = start;
    while (p < end) {
        if (*p != '\\') {
            out[n++] = *p++;
            continue;
        }
        s->p = p;
        char e = p[1];
        const char *simple = strchr("\"\\/bfnrt", e);
        if (e != '\0' && simple != NULL) {
            out[n++] = "\"\\/\b\f\n\r\t"[simple - "\"\\/bfnrt"];
            p += 2;
            continue;
        }
        unsigned cp;
        if (e != 'u' || !hex4(p + 2, &cp)) {
            free(out);
            return NULL;
        }
        p += 6;
        if (cp >= 0xDC00 && cp <= 0xDFFF) {
            free(out);
            return NULL;
        }
        if (cp >= 0xD800 && cp <= 0xDBFF) {
            unsigned low;
            if (p[0] != '\\' || p[1] != 'u' || !hex4(p + 2, &low) || low < 0xDC00 || low > 0xDFFF) {
                free(out);
                return NULL;
            }
            cp = 0x10000 + ((cp - 0xD800) << 10) + (low - 0xDC00);
            p += 6;
        }
        n += put_utf8(out + n, cp);
    }
    out[n] = '\0';
    s->p = end + 1;
    return out;
}

static int is_digit(char c) { return c >= '0' && c <= '9'; }

static sitl_json_t *parse_number(parser_t *s)
{
    /* The JSON grammar first (strtod alone would take hex, inf, nan, "1."). */
    const char *q = s->p;
    q += *q == '-';
    if (*q == '0') {
        q++;
    } else if (is_digit(*q)) {
        while (is_digit(*q)) q++;
    } else {
        s->p = q;
        return fail(s, NULL);
    }
    if (*q == '.') {
        if (!is_digit(*++q)) {
            s->p = q;
            return fail(s, NULL);
        }
        while (is_digit(*q)) q++;
    }
    if (*q == 'e' || *q == 'E') {
        q++;
        q += *q == '+' || *q == '-';
        if (!is_digit(*q)) {
            s->p = q;
            return fail(s, NULL);
        }
        while (is_digit(*q)) q++;
    }
    sitl_json_t *item = sitl_json_number(strtod(s->p, NULL));
    if (item == NULL) {
        return fail(s, NULL);
    }
    s->p = q;
    return item;
}

static sitl_json_t *parse_value(parser_t *s, int depth);

/* Items of an array or members of an object, after the opening bracket. */
static sitl_json_t *parse_container(parser_t *s, int depth, int is_object)
{
    sitl_json_t *c = is_object ? sitl_json_object() : sitl_json_array();
    char close = is_object ? '}' : ']';
    if (c == NULL || depth > MAX_DEPTH) {
        return fail(s, c);
    }
    s->p++;
    skip_space(s);
    if (*s->p == close) {
        s->p++;
        return c;
    }
    sitl_json_t **tail = &c->child;
    for (;;) {
        char *key = NULL;
        skip_space(s);
        if (is_object) {
            if (*s->p != '"' || (key = parse_string(s)) == NULL) {
                return fail(s, c);
            }
            skip_space(s);
            if (*s->p != ':') {
                free(key);
                return fail(s, c);
            }
            s->p++;
        }
        sitl_json_t *item = parse_value(s, depth + 1);
        if (item == NULL) {
            free(key);
            return fail(s, c);
        }
        item->key = key;
        *tail = item;
        tail = &item->next;
        skip_space(s);
        if (*s->p == ',') {
            s->p++;
            continue;
        }
        if (*s->p != close) {
            return fail(s, c);
        }
        s->p++;
        return c;
    }
}

static sitl_json_t *parse_literal(parser_t *s, const char *word, sitl_json_type_t type)
{
    size_t n = strlen(word);
    if (strncmp(s->p, word, n) != 0) {
        return fail(s, NULL);
    }
    sitl_json_t *item = type == SITL_JSON_NULL ? sitl_json_null() : sitl_json_bool(type == SITL_JSON_TRUE);
    if (item == NULL) {
        return fail(s, NULL);
    }
    s->p += n;
    return item;
}

static sitl_json_t *parse_value(parser_t *s, int depth)
{
    skip_space(s);
    switch (*s->p) {
    case '{': return parse_container(s, depth, 1);
    case '[': return parse_container(s, depth, 0);
    case '"': {
        char *text = parse_string(s);
        sitl_json_t *item = text != NULL ? sitl_json_null() : NULL;
        if (item == NULL) {
            free(text);
            return fail(s, NULL);
        }
        item->type = SITL_JSON_STRING;
        item->text = text;
        return item;
    }
    case 't': return parse_literal(s, "true", SITL_JSON_TRUE);
    case 'f': return parse_literal(s, "false", SITL_JSON_FALSE);
    case 'n': return parse_literal(s, "null", SITL_JSON_NULL);
    default: return parse_number(s);
    }
}

sitl_json_t *sitl_json_parse(const char *text, const char **error_at)
{
    parser_t s = {text, NULL};
    sitl_json_t *root = parse_value(&s, 1);
    if (root != NULL) {
        skip_space(&s);
        if (*s.p != '\0') {
            root = fail(&s, root);
        }
    }
    if (error_at != NULL) {
        *error_at = s.error_at;
    }
    return root;
}
