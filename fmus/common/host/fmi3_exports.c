/* The fmi3 functions of an FMI 3.0 FMU. Each checks the call against the FMI 3.0 state table
 * (fmi3_states.c), then its FMI 3.0 arguments, and then calls the layer's fmi2 functions,
 * which check everything else (value references, finite values in range, UTF-8, state
 * buffers) and reach the same slave as the FMI 2.0 FMU: one host layer, two interfaces.
 * Messages name the fmi3 function and FMI 3.0's terms (logger3). */
#include "host.h"
#include "fmi3_exports.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT3 FMI3_Export

/* The host's logger of one FMI 3.0 instance, behind the fmi2 callbacks the layer calls. */
typedef struct {
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback log;
} Logger3;

/* What the fmi2 layer's messages say, in FMI 3.0's words (first match wins). */
static const char *const RENAMED[][2] = {
    {"fmi2Instantiate", "fmi3InstantiateCoSimulation"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"},
    {"fmi2GetReal", "fmi3GetFloat64"}, {"fmi2SetReal", "fmi3SetFloat64"},
    {"fmi2GetInteger", "fmi3GetInt32"}, {"fmi2SetInteger", "fmi3SetInt32"},
    {"fmi2GetFMUstate", "fmi3GetFMUState"}, {"fmi2SetFMUstate", "fmi3SetFMUState"},
    {"fmi2FreeFMUstate", "fmi3FreeFMUState"},
    {"fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"},
    {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"},
    {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"},
    {"fmi2", "fmi3"}, {"GUID", "instantiation token"},
};

static void renamed(const char *text, char *out, size_t size)
{
    size_t n = 0;
    while (*text && n + 1 < size) {
        size_t i, count = sizeof RENAMED / sizeof RENAMED[0];
        for (i = 0; i < count; ++i)
            if (strncmp(text, RENAMED[i][0], strlen(RENAMED[i][0])) == 0) break;
        if (i == count) {
            out[n++] = *text++;
            continue;
        }
        n += (size_t)snprintf(out + n, size - n, "%s", RENAMED[i][1]);
        if (n >= size) n = size - 1;
        text += strlen(RENAMED[i][0]);
    }
    out[n] = 0;
}

/* fmi2CallbackLogger over the FMI 3.0 host's logMessage (none: messages are dropped). */
static void logger3(fmi2ComponentEnvironment environment, fmi2String name, fmi2Status status,
                    fmi2String category, fmi2String message, ...)
{
    Logger3 *logger = environment;
    (void)name;
    if (!logger || !logger->log) return;
    char text[2048], out[2600];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message ? message : "", args);
    va_end(args);
    renamed(text, out, sizeof out);
    logger->log(logger->environment, (fmi3Status)status, category, out);
}

EXPORT3 const char *fmi3GetVersion(void) { return fmi3Version; }

/* The file URI of local path ``path`` (percent-encoded but for unreserved characters and
 * '/'), which fmi2Instantiate's argument check reads back (arguments.c). */
static int file_uri(const char *path, char *uri, size_t size)
{
    static const char *const KEEP = "-._~/";
    size_t n = (size_t)snprintf(uri, size, "file://");
    for (const unsigned char *p = (const unsigned char *)path; *p; ++p) {
        int plain = (*p >= 'a' && *p <= 'z') || (*p >= 'A' && *p <= 'Z')
                    || (*p >= '0' && *p <= '9') || strchr(KEEP, *p);
        if (n + 4 >= size) return -1;
        n += (size_t)snprintf(uri + n, size - n, plain ? "%c" : "%%%02X", *p);
    }
    return 0;
}

/* An error before there is an instance, to the host's logMessage (printf's ``format``). */
static void log3(fmi3LogMessageCallback log, fmi3InstanceEnvironment environment,
                 const char *format, ...)
{
    char message[MAX_PATH_LENGTH + 200];
    va_list args;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    if (log) log(environment, fmi3Error, "logStatusError", message);
}

EXPORT3 fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate)
{
    char uri[3 * MAX_PATH_LENGTH + 8];
    /* never returns early, so intermediate updates are never asked for */
    (void)earlyReturnAllowed, (void)requiredIntermediateVariables;
    (void)nRequiredIntermediateVariables, (void)intermediateUpdate;
    if (eventModeUsed) {
        log3(logMessage, instanceEnvironment, "fmi3InstantiateCoSimulation: Event Mode is not "
                                              "provided (hasEventMode is false)");
        return NULL;
    }
    if (!resourcePath || resourcePath[0] != '/'
        || file_uri(resourcePath, uri, sizeof uri) != 0) {
        log3(logMessage, instanceEnvironment, "fmi3InstantiateCoSimulation: the resource path "
             "%s is not an absolute path of a folder", resourcePath ? resourcePath : "NULL");
        return NULL;
    }
    Logger3 *logger = calloc(1, sizeof *logger);
    if (!logger) return NULL;
    logger->environment = instanceEnvironment;
    logger->log = logMessage;
    fmi2CallbackFunctions functions = {logger3, calloc, free, NULL, logger};
    fmi2Component instance = fmi2Instantiate(instanceName, fmi2CoSimulation, instantiationToken,
                                             uri, &functions, visible, loggingOn);
    if (!instance) free(logger);
    return instance;
}

static fmi3Instance other_interface(fmi3InstanceEnvironment environment,
                                    fmi3LogMessageCallback log, const char *function)
{
    log3(log, environment, "%s: this FMU provides co-simulation only", function);
    return NULL;
}

EXPORT3 fmi3Instance fmi3InstantiateModelExchange(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible;
    (void)loggingOn;
    return other_interface(instanceEnvironment, logMessage, "fmi3InstantiateModelExchange");
}

EXPORT3 fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption)
{
    (void)instanceName, (void)instantiationToken, (void)resourcePath, (void)visible;
    (void)loggingOn, (void)clockUpdate, (void)lockPreemption, (void)unlockPreemption;
    return other_interface(instanceEnvironment, logMessage, "fmi3InstantiateScheduledExecution");
}

