/* Strict recursive-descent JSON reader (see json.h). Depth is bounded. */
#include "json.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define JSON_MAX_DEPTH 32

typedef struct {
    const char *p;
    const char *start;
    char *err;
    int err_size;
    int failed;
} parser_t;

static void fail(parser_t *ps, const char *what)
{
    if (ps->failed) {
        return;
    }
    ps->failed = 1;
    int line = 1;
    for (const char *c = ps->start; c < ps->p; c++) {
        if (*c == '\n') {
            line++;
        }
    }
    if (ps->err != NULL && ps->err_size > 0) {
        snprintf(ps->err, (size_t)ps->err_size, "JSON line %d: %s", line, what);
    }
}

static void skip_ws(parser_t *ps)
{
    while (*ps->p == ' ' || *ps->p == '\t' || *ps->p == '\n' || *ps->p == '\r') {
        ps->p++;
    }
}

static void free_children(sitl_json_t *node)
{
    for (size_t i = 0; i < node->count; i++) {
        free_children(&node->children[i]);
        free(node->children[i].string);
        free(node->children[i].key);
    }
    free(node->children);
    node->children = NULL;
    node->count = 0;
}

static int parse_value(parser_t *ps, sitl_json_t *out, int depth);

static void put_utf8(char *buf, size_t *len, unsigned cp)
{
    if (cp < 0x80) {
        buf[(*len)++] = (char)cp;
    } else if (cp < 0x800) {
        buf[(*len)++] = (char)(0xC0 | (cp >> 6));
        buf[(*len)++] = (char)(0x80 | (cp & 0x3F));
    } else if (cp < 0x10000) {
        buf[(*len)++] = (char)(0xE0 | (cp >> 12));
        buf[(*len)++] = (char)(0x80 | ((cp >> 6) & 0x3F));
        buf[(*len)++] = (char)(0x80 | (cp & 0x3F));
    } else {
        buf[(*len)++] = (char)(0xF0 | (cp >> 18));
        buf[(*len)++] = (char)(0x80 | ((cp >> 12) & 0x3F));
        buf[(*len)++] = (char)(0x80 | ((cp >> 6) & 0x3F));
        buf[(*len)++] = (char)(0x80 | (cp & 0x3F));
    }
}

static int hex4(const char *s, unsigned *out)
{
    unsigned v = 0;
    for (int i = 0; i < 4; i++) {
        char c = s[i];
        v <<= 4;
        if (c >= '0' && c <= '9') {
            v |= (unsigned)(c - '0');
        } else if (c >= 'a' && c <= 'f') {
            v |= (unsigned)(c - 'a' + 10);
        } else if (c >= 'A' && c <= 'F') {
            v |= (unsigned)(c - 'A' + 10);
        } else {
            return -1;
        }
    }
    *out = v;
    return 0;
}

static char *parse_string(parser_t *ps)
{
    /* ps->p at the opening quote; the unescaped text is never longer than the raw one. */
    const char *s = ps->p + 1;
    size_t raw = 0;
    while (s[raw] != '"') {
        if (s[raw] == '\0') {
            fail(ps, "unterminated string");
            return NULL;
        }
        if (s[raw] == '\\' && s[raw + 1] != '\0') {
            raw++;
        }
        raw++;
    }
    char *buf = malloc(raw + 1);
    if (buf == NULL) {
        fail(ps, "out of memory");
        return NULL;
    }
    size_t len = 0;
    const char *c = s;
    while (*c != '"') {
        if ((unsigned char)*c < 0x20) {
            ps->p = c;
            fail(ps, "control character in string");
            free(buf);
            return NULL;
        }
        if (*c != '\\') {
            buf[len++] = *c++;
            continue;
        }
        c++;
        switch (*c) {
        case '"': buf[len++] = '"'; break;
        case '\\': buf[len++] = '\\'; break;
        case '/': buf[len++] = '/'; break;
        case 'b': buf[len++] = '\b'; break;
        case 'f': buf[len++] = '\f'; break;
        case 'n': buf[len++] = '\n'; break;
        case 'r': buf[len++] = '\r'; break;
        case 't': buf[len++] = '\t'; break;
        case 'u': {
            unsigned cp;
            if (hex4(c + 1, &cp) != 0) {
                ps->p = c;
                fail(ps, "bad \\u escape");
                free(buf);
                return NULL;
            }
            c += 4;
            /* \uXXXX is at most 3 UTF-8 bytes for 6 raw chars: fits. Surrogates kept as is. */
            put_utf8(buf, &len, cp);
            break;
        }
        default:
            ps->p = c;
            fail(ps, "bad escape in string");
            free(buf);
            return NULL;
        }
        c++;
    }
    buf[len] = '\0';
    ps->p = c + 1;
    return buf;
}

static int parse_number(parser_t *ps, sitl_json_t *out)
{
    const char *c = ps->p;
    /* Validate the JSON number grammar, then let strtod convert. */
    if (*c == '-') {
        c++;
    }
    if (*c == '0') {
        c++;
    } else if (*c >= '1' && *c <= '9') {
        while (*c >= '0' && *c <= '9') {
            c++;
        }
    } else {
        fail(ps, "bad number");
        return -1;
    }
    if (*c == '.') {
        c++;
        if (!(*c >= '0' && *c <= '9')) {
            fail(ps, "bad number");
            return -1;
        }
        while (*c >= '0' && *c <= '9') {
            c++;
        }
    }
    if (*c == 'e' || *c == 'E') {
        c++;
        if (*c == '+' || *c == '-') {
            c++;
        }
        if (!(*c >= '0' && *c <= '9')) {
            fail(ps, "bad number");
            return -1;
        }
        while (*c >= '0' && *c <= '9') {
            c++;
        }
    }
    out->type = SITL_JSON_NUMBER;
    out->number = strtod(ps->p, NULL);
    ps->p = c;
    return 0;
}

