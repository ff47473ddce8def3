/* A minimal FMI 2.0 co-simulation host in C (no Python in the process), for the tests and
 * benchmarks of standalone FMUs.
 *
 * fmi_c_host UNPACKED_FMU MODEL_IDENTIFIER GUID STEP_S N_STEPS N_INSTANCES INPUTS OUTPUTS
 *   INPUTS  comma-separated VR=VALUE, set before every step ("-": none)
 *   OUTPUTS comma-separated VRs read after the last step
 * Loads UNPACKED_FMU/binaries/linux64/MODEL_IDENTIFIER.so, instantiates N_INSTANCES instances,
 * steps them in turn N_STEPS times and prints
 *   instantiate_s <seconds of the first fmi2Instantiate>
 *   step_us <microseconds per step of one instance: set inputs, doStep, get outputs>
 *   output <instance> <vr> <value>          (after the last step, per instance and output)
 *   log <status> <category> <message>       (every message the FMU logs)
 * Exit 0 when every call returned fmi2OK, 1 otherwise (after printing the failing call).
 *
 * fmi_c_host instantiate UNPACKED_FMU MODEL_IDENTIFIER NAME GUID RESOURCES
 *   fmi2Instantiate with exactly these arguments ("<NULL>": a NULL pointer) and, if it gives
 *   an instance, one step of 10 ms; prints "instance 1" or "instance 0", "stepped 0|1" and
 *   the log lines; exit 0 (a crash is the only other outcome). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

#define MAX_VARS 32
#define MAX_INSTANCES 8

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env, (void)name;
    char text[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    printf("log %d %s %s\n", status, category ? category : "(null)", text);
    fflush(stdout);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static size_t parse_list(char *text, fmi2ValueReference vrs[], double values[])
{
    size_t n = 0;
    if (strcmp(text, "-") == 0) return 0;
    for (char *item = strtok(text, ","); item && n < MAX_VARS; item = strtok(NULL, ",")) {
        char *equals = strchr(item, '=');
        vrs[n] = (fmi2ValueReference)strtoul(item, NULL, 10);
        if (values) values[n] = equals ? strtod(equals + 1, NULL) : 0.0;
        ++n;
    }
    return n;
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(library, #name)

#define CHECK(call)                                                                            \
    do {                                                                                       \
        fmi2Status status_ = (call);                                                           \
        if (status_ != fmi2OK) {                                                               \
            printf("failed %s: status %d\n", #call, status_);                                  \
            return 1;                                                                          \
        }                                                                                      \
    } while (0)

static const char *argument(const char *text)
{
    return strcmp(text, "<NULL>") == 0 ? NULL : text;
}

/* The "instantiate" mode (see the top). */
static int instantiate_once(char **argv)
{
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[2], argv[3]);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!library) {
        printf("failed dlopen: %s\n", dlerror());
        return 1;
    }
    LOAD(fmi2Instantiate);
    LOAD(fmi2SetupExperiment);
    LOAD(fmi2EnterInitializationMode);
    LOAD(fmi2ExitInitializationMode);
    LOAD(fmi2DoStep);
    LOAD(fmi2FreeInstance);
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate(argument(argv[4]), fmi2CoSimulation, argument(argv[5]),
                                      argument(argv[6]), &callbacks, fmi2False, fmi2False);
    printf("instance %d\n", c != NULL);
    int stepped = c && fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK
                  && fmi2EnterInitializationMode(c) == fmi2OK
                  && fmi2ExitInitializationMode(c) == fmi2OK
                  && fmi2DoStep(c, 0.0, 0.01, fmi2True) == fmi2OK;
    printf("stepped %d\n", stepped);
    if (c) fmi2FreeInstance(c);
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
    fmi2ValueReference in_vr[MAX_VARS], out_vr[MAX_VARS];
    double in_values[MAX_VARS], out_values[MAX_VARS];
    size_t n_in = parse_list(argv[7], in_vr, in_values), n_out = parse_list(argv[8], out_vr, NULL);
    if (n_instances < 1 || n_instances > MAX_INSTANCES) return 2;

    char path[4096], resources[4200];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", folder, identifier);
    snprintf(resources, sizeof resources, "file://%s/resources", folder);
    void *library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!library) {
        printf("failed dlopen: %s\n", dlerror());
        return 1;
    }
    LOAD(fmi2Instantiate);
    LOAD(fmi2SetupExperiment);
    LOAD(fmi2EnterInitializationMode);
    LOAD(fmi2ExitInitializationMode);
    LOAD(fmi2SetReal);
    LOAD(fmi2GetReal);
    LOAD(fmi2DoStep);
    LOAD(fmi2Terminate);
    LOAD(fmi2FreeInstance);
    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

    fmi2Component instances[MAX_INSTANCES];
    for (int i = 0; i < n_instances; ++i) {
        char name[32];
        snprintf(name, sizeof name, "instance%d", i);
        double started = now_s();
        instances[i] = fmi2Instantiate(name, fmi2CoSimulation, guid, resources, &callbacks,
                                       fmi2False, fmi2False);
        if (i == 0) printf("instantiate_s %.6f\n", now_s() - started);
        if (!instances[i]) {
            printf("failed fmi2Instantiate\n");
            return 1;
        }
        CHECK(fmi2SetupExperiment(instances[i], fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CHECK(fmi2EnterInitializationMode(instances[i]));
        CHECK(fmi2ExitInitializationMode(instances[i]));
    }
    double started = now_s();
    for (long k = 0; k < n_steps; ++k) {
        for (int i = 0; i < n_instances; ++i) {
            CHECK(fmi2SetReal(instances[i], in_vr, n_in, in_values));
            CHECK(fmi2DoStep(instances[i], k * step_s, step_s, fmi2True));
            CHECK(fmi2GetReal(instances[i], out_vr, n_out, out_values));
        }
    }
    if (n_steps > 0) printf("step_us %.3f\n", 1e6 * (now_s() - started) / (n_steps * n_instances));
    for (int i = 0; i < n_instances; ++i) {
        CHECK(fmi2GetReal(instances[i], out_vr, n_out, out_values));
        for (size_t j = 0; j < n_out; ++j)
            printf("output %d %u %.17g\n", i, out_vr[j], out_values[j]);
        CHECK(fmi2Terminate(instances[i]));
        fmi2FreeInstance(instances[i]);
    }
    return 0;
}
