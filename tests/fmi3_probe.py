"""Every fmi3 function of an unpacked FMI 3.0 FMU in every state, through fmpy's low-level
FMI 3 API, in a process of its own (a crash there ends only this process); prints one JSON
line.

    python tests/fmi3_probe.py matrix FOLDER
        {"answers": {function: {state: status}}, "alive": true, "messages": [...]}
"""
import json
import sys
from ctypes import byref, c_bool, c_char_p, c_double, c_float, c_int8, c_int16, c_int32
from ctypes import c_int64, c_size_t, c_uint8, c_uint16, c_uint32, c_uint64, c_void_p
from ctypes import POINTER
from pathlib import Path

from fmpy import read_model_description
from fmpy.fmi3 import FMU3Slave, fmi3IntermediateUpdateCallback, fmi3LogMessageCallback

STATES = ("instantiated", "initialisation", "step mode", "terminated", "error")
MESSAGES = []
NO_VARIABLES = {"Float32": c_float, "Int8": c_int8, "UInt8": c_uint8, "Int16": c_int16,
                "UInt16": c_uint16, "UInt32": c_uint32, "Int64": c_int64, "UInt64": c_uint64}


@fmi3LogMessageCallback
def _log(environment, status, category, message):
    MESSAGES.append([status, (category or b"").decode(errors="replace"),
                     (message or b"").decode(errors="replace")])


def instantiate(dll, token, folder):
    return dll.fmi3InstantiateCoSimulation(b"matrix", token.encode(),
                                           f"{Path(folder) / 'resources'}/".encode(), False,
                                           True, False, False, None, 0, None, _log,
                                           fmi3IntermediateUpdateCallback())


