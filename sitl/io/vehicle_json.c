/* Flight-log v1 vehicle file (spec/flightlog-v1.md) reader and writer. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "json.h"
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
    return n != NULL && n->type == SITL_JSON_NUMBER && isfinite(n->number);
}

/* A required positive number (or, with list_ok, one per rotor). */
static int read_coeff(const sitl_json_t *root, const char *key, int rotor_count, double *out,
                      const char *path, char *err, int err_size)
{
    const sitl_json_t *n = sitl_json_get(root, key);
    if (n == NULL || n->type == SITL_JSON_NULL) {
        return set_err(err, err_size, "%s: '%s' is missing or null; propid_sitl needs it", path,
                       key);
    }
    if (is_number(n)) {
        for (int i = 0; i < rotor_count; i++) {
            out[i] = n->number;
        }
    } else if (n->type == SITL_JSON_ARRAY && (int)n->count == rotor_count) {
        for (int i = 0; i < rotor_count; i++) {
            if (!is_number(&n->children[i])) {
                return set_err(err, err_size, "%s: '%s'[%d] is not a number", path, key, i);
            }
            out[i] = n->children[i].number;
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

static int load_tree(const sitl_json_t *root, const char *path, sitl_vehicle_t *v, char *err,
                     int err_size)
{
    if (root->type != SITL_JSON_OBJECT) {
        return set_err(err, err_size, "%s: the vehicle file must be a JSON object", path);
    }
    const sitl_json_t *name = sitl_json_get(root, "name");
    if (name != NULL && name->type == SITL_JSON_STRING) {
        snprintf(v->name, sizeof(v->name), "%s", name->string);
    } else {
        snprintf(v->name, sizeof(v->name), "%s", path);
    }

    const sitl_json_t *mass = sitl_json_get(root, "mass");
    if (mass == NULL || mass->type == SITL_JSON_NULL) {
        return set_err(err, err_size, "%s: 'mass' is missing or null; propid_sitl needs it", path);
    }
    if (!is_number(mass) || mass->number <= 0.0) {
        return set_err(err, err_size, "%s: 'mass' must be a positive number", path);
    }
    v->mass = mass->number;

    const sitl_json_t *inertia = sitl_json_get(root, "inertia");
    if (inertia == NULL || inertia->type == SITL_JSON_NULL) {
        return set_err(err, err_size, "%s: 'inertia' is missing or null; propid_sitl needs it",
                       path);
    }
    memset(v->inertia, 0, sizeof(v->inertia));
    if (inertia->type == SITL_JSON_ARRAY && inertia->count == 3 &&
        is_number(&inertia->children[0])) {
        for (int i = 0; i < 3; i++) {
            if (!is_number(&inertia->children[i])) {
                return set_err(err, err_size, "%s: 'inertia' diagonal must be 3 numbers", path);
            }
            v->inertia[i][i] = inertia->children[i].number;
        }
    } else if (inertia->type == SITL_JSON_ARRAY && inertia->count == 3) {
        for (int i = 0; i < 3; i++) {
            const sitl_json_t *row = &inertia->children[i];
            if (row->type != SITL_JSON_ARRAY || row->count != 3) {
                return set_err(err, err_size, "%s: 'inertia' must be [Jxx,Jyy,Jzz] or 3x3", path);
            }
            for (int j = 0; j < 3; j++) {
                if (!is_number(&row->children[j])) {
                    return set_err(err, err_size, "%s: 'inertia'[%d][%d] is not a number", path,
                                   i, j);
                }
                v->inertia[i][j] = row->children[j].number;
            }
        }
    } else {
        return set_err(err, err_size, "%s: 'inertia' must be [Jxx,Jyy,Jzz] or a 3x3 list", path);
    }

    const sitl_json_t *rotors = sitl_json_get(root, "rotors");
    if (rotors == NULL || rotors->type != SITL_JSON_ARRAY || rotors->count < 1 ||
        rotors->count > SITL_MAX_ROTORS) {
        return set_err(err, err_size, "%s: 'rotors' must be a list of 1..%d rotors", path,
                       SITL_MAX_ROTORS);
    }
    v->rotor_count = (int)rotors->count;
    double arm_sum = 0.0;
    for (int i = 0; i < v->rotor_count; i++) {
        const sitl_json_t *r = &rotors->children[i];
        const sitl_json_t *pos = sitl_json_get(r, "position");
        const sitl_json_t *sign = sitl_json_get(r, "yaw_sign");
        if (pos == NULL || pos->type != SITL_JSON_ARRAY || pos->count != 3 ||
            !is_number(&pos->children[0]) || !is_number(&pos->children[1]) ||
            !is_number(&pos->children[2])) {
            return set_err(err, err_size, "%s: rotor %d needs 'position' [x, y, z]", path, i + 1);
        }
        if (!is_number(sign) || fabs(fabs(sign->number) - 1.0) > 0.0) {
            return set_err(err, err_size, "%s: rotor %d 'yaw_sign' must be 1 or -1", path, i + 1);
        }
        for (int k = 0; k < 3; k++) {
            v->rotor[i].position[k] = pos->children[k].number;
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
    const sitl_json_t *radius = sitl_json_get(root, "rotor_radius");
    if (is_number(radius) && radius->number > 0.0) {
        v->rotor_radius = radius->number;
    }
    const sitl_json_t *rotor_inertia = sitl_json_get(root, "rotor_inertia");
    if (is_number(rotor_inertia) && rotor_inertia->number >= 0.0) {
        v->rotor_inertia = rotor_inertia->number;
    }
    return 0;
}

int sitl_vehicle_load_json(const char *path, sitl_vehicle_t *v, char *err, int err_size)
{
    char *text = sitl_read_file(path, 1u << 20);
    if (text == NULL) {
        return set_err(err, err_size, "%s: cannot read the vehicle file", path);
    }
    char jerr[160];
    sitl_json_t *root = sitl_json_parse(text, jerr, (int)sizeof(jerr));
    free(text);
    if (root == NULL) {
        return set_err(err, err_size, "%s: %s", path, jerr);
    }
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

static void write_json_string(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s != '\0'; s++) {
        unsigned char c = (unsigned char)*s;
        if (c == '"' || c == '\\') {
            fprintf(f, "\\%c", c);
        } else if (c < 0x20) {
            fprintf(f, "\\u%04x", c);
        } else {
            fputc(c, f);
        }
    }
    fputc('"', f);
}

int sitl_vehicle_write_json(const char *path, const sitl_vehicle_t *v, const char *notes)
{
    FILE *f = fopen(path, "w");
    if (f == NULL) {
        return -1;
    }
    int diagonal = 1;
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++) {
            if (i != j && v->inertia[i][j] != 0.0) {
                diagonal = 0;
            }
        }
    }
    int same_kf = 1, same_km = 1;
    for (int i = 1; i < v->rotor_count; i++) {
        same_kf &= v->rotor[i].thrust_coeff == v->rotor[0].thrust_coeff;
        same_km &= v->rotor[i].drag_coeff == v->rotor[0].drag_coeff;
    }
    fprintf(f, "{\n  \"name\": ");
    write_json_string(f, v->name);
    char b[9][32];
    fprintf(f, ",\n  \"mass\": %s,\n", num(b[0], v->mass));
    if (diagonal) {
        fprintf(f, "  \"inertia\": [%s, %s, %s],\n", num(b[0], v->inertia[0][0]),
                num(b[1], v->inertia[1][1]), num(b[2], v->inertia[2][2]));
    } else {
        for (int i = 0; i < 3; i++) {
            for (int j = 0; j < 3; j++) {
                num(b[3 * i + j], v->inertia[i][j]);
            }
        }
        fprintf(f, "  \"inertia\": [[%s, %s, %s], [%s, %s, %s], [%s, %s, %s]],\n", b[0], b[1],
                b[2], b[3], b[4], b[5], b[6], b[7], b[8]);
    }
    fprintf(f, "  \"rotors\": [\n");
    for (int i = 0; i < v->rotor_count; i++) {
        const sitl_rotor_t *r = &v->rotor[i];
        fprintf(f, "    {\"position\": [%s, %s, %s], \"yaw_sign\": %d}%s\n",
                num(b[0], r->position[0]), num(b[1], r->position[1]), num(b[2], r->position[2]),
                r->yaw_sign > 0 ? 1 : -1,
                i + 1 < v->rotor_count ? "," : "");
    }
    fprintf(f, "  ],\n");
    const char *coeff_names[2] = {"kf_nominal", "km_nominal"};
    for (int k = 0; k < 2; k++) {
        int same = k == 0 ? same_kf : same_km;
        fprintf(f, "  \"%s\": ", coeff_names[k]);
        if (same) {
            fprintf(f, "%s", num(b[0], k == 0 ? v->rotor[0].thrust_coeff : v->rotor[0].drag_coeff));
        } else {
            fputc('[', f);
            for (int i = 0; i < v->rotor_count; i++) {
                fprintf(f, "%s%s", i ? ", " : "",
                        num(b[0], k == 0 ? v->rotor[i].thrust_coeff : v->rotor[i].drag_coeff));
            }
            fputc(']', f);
        }
        fprintf(f, ",\n");
    }
    if (v->rotor_radius > 0.0) {
        fprintf(f, "  \"rotor_radius\": %s,\n", num(b[0], v->rotor_radius));
    } else {
        fprintf(f, "  \"rotor_radius\": null,\n");
    }
    if (v->rotor_inertia > 0.0) {
        fprintf(f, "  \"rotor_inertia\": %s,\n", num(b[0], v->rotor_inertia));
    } else {
        fprintf(f, "  \"rotor_inertia\": null,\n");
    }
    fprintf(f, "  \"notes\": ");
    write_json_string(f, notes != NULL ? notes : "");
    fprintf(f, "\n}\n");
    return fclose(f) == 0 ? 0 : -1;
}
