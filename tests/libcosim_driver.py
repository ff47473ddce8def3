"""Run a single FMI 2.0 co-simulation FMU in OSP libcosim through ``libcosimpy``.

libcosim is an FMI importer independent of fmpy, so the tests use this driver to
cross-check the FMUs against a second master algorithm.
"""

import numpy as np
from libcosimpy._internal import get_last_error_message
from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave

# libcosim writes FMI Library debug chatter straight to the C-level stdout; keep warnings and errors.
log_output_level(CosimLogLevel.WARNING)

# FMI variable type -> (Python conversion, initial-value setter, per-step override setter)
_SETTERS = {
    CosimVariableType.REAL: (float, CosimExecution.real_initial_value, CosimManipulator.slave_real_values),
    CosimVariableType.INTEGER: (int, CosimExecution.integer_initial_value, CosimManipulator.slave_integer_values),
    CosimVariableType.BOOLEAN: (bool, CosimExecution.boolean_initial_value, CosimManipulator.slave_boolean_values),
}


def _check(ok, what):
    """Raise a RuntimeError carrying libcosim's last error message if `ok` is false.

    Parameters
    ----------
    ok : bool
        Success flag returned by a libcosimpy call.
    what : str
        Description of the attempted operation, used in the message.
    """
    if not ok:
        raise RuntimeError(f"libcosim: {what} failed: {get_last_error_message().strip()}")


def simulate_with_libcosim(fmu_path, step_size_s, n_steps, inputs=None, parameters=None, outputs=()):
    """Run one co-simulation FMU in OSP libcosim.

    Parameters
    ----------
    fmu_path : str or os.PathLike
        Path to the ``.fmu`` file.
    step_size_s : float
        Fixed communication step (s); libcosim rounds it to whole nanoseconds.
    n_steps : int
        Number of steps.
    inputs : dict, optional
        Name -> sequence of `n_steps` values (Real, Integer or Boolean variables).
        Value k is applied before step k, i.e. held over ``[t_k, t_k + h)``.
    parameters : dict, optional
        Name -> value (float, int or bool), applied as initial values, i.e. before
        initialization. The FMU's declared type decides the conversion.
    outputs : sequence of str
        Names of Real variables to record.

    Returns
    -------
    dict of str to numpy.ndarray
        Name -> array of length `n_steps`; element k is the value read after step k,
        at time ``(k + 1) * h``.

    Raises
    ------
    KeyError
        If a name is not a variable of the FMU.
    TypeError
        If a variable has an unsupported type (or an output is not Real).
    ValueError
        If an input sequence does not have `n_steps` values.
    RuntimeError
        If libcosim fails to load the FMU, set a value or perform a step
        (e.g. the FMU's doStep reports an error).
    """
    inputs, parameters = dict(inputs or {}), dict(parameters or {})
    for name, values in inputs.items():
        if len(values) != n_steps:
            raise ValueError(f"input {name!r} has {len(values)} values, expected {n_steps}")

    execution = CosimExecution.from_step_size(round(step_size_s * 1e9))
    slave = CosimLocalSlave(str(fmu_path), "fmu")
    # A failed load leaves a null pointer, which add_local_slave would dereference (segfault).
    _check(bool(slave.ptr()), f"loading {fmu_path}")
    index = execution.add_local_slave(slave)
    _check(index >= 0, f"adding {fmu_path}")
    results = _drive(execution, n_steps, {(index, n): v for n, v in inputs.items()},
                     {(index, n): v for n, v in parameters.items()},
                     [(index, name) for name in outputs], step_size_s)
    return dict(zip(outputs, results))


def simulate_ssp_with_libcosim(ssp_path, n_steps, inputs=None, parameters=None, outputs=()):
    """Run an SSP in OSP libcosim at the base step of its ``osp:FixedStepAlgorithm``.

    Names are ``"Component.variable"``; ``inputs``, ``parameters`` and the result follow
    :func:`simulate_with_libcosim` (input k applied to step k, output k read after it).
    """
    execution = CosimExecution.from_ssp_file(str(ssp_path))
    indices = {info.name.decode(): info.index for info in execution.slave_infos()}

    def qualify(name):
        component, variable = name.split(".", 1)
        return indices[component], variable

    results = _drive(execution, n_steps,
                     {qualify(n): v for n, v in dict(inputs or {}).items()},
                     {qualify(n): v for n, v in dict(parameters or {}).items()},
                     [qualify(n) for n in outputs], None)
    return dict(zip(outputs, results))


def _drive(execution, n_steps, inputs, parameters, outputs, step_size_s):
    """Step ``execution`` n_steps times: overrides before each step, outputs after it.

    ``inputs``/``parameters`` map (slave index, variable name) to values; returns one array
    per ``(slave index, variable name)`` of ``outputs``.
    """
    manipulator = CosimManipulator.create_override()
    observer = CosimObserver.create_last_value()
    _check(execution.add_manipulator(manipulator), "adding the override manipulator")
    _check(execution.add_observer(observer), "adding the last-value observer")
    # Value references are only unique per type in FMI 2, so always keep the type alongside.
    variables = {}

    def lookup(key, allowed=_SETTERS):
        index, name = key
        if index not in variables:
            variables[index] = {v.name.decode(): (v.reference, CosimVariableType(v.type))
                                for v in execution.slave_variables(index)}
        if name not in variables[index]:
            raise KeyError(f"{name!r} is not a variable of slave {index}")
        reference, vtype = variables[index][name]
        if vtype not in allowed:
            raise TypeError(f"variable {name!r} has unsupported type {vtype.name}")
        return reference, vtype

    for key, value in parameters.items():
        reference, vtype = lookup(key)
        convert, set_initial, _ = _SETTERS[vtype]
        _check(set_initial(execution, key[0], reference, convert(value)),
               f"setting parameter {key[1]!r}")

    input_refs = {key: lookup(key) for key in inputs}
    output_refs = [(key[0], lookup(key, allowed=(CosimVariableType.REAL,))[0]) for key in outputs]
    results = np.empty((n_steps, len(output_refs)))
    for k in range(n_steps):
        # Overrides are applied when the step commences, i.e. to the step that follows.
        for key, (reference, vtype) in input_refs.items():
            convert, _, set_override = _SETTERS[vtype]
            _check(set_override(manipulator, key[0], [reference], [convert(inputs[key][k])]),
                   f"setting input {key[1]!r}")
        # The first step() also initializes the FMUs (setup, enter/exit initialization mode).
        where = f" (t = {k * step_size_s:g} s)" if step_size_s else ""
        _check(execution.step(), f"step {k}{where}")
        for j, (index, reference) in enumerate(output_refs):
            results[k, j] = observer.last_real_values(index, [reference])[0]
    return [results[:, j].copy() for j in range(len(output_refs))]