class Calls:
    """Each fmi3 function called on ``instance`` with the arguments a correct host passes."""

    def __init__(self, dll, description, instance):
        self.dll, self.i = dll, instance
        variables = description.modelVariables
        self.out = next(v.valueReference for v in variables if v.causality == "output")
        # an FMU without inputs (the circle interpolator): a Float64 parameter stands in
        # where a value reference is needed, the set passes no values (the state table alone
        # decides) and NaN for that parameter reaches the error state
        inputs = [v for v in variables if v.causality == "input"]
        real_in = (inputs or [v for v in variables
                              if v.causality == "parameter" and v.type == "Float64"])[0]
        self.inp, self.start = real_in.valueReference, float(real_in.start or 0.0)
        self.n_in = 1 if inputs else 0
        self.first = {kind: [v.valueReference for v in variables if v.type == kind][:1]
                      for kind in ("Int32", "Boolean", "String")}
        self.state = c_void_p()
        self.serialized = None

    def prepare(self):
        """A state saved in the instance's current state, and its serialisation."""
        self.state = c_void_p()
        self.dll.fmi3GetFMUState(self.i, byref(self.state))
        size = c_size_t()
        self.dll.fmi3SerializedFMUStateSize(self.i, self.state, byref(size))
        self.serialized = (c_uint8 * size.value)()
        self.dll.fmi3SerializeFMUState(self.i, self.state, self.serialized, size)

    def get(self, kind, ctype):
        vrs = self.first[kind]
        return getattr(self.dll, f"fmi3Get{kind}")(self.i, (c_uint32 * 1)(*vrs), len(vrs),
                                                   (ctype * 1)(), len(vrs))

    def set(self, kind, ctype):
        """No values: the state table alone decides (these types are fixed parameters)."""
        return getattr(self.dll, f"fmi3Set{kind}")(self.i, (c_uint32 * 1)(), 0, (ctype * 1)(), 0)

    def table(self):
        d, i = self.dll, self.i
        out, inp, none = (c_uint32 * 1)(self.out), (c_uint32 * 1)(self.inp), (c_uint32 * 1)()
        flags = [c_bool() for _ in range(6)]
        calls = {
            "fmi3SetDebugLogging": lambda: d.fmi3SetDebugLogging(i, True, 0, None),
            "fmi3EnterInitializationMode":
                lambda: d.fmi3EnterInitializationMode(i, False, 0.0, 0.0, False, 0.0),
            "fmi3ExitInitializationMode": lambda: d.fmi3ExitInitializationMode(i),
            "fmi3EnterEventMode": lambda: d.fmi3EnterEventMode(i),
            "fmi3Terminate": lambda: d.fmi3Terminate(i),
            "fmi3Reset": lambda: d.fmi3Reset(i),
            "fmi3GetFloat64": lambda: d.fmi3GetFloat64(i, out, 1, (c_double * 1)(), 1),
            "fmi3SetFloat64": lambda: d.fmi3SetFloat64(i, inp, self.n_in,
                                                      (c_double * 1)(self.start), self.n_in),
            "fmi3GetInt32": lambda: self.get("Int32", c_int32),
            "fmi3SetInt32": lambda: self.set("Int32", c_int32),
            "fmi3GetBoolean": lambda: self.get("Boolean", c_bool),
            "fmi3SetBoolean": lambda: self.set("Boolean", c_bool),
            "fmi3GetString": lambda: self.get("String", c_char_p),
            "fmi3SetString": lambda: self.set("String", c_char_p),
            "fmi3GetBinary": lambda: d.fmi3GetBinary(i, none, 0, (c_size_t * 1)(),
                                                     (POINTER(c_uint8) * 1)(), 0),
            "fmi3SetBinary": lambda: d.fmi3SetBinary(i, none, 0, (c_size_t * 1)(),
                                                     (POINTER(c_uint8) * 1)(), 0),
            "fmi3GetClock": lambda: d.fmi3GetClock(i, none, 0, (c_bool * 1)()),
            "fmi3SetClock": lambda: d.fmi3SetClock(i, none, 0, (c_bool * 1)()),
            "fmi3GetNumberOfVariableDependencies":
                lambda: d.fmi3GetNumberOfVariableDependencies(i, self.out, byref(c_size_t())),
            "fmi3GetVariableDependencies": lambda: d.fmi3GetVariableDependencies(
                i, self.out, (c_size_t * 1)(), (c_uint32 * 1)(), (c_size_t * 1)(),
                (c_int32 * 1)(), 1),
            "fmi3GetFMUState": lambda: d.fmi3GetFMUState(i, byref(c_void_p())),
            "fmi3SetFMUState": lambda: d.fmi3SetFMUState(i, self.state),
            "fmi3FreeFMUState": lambda: d.fmi3FreeFMUState(i, byref(self.state)),
            "fmi3SerializedFMUStateSize":
                lambda: d.fmi3SerializedFMUStateSize(i, self.state, byref(c_size_t())),
            "fmi3SerializeFMUState": lambda: d.fmi3SerializeFMUState(
                i, self.state, self.serialized, len(self.serialized)),
            "fmi3DeserializeFMUState": lambda: d.fmi3DeserializeFMUState(
                i, self.serialized, len(self.serialized), byref(c_void_p())),
            **{f"fmi3{name}": (lambda name=name: getattr(d, f"fmi3{name}")(
                i, out, 1, inp, 1, (c_double * 1)(1.0), 1, (c_double * 1)(), 1))
               for name in ("GetDirectionalDerivative", "GetAdjointDerivative")},
            "fmi3EnterConfigurationMode": lambda: d.fmi3EnterConfigurationMode(i),
            "fmi3ExitConfigurationMode": lambda: d.fmi3ExitConfigurationMode(i),
            "fmi3GetIntervalDecimal": lambda: d.fmi3GetIntervalDecimal(
                i, none, 0, (c_double * 1)(), (c_int32 * 1)()),
            "fmi3GetIntervalFraction": lambda: d.fmi3GetIntervalFraction(
                i, none, 0, (c_uint64 * 1)(), (c_uint64 * 1)(), (c_int32 * 1)()),
            "fmi3GetShiftDecimal": lambda: d.fmi3GetShiftDecimal(i, none, 0, (c_double * 1)()),
            "fmi3GetShiftFraction": lambda: d.fmi3GetShiftFraction(
                i, none, 0, (c_uint64 * 1)(), (c_uint64 * 1)()),
            "fmi3SetIntervalDecimal": lambda: d.fmi3SetIntervalDecimal(
                i, none, 0, (c_double * 1)()),
            "fmi3SetIntervalFraction": lambda: d.fmi3SetIntervalFraction(
                i, none, 0, (c_uint64 * 1)(), (c_uint64 * 1)()),
            "fmi3SetShiftDecimal": lambda: d.fmi3SetShiftDecimal(i, none, 0, (c_double * 1)()),
            "fmi3SetShiftFraction": lambda: d.fmi3SetShiftFraction(
                i, none, 0, (c_uint64 * 1)(), (c_uint64 * 1)()),
            "fmi3EvaluateDiscreteStates": lambda: d.fmi3EvaluateDiscreteStates(i),
            "fmi3UpdateDiscreteStates": lambda: d.fmi3UpdateDiscreteStates(
                i, *map(byref, flags[:5]), byref(c_double())),
            "fmi3EnterStepMode": lambda: d.fmi3EnterStepMode(i),
            "fmi3GetOutputDerivatives": lambda: d.fmi3GetOutputDerivatives(
                i, out, 1, (c_int32 * 1)(1), (c_double * 1)(), 1),
            "fmi3DoStep": lambda: d.fmi3DoStep(i, 0.01, 0.01, True, *map(byref, flags[:3]),
                                               byref(c_double())),
            "fmi3ActivateModelPartition": lambda: d.fmi3ActivateModelPartition(i, 0, 0.0),
            "fmi3EnterContinuousTimeMode": lambda: d.fmi3EnterContinuousTimeMode(i),
            "fmi3CompletedIntegratorStep": lambda: d.fmi3CompletedIntegratorStep(
                i, True, byref(flags[0]), byref(flags[1])),
            "fmi3SetTime": lambda: d.fmi3SetTime(i, 0.0),
            **{f"fmi3{name}": (lambda name=name: getattr(d, f"fmi3{name}")(
                i, (c_double * 1)(), 0))
               for name in ("SetContinuousStates", "GetContinuousStateDerivatives",
                            "GetEventIndicators", "GetContinuousStates",
                            "GetNominalsOfContinuousStates")},
            "fmi3GetNumberOfEventIndicators":
                lambda: d.fmi3GetNumberOfEventIndicators(i, byref(c_size_t())),
            "fmi3GetNumberOfContinuousStates":
                lambda: d.fmi3GetNumberOfContinuousStates(i, byref(c_size_t())),
        }
        for kind, ctype in NO_VARIABLES.items():
            calls[f"fmi3Get{kind}"] = lambda k=kind, t=ctype: getattr(d, f"fmi3Get{k}")(
                i, none, 0, (t * 1)(), 0)
            calls[f"fmi3Set{kind}"] = lambda k=kind, t=ctype: getattr(d, f"fmi3Set{k}")(
                i, none, 0, (t * 1)(), 0)
        return calls


