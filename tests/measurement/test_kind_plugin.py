"""A kind of measurement is one module (issue 30): a toy kind defined and registered in one
module of the tests folder (``tests/toy_kind.py``: its file, reader, effect, noise, figures,
text and scenario) runs through ``diagnose``, ``fit --add``, ``compare``, ``report``,
``simulate`` and ``sweep`` with ``--json`` on the command line with no other module touched; the contract refuses a kind that forgets a
hook or inherits an optional one undeclared."""
import ast
import json
import re
from pathlib import Path

import numpy as np
import pytest

from feedaxis import kinds
from feedaxis.case import read_case, write_case
from feedaxis.cli import main
from feedaxis.measurement.base import Measurement

TOY = str(Path(__file__).resolve().parents[1] / "toy_kind.py")
SLOPE_UM_PER_MM = 0.2


@pytest.fixture
def toy_case(tmp_path):
    import toy_kind  # registers the kind
    x_mm = np.linspace(0.0, 100.0, 41)
    noise_um = np.random.default_rng(3).normal(0.0, 0.1, x_mm.size)
    folder = write_case(tmp_path / "toy", {"name": "toy axis", "screw": {"lead_mm": 5.0}},
                        toy={"x_mm": x_mm, "deviation_um": SLOPE_UM_PER_MM * x_mm + noise_um})
    yield str(folder)
    kinds.unregister(toy_kind.Toy.kind)


def run(capsys, *argv):
    code = main([*argv, "--effects", TOY, "--json"])
    return code, json.loads(capsys.readouterr().out)


def test_a_toy_kind_from_one_module_runs_through_the_command_line(toy_case, capsys, tmp_path):
    assert set(read_case(toy_case).samples) == {"toy"}
    code, diagnosed = run(capsys, "diagnose", toy_case)
    assert code == 0 and diagnosed["measurement"] == "toy"
    assert diagnosed["verdict"] == "missing_effect"
    assert [c["effect"] for c in diagnosed["candidates"]][:1] == ["toy_slope"]
    assert "acts on positioning.csv" in diagnosed["skipped"]["lead_error"]
    model = tmp_path / "m.toml"
    code, fitted = run(capsys, "fit", toy_case, "--add", "toy_slope", "--out", str(model))
    assert code == 0 and fitted["measurement"] == "toy"
    assert fitted["params"]["toy_slope"]["slope_um_per_mm"] == pytest.approx(SLOPE_UM_PER_MM,
                                                                              rel=0.02)
    code, compared = run(capsys, "compare", toy_case, "--model", str(model))
    assert code == 0 and compared["kind"] == "toy"
    assert compared["rms_residual_um"] < 0.2 < compared["rms_measured_um"]
    code, diagnosed = run(capsys, "diagnose", toy_case, "--model", str(model))
    assert code == 0 and diagnosed["verdict"] == "adequate"
    out = tmp_path / "r.html"
    code, reported = run(capsys, "report", toy_case, "--model", str(model), "--out", str(out))
    assert code == 0 and "Toy (toy.csv)" in out.read_text(encoding="utf-8")
    assert main(["compare", toy_case, "--model", str(model), "--effects", TOY]) == 0
    assert "toy samples; model: toy_slope" in capsys.readouterr().out


@pytest.fixture
def toy_from_effects_file():
    """The toy kind as ``--effects TOY`` registers it, taken out of the registry after."""
    yield
    kinds.unregister("toy")


def test_a_toy_kind_brings_its_scenario_to_simulate_and_sweep(toy_from_effects_file, fmu_paths,
                                                              capsys, tmp_path):
    """``--effects TOY`` alone makes ``simulate toy`` and ``sweep toy`` (the kind's declared
    scenario, a ramp on the co-simulated axis) without any other module knowing it: the case
    written reads back as toy samples, and the sweep varies an FMU parameter over it."""
    fmus = str(next(iter(fmu_paths.values())).parent)
    out = tmp_path / "ramp"
    code, simulated = run(capsys, "simulate", "toy", str(out), "--length-mm", "20",
                          "--points", "11", "--fmus", fmus)
    assert code == 0 and simulated["samples"] == 11
    samples = read_case(out).samples["toy"]
    np.testing.assert_allclose(samples.x_mm, np.linspace(0.0, 20.0, 11))
    assert simulated["rms_deviation_um"] == pytest.approx(
        np.sqrt(np.mean(samples.deviation_um ** 2)))
    code, diagnosed = run(capsys, "diagnose", str(out))
    assert code == 0 and diagnosed["measurement"] == "toy"
    code, swept = run(capsys, "sweep", "toy", str(tmp_path / "sweep"), "--length-mm", "20",
                      "--points", "11", "--vary", "GeometricError.backlash_um=grid(0,4,2)",
                      "--workers", "0", "--fmus", fmus)
    assert code == 0 and (swept["finished_trials"], swept["failed_trials"]) == (2, 0)
    kinds.unregister("toy")
    assert main(["simulate", "toy", str(tmp_path / "again"), "--fmus", fmus]) == 2
    assert "invalid choice: 'toy'" in capsys.readouterr().err


def _kind(**members):
    """A Measurement subclass with the required hooks and ``members``."""
    required = {"kind": "sketch", "file": "sketch.csv", "read": classmethod(lambda *a: None),
                "noise": property(lambda self: None), "subset": lambda self, keep: self,
                "figures": lambda self, result: {}}
    return type("Sketch", (Measurement,), {**required, **members})


