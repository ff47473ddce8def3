/* The fmi2 functions. Each checks the call against the state table (states.c), then its
 * arguments (references.c, arguments.c), and only then reaches pythonfmu or the mirror. */
#include "host.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* pythonfmu's ``function`` on instance ``g`` after pending inputs are handed over; the
 * status by the state table (conclude). Declares ``status``. */
#define FORWARD(function, ...)                                                                  \
    static function##TYPE *call_; /* resolved once: dlsym costs a microsecond */              \
    if (!call_) call_ = (function##TYPE *)real(#function);                                    \
    hand_over(g);                                                                       \
    begin(g);                                                                                  \
    fmi2Status status = conclude(g, F_##function, call_(g->real, ##__VA_ARGS__))

EXPORT const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
EXPORT const char *fmi2GetVersion(void) { return fmi2Version; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid,
                                     fmi2String resources, const fmi2CallbackFunctions *functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    char folder[MAX_PATH_LENGTH], location[MAX_PATH_LENGTH + 8];
    if (!instantiate_arguments_valid(instanceName, fmuType, guid, resources, functions, folder,
                                     sizeof folder))
        return NULL;
    load_once(folder);
    if (!python_loaded()) {
        log_before_instance(functions, instanceName, fmi2Fatal, "%s",
                            *load_error ? load_error : "pythonfmu library incomplete");
        return NULL;
    }
    /* the one form pythonfmu reads: file:// and the path, decoded */
    snprintf(location, sizeof location, "file://%s", folder);
    Guard *g = reuse(instanceName, guid, location, functions, loggingOn);
    if (g) return g;
    g = calloc(1, sizeof *g);
    if (!g) return NULL;
    attach(g, instanceName, functions, loggingOn);
    g->guid = strdup(guid);
    g->resources = strdup(location);
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)real("fmi2Instantiate");
    begin(g);
    expect_slave();
    g->real = instantiate(instanceName, fmuType, guid, location, &g->mine, visible, 1);
    if (g->real && g->worst_logged < fmi2Error) {
        claim_exchange(g);
        return g;
    }
    release(g);  /* a component pythonfmu returned with an error is leaked, never touched */
    return NULL;
}

/* Allowed in every state: in the fatal state only the layer's part is freed (pythonfmu's
 * instance holds freed Python objects). */
EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Guard *g = c;
    if (!g) return;
    if (g->mode == FATAL) {
        release(g);
        return;
    }
    g->host.logger = NULL;  /* the host's callbacks end here */
    drop_exchange(g);
    if (put_pooled(g)) return;
    fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)real("fmi2FreeInstance");
    free_instance(g->real);
    release(g);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n,
                                      const fmi2String categories[])
{
    Guard *g = c;
    if (!admit(g, F_fmi2SetDebugLogging)) return fmi2Error;
    if (n > 0 && !categories)
        return refuse(g, "fmi2SetDebugLogging: NULL array for %zu categories", n);
    g->host_logging = loggingOn;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol,
                                      fmi2Real start, fmi2Boolean stopDefined, fmi2Real stop)
{
    Guard *g = c;
    if (!admit(g, F_fmi2SetupExperiment)) return fmi2Error;
    if (!isfinite(start) || (stopDefined && !(stop >= start)) || (tolDefined && !(tol > 0)))
        return refuse(g, "fmi2SetupExperiment: start time %g, stop time %g (%s), tolerance %g "
                         "(%s): the start must be finite, the stop not before it, the "
                         "tolerance > 0", start, stop, stopDefined ? "defined" : "undefined",
                      tol, tolDefined ? "defined" : "undefined");
    FORWARD(fmi2SetupExperiment, tolDefined, tol, start, stopDefined, stop);
    g->last_successful_time = start;
    return status;
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    Guard *g = c;
    if (!admit(g, F_fmi2EnterInitializationMode)) return fmi2Error;
    FORWARD(fmi2EnterInitializationMode);
    slave_changed(g);
    return status;
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    Guard *g = c;
    if (!admit(g, F_fmi2ExitInitializationMode)) return fmi2Error;
    FORWARD(fmi2ExitInitializationMode);
    slave_changed(g);
    if (fast(g)) load_mirror(g);
    return status;
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    Guard *g = c;
    if (!admit(g, F_fmi2Terminate)) return fmi2Error;
    FORWARD(fmi2Terminate);
    slave_changed(g);
    return status;
}

EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    Guard *g = c;
    if (!admit(g, F_fmi2Reset)) return fmi2Error;
    expect_slave();
    FORWARD(fmi2Reset);
    slave_changed(g);
    if (status <= fmi2Warning) {
        g->wants_to_terminate = 0;
        claim_exchange(g);
    }
    return status;
}

