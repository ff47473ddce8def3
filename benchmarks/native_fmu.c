/* The native floor of benchmarks/bench_fmi_floor.py: a minimal FMI 2.0 co-simulation FMU in C
 * with the interface of a feedaxis FMU and no physics.
 *
 * Compiled once per feedaxis FMU against the official FMI 2.0 headers (fmus/common/fmi2/)
 * with -DN_VALUES=<largest value reference + 1>. Every variable is a slot of its type indexed
 * by its value reference; fmi2SetX/fmi2GetX copy values in and out (an unknown reference is an
 * error; strings stay ""), fmi2DoStep does nothing. What an FMU costs its host beyond this
 * is its own work.
 */
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

typedef struct {
    fmi2Real reals[N_VALUES];
    fmi2Integer integers[N_VALUES];
    fmi2Boolean booleans[N_VALUES];
    fmi2String strings[N_VALUES];
} Instance;

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n,
                               const fmi2String categories[])
{
    (void)c, (void)on, (void)n, (void)categories;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid,
                              fmi2String resources, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean logging)
{
    (void)name, (void)guid, (void)resources, (void)functions, (void)visible, (void)logging;
    if (type != fmi2CoSimulation) return NULL;
    Instance *instance = calloc(1, sizeof *instance);
    for (size_t i = 0; instance && i < N_VALUES; ++i) instance->strings[i] = "";
    return instance;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolerance_defined,
                               fmi2Real tolerance, fmi2Real start, fmi2Boolean stop_defined,
                               fmi2Real stop)
{
    (void)c, (void)tolerance_defined, (void)tolerance, (void)start, (void)stop_defined, (void)stop;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2OK; }

#define ACCESSORS(Type, type, field)                                                            \
    fmi2Status fmi2Get##Type(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,       \
                             type value[])                                                      \
    {                                                                                           \
        Instance *instance = c;                                                                 \
        for (size_t i = 0; i < nvr; ++i) {                                                      \
            if (vr[i] >= N_VALUES) return fmi2Error;                                            \
            value[i] = instance->field[vr[i]];                                                  \
        }                                                                                       \
        return fmi2OK;                                                                          \
    }                                                                                           \
    fmi2Status fmi2Set##Type(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,       \
                             const type value[])                                                \
    {                                                                                           \
        Instance *instance = c;                                                                 \
        for (size_t i = 0; i < nvr; ++i) {                                                      \
            if (vr[i] >= N_VALUES) return fmi2Error;                                            \
            instance->field[vr[i]] = value[i];                                                  \
        }                                                                                       \
        return fmi2OK;                                                                          \
    }

ACCESSORS(Real, fmi2Real, reals)
ACCESSORS(Integer, fmi2Integer, integers)
ACCESSORS(Boolean, fmi2Boolean, booleans)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[])
{
    Instance *instance = c;
    for (size_t i = 0; i < nvr; ++i) {
        if (vr[i] >= N_VALUES) return fmi2Error;
        value[i] = instance->strings[vr[i]];
    }
    return fmi2OK;
}

/* Strings are not kept (the host owns its text): only "" is accepted. */
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[])
{
    (void)c;
    for (size_t i = 0; i < nvr; ++i)
        if (vr[i] >= N_VALUES || !value[i] || *value[i]) return fmi2Error;
    return fmi2OK;
}

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Instance *copy = malloc(sizeof *copy);
    if (!copy) return fmi2Error;
    memcpy(copy, c, sizeof *copy);
    *state = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    memcpy(c, state, sizeof(Instance));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    (void)c;
    free(*state);
    *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    (void)c, (void)state;
    *size = sizeof(Instance);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[],
                                 size_t size)
{
    (void)c;
    if (size != sizeof(Instance)) return fmi2Error;
    memcpy(bytes, state, size);
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state)
{
    (void)c;
    if (size != sizeof(Instance) || !(*state = malloc(size))) return fmi2Error;
    memcpy(*state, bytes, size);
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz,
                                        const fmi2Real dv[], fmi2Real dz[])
{
    (void)c, (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    return fmi2Error;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[])
{
    (void)c, (void)vr, (void)nvr, (void)order, (void)value;
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[], fmi2Real value[])
{
    (void)c, (void)vr, (void)nvr, (void)order, (void)value;
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior)
{
    (void)c, (void)t, (void)h, (void)no_set_prior;
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

#define STATUS_GETTER(Type, type)                                                               \
    fmi2Status fmi2Get##Type##Status(fmi2Component c, const fmi2StatusKind kind, type *value)  \
    {                                                                                           \
        (void)c, (void)kind, (void)value;                                                       \
        return fmi2Discard;                                                                     \
    }

STATUS_GETTER(, fmi2Status)
STATUS_GETTER(Real, fmi2Real)
STATUS_GETTER(Integer, fmi2Integer)
STATUS_GETTER(Boolean, fmi2Boolean)
STATUS_GETTER(String, fmi2String)
