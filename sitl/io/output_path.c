/* Output paths: checked before the flight, parents created at write time. */
#define _POSIX_C_SOURCE 200809L
#include "output_path.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

/* As long as any path the options accept (SITL_PATH_MAX in app/options.h). */
enum { OUTPUT_PATH_MAX = 1024 };

/* The directory part of `path` ("." when it has none) in `dir`; -1 if too long. */
static int directory_of(const char *path, char *dir, size_t dir_size)
{
    const char *slash = strrchr(path, '/');
    if (slash == NULL) {
        return snprintf(dir, dir_size, ".") < (int)dir_size ? 0 : -1;
    }
    size_t len = (slash == path) ? 1 : (size_t)(slash - path); /* "/x" -> "/" */
    if (len + 1 > dir_size) {
        return -1;
    }
    memcpy(dir, path, len);
    dir[len] = '\0';
    return 0;
}

int sitl_output_path_check(const char *path, char *why, size_t why_size)
{
    struct stat st;
    if (path[0] == '\0') {
        snprintf(why, why_size, "empty path");
        return -1;
    }
    if (stat(path, &st) == 0) {
        if (S_ISDIR(st.st_mode)) {
            snprintf(why, why_size, "'%.200s' is a directory", path);
            return -1;
        }
        if (access(path, W_OK) != 0) {
            snprintf(why, why_size, "'%.200s' is not writable", path);
            return -1;
        }
        return 0;
    }
    /* Walk up to the nearest existing ancestor: it must be a writable
     * directory; anything else in the way (a file named like a directory)
     * makes the path impossible. */
    char dir[OUTPUT_PATH_MAX];
    if (directory_of(path, dir, sizeof(dir)) != 0) {
        snprintf(why, why_size, "path too long");
        return -1;
    }
    for (int depth = 0; depth < OUTPUT_PATH_MAX; depth++) {
        if (stat(dir, &st) == 0) {
            if (!S_ISDIR(st.st_mode)) {
                snprintf(why, why_size, "'%.200s' is not a directory", dir);
                return -1;
            }
            if (access(dir, W_OK | X_OK) != 0) {
                snprintf(why, why_size, "directory '%.200s' is not writable", dir);
                return -1;
            }
            return 0;
        }
        char up[OUTPUT_PATH_MAX];
        if (directory_of(dir, up, sizeof(up)) != 0 || strcmp(up, dir) == 0) {
            break;
        }
        memcpy(dir, up, strlen(up) + 1);
    }
    snprintf(why, why_size, "no existing directory above '%.200s'", path);
    return -1;
}

int sitl_output_path_make_parents(const char *path, char *why, size_t why_size)
{
    char dir[OUTPUT_PATH_MAX];
    if (directory_of(path, dir, sizeof(dir)) != 0) {
        snprintf(why, why_size, "path too long");
        return -1;
    }
    /* Create each prefix ending at a '/' in turn, then the directory itself. */
    size_t len = strlen(dir);
    for (size_t i = 1; i <= len; i++) {
        if (i < len && dir[i] != '/') {
            continue;
        }
        char saved = dir[i];
        dir[i] = '\0';
        if (mkdir(dir, 0777) != 0 && errno != EEXIST) {
            snprintf(why, why_size, "cannot create directory '%.200s': %s", dir, strerror(errno));
            dir[i] = saved;
            return -1;
        }
        struct stat st;
        if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) {
            snprintf(why, why_size, "'%.200s' is not a directory", dir);
            dir[i] = saved;
            return -1;
        }
        dir[i] = saved;
    }
    return 0;
}
