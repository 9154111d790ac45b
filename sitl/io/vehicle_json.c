/* Flight-log v1 vehicle file (docs/flightlog.md) reader and writer on cJSON. */
#include <cjson/cJSON.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "json_file.h"
#include "text_file.h"
#include "vehicle.h"

static int set_err(char *err, int err_size, const char *fmt, ...)
{
    if (err != NULL && err_size > 0) {
        va_list ap;
        va_start(ap, fmt);
        vsnprintf(err, (size_t)err_size, fmt, ap);
        va_end(ap);
    }
    return -1;
}

static int is_number(const cJSON *n)
{
    return cJSON_IsNumber(n) && isfinite(n->valuedouble);
}

static const cJSON *member(const cJSON *object, const char *key)
{
    return cJSON_GetObjectItemCaseSensitive(object, key);
}

static int is_array_of(const cJSON *n, int count)
{
    return cJSON_IsArray(n) && cJSON_GetArraySize(n) == count;
}

/* A required positive number (or one per rotor). */
static int read_coeff(const cJSON *root, const char *key, int rotor_count, double *out,
                      const char *path, char *err, int err_size)
{
    const cJSON *n = member(root, key);
    if (n == NULL || cJSON_IsNull(n)) {
        return set_err(err, err_size, "%s: '%s' is missing or null; propid_sitl needs it", path,
                       key);
    }
    if (is_number(n)) {
        for (int i = 0; i < rotor_count; i++) {
            out[i] = n->valuedouble;
        }
    } else if (is_array_of(n, rotor_count)) {
        for (int i = 0; i < rotor_count; i++) {
            const cJSON *item = cJSON_GetArrayItem(n, i);
            if (!is_number(item)) {
                return set_err(err, err_size, "%s: '%s'[%d] is not a number", path, key, i);
            }
            out[i] = item->valuedouble;
        }
    } else {
        return set_err(err, err_size, "%s: '%s' must be a number or a list of %d numbers", path,
                       key, rotor_count);
    }
    for (int i = 0; i < rotor_count; i++) {
        if (!(out[i] > 0.0)) {
            return set_err(err, err_size, "%s: '%s' must be positive", path, key);
        }
    }
    return 0;
}

/* Three finite numbers into out; 0, or -1 if n is not such a list. */
static int read_vec3(const cJSON *n, double out[3])
{
    if (!is_array_of(n, 3)) {
        return -1;
    }
    for (int k = 0; k < 3; k++) {
        const cJSON *item = cJSON_GetArrayItem(n, k);
        if (!is_number(item)) {
            return -1;
        }
        out[k] = item->valuedouble;
    }
    return 0;
}

static int read_inertia(const cJSON *inertia, const char *path, sitl_vehicle_t *v, char *err,
                        int err_size)
{
    memset(v->inertia, 0, sizeof(v->inertia));
    if (!is_array_of(inertia, 3)) {
        return set_err(err, err_size, "%s: 'inertia' must be [Jxx,Jyy,Jzz] or a 3x3 list", path);
    }
    if (is_number(cJSON_GetArrayItem(inertia, 0))) {
        double diagonal[3];
        if (read_vec3(inertia, diagonal) != 0) {
            return set_err(err, err_size, "%s: 'inertia' diagonal must be 3 numbers", path);
        }
        for (int i = 0; i < 3; i++) {
            v->inertia[i][i] = diagonal[i];
        }
        return 0;
    }
    for (int i = 0; i < 3; i++) {
        const cJSON *row = cJSON_GetArrayItem(inertia, i);
        if (!is_array_of(row, 3)) {
            return set_err(err, err_size, "%s: 'inertia' must be [Jxx,Jyy,Jzz] or 3x3", path);
        }
        for (int j = 0; j < 3; j++) {
            const cJSON *item = cJSON_GetArrayItem(row, j);
            if (!is_number(item)) {
                return set_err(err, err_size, "%s: 'inertia'[%d][%d] is not a number", path, i,
                               j);
            }
            v->inertia[i][j] = item->valuedouble;
        }
    }
    return 0;
}

