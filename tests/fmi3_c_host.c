/* The FMI 3.0 calls of the C host of the tests (fmi_c_host.c, fmi_c_host.h). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <stdio.h>

#include "fmi3FunctionTypes.h"
#include "fmi_c_host.h"

const char *const PLATFORM = "x86_64-linux";

static struct {
    fmi3InstantiateCoSimulationTYPE *InstantiateCoSimulation;
    fmi3EnterInitializationModeTYPE *EnterInitializationMode;
    fmi3ExitInitializationModeTYPE *ExitInitializationMode;
    fmi3SetFloat64TYPE *SetFloat64;
    fmi3GetFloat64TYPE *GetFloat64;
    fmi3DoStepTYPE *DoStep;
    fmi3TerminateTYPE *Terminate;
    fmi3FreeInstanceTYPE *FreeInstance;
} fmi3;

#define FIND(name)                                                                             \
    if (!(fmi3.name = (fmi3##name##TYPE *)dlsym(library, "fmi3" #name))) return "fmi3" #name

const char *find_functions(void *library)
{
    FIND(InstantiateCoSimulation);
    FIND(EnterInitializationMode);
    FIND(ExitInitializationMode);
    FIND(SetFloat64);
    FIND(GetFloat64);
    FIND(DoStep);
    FIND(Terminate);
    FIND(FreeInstance);
    return NULL;
}

static void logger(fmi3InstanceEnvironment environment, fmi3Status status,
                   fmi3String category, fmi3String message)
{
    (void)environment;
    print_log(status, category, message ? message : "(null)");
}

void resource_location(const char *folder, char *location, size_t size)
{
    snprintf(location, size, "%s/resources/", folder);
}

Instance instantiate(const char *name, const char *guid, const char *resources)
{
    return fmi3.InstantiateCoSimulation(name, guid, resources, fmi3False, fmi3False, fmi3False,
                                        fmi3False, NULL, 0, NULL, logger, NULL);
}

int initialise(Instance instance)
{
    fmi3Status status = fmi3.EnterInitializationMode(instance, fmi3False, 0.0, 0.0, fmi3False,
                                                     0.0);
    return status == fmi3OK ? fmi3.ExitInitializationMode(instance) : status;
}

int set_reals(Instance instance, const unsigned vr[], size_t n, const double values[])
{
    return fmi3.SetFloat64(instance, vr, n, values, n);
}

int get_reals(Instance instance, const unsigned vr[], size_t n, double values[])
{
    return fmi3.GetFloat64(instance, vr, n, values, n);
}

int do_step(Instance instance, double time_s, double step_s)
{
    fmi3Boolean event_handling_needed, terminate_simulation, early_return;
    fmi3Float64 last_successful_time_s;
    return fmi3.DoStep(instance, time_s, step_s, fmi3True, &event_handling_needed,
                       &terminate_simulation, &early_return, &last_successful_time_s);
}

int terminate(Instance instance)
{
    return fmi3.Terminate(instance);
}

void free_instance(Instance instance)
{
    fmi3.FreeInstance(instance);
}
