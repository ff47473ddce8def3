/* The FMI 2.0 calls of the C host of the tests (fmi_c_host.c, fmi_c_host.h). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi2FunctionTypes.h"
#include "fmi_c_host.h"

const char *const PLATFORM = "linux64";

static struct {
    fmi2InstantiateTYPE *Instantiate;
    fmi2SetupExperimentTYPE *SetupExperiment;
    fmi2EnterInitializationModeTYPE *EnterInitializationMode;
    fmi2ExitInitializationModeTYPE *ExitInitializationMode;
    fmi2SetRealTYPE *SetReal;
    fmi2GetRealTYPE *GetReal;
    fmi2DoStepTYPE *DoStep;
    fmi2TerminateTYPE *Terminate;
    fmi2FreeInstanceTYPE *FreeInstance;
} fmi2;

#define FIND(name)                                                                             \
    if (!(fmi2.name = (fmi2##name##TYPE *)dlsym(library, "fmi2" #name))) return "fmi2" #name

const char *find_functions(void *library)
{
    FIND(Instantiate);
    FIND(SetupExperiment);
    FIND(EnterInitializationMode);
    FIND(ExitInitializationMode);
    FIND(SetReal);
    FIND(GetReal);
    FIND(DoStep);
    FIND(Terminate);
    FIND(FreeInstance);
    return NULL;
}

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    (void)env, (void)name;
    char text[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    print_log(status, category, text);
}

static const fmi2CallbackFunctions CALLBACKS = {logger, calloc, free, NULL, NULL};

void resource_location(const char *folder, char *location, size_t size)
{
    snprintf(location, size, "file://%s/resources", folder);
}

Instance instantiate(const char *name, const char *guid, const char *resources)
{
    return fmi2.Instantiate(name, fmi2CoSimulation, guid, resources, &CALLBACKS, fmi2False,
                            fmi2False);
}

int initialise(Instance instance)
{
    fmi2Status status = fmi2.SetupExperiment(instance, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    if (status == fmi2OK) status = fmi2.EnterInitializationMode(instance);
    return status == fmi2OK ? fmi2.ExitInitializationMode(instance) : status;
}

int set_reals(Instance instance, const unsigned vr[], size_t n, const double values[])
{
    return fmi2.SetReal(instance, vr, n, values);
}

int get_reals(Instance instance, const unsigned vr[], size_t n, double values[])
{
    return fmi2.GetReal(instance, vr, n, values);
}

int do_step(Instance instance, double time_s, double step_s)
{
    return fmi2.DoStep(instance, time_s, step_s, fmi2True);
}

int terminate(Instance instance)
{
    return fmi2.Terminate(instance);
}

void free_instance(Instance instance)
{
    fmi2.FreeInstance(instance);
}
