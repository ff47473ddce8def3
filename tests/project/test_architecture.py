"""Checks on the codebase itself: no import cycle among feedaxis's modules (function-level
imports included), the floors of the import graph stay layered (run this file as a
script to print them), and no merge left its conflict markers in a file."""
import ast
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "src" / "feedaxis"
TEXT_SUFFIXES = {".py", ".md", ".toml", ".c", ".h", ".yml", ".yaml", ".txt", ".cfg"}


def module_name(path):
    parts = ["feedaxis", *path.relative_to(SOURCE).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package(name, path):
    return name if path.name == "__init__.py" else name.rsplit(".", 1)[0]


def import_graph():
    """{module: {feedaxis modules it imports}}, every import statement counted.

    Importing ``feedaxis.a.b`` from outside package ``feedaxis.a`` runs ``feedaxis.a``
    (its ``__init__``) first, so that is an edge too; ``from package import name`` is an
    edge to the submodule when ``name`` is one.
    """
    paths = {module_name(p): p for p in SOURCE.rglob("*.py")}
    graph = {}
    for name, path in paths.items():
        package, targets = _package(name, path), set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                found = [base] + [f"{base}.{alias.name}" for alias in node.names]
            else:
                continue
            for target in found:
                if target in paths:
                    targets.add(target)
                    parent = target.rsplit(".", 1)[0]
                    while parent != "feedaxis" and not name.startswith(parent + "."):
                        targets.add(parent)
                        parent = parent.rsplit(".", 1)[0]
        targets.discard(name)
        graph[name] = {t for t in targets if not name.startswith(t + ".")}
    return graph


def cycles(graph):
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph.get(node, ()):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = set()
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.add(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def floors(graph):
    """{module: floor}: 0 for a module importing no feedaxis module, else one above the
    highest floor it imports (defined when the graph has no cycle)."""
    result = {}

    def floor(node):
        if node not in result:
            result[node] = 1 + max((floor(t) for t in graph[node]), default=-1)
        return result[node]

    for node in graph:
        floor(node)
    return result


def test_no_import_cycle_among_feedaxis_modules():
    assert cycles(import_graph()) == []


def test_the_checker_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_the_leaves_stay_leaves():
    """The ISO 230-2 figures, the physics and the statistics import nothing above them."""
    graph, floor = import_graph(), floors(import_graph())
    assert graph["feedaxis.iso230"] == set()
    for name in graph:
        if name.startswith(("feedaxis.physics", "feedaxis.stats")):
            assert all(t.startswith(("feedaxis.physics", "feedaxis.stats", "feedaxis.iso230",
                                     "feedaxis.errors")) for t in graph[name]), name
    assert floor["feedaxis.fit"] < floor["feedaxis.diagnose"] < floor["feedaxis.analysis"] \
        < floor["feedaxis.cli"]



def test_no_conflict_markers_in_the_project():
    """A merge's ``<<<<<<<`` / ``>>>>>>>`` lines never reach a committed file."""
    folders = ("src", "tests", "docs", "benchmarks", "fmus", "examples", ".ci")
    marked = [f"{path.relative_to(ROOT)}:{number}"
              for folder in folders for path in (ROOT / folder).rglob("*")
              if path.suffix in TEXT_SUFFIXES and path.is_file()
              for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1)
              if line.startswith(("<<<<<<< ", ">>>>>>> "))]
    marked += [f"{path.name}:{number}" for path in ROOT.glob("*.md")
               for number, line in enumerate(path.read_text().splitlines(), 1)
               if line.startswith(("<<<<<<< ", ">>>>>>> "))]
    assert not marked, marked


def test_scipy_stats_and_signal_load_when_first_used():
    """Start-up (issue 21): importing the command line and the analysis does not import
    scipy.stats or scipy.signal (about 0.5 s together); a test that needs them loads them."""
    code = ("import sys, feedaxis.cli, feedaxis.analysis, feedaxis.fit, feedaxis.diagnose, "
            "feedaxis.measurement.tracking, feedaxis.comptable.verify; "
            "print(sorted(m for m in ('scipy.stats', 'scipy.signal') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT / "src")})
    assert done.stdout.strip() == "[]", done.stdout + done.stderr

if __name__ == "__main__":
    by_floor = {}
    for name, level in floors(import_graph()).items():
        by_floor.setdefault(level, []).append(name.removeprefix("feedaxis."))
    for level in sorted(by_floor):
        print(f"{level:2d}  {', '.join(sorted(by_floor[level]))}")
