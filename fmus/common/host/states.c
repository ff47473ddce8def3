/* The FMI 2.0 co-simulation state machine as one table (the standard's section 4.2.4 and
 * its table of the functions callable per state; the reference FMUs keep the same masks).
 *
 * Every call is checked against its row before anything else (admit) and moves the instance
 * by its status (conclude): fmi2OK or fmi2Warning to the row's next state, fmi2Discard from
 * fmi2DoStep to stepFailed, fmi2Error to the error state, fmi2Fatal to the fatal state. A
 * call the table does not allow is fmi2Error: the standard makes every fmi2Error end in the
 * error state, whatever caused it. The error state is left by fmi2Reset (to instantiated),
 * fmi2SetFMUstate with a state saved while healthy (to the state it was saved in) and
 * fmi2FreeInstance; in it, the fmi2Get functions still answer (to find out what happened).
 * The fatal state allows only fmi2FreeInstance, which then never reaches pythonfmu (its
 * instance holds freed Python objects). fmi2GetTypesPlatform and fmi2GetVersion take no
 * instance, fmi2Instantiate makes one: neither is in the table. */
#include "host.h"

#include <stdarg.h>
#include <stdio.h>

#define BIT(mode) (1u << (mode))
#define LIVE (BIT(INSTANTIATED) | BIT(INITIALISATION) | BIT(STEP_COMPLETE) | BIT(STEP_FAILED) \
              | BIT(TERMINATED) | BIT(ERROR))
#define INITIALISED (BIT(INITIALISATION) | BIT(STEP_COMPLETE) | BIT(STEP_FAILED) \
                     | BIT(TERMINATED) | BIT(ERROR))
#define SETTABLE (BIT(INSTANTIATED) | BIT(INITIALISATION) | BIT(STEP_COMPLETE))
#define STATUS (BIT(STEP_COMPLETE) | BIT(STEP_FAILED) | BIT(TERMINATED))
#define STAY N_MODES /* next: the state does not change */

const char *const MODE_NAMES[N_MODES] = {"instantiated", "initialisation mode", "step complete",
                                         "step failed", "terminated", "the error state",
                                         "the fatal state"};

static const struct {
    const char *name;
    unsigned allowed; /* BIT(mode) of each state the function may be called in */
    enum mode next;   /* the state after fmi2OK or fmi2Warning */
} TABLE[N_FUNCTIONS] = {
    [F_fmi2SetDebugLogging] = {"fmi2SetDebugLogging", LIVE, STAY},
    [F_fmi2SetupExperiment] = {"fmi2SetupExperiment", BIT(INSTANTIATED), STAY},
    [F_fmi2EnterInitializationMode] = {"fmi2EnterInitializationMode", BIT(INSTANTIATED),
                                       INITIALISATION},
    [F_fmi2ExitInitializationMode] = {"fmi2ExitInitializationMode", BIT(INITIALISATION),
                                      STEP_COMPLETE},
    [F_fmi2Terminate] = {"fmi2Terminate", BIT(STEP_COMPLETE) | BIT(STEP_FAILED), TERMINATED},
    [F_fmi2Reset] = {"fmi2Reset", LIVE, INSTANTIATED},
    [F_fmi2GetReal] = {"fmi2GetReal", INITIALISED, STAY},
    [F_fmi2GetInteger] = {"fmi2GetInteger", INITIALISED, STAY},
    [F_fmi2GetBoolean] = {"fmi2GetBoolean", INITIALISED, STAY},
    [F_fmi2GetString] = {"fmi2GetString", INITIALISED, STAY},
    [F_fmi2SetReal] = {"fmi2SetReal", SETTABLE, STAY},
    [F_fmi2SetInteger] = {"fmi2SetInteger", SETTABLE, STAY},
    [F_fmi2SetBoolean] = {"fmi2SetBoolean", SETTABLE, STAY},
    [F_fmi2SetString] = {"fmi2SetString", SETTABLE, STAY},
    [F_fmi2GetFMUstate] = {"fmi2GetFMUstate", LIVE, STAY},
    [F_fmi2SetFMUstate] = {"fmi2SetFMUstate", LIVE, STAY}, /* then: the saved state's */
    [F_fmi2FreeFMUstate] = {"fmi2FreeFMUstate", LIVE, STAY},
    [F_fmi2SerializedFMUstateSize] = {"fmi2SerializedFMUstateSize", LIVE, STAY},
    [F_fmi2SerializeFMUstate] = {"fmi2SerializeFMUstate", LIVE, STAY},
    [F_fmi2DeSerializeFMUstate] = {"fmi2DeSerializeFMUstate", LIVE, STAY},
    [F_fmi2GetDirectionalDerivative] = {"fmi2GetDirectionalDerivative", INITIALISED, STAY},
    [F_fmi2SetRealInputDerivatives] = {"fmi2SetRealInputDerivatives", SETTABLE, STAY},
    [F_fmi2GetRealOutputDerivatives] = {"fmi2GetRealOutputDerivatives",
                                        STATUS | BIT(ERROR), STAY},
    [F_fmi2DoStep] = {"fmi2DoStep", BIT(STEP_COMPLETE), STAY},
    [F_fmi2CancelStep] = {"fmi2CancelStep", 0 /* stepInProgress: never entered */, STAY},
    [F_fmi2GetStatus] = {"fmi2GetStatus", STATUS, STAY},
    [F_fmi2GetRealStatus] = {"fmi2GetRealStatus", STATUS, STAY},
    [F_fmi2GetIntegerStatus] = {"fmi2GetIntegerStatus", STATUS, STAY},
    [F_fmi2GetBooleanStatus] = {"fmi2GetBooleanStatus", STATUS, STAY},
    [F_fmi2GetStringStatus] = {"fmi2GetStringStatus", STATUS, STAY},
};

/* Log ``format`` as an error and put the instance into the error state (the fatal state
 * stays). Returns fmi2Error. */
fmi2Status refuse(Guard *g, const char *format, ...)
{
    char message[512];
    va_list args;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    tell_host(g, fmi2Error, NULL, message);
    if (g->mode != FATAL) g->mode = ERROR;
    return fmi2Error;
}

/* Whether instance ``g`` may take a call of ``f`` now; refuses it otherwise (a NULL
 * instance silently: there is no logger to tell). */
int admit(Guard *g, enum function f)
{
    if (!g) return 0;
    if (TABLE[f].allowed & BIT(g->mode)) return 1;
    refuse(g, "%s is not allowed in %s (FMI 2.0, section 4.2.4)", TABLE[f].name,
           MODE_NAMES[g->mode]);
    return 0;
}

void begin(Guard *g)
{
    g->worst_logged = fmi2OK;
}

/* The status of a call of ``f`` that returned ``status``: made worse by an error the slave
 * logged meanwhile; the instance moves by it (the top of this file). */
fmi2Status conclude(Guard *g, enum function f, fmi2Status status)
{
    if (g->worst_logged >= fmi2Error && status < g->worst_logged) status = g->worst_logged;
    if (status == fmi2Fatal) g->mode = FATAL;
    else if (status == fmi2Error) g->mode = ERROR;
    else if (status == fmi2Discard && f == F_fmi2DoStep) g->mode = STEP_FAILED;
    else if (status <= fmi2Warning && TABLE[f].next != STAY) g->mode = TABLE[f].next;
    return status;
}
