/* The FMI 3.0 co-simulation state machine as one table (FMI 3.0, section 4.2 and its
 * table of the functions callable per state), for an FMU without Event Mode, clocks,
 * structural parameters or intermediate updates: Configuration, Reconfiguration, Event,
 * Clock Activation and Intermediate Update Mode are never entered.
 *
 * The instance's state is the one the fmi2 layer keeps (Guard.mode): instantiated,
 * initialisation mode, step mode (fmi2's step complete), step discarded (step failed),
 * terminated, the error and the fatal state. Each fmi3 function is checked against its row
 * here before anything else (admit3) and then calls the fmi2 functions of the layer, whose
 * outcome moves the instance (states.c): fmi3EnterInitializationMode to initialisation mode,
 * fmi3ExitInitializationMode to step mode, fmi3Terminate to terminated, fmi3Reset to
 * instantiated, fmi3DoStep's fmi3Discard to step discarded, every fmi3Error to the error
 * state, left by fmi3Reset, fmi3SetFMUState with a state saved while healthy, and
 * fmi3FreeInstance. */
#include "host.h"
#include "fmi3_exports.h"

#define BIT(mode) (1u << (mode))
#define LIVE (BIT(INSTANTIATED) | BIT(INITIALISATION) | BIT(STEP_COMPLETE) | BIT(STEP_FAILED) \
              | BIT(TERMINATED) | BIT(ERROR))
#define STEPPING (BIT(STEP_COMPLETE) | BIT(STEP_FAILED))
#define READABLE (BIT(INITIALISATION) | STEPPING | BIT(TERMINATED) | BIT(ERROR))
#define SETTABLE (BIT(INSTANTIATED) | BIT(INITIALISATION) | BIT(STEP_COMPLETE))
#define NEVER 0u /* only in a mode these FMUs never enter */

static const char *const MODE_NAMES3[N_MODES] = {
    "instantiated", "initialisation mode", "step mode", "step mode after a discarded step",
    "terminated", "the error state", "the fatal state"};

