/* The FMI 3.0 side of the host layer (an FMI 3.0 FMU is compiled with FEEDAXIS_FMI3). */
#ifndef FEEDAXIS_FMI3_EXPORTS_H
#define FEEDAXIS_FMI3_EXPORTS_H

#include "fmi3Functions.h" /* the official FMI 3.0 headers (fmi3/): every export checked */

#define FUNCTIONS3(X)                                                                          \
    X(SetDebugLogging) X(EnterInitializationMode) X(ExitInitializationMode) X(EnterEventMode)  \
    X(Terminate) X(Reset)                                                                      \
    X(GetFloat32) X(GetFloat64) X(GetInt8) X(GetUInt8) X(GetInt16) X(GetUInt16) X(GetInt32)   \
    X(GetUInt32) X(GetInt64) X(GetUInt64) X(GetBoolean) X(GetString) X(GetBinary) X(GetClock) \
    X(SetFloat32) X(SetFloat64) X(SetInt8) X(SetUInt8) X(SetInt16) X(SetUInt16) X(SetInt32)   \
    X(SetUInt32) X(SetInt64) X(SetUInt64) X(SetBoolean) X(SetString) X(SetBinary) X(SetClock) \
    X(GetNumberOfVariableDependencies) X(GetVariableDependencies)                              \
    X(GetFMUState) X(SetFMUState) X(FreeFMUState) X(SerializedFMUStateSize)                    \
    X(SerializeFMUState) X(DeserializeFMUState)                                                \
    X(GetDirectionalDerivative) X(GetAdjointDerivative)                                        \
    X(EnterConfigurationMode) X(ExitConfigurationMode)                                         \
    X(GetIntervalDecimal) X(GetIntervalFraction) X(GetShiftDecimal) X(GetShiftFraction)        \
    X(SetIntervalDecimal) X(SetIntervalFraction) X(SetShiftDecimal) X(SetShiftFraction)        \
    X(EvaluateDiscreteStates) X(UpdateDiscreteStates)                                          \
    X(EnterStepMode) X(GetOutputDerivatives) X(DoStep) X(ActivateModelPartition)              \
    X(EnterContinuousTimeMode) X(CompletedIntegratorStep) X(SetTime) X(SetContinuousStates)    \
    X(GetContinuousStateDerivatives) X(GetEventIndicators) X(GetContinuousStates)              \
    X(GetNominalsOfContinuousStates) X(GetNumberOfEventIndicators)                             \
    X(GetNumberOfContinuousStates)

#define ENUMERATE3(name) F3_fmi3##name,
enum function3 { FUNCTIONS3(ENUMERATE3) N_FUNCTIONS3 };
#undef ENUMERATE3

/* ---- fmi3_states.c ---- */
int admit3(Guard *g, enum function3 f);
const char *function3_name(enum function3 f);

#endif