static int append_child(parser_t *ps, sitl_json_t *node, size_t *cap, sitl_json_t **slot)
{
    if (node->count == *cap) {
        size_t ncap = (*cap == 0) ? 8 : 2 * *cap;
        sitl_json_t *n = realloc(node->children, ncap * sizeof(*n));
        if (n == NULL) {
            fail(ps, "out of memory");
            return -1;
        }
        node->children = n;
        *cap = ncap;
    }
    *slot = &node->children[node->count];
    memset(*slot, 0, sizeof(**slot));
    node->count++;
    return 0;
}

static int parse_container(parser_t *ps, sitl_json_t *out, int depth, int is_object)
{
    char close = is_object ? '}' : ']';
    size_t cap = 0;
    out->type = is_object ? SITL_JSON_OBJECT : SITL_JSON_ARRAY;
    ps->p++;
    skip_ws(ps);
    if (*ps->p == close) {
        ps->p++;
        return 0;
    }
    for (;;) {
        sitl_json_t *child;
        char *key = NULL;
        skip_ws(ps);
        if (is_object) {
            if (*ps->p != '"') {
                fail(ps, "expected a member name");
                return -1;
            }
            key = parse_string(ps);
            if (key == NULL) {
                return -1;
            }
            skip_ws(ps);
            if (*ps->p != ':') {
                free(key);
                fail(ps, "expected ':'");
                return -1;
            }
            ps->p++;
        }
        if (append_child(ps, out, &cap, &child) != 0) {
            free(key);
            return -1;
        }
        child->key = key;
        if (parse_value(ps, child, depth + 1) != 0) {
            return -1;
        }
        skip_ws(ps);
        if (*ps->p == ',') {
            ps->p++;
            continue;
        }
        if (*ps->p == close) {
            ps->p++;
            return 0;
        }
        fail(ps, is_object ? "expected ',' or '}'" : "expected ',' or ']'");
        return -1;
    }
}

/* true / false / null: consume the word and fill out; 0 if it is not there. */
static int match_literal(parser_t *ps, const char *word, sitl_json_type_t type, double number,
                         sitl_json_t *out)
{
    const size_t length = strlen(word);
    if (strncmp(ps->p, word, length) != 0) {
        return 0;
    }
    out->type = type;
    out->number = number;
    ps->p += length;
    return 1;
}

static int parse_value(parser_t *ps, sitl_json_t *out, int depth)
{
    if (depth > JSON_MAX_DEPTH) {
        fail(ps, "nesting too deep");
        return -1;
    }
    skip_ws(ps);
    switch (*ps->p) {
    case '{':
        return parse_container(ps, out, depth, 1);
    case '[':
        return parse_container(ps, out, depth, 0);
    case '"':
        out->type = SITL_JSON_STRING;
        out->string = parse_string(ps);
        return out->string == NULL ? -1 : 0;
    case 't':
        if (match_literal(ps, "true", SITL_JSON_BOOL, 1.0, out)) {
            return 0;
        }
        break;
    case 'f':
        if (match_literal(ps, "false", SITL_JSON_BOOL, 0.0, out)) {
            return 0;
        }
        break;
    case 'n':
        if (match_literal(ps, "null", SITL_JSON_NULL, 0.0, out)) {
            return 0;
        }
        break;
    default:
        if (*ps->p == '-' || (*ps->p >= '0' && *ps->p <= '9')) {
            return parse_number(ps, out);
        }
        break;
    }
    fail(ps, "unexpected character");
    return -1;
}

sitl_json_t *sitl_json_parse(const char *text, char *err, int err_size)
{
    parser_t ps = {text, text, err, err_size, 0};
    sitl_json_t *root = calloc(1, sizeof(*root));
    if (root == NULL) {
        return NULL;
    }
    if (parse_value(&ps, root, 0) == 0) {
        skip_ws(&ps);
        if (*ps.p != '\0') {
            fail(&ps, "trailing characters after the document");
        }
    }
    if (ps.failed) {
        sitl_json_free(root);
        return NULL;
    }
    return root;
}

void sitl_json_free(sitl_json_t *root)
{
    if (root == NULL) {
        return;
    }
    free_children(root);
    free(root->string);
    free(root->key);
    free(root);
}

const sitl_json_t *sitl_json_get(const sitl_json_t *object, const char *key)
{
    if (object == NULL || object->type != SITL_JSON_OBJECT) {
        return NULL;
    }
    for (size_t i = 0; i < object->count; i++) {
        if (object->children[i].key != NULL && strcmp(object->children[i].key, key) == 0) {
            return &object->children[i];
        }
    }
    return NULL;
}

char *sitl_read_file(const char *path, size_t max_bytes)
{
    FILE *f = fopen(path, "rb");
    if (f == NULL) {
        return NULL;
    }
    size_t cap = 4096, len = 0;
    char *buf = malloc(cap);
    while (buf != NULL) {
        if (len + 1 >= cap) {
            if (cap >= max_bytes) {
                free(buf);
                buf = NULL;
                break;
            }
            char *n = realloc(buf, cap * 2);
            if (n == NULL) {
                free(buf);
                buf = NULL;
                break;
            }
            buf = n;
            cap *= 2;
        }
        size_t got = fread(buf + len, 1, cap - 1 - len, f);
        len += got;
        if (got == 0) {
            buf[len] = '\0';
            break;
        }
    }
    fclose(f);
    return buf;
}