/* Allowed in every state (the fmi2 layer frees or pools the instance). */
EXPORT3 void fmi3FreeInstance(fmi3Instance instance)
{
    Guard *g = instance;
    if (!g) return;
    Logger3 *logger = g->host.componentEnvironment;
    g->host.componentEnvironment = NULL; /* freed twice by a host: the logger once */
    fmi2FreeInstance(g);
    free(logger);
}

EXPORT3 fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn,
                                       size_t nCategories, const fmi3String categories[])
{
    if (!admit3(instance, F3_fmi3SetDebugLogging)) return fmi3Error;
    return (fmi3Status)fmi2SetDebugLogging(instance, loggingOn, nCategories, categories);
}

EXPORT3 fmi3Status fmi3EnterInitializationMode(fmi3Instance instance,
                                               fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                               fmi3Float64 startTime, fmi3Boolean stopTimeDefined,
                                               fmi3Float64 stopTime)
{
    if (!admit3(instance, F3_fmi3EnterInitializationMode)) return fmi3Error;
    fmi2Status status = fmi2SetupExperiment(instance, toleranceDefined, tolerance, startTime,
                                            stopTimeDefined, stopTime);
    if (status > fmi2Warning) return (fmi3Status)status;
    fmi2Status entered = fmi2EnterInitializationMode(instance);
    return (fmi3Status)(entered > status ? entered : status);
}

EXPORT3 fmi3Status fmi3ExitInitializationMode(fmi3Instance instance)
{
    if (!admit3(instance, F3_fmi3ExitInitializationMode)) return fmi3Error;
    return (fmi3Status)fmi2ExitInitializationMode(instance);
}

EXPORT3 fmi3Status fmi3Terminate(fmi3Instance instance)
{
    if (!admit3(instance, F3_fmi3Terminate)) return fmi3Error;
    return (fmi3Status)fmi2Terminate(instance);
}

