/* A minimal FMI co-simulation host in C (no Python in the process), for the tests and
 * benchmarks of the FMUs; one program per FMI version: this file with fmi2_c_host.c (FMI 2.0)
 * or fmi3_c_host.c (FMI 3.0), which make its calls in that version (fmi_c_host.h).
 *
 * fmi_c_host UNPACKED_FMU MODEL_IDENTIFIER GUID STEP_S N_STEPS N_INSTANCES INPUTS OUTPUTS
 *   INPUTS  comma-separated VR=VALUE, set before every step ("-": none)
 *   OUTPUTS comma-separated VRs read after the last step
 * Loads UNPACKED_FMU/binaries/<platform>/MODEL_IDENTIFIER.so, instantiates N_INSTANCES
 * instances (GUID: FMI 3.0's instantiation token), steps them in turn N_STEPS times and prints
 *   instantiate_s <seconds of the first instantiation>
 *   step_us <microseconds per step of one instance: set inputs, doStep, get outputs>
 *   output <instance> <vr> <value>          (after the last step, per instance and output)
 *   log <status> <category> <message>       (every message the FMU logs)
 * Exit 0 when every call returned OK, 1 otherwise (after printing the failing call).
 *
 * fmi_c_host instantiate UNPACKED_FMU MODEL_IDENTIFIER NAME GUID RESOURCES
 *   the version's co-simulation instantiation with exactly these arguments ("<NULL>": a
 *   NULL pointer; RESOURCES: FMI 2.0's resource URI or FMI 3.0's resource path) and, if it
 *   gives an instance, one step of 10 ms; prints "instance 1" or "instance 0", "stepped 0|1"
 *   and the log lines; exit 0 (a crash is the only other outcome). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi_c_host.h"

#define MAX_VARS 32
#define MAX_INSTANCES 8

void print_log(int status, const char *category, const char *message)
{
    printf("log %d %s %s\n", status, category ? category : "(null)", message);
    fflush(stdout);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static size_t parse_list(char *text, unsigned vrs[], double values[])
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (char *item = strtok(text, ","); item && n < MAX_VARS; item = strtok(NULL, ",")) {
        char *equals = strchr(item, '=');
        vrs[n] = (unsigned)strtoul(item, NULL, 10);
        if (values) values[n] = equals ? strtod(equals + 1, NULL) : 0.0;
        ++n;
    }
    return n;
}

#define CHECK(call)                                                                            \
    do {                                                                                       \
        int status_ = (call);                                                                  \
        if (status_ != 0) {                                                                    \
            printf("failed %s: status %d\n", #call, status_);                                  \
            return 1;                                                                          \
        }                                                                                      \
    } while (0)

static const char *argument(const char *text)
{
    return strcmp(text, "<NULL>") == 0 ? NULL : text;
}

/* Load UNPACKED_FMU/binaries/<platform>/MODEL_IDENTIFIER.so and find its functions: 0, or 1
 * after printing why not. */
static int open_library(const char *folder, const char *identifier)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/%s/%s.so", folder, PLATFORM, identifier);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!library) {
        printf("failed dlopen: %s\n", dlerror());
        return 1;
    }
    const char *missing = find_functions(library);
    if (missing) {
        printf("failed dlsym: %s\n", missing);
        return 1;
    }
    return 0;
}

/* The "instantiate" mode (see the top). */
static int instantiate_once(char **argv)
{
    if (open_library(argv[2], argv[3]) != 0) return 1;
    Instance c = instantiate(argument(argv[4]), argument(argv[5]), argument(argv[6]));
    printf("instance %d\n", c != NULL);
    int stepped = c && initialise(c) == 0 && do_step(c, 0.0, 0.01) == 0;
    printf("stepped %d\n", stepped);
    if (c) free_instance(c);
    return 0;
}

int main(int argc, char **argv)
{
    if (argc == 7 && strcmp(argv[1], "instantiate") == 0) return instantiate_once(argv);
    if (argc != 9) {
        fprintf(stderr, "usage: %s UNPACKED_FMU MODEL_IDENTIFIER GUID STEP_S N_STEPS "
                        "N_INSTANCES INPUTS OUTPUTS\n", argv[0]);
        return 2;
    }
    const char *folder = argv[1], *identifier = argv[2], *guid = argv[3];
    double step_s = strtod(argv[4], NULL);
    long n_steps = strtol(argv[5], NULL, 10);
    int n_instances = atoi(argv[6]);
    unsigned in_vr[MAX_VARS], out_vr[MAX_VARS];
    double in_values[MAX_VARS], out_values[MAX_VARS];
    size_t n_in = parse_list(argv[7], in_vr, in_values), n_out = parse_list(argv[8], out_vr, NULL);
    if (n_instances < 1 || n_instances > MAX_INSTANCES) return 2;
    if (open_library(folder, identifier) != 0) return 1;
    char resources[3 * 4096 + 16];
    resource_location(folder, resources, sizeof resources);

    Instance instances[MAX_INSTANCES];
    for (int i = 0; i < n_instances; ++i) {
        char name[32];
        snprintf(name, sizeof name, "instance%d", i);
        double started = now_s();
        instances[i] = instantiate(name, guid, resources);
        if (i == 0) printf("instantiate_s %.6f\n", now_s() - started);
        if (!instances[i]) {
            printf("failed to instantiate\n");
            return 1;
        }
        CHECK(initialise(instances[i]));
    }
    double started = now_s();
    for (long k = 0; k < n_steps; ++k) {
        for (int i = 0; i < n_instances; ++i) {
            CHECK(set_reals(instances[i], in_vr, n_in, in_values));
            CHECK(do_step(instances[i], k * step_s, step_s));
            CHECK(get_reals(instances[i], out_vr, n_out, out_values));
        }
    }
    if (n_steps > 0) printf("step_us %.3f\n", 1e6 * (now_s() - started) / (n_steps * n_instances));
    for (int i = 0; i < n_instances; ++i) {
        CHECK(get_reals(instances[i], out_vr, n_out, out_values));
        for (size_t j = 0; j < n_out; ++j)
            printf("output %d %u %.17g\n", i, out_vr[j], out_values[j]);
        CHECK(terminate(instances[i]));
        free_instance(instances[i]);
    }
    return 0;
}
