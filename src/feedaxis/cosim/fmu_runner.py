"""Run one FMU through fmpy's low-level FMI 2.0 or FMI 3.0 co-simulation API.

The step convention is the one every comparison in the project uses: input value k is set
before step k (held over [t_k, t_k + h)), output value k is read after it, at t_k + h.
"""
from __future__ import annotations

import copy
import ctypes
import os
import shutil
import tempfile
import zipfile
import zlib
from pathlib import PurePosixPath

import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave

from ..errors import InputError

# FMI 3.0's names of the variable types these FMUs use, and FMI 2.0's, which the project's
# code reads (LoadedFmu.variables holds these for FMUs of either version)
FMI2_TYPES = {"Float64": "Real", "Int32": "Integer", "Boolean": "Boolean", "String": "String"}


def check_fmu_archive(path):
    """Raise :class:`InputError` naming ``path`` unless it is a zip archive holding
    ``modelDescription.xml`` whose every member unpacks inside the FMU's own folder
    (no absolute path, drive, backslash or ``..``)."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
    except (zipfile.BadZipFile, OSError) as error:
        raise InputError(f"not an FMU (FMUs are zip archives): {error}", path=path) from None
    for name in names:
        if (name.startswith("/") or "\\" in name or ":" in name
                or ".." in PurePosixPath(name).parts):
            raise InputError(f"holds the member {name!r}, which would unpack outside the "
                             "FMU's folder: refused as unsafe", path=path)
    if "modelDescription.xml" not in names:
        raise InputError("not an FMU: no modelDescription.xml at its top", path=path)


class LoadedFmu:
    """An extracted FMU with its variables by name; instantiate many times, free once."""

    def __init__(self, fmu_path):
        self.path = str(fmu_path)
        self.description = read_model_description(self.path)
        self.unzip_dir = tempfile.mkdtemp(prefix="feedaxis_fmu_")
        try:
            extract(self.path, self.unzip_dir)
        except (zipfile.BadZipFile, zlib.error, EOFError) as error:  # a damaged member
            shutil.rmtree(self.unzip_dir, ignore_errors=True)
            raise InputError(f"damaged, it does not unpack: {error}", path=fmu_path) from None
        except BaseException:
            shutil.rmtree(self.unzip_dir, ignore_errors=True)
            raise
        self.fmi3 = self.description.fmiVersion.startswith("3.")
        self.variables = fmi2_variables(self.description)

    def instantiate(self, instance_name):
        """Return an instantiated :class:`fmpy.fmi2.FMU2Slave` (an FMI 3.0 FMU:
        :class:`fmpy.fmi3.FMU3Slave`); its log goes to stdout. A shared library that does
        not load (damaged, another platform's) is an :class:`InputError` naming the FMU."""
        working_folder = os.getcwd()
        try:
            slave = (FMU3Slave if self.fmi3 else FMU2Slave)(
                guid=self.description.guid, unzipDirectory=self.unzip_dir,
                modelIdentifier=self.description.coSimulation.modelIdentifier,
                instanceName=instance_name)
        except Exception as error:  # fmpy raises a bare Exception for a library not loading
            raise InputError(f"its shared library does not load: {error}",
                             path=self.path) from None
        finally:  # fmpy changes into the library's folder and stays there when it fails
            os.chdir(working_folder)
        slave.instantiate(loggingOn=True)
        return slave

    def enter_initialisation(self, slave, start_time_s=0.0):
        """Set up the experiment from ``start_time_s`` and enter initialisation mode."""
        if self.fmi3:
            slave.enterInitializationMode(startTime=start_time_s)
        else:
            slave.setupExperiment(startTime=start_time_s)
            slave.enterInitializationMode()

    def set_values(self, slave, values):
        """Set Real (Float64), Integer (Int32), Boolean or String variables by name."""
        names = {"Real": "Float64", "Integer": "Int32"} if self.fmi3 else {}
        for name, value in values.items():
            variable = self.variables[name]
            setter = getattr(slave, f"set{names.get(variable.type, variable.type)}")
            setter([variable.valueReference], [value])

    def native_stepping_functions(self, slave):
        """(whether FMI 3.0, then fmpy's raw ctypes functions fmi2SetReal, fmi2DoStep,
        fmi2GetReal of ``slave``; FMI 3.0: fmi3SetFloat64, fmi3DoStep, fmi3GetFloat64, whose
        signatures differ)."""
        names = (("fmi3SetFloat64", "fmi3DoStep", "fmi3GetFloat64") if self.fmi3 else
                 ("fmi2SetReal", "fmi2DoStep", "fmi2GetReal"))
        return (self.fmi3, *(slave._functions[name] for name in names))

    def stepping_functions(self, slave):
        """fmpy's raw ctypes functions (set_real, do_step, get_real) of ``slave``, each
        called as FMI 2.0's fmi2SetReal(c, vrs, n, values), fmi2DoStep(c, t, h,
        noSetFMUStatePriorToCurrentPoint) and fmi2GetReal(c, vrs, n, values) whichever the
        FMU's version; each returns the call's status."""
        fmi3, *functions = self.native_stepping_functions(slave)
        if not fmi3:
            return tuple(functions)
        set_float, do_step, get_float = functions
        results = [ctypes.c_bool(), ctypes.c_bool(), ctypes.c_bool(), ctypes.c_double()]
        pointers = tuple(map(ctypes.byref, results))
        return (lambda c, vrs, n, values: set_float(c, vrs, n, values, n),
                lambda c, t, h, no_prior: do_step(c, t, h, no_prior, *pointers),
                lambda c, vrs, n, values: get_float(c, vrs, n, values, n))

    def get_reals(self, slave, names):
        """Current values of Real (FMI 3.0: Float64) variables, in the order of ``names``."""
        getter = slave.getFloat64 if self.fmi3 else slave.getReal
        return getter([self.variables[n].valueReference for n in names])

    def close(self):
        """Remove the extracted files."""
        shutil.rmtree(self.unzip_dir, ignore_errors=True)


def fmi2_variables(description):
    """{name: model variable} of the FMU ``description`` describes, FMI 3.0's types under
    FMI 2.0's names (which the project's code reads), the independent variable left out."""
    fmi3 = description.fmiVersion.startswith("3.")
    return {v.name: _fmi2_typed(v) if fmi3 else v for v in description.modelVariables
            if v.causality != "independent"}


def _fmi2_typed(variable):
    """A copy of FMI 3.0 ``variable`` with its type's FMI 2.0 name."""
    typed = copy.copy(variable)
    typed.type = FMI2_TYPES[variable.type]
    return typed


def run_fmu(fmu, step_size_s, n_steps, inputs=None, parameters=None, outputs=(),
            instance_name="feedaxis"):
    """Simulate one FMU for ``n_steps`` fixed steps and return its outputs.

    Parameters
    ----------
    fmu : LoadedFmu or path
    step_size_s : float
        Communication step (s).
    n_steps : int
    inputs : dict, optional
        name -> sequence of ``n_steps`` values, value k applied over step k.
    parameters : dict, optional
        name -> value, set before initialisation.
    outputs : sequence of str
        Real variables to record after each step.

    Returns
    -------
    dict
        ``"time"`` (end of each step, s) and each output name -> ndarray of ``n_steps``.
    """
    loaded = fmu if isinstance(fmu, LoadedFmu) else LoadedFmu(fmu)
    inputs = {name: np.asarray(values) for name, values in (inputs or {}).items()}
    slave = loaded.instantiate(instance_name)
    try:
        loaded.set_values(slave, parameters or {})
        loaded.enter_initialisation(slave)
        loaded.set_values(slave, {name: values[0].item() for name, values in inputs.items()})
        slave.exitInitializationMode()
        recorded = np.empty((n_steps, len(outputs)))
        for k in range(n_steps):
            loaded.set_values(slave, {name: values[k].item() for name, values in inputs.items()})
            slave.doStep(currentCommunicationPoint=k * step_size_s,
                         communicationStepSize=step_size_s)
            recorded[k] = loaded.get_reals(slave, outputs)
        slave.terminate()
    finally:
        slave.freeInstance()
        if loaded is not fmu:
            loaded.close()
    result = {"time": (np.arange(n_steps) + 1) * step_size_s}
    result.update({name: recorded[:, i] for i, name in enumerate(outputs)})
    return result
