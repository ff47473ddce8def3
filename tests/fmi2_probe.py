"""Calls a host may make into an unpacked FMI 2.0 FMU, through fmpy's low-level API, in a
process of their own (a crash there ends only this process); prints one JSON line.

    python tests/fmi2_probe.py instantiate FOLDER NAME GUID RESOURCES
        fmi2Instantiate with these arguments ("<NULL>" for a NULL pointer), then, if it gave an
        instance, one step and fmi2FreeInstance: {"instance": bool, "stepped": bool,
        "messages": [[status, category, text], ...]}
    python tests/fmi2_probe.py matrix FOLDER
        every fmi2 function in every state (STATES) of a fresh instance:
        {"answers": {function: {state: status}}, "messages": [...]}
"""
import json
import sys
from pathlib import Path
from ctypes import CFUNCTYPE, byref, c_char_p, c_double, c_int, c_size_t, c_uint, c_void_p, cast
from ctypes import create_string_buffer

from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

NULL = "<NULL>"
STATES = ("instantiated", "initialisation", "step complete", "terminated", "error")
MESSAGES = []


# fmi2CallbackLoggerTYPE with the first variadic argument: the layer passes text holding a
# '%' as the argument of the format "%s" (x86-64 passes it as a fixed one would be passed)
LOGGER_WITH_ARGUMENT = CFUNCTYPE(None, c_void_p, c_char_p, c_int, c_char_p, c_char_p, c_char_p)


@LOGGER_WITH_ARGUMENT
def _logger(environment, instance, status, category, message, argument):
    text = argument if message == b"%s" else message
    MESSAGES.append([status, (category or b"").decode(errors="replace"),
                     (text or b"").decode(errors="replace")])


def callbacks():
    functions = fmi2CallbackFunctions()
    functions.logger = cast(_logger, fmi2CallbackLoggerTYPE)
    return functions


CALLBACKS = callbacks()


def argument(text):
    return None if text == NULL else text.encode("utf-8", "surrogateescape")


def loaded(folder):
    """(fmpy slave with its library loaded, model description)."""
    description = read_model_description(folder)
    slave = FMU2Slave(guid=description.guid, unzipDirectory=folder,
                      modelIdentifier=description.coSimulation.modelIdentifier,
                      instanceName="probe")
    return slave, description


def instantiate(dll, name, guid, resources):
    return dll.fmi2Instantiate(argument(name), 1, argument(guid), argument(resources),
                               byref(CALLBACKS), 0, 1)


def probe_instantiate(folder, name, guid, resources):
    slave, _ = loaded(folder)
    component = instantiate(slave.dll, name, guid, resources)
    stepped = False
    if component:
        dll = slave.dll
        stepped = (dll.fmi2SetupExperiment(component, 0, 0.0, 0.0, 0, 0.0) == 0
                   and dll.fmi2EnterInitializationMode(component) == 0
                   and dll.fmi2ExitInitializationMode(component) == 0
                   and dll.fmi2DoStep(component, 0.0, 0.01, 1) == 0)
        dll.fmi2FreeInstance(component)
    return {"instance": bool(component), "stepped": stepped, "messages": MESSAGES}