EXPORT3 fmi3Status fmi3Reset(fmi3Instance instance)
{
    if (!admit3(instance, F3_fmi3Reset)) return fmi3Error;
    return (fmi3Status)fmi2Reset(instance);
}

/* ---- values: Float64, Int32, Boolean and String variables, all scalars ---- */

/* Whether ``nValues`` fits ``nvr`` scalars; refuses the call otherwise. */
static int scalars(Guard *g, enum function3 f, size_t nvr, size_t nValues)
{
    if (nValues == nvr) return 1;
    refuse(g, "%s: %zu values for %zu value references (every variable of this FMU is a "
              "scalar)", function3_name(f), nValues, nvr);
    return 0;
}

#define SAME_TYPE(type3, function2, const_)                                                    \
    EXPORT3 fmi3Status fmi3##type3(fmi3Instance instance, const fmi3ValueReference vr[],        \
                                   size_t nvr, const_ fmi3##type3##Value values[],             \
                                   size_t nValues)                                             \
    {                                                                                          \
        if (!admit3(instance, F3_fmi3##type3) || !scalars(instance, F3_fmi3##type3, nvr, nValues)) \
            return fmi3Error;                                                                  \
        return (fmi3Status)function2(instance, vr, nvr, values);                               \
    }

typedef fmi3Int32 fmi3GetInt32Value, fmi3SetInt32Value;
typedef fmi3String fmi3GetStringValue, fmi3SetStringValue;
SAME_TYPE(GetInt32, fmi2GetInteger, )
SAME_TYPE(SetInt32, fmi2SetInteger, const)
SAME_TYPE(GetString, fmi2GetString, )
SAME_TYPE(SetString, fmi2SetString, const)

/* Whether ``vr`` names the independent variable time (FEEDAXIS_TIME_VR, after the others). */
static int time_among(const fmi3ValueReference vr[], size_t nvr)
{
    for (size_t i = 0; vr && i < nvr; ++i)
        if (vr[i] == FEEDAXIS_TIME_VR) return 1;
    return 0;
}

/* Float64: the slave's variables, and time, the last successful communication point. */
EXPORT3 fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, fmi3Float64 values[], size_t nValues)
{
    Guard *g = instance;
    if (!admit3(g, F3_fmi3GetFloat64) || !scalars(g, F3_fmi3GetFloat64, nvr, nValues))
        return fmi3Error;
    if (!time_among(vr, nvr) || !values) return (fmi3Status)fmi2GetReal(g, vr, nvr, values);
    fmi2Status status = fmi2OK;
    for (size_t i = 0; i < nvr && status <= fmi2Warning; ++i) {
        fmi2Status one = vr[i] == FEEDAXIS_TIME_VR
                             ? (values[i] = g->last_successful_time, fmi2OK)
                             : fmi2GetReal(g, &vr[i], 1, &values[i]);
        if (one > status) status = one;
    }
    return (fmi3Status)status;
}

EXPORT3 fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, const fmi3Float64 values[], size_t nValues)
{
    Guard *g = instance;
    if (!admit3(g, F3_fmi3SetFloat64) || !scalars(g, F3_fmi3SetFloat64, nvr, nValues))
        return fmi3Error;
    if (time_among(vr, nvr))
        return (fmi3Status)refuse(g, "fmi3SetFloat64: time (value reference %u) is the "
                                     "independent variable, which no host sets",
                                  FEEDAXIS_TIME_VR);
    return (fmi3Status)fmi2SetReal(g, vr, nvr, values);
}