static int load_tree(const cJSON *root, const char *path, sitl_vehicle_t *v, char *err,
                     int err_size)
{
    if (!cJSON_IsObject(root)) {
        return set_err(err, err_size, "%s: the vehicle file must be a JSON object", path);
    }
    const cJSON *name = member(root, "name");
    if (cJSON_IsString(name)) {
        snprintf(v->name, sizeof(v->name), "%s", name->valuestring);
    } else {
        snprintf(v->name, sizeof(v->name), "%s", path);
    }

    const cJSON *mass = member(root, "mass");
    if (mass == NULL || cJSON_IsNull(mass)) {
        return set_err(err, err_size, "%s: 'mass' is missing or null; propid_sitl needs it", path);
    }
    if (!is_number(mass) || mass->valuedouble <= 0.0) {
        return set_err(err, err_size, "%s: 'mass' must be a positive number", path);
    }
    v->mass = mass->valuedouble;

    const cJSON *inertia = member(root, "inertia");
    if (inertia == NULL || cJSON_IsNull(inertia)) {
        return set_err(err, err_size, "%s: 'inertia' is missing or null; propid_sitl needs it",
                       path);
    }
    if (read_inertia(inertia, path, v, err, err_size) != 0) {
        return -1;
    }

    const cJSON *rotors = member(root, "rotors");
    int rotor_count = cJSON_IsArray(rotors) ? cJSON_GetArraySize(rotors) : 0;
    if (rotor_count < 1 || rotor_count > SITL_MAX_ROTORS) {
        return set_err(err, err_size, "%s: 'rotors' must be a list of 1..%d rotors", path,
                       SITL_MAX_ROTORS);
    }
    v->rotor_count = rotor_count;
    double arm_sum = 0.0;
    for (int i = 0; i < v->rotor_count; i++) {
        const cJSON *r = cJSON_GetArrayItem(rotors, i);
        const cJSON *sign = member(r, "yaw_sign");
        if (read_vec3(member(r, "position"), v->rotor[i].position) != 0) {
            return set_err(err, err_size, "%s: rotor %d needs 'position' [x, y, z]", path, i + 1);
        }
        if (!is_number(sign) || fabs(fabs(sign->valuedouble) - 1.0) > 0.0) {
            return set_err(err, err_size, "%s: rotor %d 'yaw_sign' must be 1 or -1", path, i + 1);
        }
        v->rotor[i].yaw_sign = sign->valuedouble;
        arm_sum += hypot(v->rotor[i].position[0], v->rotor[i].position[1]);
    }
    v->arm_length = arm_sum / (double)v->rotor_count;

    double kf[SITL_MAX_ROTORS], km[SITL_MAX_ROTORS];
    if (read_coeff(root, "kf_nominal", v->rotor_count, kf, path, err, err_size) != 0 ||
        read_coeff(root, "km_nominal", v->rotor_count, km, path, err, err_size) != 0) {
        return -1;
    }
    for (int i = 0; i < v->rotor_count; i++) {
        v->rotor[i].thrust_coeff = kf[i];
        v->rotor[i].drag_coeff = km[i];
    }

    /* Optional: a present number overrides the caller's default. */
    const cJSON *radius = member(root, "rotor_radius");
    if (is_number(radius) && radius->valuedouble > 0.0) {
        v->rotor_radius = radius->valuedouble;
    }
    const cJSON *rotor_inertia = member(root, "rotor_inertia");
    if (is_number(rotor_inertia) && rotor_inertia->valuedouble >= 0.0) {
        v->rotor_inertia = rotor_inertia->valuedouble;
    }
    return 0;
}

/* 1-based line of position `at` in text. */
static int line_of(const char *text, const char *at)
{
    int line = 1;
    for (const char *p = text; p < at && *p != '\0'; p++) {
        line += *p == '\n';
    }
    return line;
}