/* ``code``: the variable type the function takes (references_known). */
#define GETTER(function, type, code)                                                            \
    EXPORT fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                               type value[])                                                    \
    {                                                                                           \
        Guard *g = c;                                                                           \
        if (!admit(g, F_##function) || !references_known(g, #function, code, vr, nvr, value))   \
            return fmi2Error;                                                                   \
        FORWARD(function, vr, nvr, value);                                                      \
        return status;                                                                          \
    }

GETTER(fmi2GetInteger, fmi2Integer, 'I')
GETTER(fmi2GetBoolean, fmi2Boolean, 'B')
GETTER(fmi2GetString, fmi2String, 'S')

/* ``valid``: the check of the values (references.c), or NULL when any value will do. */
#define SETTER(function, type, code, valid)                                                     \
    EXPORT fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                               const type value[])                                              \
    {                                                                                           \
        Guard *g = c;                                                                           \
        int (*check)(Guard *, const char *, const fmi2ValueReference[], size_t,                 \
                     const type[]) = valid;                                                     \
        if (!admit(g, F_##function) || !references_known(g, #function, code, vr, nvr, value)   \
            || !settable(g, vr, nvr) || (check && !check(g, #function, vr, nvr, value)))       \
            return fmi2Error;                                                                   \
        FORWARD(function, vr, nvr, value);                                                      \
        slave_changed(g);                                                                       \
        return status;                                                                          \
    }

SETTER(fmi2SetInteger, fmi2Integer, 'I', integers_valid)
SETTER(fmi2SetBoolean, fmi2Boolean, 'B', NULL)
SETTER(fmi2SetString, fmi2String, 'S', strings_valid)

/* Reals: in step complete, the mirror answers the Real inputs and outputs (mirror_get,
 * mirror_set); any other Real goes to pythonfmu as the other types do. */
EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                              fmi2Real value[])
{
    Guard *g = c;
    if (mirror_get(g, vr, nvr, value)) return fmi2OK; /* step complete: allowed */
    if (!admit(g, F_fmi2GetReal) || !references_known(g, "fmi2GetReal", 'R', vr, nvr, value))
        return fmi2Error;
    FORWARD(fmi2GetReal, vr, nvr, value);
    return status;
}

EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                              const fmi2Real value[])
{
    Guard *g = c;
    if (!admit(g, F_fmi2SetReal) || !references_known(g, "fmi2SetReal", 'R', vr, nvr, value)
        || !settable(g, vr, nvr) || !reals_valid(g, "fmi2SetReal", vr, nvr, value))
        return fmi2Error;
    if (mirror_set(g, vr, nvr, value)) return fmi2OK; /* inputs, in step complete */
    FORWARD(fmi2SetReal, vr, nvr, value);
    slave_changed(g);
    return status;
}

/* ---- what the FMUs do not provide (their capability flags say so) ---- */

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[],
                                               size_t nu, const fmi2ValueReference z[], size_t nz,
                                               const fmi2Real dv[], fmi2Real dz[])
{
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    return admit(c, F_fmi2GetDirectionalDerivative)
               ? refuse(c, "fmi2GetDirectionalDerivative is not provided "
                           "(providesDirectionalDerivative is false)")
               : fmi2Error;
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                              size_t nvr, const fmi2Integer order[],
                                              const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return admit(c, F_fmi2SetRealInputDerivatives)
               ? refuse(c, "fmi2SetRealInputDerivatives is not provided (canInterpolateInputs "
                           "is false)")
               : fmi2Error;
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                               size_t nvr, const fmi2Integer order[],
                                               fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return admit(c, F_fmi2GetRealOutputDerivatives)
               ? refuse(c, "fmi2GetRealOutputDerivatives is not provided "
                           "(maxOutputDerivativeOrder is 0)")
               : fmi2Error;
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    /* allowed in stepInProgress only, which is never entered: admit refuses it */
    return admit(c, F_fmi2CancelStep) ? fmi2OK : fmi2Error;
}

/* ---- stepping ---- */

/* Bookkeeping after a step from ``t`` over ``h`` that ended with ``status``. */
static fmi2Status stepped(Guard *g, fmi2Real t, fmi2Real h, fmi2Status status)
{
    g->last_successful_time = status <= fmi2Warning ? t + h : t;
    if (status > fmi2Warning) g->wants_to_terminate = 1;
    return status;
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior)
{
    Guard *g = c;
    if (!admit(g, F_fmi2DoStep)) return fmi2Error;
    if (fast(g) && (g->inputs_current || load_mirror(g))) {
        begin(g);
        return stepped(g, t, h, conclude(g, F_fmi2DoStep, exchange_step(g, t, h)));
    }
    FORWARD(fmi2DoStep, t, h, no_set_prior);
    slave_changed(g);
    return stepped(g, t, h, status);
}

/* ---- status: kept here (fmi2DoStep never returns fmi2Pending); a kind the FMU does not
 * provide is fmi2Discard, as the standard says ---- */

#define NO_STATUS(function, type)                                                               \
    EXPORT fmi2Status function(fmi2Component c, const fmi2StatusKind kind, type *value)         \
    {                                                                                           \
        (void)kind, (void)value;                                                                \
        return admit(c, F_##function) ? fmi2Discard : fmi2Error;                                \
    }

NO_STATUS(fmi2GetStatus, fmi2Status)
NO_STATUS(fmi2GetIntegerStatus, fmi2Integer)
NO_STATUS(fmi2GetStringStatus, fmi2String)

EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *value)
{
    Guard *g = c;
    if (!admit(g, F_fmi2GetRealStatus)) return fmi2Error;
    if (!value) return refuse(g, "fmi2GetRealStatus: NULL pointer for the value");
    if (kind != fmi2LastSuccessfulTime) return fmi2Discard;
    *value = g->last_successful_time;
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind,
                                       fmi2Boolean *value)
{
    Guard *g = c;
    if (!admit(g, F_fmi2GetBooleanStatus)) return fmi2Error;
    if (!value) return refuse(g, "fmi2GetBooleanStatus: NULL pointer for the value");
    if (kind != fmi2Terminated) return fmi2Discard;
    *value = g->wants_to_terminate;
    return fmi2OK;
}
