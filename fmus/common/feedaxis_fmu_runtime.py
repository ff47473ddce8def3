"""The Python side of a standalone FMU's own runtime (binaries/linux64/python/, in FMI 3.0
binaries/x86_64-linux/python/; see feedaxis.fmu_standalone): standalone FMUs in one process
share one interpreter.

The first standalone FMU a host loads starts the Python it carries; the others find it
running and :func:`join` it with their own runtimes. Each FMU carries only what its own step
path imports, so two FMUs' copies of a package may hold different modules, while an
interpreter imports a package once: a finder placed last on ``sys.meta_path`` looks for
every module the usual finders miss in each joined runtime (a scipy only the servo carries,
a numpy submodule only it imports). Runtimes join only when built alike: the same Python
and the same version of every package both carry (their ``feedaxis-runtime.json``).
"""
import json
import sys
from importlib.machinery import PathFinder
from pathlib import Path

MANIFEST = "feedaxis-runtime.json"
_joined = []  # (runtime folder, its manifest), in the order joined


def _folders(runtime):
    """The runtime's extension-module and site-packages folders."""
    library = Path(runtime) / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}"
    return library / "lib-dynload", library / "site-packages"


class JoinedRuntimes:
    """Finds, in every joined runtime, a module the usual finders do not."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        parent = name.rpartition(".")[0]
        for runtime, _ in _joined:
            dynload, site = _folders(runtime)
            search = [site.joinpath(*parent.split("."))] if parent else [dynload, site]
            spec = PathFinder.find_spec(name, [str(folder) for folder in search])
            if spec is not None:
                return spec
        return None


def _conflicts(manifest, other):
    """What differs between two runtimes' manifests ('' when they can share a process)."""
    differences = []
    if manifest["python"] != other["python"]:
        differences.append(f"Python {manifest['python']} / {other['python']}")
    differences += [f"{name} {version} / {other['packages'][name]}"
                    for name, version in manifest["packages"].items()
                    if other["packages"].get(name, version) != version]
    return ", ".join(differences)


def join(runtime):
    """Let this interpreter import from ``runtime`` (a standalone FMU's CPython prefix);
    raise ImportError naming what differs from a runtime joined before."""
    if any(folder == runtime for folder, _ in _joined):
        return
    manifest = json.loads((Path(runtime) / MANIFEST).read_text(encoding="utf-8"))
    for folder, other in _joined:
        conflicts = _conflicts(manifest, other)
        if conflicts:
            raise ImportError(f"this standalone FMU's Python differs from the one another "
                              f"standalone FMU started in this process ({conflicts}): load "
                              f"FMUs built with the same Python and packages together")
    _joined.append((runtime, manifest))
    for folder in map(str, _folders(runtime)):
        if folder not in sys.path:
            sys.path.append(folder)
    if JoinedRuntimes not in sys.meta_path:
        sys.meta_path.append(JoinedRuntimes)
