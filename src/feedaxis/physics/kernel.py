"""The FMUs' compiled module: the physics an FMU steps, compiled ahead of time.

feedaxis.kernel_build compiles it with numba's ahead-of-time compiler and puts it beside
this file in an FMU's copy of the physics (``physics/step_kernel*.so``): the servo loop
(:func:`.servo.run_loop`) as a Python function, and each FMU's step
(:mod:`.fmu_steps`) as a C function the FMU's host layer calls without Python.
feedaxis's own copy of the physics has none.
"""
from __future__ import annotations

import importlib
from functools import lru_cache

MODULE_NAME = "step_kernel"


@lru_cache(maxsize=1)
def shipped_kernel():
    """(the compiled module, or None; why it did not load, or None).

    Absent: (None, None). A module that is there but does not load (another Python or
    numpy than the one that built it) gives its reason.
    """
    try:
        module = importlib.import_module(f"{__package__}.{MODULE_NAME}")
    except ModuleNotFoundError as error:
        if error.name == f"{__package__}.{MODULE_NAME}":
            return None, None
        return None, str(error)
    except ImportError as error:
        return None, str(error)
    return module, None