/* fmi3Boolean is a C bool, fmi2Boolean an int: converted through a copy. */
EXPORT3 fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, fmi3Boolean values[], size_t nValues)
{
    Guard *g = instance;
    if (!admit3(g, F3_fmi3GetBoolean) || !scalars(g, F3_fmi3GetBoolean, nvr, nValues))
        return fmi3Error;
    fmi2Boolean *copy = calloc(nvr ? nvr : 1, sizeof *copy);
    if (!copy) return (fmi3Status)refuse(g, "fmi3GetBoolean: out of memory");
    fmi2Status status = fmi2GetBoolean(g, vr, nvr, values ? copy : NULL);
    for (size_t i = 0; status <= fmi2Warning && values && i < nvr; ++i) values[i] = copy[i];
    free(copy);
    return (fmi3Status)status;
}

EXPORT3 fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[],
                                  size_t nvr, const fmi3Boolean values[], size_t nValues)
{
    Guard *g = instance;
    if (!admit3(g, F3_fmi3SetBoolean) || !scalars(g, F3_fmi3SetBoolean, nvr, nValues))
        return fmi3Error;
    fmi2Boolean *copy = calloc(nvr ? nvr : 1, sizeof *copy);
    if (!copy) return (fmi3Status)refuse(g, "fmi3SetBoolean: out of memory");
    for (size_t i = 0; values && i < nvr; ++i) copy[i] = values[i];
    fmi2Status status = fmi2SetBoolean(g, vr, nvr, values ? copy : NULL);
    free(copy);
    return (fmi3Status)status;
}

/* A type this FMU has no variable of: nothing to get or set but an empty list. */
static fmi3Status no_variables(Guard *g, enum function3 f, const fmi3ValueReference vr[],
                               size_t nvr)
{
    if (!admit3(g, f)) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    return (fmi3Status)refuse(g, "%s: value reference %u is not a variable of this FMU's type "
                                 "(its variables are Float64, Int32, Boolean and String)",
                              function3_name(f), vr ? vr[0] : 0u);
}

#define NO_VARIABLES(type)                                                                      \
    EXPORT3 fmi3Status fmi3Get##type(fmi3Instance instance, const fmi3ValueReference vr[],      \
                                     size_t nvr, fmi3##type values[], size_t nValues)          \
    {                                                                                          \
        (void)values, (void)nValues;                                                           \
        return no_variables(instance, F3_fmi3Get##type, vr, nvr);                              \
    }                                                                                          \
    EXPORT3 fmi3Status fmi3Set##type(fmi3Instance instance, const fmi3ValueReference vr[],      \
                                     size_t nvr, const fmi3##type values[], size_t nValues)    \
    {                                                                                          \
        (void)values, (void)nValues;                                                           \
        return no_variables(instance, F3_fmi3Set##type, vr, nvr);                              \
    }

NO_VARIABLES(Float32)
NO_VARIABLES(Int8)
NO_VARIABLES(UInt8)
NO_VARIABLES(Int16)
NO_VARIABLES(UInt16)
NO_VARIABLES(UInt32)
NO_VARIABLES(Int64)
NO_VARIABLES(UInt64)

EXPORT3 fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[],
                                 size_t nvr, size_t valueSizes[], fmi3Binary values[],
                                 size_t nValues)
{
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables(instance, F3_fmi3GetBinary, vr, nvr);
}

EXPORT3 fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[],
                                 size_t nvr, const size_t valueSizes[],
                                 const fmi3Binary values[], size_t nValues)
{
    (void)valueSizes, (void)values, (void)nValues;
    return no_variables(instance, F3_fmi3SetBinary, vr, nvr);
}

/* ---- saved states: the fmi2 layer's, which carry the state they were saved in ---- */

EXPORT3 fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    if (!admit3(instance, F3_fmi3GetFMUState)) return fmi3Error;
    return (fmi3Status)fmi2GetFMUstate(instance, state);
}

EXPORT3 fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState state)
{
    if (!admit3(instance, F3_fmi3SetFMUState)) return fmi3Error;
    return (fmi3Status)fmi2SetFMUstate(instance, state);
}

EXPORT3 fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *state)
{
    if (!admit3(instance, F3_fmi3FreeFMUState)) return fmi3Error;
    return (fmi3Status)fmi2FreeFMUstate(instance, state);
}