int sitl_vehicle_load_json(const char *path, sitl_vehicle_t *v, char *err, int err_size)
{
    char *text = sitl_read_file(path, 1u << 20);
    if (text == NULL) {
        return set_err(err, err_size, "%s: cannot read the vehicle file", path);
    }
    const char *error_at = NULL;
    cJSON *root = cJSON_ParseWithOpts(text, &error_at, 1);
    if (root == NULL) {
        int line = error_at != NULL ? line_of(text, error_at) : 1;
        free(text);
        return set_err(err, err_size, "%s: not valid JSON (JSON line %d)", path, line);
    }
    free(text);
    int rc = load_tree(root, path, v, err, err_size);
    cJSON_Delete(root);
    if (rc == 0) {
        return sitl_vehicle_check(v, err, err_size);
    }
    return rc;
}

/* Shortest of %.15g / %.16g / %.17g that reads back to the same double. */
static const char *num(char *buf, double x)
{
    for (int digits = 15; digits <= 17; digits++) {
        snprintf(buf, 32, "%.*g", digits, x);
        if (strtod(buf, NULL) == x) {
            break;
        }
    }
    return buf;
}

/* A number member written with the shortest round-trip digits (cJSON's own
 * printer rounds to 15 digits when that is within an epsilon). */
static cJSON *exact_number(double x)
{
    char buf[32];
    return cJSON_CreateRaw(num(buf, x));
}

static cJSON *exact_array(const double *x, int count, int stride)
{
    cJSON *array = cJSON_CreateArray();
    for (int i = 0; array != NULL && i < count; i++) {
        cJSON_AddItemToArray(array, exact_number(x[i * stride]));
    }
    return array;
}

static cJSON *positive_or_null(double x)
{
    return x > 0.0 ? exact_number(x) : cJSON_CreateNull();
}

/* One number when every rotor has the same value, else one per rotor. */
static cJSON *per_rotor(const sitl_vehicle_t *v, int drag)
{
    double values[SITL_MAX_ROTORS] = {0};
    int same = 1;
    for (int i = 0; i < v->rotor_count; i++) {
        values[i] = drag ? v->rotor[i].drag_coeff : v->rotor[i].thrust_coeff;
        same &= values[i] == values[0];
    }
    return same ? exact_number(values[0]) : exact_array(values, v->rotor_count, 1);
}

int sitl_vehicle_write_json(const char *path, const sitl_vehicle_t *v, const char *notes)
{
    int diagonal = 1;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            if (i != j && v->inertia[i][j] != 0.0) {
                diagonal = 0;
            }
        }
    }
    cJSON *root = cJSON_CreateObject();
    cJSON_AddItemToObject(root, "name", cJSON_CreateString(v->name));
    cJSON_AddItemToObject(root, "mass", exact_number(v->mass));
    if (diagonal) {
        cJSON_AddItemToObject(root, "inertia", exact_array(&v->inertia[0][0], 3, 4));
    } else {
        cJSON *rows = cJSON_CreateArray();
        for (int i = 0; i < 3; i++) {
            cJSON_AddItemToArray(rows, exact_array(v->inertia[i], 3, 1));
        }
        cJSON_AddItemToObject(root, "inertia", rows);
    }
    cJSON *rotors = cJSON_CreateArray();
    for (int i = 0; i < v->rotor_count; i++) {
        cJSON *rotor = cJSON_CreateObject();
        cJSON_AddItemToObject(rotor, "position", exact_array(v->rotor[i].position, 3, 1));
        cJSON_AddItemToObject(rotor, "yaw_sign", cJSON_CreateNumber(v->rotor[i].yaw_sign > 0 ? 1 : -1));
        cJSON_AddItemToArray(rotors, rotor);
    }
    cJSON_AddItemToObject(root, "rotors", rotors);
    cJSON_AddItemToObject(root, "kf_nominal", per_rotor(v, 0));
    cJSON_AddItemToObject(root, "km_nominal", per_rotor(v, 1));
    cJSON_AddItemToObject(root, "rotor_radius", positive_or_null(v->rotor_radius));
    /* as described: an inertia the simulator assumed for its effects is not the vehicle's */
    cJSON_AddItemToObject(root, "rotor_inertia",
                          positive_or_null(v->rotor_inertia_assumed ? 0.0 : v->rotor_inertia));
    cJSON_AddItemToObject(root, "notes", cJSON_CreateString(notes != NULL ? notes : ""));
    return sitl_write_json_file(path, root);
}