def test_a_kind_missing_a_required_hook_is_refused():
    cls = type("Sketch", (Measurement,), {"kind": "sketch", "file": "sketch.csv"})
    with pytest.raises(TypeError, match="must define figures, noise, read, subset"):
        kinds.register(cls)


def test_an_optional_hook_needs_its_capability_declared():
    with pytest.raises(TypeError, match="defines outliers without declaring .*'outliers'"):
        kinds.register(_kind(outliers=lambda self, residual_um: []))
    with pytest.raises(TypeError, match="declares 'shapes' but defines none"):
        kinds.register(_kind(capabilities=("shapes",)))
    cls = _kind(capabilities=("outliers",), outliers=lambda self, residual_um: [])
    assert kinds.register(cls) is cls
    kinds.unregister("sketch")


def test_a_second_kind_under_a_registered_name_is_refused():
    with pytest.raises(TypeError, match="registered already"):
        kinds.register(_kind(kind="tracking", file="other.csv"))


SOURCE = Path(__file__).resolve().parents[2] / "src" / "feedaxis"
# The modules each kind owns: only they may branch on its name, key by it or read its
# samples as a Case field (``case.positioning``); everything else iterates the registry.
OWNERS = {
    "positioning": ("measurement/positioning.py", "effects/positioning.py",
                    "effects/catalog.py", "positioning_details.py", "report/positioning.py",
                    "report/compensation_table.py", "comptable/", "compensate.py",
                    "uncertainty/", "importers/", "examples.py", "demo.py",
                    "cosim/scenarios/positioning.py", "cosim/replay.py", "standards/"),
    "tracking": ("measurement/tracking.py", "effects/tracking.py", "tracking_details.py",
                 "report/tracking.py", "cosim/scenarios/tracking.py"),
    "circular": ("measurement/circular.py", "circular_case.py", "effects/circular.py",
                 "report/circular.py", "comptable/circle.py", "cosim/circular.py",
                 "cosim/machine.py"),
}


def kind_name_uses(tree, names):
    """[(line, what)] where ``tree`` branches on, keys by or reads as a field one of
    ``names``: an attribute ``.name``, a keyword ``name=``, or the string ``"name"`` compared,
    used as a dict key or subscript, or listed in a container tested with ``in``."""
    found = []

    def literal(node):
        return isinstance(node, ast.Constant) and node.value in names

    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and node.attr in names:
            found.append((node.lineno, f".{node.attr}"))
        elif isinstance(node, ast.keyword) and node.arg in names:
            found.append((node.value.lineno, f"{node.arg}="))
        elif isinstance(node, ast.Compare):
            parts = [node.left, *node.comparators]
            parts += [e for p in parts if isinstance(p, (ast.Tuple, ast.List, ast.Set))
                      for e in p.elts]
            found += [(p.lineno, repr(p.value)) for p in parts if literal(p)]
        elif isinstance(node, ast.Dict):
            found += [(k.lineno, repr(k.value)) for k in node.keys if k is not None and literal(k)]
        elif isinstance(node, ast.Subscript) and literal(node.slice):
            found.append((node.lineno, repr(node.slice.value)))
    return found


def foreign_uses(names_by_owner):
    """{module path: [(line, what)]} of uses of a name outside its owner's modules."""
    foreign = {}
    for path in sorted(SOURCE.rglob("*.py")):
        relative = path.relative_to(SOURCE).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for owner, names in names_by_owner.items():
            if any(relative == own or (own.endswith("/") and relative.startswith(own))
                   for own in owner):
                continue
            for line, what in kind_name_uses(tree, names):
                foreign.setdefault(relative, []).append((line, what))
    return foreign


def test_no_module_branches_on_a_kind_outside_its_own():
    assert set(OWNERS) == set(kinds.kinds())
    assert foreign_uses({OWNERS[kind]: {kind} for kind in OWNERS}) == {}


def controller_mentions(tree, names):
    """[(line, name)] of every string (docstrings too) naming one of ``names`` as a word."""
    return [(node.lineno, name) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            for name in names if re.search(rf"\b{name}\b", node.value, re.IGNORECASE)]


def test_no_controller_name_outside_its_module():
    """A controller is named only in its own module: the registry, the command line and
    its help read the Controller objects."""
    from feedaxis.comptable import CONTROLLERS
    foreign = {}
    for path in sorted(SOURCE.rglob("*.py")):
        relative = path.relative_to(SOURCE).as_posix()
        names = {name for name, controller in CONTROLLERS.items()
                 if relative != f"comptable/{controller.module}.py"}
        tree = ast.parse(path.read_text(encoding="utf-8"))
        found = kind_name_uses(tree, names) + controller_mentions(tree, names)
        if found:
            foreign[relative] = found
    assert foreign == {}


def test_the_checks_find_a_branch_on_a_kind_and_a_controller_named():
    code = ('if comparison["kind"] == "tracking":\n    pass\n'
            'size = case.positioning.size\nVIEWS = {"tracking": 1}\n'
            'write_case(folder, axis, positioning=columns)\nif kind in ("tracking",): pass\n')
    found = kind_name_uses(ast.parse(code), {"positioning", "tracking"})
    assert sorted(line for line, _ in found) == [1, 3, 4, 5, 6]
    code = 'CHOICES = ("alpha", "beta")\nHELP = "the .COM of Alpha"\n'
    assert sorted(controller_mentions(ast.parse(code), {"alpha"})) == [(1, "alpha"), (2, "alpha")]
