/* propid_sitl: closed-loop multirotor SITL with the propid filter in the loop. */
#include <stdio.h>

#include "options.h"
#include "sim.h"

int main(int argc, char **argv)
{
    static sitl_options_t opts;
    sitl_options_default(&opts);
    int rc = sitl_options_parse(&opts, argc, argv);
    if (rc == 1) {
        return SITL_EXIT_OK;
    }
    if (rc != 0) {
        return rc;
    }
    static sitl_result_t result;
    rc = sitl_run(&opts, &result, stdout);
    if (rc != SITL_EXIT_OK && rc != SITL_EXIT_DIVERGED) {
        fprintf(stderr, "propid_sitl: %s\n", result.message);
        return rc;
    }
    if (rc == SITL_EXIT_DIVERGED) {
        fprintf(stderr, "propid_sitl: %s (log kept up to there)\n", result.message);
    }
    sitl_print_final_summary(stdout, &opts, &result);
    if (opts.summary_json[0] != '\0' &&
        sitl_write_summary_json(opts.summary_json, &opts, &result) != 0) {
        fprintf(stderr, "propid_sitl: cannot write '%s'\n", opts.summary_json);
        return SITL_EXIT_ERROR;
    }
    return rc;
}