EXPORT3 fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState state,
                                              size_t *size)
{
    if (!admit3(instance, F3_fmi3SerializedFMUStateSize)) return fmi3Error;
    return (fmi3Status)fmi2SerializedFMUstateSize(instance, state, size);
}

EXPORT3 fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState state,
                                         fmi3Byte serializedState[], size_t size)
{
    if (!admit3(instance, F3_fmi3SerializeFMUState)) return fmi3Error;
    return (fmi3Status)fmi2SerializeFMUstate(instance, state, (fmi2Byte *)serializedState, size);
}

EXPORT3 fmi3Status fmi3DeserializeFMUState(fmi3Instance instance,
                                           const fmi3Byte serializedState[], size_t size,
                                           fmi3FMUState *state)
{
    if (!admit3(instance, F3_fmi3DeserializeFMUState)) return fmi3Error;
    return (fmi3Status)fmi2DeSerializeFMUstate(instance, (const fmi2Byte *)serializedState,
                                               size, state);
}

/* ---- stepping ---- */

EXPORT3 fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                              fmi3Float64 communicationStepSize,
                              fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                              fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                              fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime)
{
    Guard *g = instance;
    if (!admit3(g, F3_fmi3DoStep)) return fmi3Error;
    if (!eventHandlingNeeded || !terminateSimulation || !earlyReturn || !lastSuccessfulTime)
        return (fmi3Status)refuse(g, "fmi3DoStep: NULL pointer for eventHandlingNeeded, "
                                     "terminateSimulation, earlyReturn or lastSuccessfulTime");
    fmi2Status status = fmi2DoStep(g, currentCommunicationPoint, communicationStepSize,
                                   noSetFMUStatePriorToCurrentPoint);
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    *terminateSimulation = g->wants_to_terminate ? fmi3True : fmi3False;
    *lastSuccessfulTime = g->last_successful_time;
    return (fmi3Status)status;
}

/* ---- what the FMUs do not provide (their capability flags say so) or never reach ---- */

static fmi3Status not_provided(Guard *g, enum function3 f, const char *why)
{
    return admit3(g, f) ? (fmi3Status)refuse(g, "%s is not provided (%s)", function3_name(f), why)
                        : fmi3Error;
}

EXPORT3 fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                                       fmi3ValueReference valueReference,
                                                       size_t *nDependencies)
{
    (void)valueReference, (void)nDependencies;
    return not_provided(instance, F3_fmi3GetNumberOfVariableDependencies,
                        "providesPerElementDependencies is false");
}

EXPORT3 fmi3Status fmi3GetVariableDependencies(
    fmi3Instance instance, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
    fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
    fmi3DependencyKind dependencyKinds[], size_t nDependencies)
{
    (void)dependent, (void)elementIndicesOfDependent, (void)independents;
    (void)elementIndicesOfIndependents, (void)dependencyKinds, (void)nDependencies;
    return not_provided(instance, F3_fmi3GetVariableDependencies,
                        "providesPerElementDependencies is false");
}

#define DERIVATIVE(name, flag)                                                                  \
    EXPORT3 fmi3Status fmi3##name(fmi3Instance instance, const fmi3ValueReference unknowns[],   \
                                  size_t nUnknowns, const fmi3ValueReference knowns[],          \
                                  size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,       \
                                  fmi3Float64 sensitivity[], size_t nSensitivity)               \
    {                                                                                           \
        (void)unknowns, (void)nUnknowns, (void)knowns, (void)nKnowns, (void)seed, (void)nSeed;  \
        (void)sensitivity, (void)nSensitivity;                                                  \
        return not_provided(instance, F3_fmi3##name, flag " is false");                         \
    }

DERIVATIVE(GetDirectionalDerivative, "providesDirectionalDerivatives")
DERIVATIVE(GetAdjointDerivative, "providesAdjointDerivatives")

EXPORT3 fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                            const fmi3ValueReference valueReferences[],
                                            size_t nValueReferences, const fmi3Int32 orders[],
                                            fmi3Float64 values[], size_t nValues)
{
    (void)valueReferences, (void)nValueReferences, (void)orders, (void)values, (void)nValues;
    return not_provided(instance, F3_fmi3GetOutputDerivatives,
                        "maxOutputDerivativeOrder is 0");
}

