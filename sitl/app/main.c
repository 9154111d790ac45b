/* propid_sitl: closed-loop multirotor SITL with the propid filter in the loop. */
#define _POSIX_C_SOURCE 200809L
#include <signal.h>
#include <stdio.h>
#include <string.h>

#include "options.h"
#include "output_path.h"
#include "sim.h"

static void on_signal(int signo)
{
    (void)signo;
    sitl_request_stop();
}

int main(int argc, char **argv)
{
    /* Ctrl-C during a real-time flight: stop cleanly, keep the log. */
    struct sigaction sa;
    memset(&sa, 0, sizeof(sa));
    sa.sa_handler = on_signal;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGTERM, &sa, NULL);

    static sitl_options_t opts;
    sitl_options_default(&opts);
    int rc = sitl_options_parse(&opts, argc, argv);
    if (rc == 1) {
        return SITL_EXIT_OK;
    }
    if (rc != 0) {
        return rc;
    }
    /* Output paths checked before the flight: a bad one fails now, not
     * after it (their missing directories are created when written). */
    const char *outputs[3] = {opts.log_path, opts.summary_json, opts.nees_dump};
    const char *output_names[3] = {"--log", "--summary-json", "--nees-dump"};
    for (int k = 0; k < 3; k++) {
        char why[300];
        if (outputs[k][0] != '\0' && sitl_output_path_check(outputs[k], why, sizeof(why)) != 0) {
            fprintf(stderr, "propid_sitl: cannot write %s %s: %s\n", output_names[k], outputs[k], why);
            return SITL_EXIT_ERROR;
        }
    }
    static sitl_result_t result;
    rc = sitl_run(&opts, &result, stdout);
    if (rc != SITL_EXIT_OK && rc != SITL_EXIT_DIVERGED && rc != SITL_EXIT_INTERRUPTED) {
        fprintf(stderr, "propid_sitl: %s\n", result.message);
        return rc;
    }
    if (rc == SITL_EXIT_DIVERGED || rc == SITL_EXIT_INTERRUPTED) {
        fprintf(stderr, "propid_sitl: %s (log kept up to there)\n", result.message);
    }
    sitl_print_final_summary(stdout, &opts, &result);
    if (opts.summary_json[0] != '\0') {
        char why[300];
        if (sitl_output_path_make_parents(opts.summary_json, why, sizeof(why)) != 0) {
            fprintf(stderr, "propid_sitl: cannot write --summary-json %s: %s\n", opts.summary_json, why);
            return SITL_EXIT_ERROR;
        }
        if (sitl_write_summary_json(opts.summary_json, &opts, &result) != 0) {
            fprintf(stderr, "propid_sitl: cannot write '%s'\n", opts.summary_json);
            return SITL_EXIT_ERROR;
        }
    }
    return rc;
}