#define GETSET(type) [F3_fmi3Get##type] = {"fmi3Get" #type, READABLE}, \
                     [F3_fmi3Set##type] = {"fmi3Set" #type, SETTABLE}

static const struct {
    const char *name;
    unsigned allowed; /* BIT(mode) of each state the function may be called in */
} TABLE3[N_FUNCTIONS3] = {
    [F3_fmi3SetDebugLogging] = {"fmi3SetDebugLogging", LIVE},
    [F3_fmi3EnterInitializationMode] = {"fmi3EnterInitializationMode", BIT(INSTANTIATED)},
    [F3_fmi3ExitInitializationMode] = {"fmi3ExitInitializationMode", BIT(INITIALISATION)},
    [F3_fmi3EnterEventMode] = {"fmi3EnterEventMode", NEVER},
    [F3_fmi3Terminate] = {"fmi3Terminate", STEPPING},
    [F3_fmi3Reset] = {"fmi3Reset", LIVE},
    GETSET(Float32), GETSET(Float64), GETSET(Int8), GETSET(UInt8), GETSET(Int16),
    GETSET(UInt16), GETSET(Int32), GETSET(UInt32), GETSET(Int64), GETSET(UInt64),
    GETSET(Boolean), GETSET(String), GETSET(Binary),
    [F3_fmi3GetClock] = {"fmi3GetClock", NEVER},
    [F3_fmi3SetClock] = {"fmi3SetClock", NEVER},
    [F3_fmi3GetNumberOfVariableDependencies] = {"fmi3GetNumberOfVariableDependencies", LIVE},
    [F3_fmi3GetVariableDependencies] = {"fmi3GetVariableDependencies", LIVE},
    [F3_fmi3GetFMUState] = {"fmi3GetFMUState", LIVE},
    [F3_fmi3SetFMUState] = {"fmi3SetFMUState", LIVE},
    [F3_fmi3FreeFMUState] = {"fmi3FreeFMUState", LIVE},
    [F3_fmi3SerializedFMUStateSize] = {"fmi3SerializedFMUStateSize", LIVE},
    [F3_fmi3SerializeFMUState] = {"fmi3SerializeFMUState", LIVE},
    [F3_fmi3DeserializeFMUState] = {"fmi3DeserializeFMUState", LIVE},
    [F3_fmi3GetDirectionalDerivative] = {"fmi3GetDirectionalDerivative",
                                         READABLE & ~BIT(ERROR)},
    [F3_fmi3GetAdjointDerivative] = {"fmi3GetAdjointDerivative", READABLE & ~BIT(ERROR)},
    [F3_fmi3EnterConfigurationMode] = {"fmi3EnterConfigurationMode",
                                       BIT(INSTANTIATED) | BIT(STEP_COMPLETE)},
    [F3_fmi3ExitConfigurationMode] = {"fmi3ExitConfigurationMode", NEVER},
    [F3_fmi3GetIntervalDecimal] = {"fmi3GetIntervalDecimal", NEVER},
    [F3_fmi3GetIntervalFraction] = {"fmi3GetIntervalFraction", NEVER},
    [F3_fmi3GetShiftDecimal] = {"fmi3GetShiftDecimal", NEVER},
    [F3_fmi3GetShiftFraction] = {"fmi3GetShiftFraction", NEVER},
    [F3_fmi3SetIntervalDecimal] = {"fmi3SetIntervalDecimal", NEVER},
    [F3_fmi3SetIntervalFraction] = {"fmi3SetIntervalFraction", NEVER},
    [F3_fmi3SetShiftDecimal] = {"fmi3SetShiftDecimal", NEVER},
    [F3_fmi3SetShiftFraction] = {"fmi3SetShiftFraction", NEVER},
    [F3_fmi3EvaluateDiscreteStates] = {"fmi3EvaluateDiscreteStates", NEVER},
    [F3_fmi3UpdateDiscreteStates] = {"fmi3UpdateDiscreteStates", NEVER},
    [F3_fmi3EnterStepMode] = {"fmi3EnterStepMode", NEVER},
    [F3_fmi3GetOutputDerivatives] = {"fmi3GetOutputDerivatives",
                                     STEPPING | BIT(TERMINATED) | BIT(ERROR)},
    [F3_fmi3DoStep] = {"fmi3DoStep", BIT(STEP_COMPLETE)},
    [F3_fmi3ActivateModelPartition] = {"fmi3ActivateModelPartition", NEVER},
    /* Model Exchange's: a co-simulation instance takes none */
    [F3_fmi3EnterContinuousTimeMode] = {"fmi3EnterContinuousTimeMode", NEVER},
    [F3_fmi3CompletedIntegratorStep] = {"fmi3CompletedIntegratorStep", NEVER},
    [F3_fmi3SetTime] = {"fmi3SetTime", NEVER},
    [F3_fmi3SetContinuousStates] = {"fmi3SetContinuousStates", NEVER},
    [F3_fmi3GetContinuousStateDerivatives] = {"fmi3GetContinuousStateDerivatives", NEVER},
    [F3_fmi3GetEventIndicators] = {"fmi3GetEventIndicators", NEVER},
    [F3_fmi3GetContinuousStates] = {"fmi3GetContinuousStates", NEVER},
    [F3_fmi3GetNominalsOfContinuousStates] = {"fmi3GetNominalsOfContinuousStates", NEVER},
    [F3_fmi3GetNumberOfEventIndicators] = {"fmi3GetNumberOfEventIndicators", NEVER},
    [F3_fmi3GetNumberOfContinuousStates] = {"fmi3GetNumberOfContinuousStates", NEVER},
};

/* Whether instance ``g`` may take a call of ``f`` now; refuses it otherwise (fmi3Error,
 * the error state; a NULL instance silently: there is no logger to tell). */
int admit3(Guard *g, enum function3 f)
{
    if (!g) return 0;
    if (TABLE3[f].allowed & BIT(g->mode)) return 1;
    refuse(g, "%s is not allowed in %s (FMI 3.0, section 4.2)", TABLE3[f].name,
           MODE_NAMES3[g->mode]);
    return 0;
}

const char *function3_name(enum function3 f)
{
    return TABLE3[f].name;
}
