"""The FMUs' compiled module, cached per source: the servo loop and each FMU's step.

``physics.servo.run_loop`` is the one definition of the closed loop (Anang et al. 2017 Eq. 1-8). The
fit runs it compiled by numba's JIT (``servo.compiled_loop``), whose disk cache is keyed to
the source's path: in a freshly unpacked FMU it would import numba and compile again, about
1.4 s per instantiate. Here the same function is compiled once by numba's ahead-of-time
compiler (``numba.pycc``) into a Python extension module ``step_kernel`` that needs only
numpy to import; the FMU build puts it beside the physics (``physics/step_kernel*.so``,
inside the FMU's resources, loaded by ``physics.kernel``), and ``servo.Servo`` steps with it
when present.

The same module carries each FMU's step (``physics.fmu_steps``: NpidServo, StepperError,
GeometricError, ThermalScrew) as a C function the FMU's host layer calls without entering
Python. pycc exports Python wrappers only; numba also compiles a C-ABI wrapper of every function
(what ``numba.cfunc`` exposes), which pycc leaves hidden. :data:`COMPILE` renames those
wrappers of the FMU steps to their symbols (``fmu_steps.STEPS``) and exports them, by
wrapping ``numba.pycc.compiler.compile_extra``, the one place the compile result is seen.

``numba.pycc`` is pending deprecation since numba 0.57 (still present, no removal scheduled
as of 0.68, "replacement technology is being developed") and needs setuptools and a C
compiler. Where it cannot build, the FMUs keep their Python steps (same results, slower;
a 1 ms step with NPID or Coulomb friction then costs about 2.4 times a PID step, whose
linear loop has a propagator) and the build warns once; CI requires the module.
The compile takes seconds (numba, then its C helpers), so the module is kept in the user
cache, keyed by the physics sources, numba, numpy and the Python ABI, and built in a
subprocess (numba stays out of the calling process).
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import platform
import shutil
import subprocess
import sys
import sysconfig
import warnings
from pathlib import Path

from .output import built_once
from .physics.kernel import MODULE_NAME
from .toolchain import compiler_missing

SIGNATURE = "void(f8[::1], i8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1])"
PHYSICS_DIR = Path(__file__).resolve().parent / "physics"
COMPILE = f"""
import sys, warnings
warnings.simplefilter("ignore")
import numba
import numba.pycc.cc
import numba.pycc.compiler as module_compiler
from numba.pycc import CC
from feedaxis.physics import fmu_steps, servo

steps = fmu_steps.compiled_steps(numba)
symbols = {{function: symbol for symbol, function in steps.items()}}
compilers = []
compile_extra = module_compiler.compile_extra


def exporting_c_wrappers(*args, **kwargs):
    result = compile_extra(*args, **kwargs)
    symbol = symbols.get(args[2])
    if symbol is not None:  # the C-ABI wrapper numba made, under the step's symbol
        result.library.get_function(result.fndesc.llvm_cfunc_wrapper_name).name = symbol
        compilers[-1].dll_exports.append(symbol)
    return result


class ModuleCompiler(module_compiler.ModuleCompiler):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        compilers.append(self)


module_compiler.compile_extra = exporting_c_wrappers
numba.pycc.cc.ModuleCompiler = ModuleCompiler

cc = CC({MODULE_NAME!r})
cc.output_dir = sys.argv[1]
cc.use_nrt = True  # the steps view their block as arrays (numba.carray); nothing allocates
cc.export("run_loop", {SIGNATURE!r})(servo.numba_ready_loop(numba))
for symbol, function in steps.items():
    cc.export(symbol, fmu_steps.SIGNATURE)(function)
cc.compile()
"""


class KernelUnavailable(RuntimeError):
    """The FMUs' compiled module cannot be compiled on this machine."""


def kernel_missing():
    """Why the kernel cannot be compiled here (None when it can)."""
    missing = compiler_missing("the FMUs' compiled steps")
    if missing:
        return missing
    for module in ("numba", "setuptools"):  # numba.pycc needs both; importing numba takes 0.3 s
        if importlib.util.find_spec(module) is None:
            return f"no {module} (numba's ahead-of-time compiler needs numba and setuptools)"
    return None


def kernel_key():
    """SHA-256 (first 12 hex digits) of what the compiled module depends on."""
    import numba
    import numpy

    digest = hashlib.sha256()
    for source in sorted(PHYSICS_DIR.glob("*.py")):
        digest.update(source.read_bytes())
    for part in (COMPILE, numba.__version__, numpy.__version__, sys.implementation.cache_tag,
                 platform.machine()):
        digest.update(part.encode())
    return digest.hexdigest()[:12]


def cached_kernel(cache_root):
    """Path of the compiled module in ``<cache_root>/step-kernel-<key>/``, compiled on
    first use (:func:`~feedaxis.output.built_once`: concurrent builds cannot tear it)."""
    name = f"{MODULE_NAME}{sysconfig.get_config_var('EXT_SUFFIX')}"

    def compile_into(staging):
        result = subprocess.run([sys.executable, "-c", COMPILE, str(staging)],
                                capture_output=True, text=True)
        if result.returncode != 0 or not (staging / name).is_file():
            raise KernelUnavailable("compiling the FMUs' steps failed:\n"
                                    + result.stderr[-2000:])

    folder = built_once(Path(cache_root) / f"step-kernel-{kernel_key()}", compile_into,
                        lambda folder: (folder / name).is_file())
    return folder / name


def install_kernel(physics_dir, cache_root):
    """Put the compiled module into ``physics_dir`` (an FMU's physics copy); True if done.

    Where it cannot be compiled, warn and return False (the FMU steps in Python); under CI
    that is an error.
    """
    missing = kernel_missing()
    try:
        if missing is not None:
            raise KernelUnavailable(missing)
        shutil.copy2(cached_kernel(cache_root), Path(physics_dir))
    except KernelUnavailable as error:
        if os.environ.get("CI") == "true":
            raise KernelUnavailable(f"{error}: CI requires the FMUs' compiled steps") from None
        warnings.warn(f"the FMUs step in Python, slower (NpidServo's NPID and friction more "
                      f"than twice as slow) ({error}); see fmus/README.md", stacklevel=3)
        return False
    return True
