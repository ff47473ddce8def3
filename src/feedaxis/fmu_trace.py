"""Run one FMU's Python slave as its host layer does and list every file it loads.

A script, run by :mod:`feedaxis.fmu_standalone` in a fresh interpreter (``python -I``) on
the FMU's unpacked ``resources`` folder; it imports nothing from feedaxis, so what it lists
is what the FMU's step path needs. It drives the slave through the calls the host layer
and pythonfmu make (setup, initialisation, the cross-check input through pythonfmu's set and
get and through the host layer's exchange function, a saved and restored state, a long
step, termination) once with the default parameters, once per Boolean parameter flipped
and once with every Real parameter that defaults to 0 set to 1, so the branches these
switch (NPID, friction) run too. Errors the slave logs (a refused long step) are part of
the path.

Usage: ``python -I fmu_trace.py RESOURCES CLASS INPUT_CSV ALLOWED OUT_JSON``, ALLOWED the
installed packages the FMU may use (comma-separated; others are hidden); writes
``{"modules": {name: file}, "opened": [file], "libraries": [file]}``: the modules imported
and files opened after start-up, and the shared libraries mapped at the end.
"""
import csv
import importlib
import json
import sys

HANDOFF_MODULE = "feedaxis_fmu_handoff"  # feedaxis_slave.HANDOFF_MODULE
LONG_STEP_S = 1000.0
SHORT_RUN_ROWS = 50


def read_inputs(input_csv):
    """(times, {input name: values}) of a cross-check input file (quoted names, "time" first)."""
    with open(input_csv, newline="", encoding="utf-8") as stream:
        rows = list(csv.reader(stream))
    names, values = rows[0], [[float(cell) for cell in row] for row in rows[1:] if row]
    columns = {name: [row[i] for row in values] for i, name in enumerate(names)}
    return columns.pop("time"), columns


def variables(slave):
    """{name: (value reference, variable)} of a pythonfmu slave."""
    return {variable.name: (vr, variable) for vr, variable in slave.vars.items()}


def variations(slave_class):
    """Parameter sets to run: the defaults, each Boolean flipped, zero Reals set to 1."""
    probe = slave_class(instance_name="trace")
    parameters = {name: getattr(probe, name) for name, (_, variable) in variables(probe).items()
                  if variable.causality.name == "parameter"}
    runs = [{}]
    runs += [{name: not value} for name, value in parameters.items() if isinstance(value, bool)]
    zeros = {name: 1.0 for name, value in parameters.items()
             if isinstance(value, float) and value == 0.0}
    return runs + ([zeros] if zeros else [])


def set_values(slave, values):
    """Set ``values`` through pythonfmu's typed setters, as fmi2Set* does."""
    table = variables(slave)
    for name, value in values.items():
        vr = table[name][0]
        setter = {bool: slave.set_boolean, int: slave.set_integer, float: slave.set_real,
                  str: slave.set_string}[type(value)]
        setter([vr], [value])


def drive(slave_class, resources, parameters, times, inputs, n_rows):
    """One run of the slave over the first ``n_rows`` input rows."""
    slave = slave_class(instance_name="trace", resources=resources, visible=False)
    table = variables(slave)
    outputs = [name for name, (_, v) in table.items() if v.causality.name == "output"]
    slave.setup_experiment(times[0], None, None)
    slave.enter_initialization_mode()
    set_values(slave, parameters)
    slave.exit_initialization_mode()
    handoff = sys.modules.get(HANDOFF_MODULE)
    exchange = handoff.claim(list(inputs), outputs) if handoff else None
    rows = min(n_rows, len(times)) - 1
    for k in range(rows):
        step_s, row = times[k + 1] - times[k], [inputs[name][k] for name in inputs]
        if exchange is not None and k >= rows // 2:
            exchange(times[k], step_s, *row)
        else:
            slave.set_real([table[name][0] for name in inputs], row)
            slave.do_step(times[k], step_s)
            slave.get_real([table[name][0] for name in outputs])
        if k == rows // 3:
            saved = slave._fmu_state_to_bytes(slave._get_fmu_state())
    if rows > 0:
        slave._set_fmu_state(slave._fmu_state_from_bytes(saved))
    slave.do_step(times[rows], LONG_STEP_S)
    slave.terminate()


class OnlyAllowed:
    """A meta path finder that hides every installed package but the allowed ones, as on a
    host that has only those: the FMU carries its own copy of the physics, which takes
    optional helpers (feedaxis's error class, threadpoolctl) only where they are installed.
    The standard library, the FMU's own resources and private modules stay visible."""

    def __init__(self, allowed):
        self.allowed = set(allowed)

    def find_spec(self, name, path=None, target=None):
        top = name.split(".")[0]
        if not (top in self.allowed or top in sys.stdlib_module_names or top.startswith("_")
                or top in sys.builtin_module_names):
            raise ModuleNotFoundError(f"{name} is hidden from the trace", name=name)
        return None


def own_modules(resources):
    """The top-level modules the FMU carries in ``resources``."""
    import pkgutil

    return [module.name for module in pkgutil.iter_modules([resources])]


def mapped_libraries():
    """Shared libraries mapped into this process."""
    with open("/proc/self/maps", encoding="utf-8") as maps:
        return sorted({line.split()[-1] for line in maps if ".so" in line.split()[-1]})


def main(resources, class_name, input_csv, allowed, out_json):
    times, inputs = read_inputs(input_csv)
    with open(f"{resources}/slavemodule.txt", encoding="utf-8") as stream:
        entry_module = stream.read().strip()
    opened, recording = set(), [True]
    sys.addaudithook(lambda event, args: opened.add(args[0]) if recording[0] and event == "open"
                     and isinstance(args[0], str) else None)
    started = set(sys.modules)
    sys.meta_path.insert(0, OnlyAllowed([*allowed.split(","), *own_modules(resources)]))
    sys.path.insert(0, resources)
    slave_class = getattr(importlib.import_module(entry_module), class_name)
    for k, parameters in enumerate(variations(slave_class)):
        drive(slave_class, resources, parameters, times, inputs,
              len(times) if k == 0 else SHORT_RUN_ROWS)
    recording[0] = False
    modules = {name: getattr(module, "__file__", None) for name, module in sys.modules.items()
               if name not in started}
    with open(out_json, "w", encoding="utf-8") as stream:
        json.dump({"modules": {name: file for name, file in modules.items() if file},
                   "opened": sorted(opened), "libraries": mapped_libraries()}, stream)


if __name__ == "__main__":
    main(*sys.argv[1:])
