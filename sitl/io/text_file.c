/* Whole-file reader (see text_file.h). */
#include "text_file.h"

#include <stdio.h>
#include <stdlib.h>

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