EXPORT3 fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance)
{
    return not_provided(instance, F3_fmi3EnterConfigurationMode,
                        "the FMU has no structural parameters");
}

/* Functions of modes never entered, and Model Exchange's: the table refuses them in every
 * state. */
#define NEVER_ENTERED(name, ...)                                                                \
    EXPORT3 fmi3Status fmi3##name(fmi3Instance instance, ##__VA_ARGS__)                         \
    {                                                                                           \
        return admit3(instance, F3_fmi3##name) ? fmi3OK : fmi3Error;                            \
    }

NEVER_ENTERED(EnterEventMode)
NEVER_ENTERED(ExitConfigurationMode)
NEVER_ENTERED(EvaluateDiscreteStates)
NEVER_ENTERED(EnterStepMode)
NEVER_ENTERED(UpdateDiscreteStates, fmi3Boolean *a, fmi3Boolean *b, fmi3Boolean *c,
              fmi3Boolean *d, fmi3Boolean *e, fmi3Float64 *f)
NEVER_ENTERED(GetClock, const fmi3ValueReference a[], size_t b, fmi3Clock c[])
NEVER_ENTERED(SetClock, const fmi3ValueReference a[], size_t b, const fmi3Clock c[])
NEVER_ENTERED(GetIntervalDecimal, const fmi3ValueReference a[], size_t b, fmi3Float64 c[],
              fmi3IntervalQualifier d[])
NEVER_ENTERED(GetIntervalFraction, const fmi3ValueReference a[], size_t b, fmi3UInt64 c[],
              fmi3UInt64 d[], fmi3IntervalQualifier e[])
NEVER_ENTERED(GetShiftDecimal, const fmi3ValueReference a[], size_t b, fmi3Float64 c[])
NEVER_ENTERED(GetShiftFraction, const fmi3ValueReference a[], size_t b, fmi3UInt64 c[],
              fmi3UInt64 d[])
NEVER_ENTERED(SetIntervalDecimal, const fmi3ValueReference a[], size_t b, const fmi3Float64 c[])
NEVER_ENTERED(SetIntervalFraction, const fmi3ValueReference a[], size_t b, const fmi3UInt64 c[],
              const fmi3UInt64 d[])
NEVER_ENTERED(SetShiftDecimal, const fmi3ValueReference a[], size_t b, const fmi3Float64 c[])
NEVER_ENTERED(SetShiftFraction, const fmi3ValueReference a[], size_t b, const fmi3UInt64 c[],
              const fmi3UInt64 d[])
NEVER_ENTERED(ActivateModelPartition, fmi3ValueReference a, fmi3Float64 b)
NEVER_ENTERED(EnterContinuousTimeMode)
NEVER_ENTERED(CompletedIntegratorStep, fmi3Boolean a, fmi3Boolean *b, fmi3Boolean *c)
NEVER_ENTERED(SetTime, fmi3Float64 a)
NEVER_ENTERED(SetContinuousStates, const fmi3Float64 a[], size_t b)
NEVER_ENTERED(GetContinuousStateDerivatives, fmi3Float64 a[], size_t b)
NEVER_ENTERED(GetEventIndicators, fmi3Float64 a[], size_t b)
NEVER_ENTERED(GetContinuousStates, fmi3Float64 a[], size_t b)
NEVER_ENTERED(GetNominalsOfContinuousStates, fmi3Float64 a[], size_t b)
NEVER_ENTERED(GetNumberOfEventIndicators, size_t *a)
NEVER_ENTERED(GetNumberOfContinuousStates, size_t *a)