def reach(dll, instance, calls, state):
    """Drive a fresh instance into ``state`` by correct calls; the error state by an input
    set to NaN."""
    depth = {"instantiated": 0, "initialisation": 1, "step mode": 2, "terminated": 3,
             "error": 2}[state]
    flags = [c_bool() for _ in range(3)]
    if depth >= 1:
        assert dll.fmi3EnterInitializationMode(instance, False, 0.0, 0.0, False, 0.0) == 0
    if depth >= 2:
        assert dll.fmi3ExitInitializationMode(instance) == 0
        assert dll.fmi3DoStep(instance, 0.0, 0.01, True, *map(byref, flags),
                              byref(c_double())) == 0
    if depth >= 3:
        assert dll.fmi3Terminate(instance) == 0
    if state == "error":
        vr = (c_uint32 * 1)(calls.inp)
        assert dll.fmi3SetFloat64(instance, vr, 1, (c_double * 1)(float("nan")), 1) == 3


def probe_matrix(folder):
    description = read_model_description(folder)
    slave = FMU3Slave(guid=description.guid, unzipDirectory=folder,
                      modelIdentifier=description.coSimulation.modelIdentifier,
                      instanceName="probe")
    dll = slave.dll
    answers = {}
    for function in Calls(dll, description, None).table():
        answers[function] = {}
        for state in STATES:
            instance = instantiate(dll, description.guid, folder)
            calls = Calls(dll, description, instance)
            reach(dll, instance, calls, state)
            calls.prepare()
            answers[function][state] = calls.table()[function]()
            dll.fmi3FreeInstance(instance)
    instance = instantiate(dll, description.guid, folder)  # the host, and the FMU, go on
    alive = dll.fmi3EnterInitializationMode(instance, False, 0.0, 0.0, False, 0.0) == 0
    dll.fmi3FreeInstance(instance)
    return {"answers": answers, "alive": alive, "messages": MESSAGES}


if __name__ == "__main__":
    print(json.dumps(probe_matrix(sys.argv[2])))
