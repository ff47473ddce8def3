"""Freeing an FMU built by plain pythonfmu without corrupting the heap at exit (imports
nothing: the first-start processes of bench_fmi_floor use it before their first import
of feedaxis)."""


def free_instance(slave):
    """Free ``slave``'s instance and unload its library, as fmpy's ``freeInstance`` does, with
    a plain pythonfmu library's interpreter state released in between.

    pythonfmu's library (the empty set's) frees that state in a C++ static destructor at exit
    and then writes into it from its ELF destructor ``finalizePythonInterpreter`` (valgrind:
    invalid reads in finalizePythonInterpreter at exit, the block freed by the exit handlers),
    which now and then made glibc abort this benchmark at exit ("corrupted double-linked
    list"). Called while the state is alive, ``finalizePythonInterpreter`` empties it and
    the exit-time calls find nothing to free. The feedaxis FMUs' host layer does the same
    for the pythonfmu library it carries; the native FMUs have no such function."""
    slave.fmi2FreeInstance(slave.component)
    release = getattr(slave.dll, "finalizePythonInterpreter", None)
    if release is not None:
        release()
    slave.freeLibrary()
