/* Flight-log v1 vehicle file (docs/flightlog.md) reader and writer on the simulator's JSON tree (json.h). */
#include "json.h"
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

static int is_number(const sitl_json_t *n)
{
    return sitl_json_is(n, SITL_JSON_NUMBER) && isfinite(n->number);
}

static const sitl_json_t *member(const sitl_json_t *object, const char *key)
{
    return sitl_json_member(object, key);
}

static int is_array_of(const sitl_json_t *n, int count)
{
    return sitl_json_is(n, SITL_JSON_ARRAY) && sitl_json_size(n) == count;
}

/* A required positive number (or one per rotor). */
static int read_coeff(const sitl_json_t *root, const char *key, int rotor_count, double *out,
                      const char *path, char *err, int err_size)
{
    const sitl_json_t *n = member(root, key);
    if (n == NULL || sitl_json_is(n, SITL_JSON_NULL)) {
        return set_err(err, err_size, "%s: '%s' is missing or null; propid_sitl needs it", path,
                       key);
    }
    if (is_number(n)) {
        for (int i = 0; i < rotor_count; i++) {
            out[i] = n->number;
        }
    } else if (is_array_of(n, rotor_count)) {
        for (int i = 0; i < rotor_count; i++) {
            const sitl_json_t *item = sitl_json_item(n, i);
            if (!is_number(item)) {
                return set_err(err, err_size, "%s: '%s'[%d] is not a number", path, key, i);
            }
            out[i] = item->number;
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
static int read_vec3(const sitl_json_t *n, double out[3])
{
    if (!is_array_of(n, 3)) {
        return -1;
    }
    for (int k = 0; k < 3; k++) {
        const sitl_json_t *item = sitl_json_item(n, k);
        if (!is_number(item)) {
            return -1;
        }
        out[k] = item->number;
    }
    return 0;
}

static int read_inertia(const sitl_json_t *inertia, const char *path, sitl_vehicle_t *v, char *err,
                        int err_size)
{
    memset(v->inertia, 0, sizeof(v->inertia));
    if (!is_array_of(inertia, 3)) {
        return set_err(err, err_size, "%s: 'inertia' must be [Jxx,Jyy,Jzz] or a 3x3 list", path);
    }
    if (is_number(sitl_json_item(inertia, 0))) {
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
        const sitl_json_t *row = sitl_json_item(inertia, i);
        if (!is_array_of(row, 3)) {
            return set_err(err, err_size, "%s: 'inertia' must be [Jxx,Jyy,Jzz] or 3x3", path);
        }
        for (int j = 0; j < 3; j++) {
            const sitl_json_t *item = sitl_json_item(row, j);
            if (!is_number(item)) {
                return set_err(err, err_size, "%s: 'inertia'[%d][%d] is not a number", path, i,
                               j);
            }
            v->inertia[i][j] = item->number;
        }
    }
    return 0;
}

static int load_tree(const sitl_json_t *root, const char *path, sitl_vehicle_t *v, char *err,
                     int err_size)
{
    if (!sitl_json_is(root, SITL_JSON_OBJECT)) {
        return set_err(err, err_size, "%s: the vehicle file must be a JSON object", path);
    }
    const sitl_json_t *name = member(root, "name");
    if (sitl_json_is(name, SITL_JSON_STRING)) {
        snprintf(v->name, sizeof(v->name), "%s", name->text);
    } else {
        snprintf(v->name, sizeof(v->name), "%s", path);
    }

    const sitl_json_t *mass = member(root, "mass");
    if (mass == NULL || sitl_json_is(mass, SITL_JSON_NULL)) {
        return set_err(err, err_size, "%s: 'mass' is missing or null; propid_sitl needs it", path);
    }
    if (!is_number(mass) || mass->number <= 0.0) {
        return set_err(err, err_size, "%s: 'mass' must be a positive number", path);
    }
    v->mass = mass->number;

    const sitl_json_t *inertia = member(root, "inertia");
    if (inertia == NULL || sitl_json_is(inertia, SITL_JSON_NULL)) {
        return set_err(err, err_size, "%s: 'inertia' is missing or null; propid_sitl needs it",
                       path);
    }
    if (read_inertia(inertia, path, v, err, err_size) != 0) {
        return -1;
    }

    const sitl_json_t *rotors = member(root, "rotors");
    int rotor_count = sitl_json_is(rotors, SITL_JSON_ARRAY) ? sitl_json_size(rotors) : 0;
    if (rotor_count < 1 || rotor_count > SITL_MAX_ROTORS) {
        return set_err(err, err_size, "%s: 'rotors' must be a list of 1..%d rotors", path,
                       SITL_MAX_ROTORS);
    }
    v->rotor_count = rotor_count;
    double arm_sum = 0.0;
    for (int i = 0; i < v->rotor_count; i++) {
        const sitl_json_t *r = sitl_json_item(rotors, i);
        const sitl_json_t *sign = member(r, "yaw_sign");
        if (read_vec3(member(r, "position"), v->rotor[i].position) != 0) {
            return set_err(err, err_size, "%s: rotor %d needs 'position' [x, y, z]", path, i + 1);
        }
        if (!is_number(sign) || fabs(fabs(sign->number) - 1.0) > 0.0) {
            return set_err(err, err_size, "%s: rotor %d 'yaw_sign' must be 1 or -1", path, i + 1);
        }
        v->rotor[i].yaw_sign = sign->number;
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
    const sitl_json_t *radius = member(root, "rotor_radius");
    if (is_number(radius) && radius->number > 0.0) {
        v->rotor_radius = radius->number;
    }
    const sitl_json_t *rotor_inertia = member(root, "rotor_inertia");
    if (is_number(rotor_inertia) && rotor_inertia->number >= 0.0) {
        v->rotor_inertia = rotor_inertia->number;
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
    sitl_json_t *root = sitl_json_parse(text, &error_at);
    if (root == NULL) {
        int line = error_at != NULL ? line_of(text, error_at) : 1;
        free(text);
        return set_err(err, err_size, "%s: not valid JSON (JSON line %d)", path, line);
    }
    free(text);
    int rc = load_tree(root, path, v, err, err_size);
    sitl_json_free(root);
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

/* A number member written with the shortest round-trip digits (sitl_json_t's own
 * printer rounds to 15 digits when that is within an epsilon). */
static sitl_json_t *exact_number(double x)
{
    char buf[32];
    return sitl_json_raw(num(buf, x));
}

static sitl_json_t *exact_array(const double *x, int count, int stride)
{
    sitl_json_t *array = sitl_json_array();
    for (int i = 0; array != NULL && i < count; i++) {
        sitl_json_append(array, exact_number(x[i * stride]));
    }
    return array;
}

static sitl_json_t *positive_or_null(double x)
{
    return x > 0.0 ? exact_number(x) : sitl_json_null();
}

/* One number when every rotor has the same value, else one per rotor. */
static sitl_json_t *per_rotor(const sitl_vehicle_t *v, int drag)
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
    sitl_json_t *root = sitl_json_object();
    sitl_json_add(root, "name", sitl_json_string(v->name));
    sitl_json_add(root, "mass", exact_number(v->mass));
    if (diagonal) {
        sitl_json_add(root, "inertia", exact_array(&v->inertia[0][0], 3, 4));
    } else {
        sitl_json_t *rows = sitl_json_array();
        for (int i = 0; i < 3; i++) {
            sitl_json_append(rows, exact_array(v->inertia[i], 3, 1));
        }
        sitl_json_add(root, "inertia", rows);
    }
    sitl_json_t *rotors = sitl_json_array();
    for (int i = 0; i < v->rotor_count; i++) {
        sitl_json_t *rotor = sitl_json_object();
        sitl_json_add(rotor, "position", exact_array(v->rotor[i].position, 3, 1));
        sitl_json_add(rotor, "yaw_sign", sitl_json_number(v->rotor[i].yaw_sign > 0 ? 1 : -1));
        sitl_json_append(rotors, rotor);
    }
    sitl_json_add(root, "rotors", rotors);
    sitl_json_add(root, "kf_nominal", per_rotor(v, 0));
    sitl_json_add(root, "km_nominal", per_rotor(v, 1));
    sitl_json_add(root, "rotor_radius", positive_or_null(v->rotor_radius));
    sitl_json_add(root, "rotor_inertia", positive_or_null(v->rotor_inertia));
    sitl_json_add(root, "notes", sitl_json_string(notes != NULL ? notes : ""));
    return sitl_write_json_file(path, root);
}
