"""Each FMU in a second, independent importer (OSP libcosim) gives fmpy's outputs."""
import numpy as np
import pytest

from feedaxis.fmu_build import FMU_NAMES
from libcosim_driver import simulate_with_libcosim
from scenarios import N_STEPS, OUTPUTS, PARAMETERS, STEP_SIZE_S, scripted_inputs
from test_fmus import run_scripted


@pytest.mark.parametrize("name", FMU_NAMES)
def test_libcosim_gives_the_same_outputs_as_fmpy(fmu_paths, loaded_fmus, name):
    numeric = {k: v for k, v in PARAMETERS[name].items() if not isinstance(v, str)}
    expected = run_scripted(loaded_fmus[name], name, numeric)
    result = simulate_with_libcosim(fmu_paths[name], STEP_SIZE_S[name], N_STEPS[name],
                                    scripted_inputs(name), numeric, OUTPUTS[name])
    for output in OUTPUTS[name]:
        scale = np.max(np.abs(expected[output]))
        np.testing.assert_allclose(result[output], expected[output], rtol=1e-9, atol=1e-9 * scale)
