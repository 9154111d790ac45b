/* cJSON document -> file (see json_file.h). */
#include "json_file.h"

#include <stdio.h>
#include <stdlib.h>

int sitl_write_json_file(const char *path, cJSON *root)
{
    char *text = root != NULL ? cJSON_Print(root) : NULL;
    cJSON_Delete(root);
    if (text == NULL) {
        return -1;
    }
    FILE *f = fopen(path, "w");
    int ok = f != NULL && fputs(text, f) >= 0 && fputc('\n', f) != EOF;
    if (f != NULL && fclose(f) != 0) {
        ok = 0;
    }
    free(text);
    return ok ? 0 : -1;
}
