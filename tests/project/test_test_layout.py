"""The tests' layout (issue 30): one folder per layer of feedaxis, and every module of
src/feedaxis imported by name by some test (a package's name counts for the modules whose
names it re-exports), so a reader finds a module's tests by searching for its name."""
import ast
import importlib
import inspect
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
SOURCE = TESTS.parent / "src"
# The modules no test imports by name, and why each stays so.
NOT_IMPORTED = {
    "feedaxis.__main__": "the console script: tests/cli runs it as a program",
    "feedaxis.console": "how the command line reports a failure: through feedaxis.cli.main "
                        "in tests/cli/test_bad_input.py (every error, with and without --json)",
    "feedaxis.fmu_trace": "a script run by hand to list what an FMU's step path loads; the "
                          "standalone build it informed is tested in tests/fmus/test_standalone.py",
    "feedaxis.cosim.physics_check": "the FMUs' parameter checks before a run: refusals of "
                                    "simulate, sweep and export in tests/cli/test_bad_input.py",
    "feedaxis.cosim.sweep.plan": "a sweep's plan, checked before any trial: through sweep() "
                                 "in tests/cosim/test_sweep.py (bad specs refused)",
    "feedaxis.cosim.sweep.summary": "a sweep's summary.json: through sweep() in "
                                    "tests/cosim/test_sweep.py (sensitivities, bands)",
    "feedaxis.comptable.base": "the Controller object: every registered controller "
                               "(feedaxis.comptable.CONTROLLERS) in tests/comptable",
    "feedaxis.effects.positioning": "the @effect of a user's file: examples/coupling_ripple.py "
                                    "through --effects in tests/fit_diagnosis/test_loop.py",
    "feedaxis.importers.drive_trace": "feedaxis import of a drive's trace through a column "
                                      "map in tests/fit_diagnosis/test_cascade.py",
    "feedaxis.importers.wide_csv": "through feedaxis import of wide CSV files in "
                                   "tests/case/test_import.py",
    "feedaxis.measurement.circular": "a kind loaded by the registry (feedaxis.kinds.BUILT_IN): "
                                     "circular cases in tests/*/test_circular_*.py",
    "feedaxis.report.circular": "the circular kind's views part: reports in "
                                "tests/fit_diagnosis/test_circular_diagnosis.py",
    "feedaxis.report.tracking": "the tracking kind's views part: reports in "
                                "tests/fit_diagnosis/test_tracking_loop.py",
    "feedaxis.report.compensation_table": "the table section of a positioning report "
                                          "(report/positioning.py): reports in tests/report",
    "feedaxis.report.sweep": "a sweep's report.html: through sweep in tests/cosim/test_sweep.py",
    "feedaxis.standards.compare": "--standard of compare in tests/uncertainty/test_standards.py",
    "feedaxis.standards.definitions": "the standards' definitions, read through "
                                      "feedaxis.standards in tests/uncertainty/test_standards.py",
    "feedaxis.standards.text": "--standard's terminal text in tests/uncertainty/test_standards.py",
    "feedaxis.uncertainty.page": "feedaxis uncertainty --html in tests/uncertainty/test_uncertainty.py",
    "feedaxis.uncertainty.text": "feedaxis uncertainty's text in tests/uncertainty/test_uncertainty.py",
}


def source_modules():
    """Every module of src/feedaxis by dotted name (a package by its own name)."""
    names = set()
    for path in (SOURCE / "feedaxis").rglob("*.py"):
        parts = list(path.relative_to(SOURCE).with_suffix("").parts)
        names.add(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


def imported_modules():
    """The feedaxis modules the tests import by name: ``import m``, ``from m import name``
    (and the module that defines ``name``), with every package above them."""
    found = set()
    for path in TESTS.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found |= {alias.name for alias in node.names}
            elif (isinstance(node, ast.ImportFrom) and node.level == 0
                  and (node.module or "").startswith("feedaxis")):
                found.add(node.module)
                module = importlib.import_module(node.module)
                for alias in node.names:  # a submodule, or a name and where it is defined
                    value = getattr(module, alias.name, None)
                    found.add(f"{node.module}.{alias.name}")
                    found.add(value.__name__ if inspect.ismodule(value)
                              else getattr(value, "__module__", None) or node.module)
    return found | {".".join(name.split(".")[:i]) for name in found
                    for i in range(1, name.count(".") + 1)}


def test_every_module_is_imported_by_some_test():
    missing = source_modules() - imported_modules() - set(NOT_IMPORTED)
    assert sorted(missing) == []


def test_the_listed_exceptions_are_current():
    """An exception a test now imports, or a module that is gone, leaves the list."""
    modules, imported = source_modules(), imported_modules()
    assert sorted(m for m in NOT_IMPORTED if m not in modules or m in imported) == []


def test_every_test_file_sits_in_a_layer_folder():
    assert sorted(path.name for path in TESTS.glob("test_*.py")) == []