class Calls:
    """Each fmi2 function called on ``component`` with arguments a correct host passes."""

    def __init__(self, dll, description, component):
        self.dll, self.c = dll, component
        variables = description.modelVariables
        self.real_out = next(v.valueReference for v in variables if v.causality == "output")
        # an FMU without inputs (the circle interpolator): a Real parameter stands in
        # where a value reference is needed, the set passes no values (the state table alone
        # decides) and NaN for that parameter reaches the error state
        inputs = [v for v in variables if v.causality == "input"]
        real_in = (inputs or [v for v in variables
                              if v.causality == "parameter" and v.type == "Real"])[0]
        self.real_in, self.start = real_in.valueReference, float(real_in.start or 0.0)
        self.n_in = 1 if inputs else 0
        self.first = {kind: [v.valueReference for v in variables if v.type == kind][:1]
                      for kind in ("Integer", "Boolean", "String")}
        self.state = c_void_p()
        self.serialized = None

    def prepare(self):
        """A state saved in the instance's current state, and its serialisation."""
        self.state = c_void_p()
        self.dll.fmi2GetFMUstate(self.c, byref(self.state))
        size = c_size_t()
        self.dll.fmi2SerializedFMUstateSize(self.c, self.state, byref(size))
        buffer = create_string_buffer(size.value)
        self.dll.fmi2SerializeFMUstate(self.c, self.state, buffer, size)
        self.serialized = buffer

    def get(self, function, kind, ctype):
        vrs = self.first[kind]
        return getattr(self.dll, function)(self.c, (c_uint * 1)(*vrs), len(vrs), (ctype * 1)())

    def set(self, function, kind, ctype):
        """No values (nvr = 0): the state table alone decides (the variables of these types
        are fixed parameters, which a set in step complete must be refused for anyway)."""
        return getattr(self.dll, function)(self.c, (c_uint * 1)(), 0, (ctype * 1)())

    def table(self):
        d, c = self.dll, self.c
        vr_out, vr_in = (c_uint * 1)(self.real_out), (c_uint * 1)(self.real_in)
        return {
            "fmi2SetDebugLogging": lambda: d.fmi2SetDebugLogging(c, 1, 0, None),
            "fmi2SetupExperiment": lambda: d.fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0),
            "fmi2EnterInitializationMode": lambda: d.fmi2EnterInitializationMode(c),
            "fmi2ExitInitializationMode": lambda: d.fmi2ExitInitializationMode(c),
            "fmi2Terminate": lambda: d.fmi2Terminate(c),
            "fmi2Reset": lambda: d.fmi2Reset(c),
            "fmi2GetReal": lambda: d.fmi2GetReal(c, vr_out, 1, (c_double * 1)()),
            "fmi2GetInteger": lambda: self.get("fmi2GetInteger", "Integer", c_int),
            "fmi2GetBoolean": lambda: self.get("fmi2GetBoolean", "Boolean", c_int),
            "fmi2GetString": lambda: self.get("fmi2GetString", "String", c_char_p),
            "fmi2SetReal": lambda: d.fmi2SetReal(c, vr_in, self.n_in,
                                                (c_double * 1)(self.start)),
            "fmi2SetInteger": lambda: self.set("fmi2SetInteger", "Integer", c_int),
            "fmi2SetBoolean": lambda: self.set("fmi2SetBoolean", "Boolean", c_int),
            "fmi2SetString": lambda: self.set("fmi2SetString", "String", c_char_p),
            "fmi2GetFMUstate": lambda: d.fmi2GetFMUstate(c, byref(c_void_p())),
            "fmi2SetFMUstate": lambda: d.fmi2SetFMUstate(c, self.state),
            "fmi2FreeFMUstate": lambda: d.fmi2FreeFMUstate(c, byref(self.state)),
            "fmi2SerializedFMUstateSize":
                lambda: d.fmi2SerializedFMUstateSize(c, self.state, byref(c_size_t())),
            "fmi2SerializeFMUstate": lambda: d.fmi2SerializeFMUstate(
                c, self.state, self.serialized, len(self.serialized)),
            "fmi2DeSerializeFMUstate": lambda: d.fmi2DeSerializeFMUstate(
                c, self.serialized, len(self.serialized), byref(c_void_p())),
            "fmi2GetDirectionalDerivative": lambda: d.fmi2GetDirectionalDerivative(
                c, vr_out, 1, vr_in, 1, (c_double * 1)(1.0), (c_double * 1)()),
            "fmi2SetRealInputDerivatives": lambda: d.fmi2SetRealInputDerivatives(
                c, vr_in, 1, (c_int * 1)(1), (c_double * 1)(0.0)),
            "fmi2GetRealOutputDerivatives": lambda: d.fmi2GetRealOutputDerivatives(
                c, vr_out, 1, (c_int * 1)(1), (c_double * 1)()),
            "fmi2DoStep": lambda: d.fmi2DoStep(c, 0.0, 0.01, 1),
            "fmi2CancelStep": lambda: d.fmi2CancelStep(c),
            "fmi2GetStatus": lambda: d.fmi2GetStatus(c, 0, byref(c_int())),
            "fmi2GetRealStatus": lambda: d.fmi2GetRealStatus(c, 2, byref(c_double())),
            "fmi2GetIntegerStatus": lambda: d.fmi2GetIntegerStatus(c, 0, byref(c_int())),
            "fmi2GetBooleanStatus": lambda: d.fmi2GetBooleanStatus(c, 3, byref(c_int())),
            "fmi2GetStringStatus": lambda: d.fmi2GetStringStatus(c, 1, byref(c_char_p())),
        }


def reach(dll, component, calls, state):
    """Drive a fresh instance into ``state`` (STATES) by correct calls; the error state by
    an input set to NaN."""
    steps = {"initialisation": 1, "step complete": 2, "terminated": 3, "error": 2}[state] \
        if state != "instantiated" else 0
    if steps >= 1:
        assert dll.fmi2SetupExperiment(component, 0, 0.0, 0.0, 0, 0.0) == 0
        assert dll.fmi2EnterInitializationMode(component) == 0
    if steps >= 2:
        assert dll.fmi2ExitInitializationMode(component) == 0
        assert dll.fmi2DoStep(component, 0.0, 0.01, 1) == 0
    if steps >= 3:
        assert dll.fmi2Terminate(component) == 0
    if state == "error":
        vr = (c_uint * 1)(calls.real_in)
        assert dll.fmi2SetReal(component, vr, 1, (c_double * 1)(float("nan"))) == 3


def probe_matrix(folder):
    slave, description = loaded(folder)
    dll = slave.dll
    answers = {}
    for function in Calls(dll, description, None).table():
        answers[function] = {}
        for state in STATES:
            component = instantiate(dll, "matrix", description.guid,
                                    (Path(folder) / "resources").as_uri())
            calls = Calls(dll, description, component)
            reach(dll, component, calls, state)
            calls.prepare()
            answers[function][state] = calls.table()[function]()
            dll.fmi2FreeInstance(component)
    return {"answers": answers, "messages": MESSAGES}


if __name__ == "__main__":
    mode, *arguments = sys.argv[1:]
    result = probe_instantiate(*arguments) if mode == "instantiate" else probe_matrix(*arguments)
    print(json.dumps(result))
