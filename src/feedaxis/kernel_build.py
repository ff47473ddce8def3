"""The servo loop compiled ahead of time for the NpidServo FMU, cached per source.

``physics.servo.run_loop`` is the one definition of the closed loop (Anang et al. 2017 Eq. 1-8). The
fit runs it compiled by numba's JIT (``servo.compiled_loop``), whose disk cache is keyed to
the source's path: in a freshly unpacked FMU it would import numba and compile again, about
1.4 s per instantiate. Here the same function is compiled once by numba's ahead-of-time
compiler (``numba.pycc``) into a Python extension module ``servo_kernel`` that needs only
numpy to import; the FMU build puts it beside the physics (``physics/servo_kernel*.so``,
inside the FMU's resources), and ``servo.Servo`` steps with it when present.

``numba.pycc`` is pending deprecation since numba 0.57 (still present, no removal scheduled
as of 0.68, "replacement technology is being developed") and needs setuptools and a C
compiler. Where it cannot build, the FMU keeps the plain Python loop (same results; a 1 ms
step with NPID or Coulomb friction then costs about 2.4 times a PID step, whose linear loop
has a propagator) and the build warns once; CI requires the kernel.
The compile takes seconds (numba, then its C helpers), so the module is kept in the user
cache, keyed by the loop's source, numba, numpy and the Python ABI, and built in a
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
from .toolchain import compiler_missing

MODULE_NAME = "servo_kernel"
SIGNATURE = "void(f8[::1], i8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1])"
SERVO_SOURCE = Path(__file__).resolve().parent / "physics" / "servo.py"
COMPILE = f"""
import sys, warnings
warnings.simplefilter("ignore")
import numba
from numba.pycc import CC
from feedaxis.physics import servo

cc = CC({MODULE_NAME!r})
cc.output_dir = sys.argv[1]
cc.use_nrt = False  # the loop allocates nothing
cc.export("run_loop", {SIGNATURE!r})(servo.numba_ready_loop(numba))
cc.compile()
"""


class KernelUnavailable(RuntimeError):
    """The servo kernel cannot be compiled on this machine."""


def kernel_missing():
    """Why the kernel cannot be compiled here (None when it can)."""
    missing = compiler_missing("the servo kernel")
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

    digest = hashlib.sha256(SERVO_SOURCE.read_bytes())
    for part in (COMPILE, numba.__version__, numpy.__version__, sys.implementation.cache_tag,
                 platform.machine()):
        digest.update(part.encode())
    return digest.hexdigest()[:12]


def cached_kernel(cache_root):
    """Path of the compiled module in ``<cache_root>/servo-kernel-<key>/``, compiled on
    first use (:func:`~feedaxis.output.built_once`: concurrent builds cannot tear it)."""
    name = f"{MODULE_NAME}{sysconfig.get_config_var('EXT_SUFFIX')}"

    def compile_into(staging):
        result = subprocess.run([sys.executable, "-c", COMPILE, str(staging)],
                                capture_output=True, text=True)
        if result.returncode != 0 or not (staging / name).is_file():
            raise KernelUnavailable("compiling the servo kernel failed:\n"
                                    + result.stderr[-2000:])

    folder = built_once(Path(cache_root) / f"servo-kernel-{kernel_key()}", compile_into,
                        lambda folder: (folder / name).is_file())
    return folder / name


def install_kernel(physics_dir, cache_root):
    """Put the compiled loop into ``physics_dir`` (an FMU's physics copy); True if done.

    Where it cannot be compiled, warn and return False (the FMU steps the Python loop);
    under CI that is an error.
    """
    missing = kernel_missing()
    try:
        if missing is not None:
            raise KernelUnavailable(missing)
        shutil.copy2(cached_kernel(cache_root), Path(physics_dir))
    except KernelUnavailable as error:
        if os.environ.get("CI") == "true":
            raise KernelUnavailable(f"{error}: CI requires the compiled servo kernel") from None
        warnings.warn(f"the NpidServo FMU steps NPID and friction in Python, more than twice "
                      f"as slow ({error}); see fmus/README.md", stacklevel=3)
        return False
    return True
