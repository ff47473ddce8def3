/* Loading Python and pythonfmu's library.
 *
 * pythonfmu's platform library (libpythonfmu-export.so beside this one) expects the host to
 * have loaded libpython, which only Python hosts do. This part loads libpython RTLD_GLOBAL
 * when the host has not (a plain C host such as fmuCheck or OMSimulator) and starts the
 * interpreter that built the FMU (its program name finds the virtual environment) or, in a
 * standalone FMU, the one the FMU carries (FEEDAXIS_RUNTIME), never finalising it:
 * finalisation runs libgfortran's close_units on a heap pythonfmu has already damaged, and
 * the process is ending anyway; a Python of another minor version than the one the layer is
 * compiled against is refused.
 *
 * Build-time constants (-D): FEEDAXIS_PYTHON_VERSION (major.minor of the C API compiled
 * against); FEEDAXIS_PYTHON (the interpreter to start) and FEEDAXIS_LIBPYTHON (its shared
 * library), which the environment variables of the same names override on the host; or, for
 * a standalone FMU, FEEDAXIS_RUNTIME (its CPython's folder in the unpacked FMU:
 * binaries/linux64/python, or binaries/x86_64-linux/python in an FMI 3.0 FMU),
 * FEEDAXIS_LIBPYTHON_NAME and FEEDAXIS_REQUIRED_MODULES (what a Python host must import).
 * Python is reached only through dlsym, so the library loads in a host without libpython. */
#define _GNU_SOURCE
#include "host.h"

#include <dlfcn.h>
#include <errno.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

struct PythonApi py;
char load_error[1024];
static void *real_library;

/* pythonfmu's function ``symbol`` (NULL before its library is loaded). */
void *real(const char *symbol)
{
    return real_library ? dlsym(real_library, symbol) : NULL;
}

int python_loaded(void)
{
    return real_library != NULL;
}

/* ---- the Python C API, found with dlsym (never linked: see the top) ------------------- */

#define FIND(field, symbol) (py.field = dlsym(RTLD_DEFAULT, symbol)) != NULL

/* Resolve the API once Python runs; py.ready stays 0 if a symbol is missing. */
static void resolve_python_api(void)
{
    py.ready = FIND(gil_ensure, "PyGILState_Ensure") && FIND(gil_release, "PyGILState_Release")
        && FIND(import, "PyImport_ImportModule") && FIND(get_attr, "PyObject_GetAttrString")
        && FIND(call, "PyObject_CallObject")
        && FIND(tuple_new, "PyTuple_New") && FIND(tuple_set, "PyTuple_SetItem")
        && FIND(tuple_get, "PyTuple_GetItem") && FIND(tuple_size, "PyTuple_Size")
        && FIND(list_get, "PyList_GetItem") && FIND(list_size, "PyList_Size")
        && FIND(dict_get, "PyDict_GetItemString") && FIND(sys_get, "PySys_GetObject")
        && FIND(from_double, "PyFloat_FromDouble") && FIND(as_double, "PyFloat_AsDouble")
        && FIND(as_long, "PyLong_AsLong") && FIND(from_string, "PyUnicode_FromString")
        && FIND(from_path, "PyUnicode_DecodeFSDefault") && FIND(as_utf8, "PyUnicode_AsUTF8")
        && FIND(bytes_new, "PyBytes_FromStringAndSize")
        && FIND(decref, "Py_DecRef") && FIND(err_occurred, "PyErr_Occurred")
        && FIND(err_fetch, "PyErr_Fetch") && FIND(err_clear, "PyErr_Clear")
        && FIND(str, "PyObject_Str") && FIND(is_initialized, "Py_IsInitialized")
        && FIND(none, "_Py_NoneStruct") && FIND(true_, "_Py_TrueStruct");
}

/* The pending Python exception's text in ``text``; clears it. Holds the GIL. */
void take_python_error(char *text, size_t size)
{
    PyObject *type = NULL, *value = NULL, *traceback = NULL;
    py.err_fetch(&type, &value, &traceback);
    PyObject *message = value ? py.str(value) : NULL;
    const char *reason = message ? py.as_utf8(message) : NULL;
    snprintf(text, size, "%s", reason ? reason : "(no message)");
    if (py.err_occurred()) py.err_clear();
    if (message) py.decref(message);
    if (type) py.decref(type);
    if (value) py.decref(value);
    if (traceback) py.decref(traceback);
}

/* ---- starting Python --------------------------------------------------------------- */


/* Why loading failed: the message fmi2Instantiate gives the host. Returns -1. */
static int fail(const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(load_error, sizeof load_error, format, args);
    va_end(args);
    return -1;
}

/* Whether ``version`` (Py_GetVersion: "3.11.7 (main, ...") is FEEDAXIS_PYTHON_VERSION: the
 * layer is compiled against that minor version's C API (PyConfig's layout, the object
 * macros), so the minor version must match; ``which`` names the Python in the message. */
static int check_version(const char *version, const char *which)
{
    size_t n = strlen(FEEDAXIS_PYTHON_VERSION);
    if (version && strncmp(version, FEEDAXIS_PYTHON_VERSION, n) == 0 && version[n] == '.')
        return 0;
    return fail("%s is Python %.*s; this FMU needs CPython %s (the minor version that built it: "
                "its host layer is compiled against that version's C API)", which,
                version ? (int)strcspn(version, " ") : 1, version ? version : "?",
                FEEDAXIS_PYTHON_VERSION);
}

/* Load libpython ``path`` RTLD_GLOBAL (pythonfmu's library and numpy's extension modules
 * take its symbols from the process); ``which`` names it in the messages. */
static int load_libpython(const char *path, const char *which)
{
    void *library = dlopen(path, RTLD_NOW | RTLD_GLOBAL);
    if (!library) return fail("cannot load %s: %s", which, dlerror());
    const char *(*get_version)(void) = (const char *(*)(void))dlsym(library, "Py_GetVersion");
    if (!get_version || !dlsym(library, "Py_IsInitialized"))
        return fail("%s is not a libpython", which);
    return check_version(get_version(), which);
}

/* An isolated Python decodes file names by the locale, ASCII in a bare root (no locale):
 * a resource folder named in UTF-8 (what a file URI's %-escapes encode) would not import.
 * UTF-8 mode (PEP 540) makes every file name UTF-8, as a Python in the C locale does. */
static int preinitialise_utf8(void)
{
    void (*init)(PyPreConfig *) = dlsym(RTLD_DEFAULT, "PyPreConfig_InitIsolatedConfig");
    PyStatus (*preinitialise)(const PyPreConfig *) = dlsym(RTLD_DEFAULT, "Py_PreInitialize");
    int (*is_exception)(PyStatus) = dlsym(RTLD_DEFAULT, "PyStatus_Exception");
    if (!init || !preinitialise || !is_exception) return -1;
    PyPreConfig preconfig;
    init(&preconfig);
    preconfig.utf8_mode = 1;
    return is_exception(preinitialise(&preconfig)) ? -1 : 0;
}

/* Start the interpreter: ``isolated`` (the FMU's own runtime: no environment variables, no
 * user site, no bytecode written) with prefix ``path``, else Python's default configuration
 * with program name ``path`` (which finds that interpreter's virtual environment). Never
 * finalised: finalisation runs libgfortran's close_units on a heap pythonfmu has already
 * damaged, and the process is ending anyway. */
static int start_interpreter(int isolated, const char *path, const char *which)
{
    void (*init_config)(PyConfig *) =
        dlsym(RTLD_DEFAULT, isolated ? "PyConfig_InitIsolatedConfig" : "PyConfig_InitPythonConfig");
    PyStatus (*set_string)(PyConfig *, wchar_t **, const char *) =
        dlsym(RTLD_DEFAULT, "PyConfig_SetBytesString");
    PyStatus (*initialize)(const PyConfig *) = dlsym(RTLD_DEFAULT, "Py_InitializeFromConfig");
    void (*clear)(PyConfig *) = dlsym(RTLD_DEFAULT, "PyConfig_Clear");
    int (*is_exception)(PyStatus) = dlsym(RTLD_DEFAULT, "PyStatus_Exception");
    PyThreadState *(*save_thread)(void) = dlsym(RTLD_DEFAULT, "PyEval_SaveThread");
    if (!init_config || !set_string || !initialize || !clear || !is_exception || !save_thread)
        return fail("%s lacks the PyConfig API", which);
    if (isolated && preinitialise_utf8() != 0) return fail("cannot pre-initialise %s", which);
    PyConfig config;
    init_config(&config);
    config.install_signal_handlers = 0; /* the host owns SIGINT */
    config.parse_argv = 0;
    PyStatus status;
    if (isolated) {
        /* the prefix, and a program name inside it: a bare name would be looked up on PATH,
         * and a virtual environment found there would become sys.prefix */
        char program[4200];
        snprintf(program, sizeof program, "%s/bin/python%s", path, FEEDAXIS_PYTHON_VERSION);
        config.write_bytecode = 0; /* the FMU's folder may be read-only */
        status = set_string(&config, &config.home, path);
        if (!is_exception(status)) status = set_string(&config, &config.program_name, program);
    } else {
        status = set_string(&config, &config.program_name, path);
    }
    if (!is_exception(status)) status = initialize(&config);
    clear(&config);
    if (is_exception(status))
        return fail("cannot start %s: %s", which, status.err_msg ? status.err_msg : "no reason");
    save_thread(); /* pythonfmu takes the GIL with PyGILState_Ensure */
    return 0;
}

#ifdef FEEDAXIS_RUNTIME
/* A standalone FMU: it carries its own CPython (libpython, the standard library and the
 * packages its step path imports) in <unpacked FMU>/FEEDAXIS_RUNTIME, found
 * from the resource location the host passes, never from a path of the build machine.
 * A C host: the layer starts that Python. A process where another standalone feedaxis FMU
 * started its own: this FMU's packages go behind that one's on sys.path. A Python host: its
 * own interpreter runs the FMU when it imports FEEDAXIS_REQUIRED_MODULES, else
 * fmi2Instantiate fails naming what is missing. */
#define RUNTIME_MARK "feedaxis_fmu_runtime" /* the module a standalone FMU's Python carries */

static char runtime[MAX_PATH_LENGTH]; /* this FMU's own CPython prefix */

/* The runtime of the FMU whose resources are in ``folder`` (a local path). */
static int find_runtime(const char *folder)
{
    char unpacked[MAX_PATH_LENGTH];
    snprintf(unpacked, sizeof unpacked, "%s", folder);
    char *slash = strrchr(unpacked, '/');
    if (slash) *slash = 0; /* the unpacked FMU */
    int length = snprintf(runtime, sizeof runtime, "%s/%s", unpacked, FEEDAXIS_RUNTIME);
    if (length < 0 || (size_t)length >= sizeof runtime)
        return fail("the resource folder %s is too long a path", folder);
    if (access(runtime, R_OK | X_OK) != 0)
        return fail("this standalone FMU's own Python is missing: %s: %s (resource folder %s)",
                    runtime, strerror(errno), folder);
    return 0;
}

/* feedaxis_fmu_runtime.join(runtime): this FMU's runtime joins the interpreter (its module,
 * fmus/common/feedaxis_fmu_runtime.py, is carried in the runtime's site-packages). */
static int join_runtime(void)
{
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *module = py.import(RUNTIME_MARK);
    PyObject *join = module ? py.get_attr(module, "join") : NULL;
    PyObject *args = join ? py.tuple_new(1) : NULL;
    PyObject *result = NULL;
    if (args && py.tuple_set(args, 0, py.from_path(runtime)) == 0) result = py.call(join, args);
    char reason[512] = "";
    if (!result) take_python_error(reason, sizeof reason);
    if (result) py.decref(result);
    if (args) py.decref(args);
    if (join) py.decref(join);
    if (module) py.decref(module);
    py.gil_release(gil);
    return result ? 0 : fail("cannot use this FMU's own Python: %s", reason);
}

/* Start the Python this FMU carries (its libpython loaded already, by this FMU or another
 * of the same minor version). */
static int start_own_python(void)
{
    if (start_interpreter(1, runtime, "this FMU's own Python") != 0) return -1;
    resolve_python_api();
    if (!py.ready) return fail("this FMU's own libpython lacks a function the layer calls");
    return join_runtime();
}

/* The names of FEEDAXIS_REQUIRED_MODULES the running Python cannot import, in ``missing``;
 * holds the GIL. */
static void find_missing(char *missing, size_t size)
{
    PyObject *util = py.import("importlib.util");
    PyObject *find_spec = util ? py.get_attr(util, "find_spec") : NULL;
    char names[] = FEEDAXIS_REQUIRED_MODULES, *rest = NULL;
    for (char *name = strtok_r(names, " ", &rest); name && find_spec;
         name = strtok_r(NULL, " ", &rest)) {
        PyObject *args = py.tuple_new(1);
        PyObject *spec = NULL;
        if (args && py.tuple_set(args, 0, py.from_string(name)) == 0)
            spec = py.call(find_spec, args);
        if (args) py.decref(args);
        if (!spec || spec == py.none)
            snprintf(missing + strlen(missing), size - strlen(missing), "%s%s",
                     *missing ? ", " : "", name);
        if (spec) py.decref(spec);
        if (py.err_occurred()) py.err_clear();
    }
    if (find_spec) py.decref(find_spec);
    if (util) py.decref(util);
    if (py.err_occurred()) py.err_clear();
}

/* Python runs already: join the interpreter another standalone FMU started, or check that
 * the host's own Python imports what this FMU needs. */
static int use_running_python(void)
{
    resolve_python_api();
    if (!py.ready) return fail("the Python in this process lacks a function the layer calls");
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *modules = py.sys_get("modules");
    int started_by_a_standalone_fmu = modules && py.dict_get(modules, RUNTIME_MARK);
    char missing[512] = "", executable[512] = "?";
    if (!started_by_a_standalone_fmu) {
        find_missing(missing, sizeof missing);
        PyObject *program = py.sys_get("executable");
        const char *text = program ? py.as_utf8(program) : NULL;
        if (text) snprintf(executable, sizeof executable, "%s", text);
        if (py.err_occurred()) py.err_clear();
    }
    py.gil_release(gil);
    if (started_by_a_standalone_fmu) return join_runtime();
    if (*missing)
        return fail("the Python running in this process (%s) cannot import %s, which this FMU "
                    "needs: install it there, or run the FMU in a host that is not a Python "
                    "process, where it starts the Python it carries", executable, missing);
    return 0;
}

static int start_python(const char *folder)
{
    if (find_runtime(folder) != 0) return -1;
    const char *(*get_version)(void) = dlsym(RTLD_DEFAULT, "Py_GetVersion");
    if (get_version) {
        if (check_version(get_version(), "the Python loaded in this process") != 0) return -1;
    } else {
        char libpython[4160], which[4200];
        snprintf(libpython, sizeof libpython, "%s/lib/%s", runtime, FEEDAXIS_LIBPYTHON_NAME);
        snprintf(which, sizeof which, "this FMU's own libpython %s", libpython);
        if (load_libpython(libpython, which) != 0) return -1;
    }
    int (*is_initialized)(void) = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    return is_initialized() ? use_running_python() : start_own_python();
}
#else
/* The FMU runs in the Python that built it (FEEDAXIS_PYTHON, FEEDAXIS_LIBPYTHON at build
 * time), or the one the environment variables of the same names give, or the host's own. */
static const char *setting(const char *name, const char *built_in, char *which, size_t size)
{
    const char *value = getenv(name);
    if (value && *value) {
        snprintf(which, size, "%s=%s", name, value);
        return value;
    }
    snprintf(which, size, "%s (the build machine's; set %s to one here)", built_in, name);
    return built_in;
}

static int start_python(const char *folder)
{
    (void)folder;
    char which[4200];
    const char *(*get_version)(void) = dlsym(RTLD_DEFAULT, "Py_GetVersion");
    if (get_version) { /* a Python host, or another FMU loaded one */
        if (check_version(get_version(), "the Python loaded in this process") != 0) return -1;
    } else {
        const char *libpython =
            setting("FEEDAXIS_LIBPYTHON", FEEDAXIS_LIBPYTHON, which, sizeof which);
        if (!*libpython)
            return fail("the Python that built this FMU has no shared libpython: set "
                        "FEEDAXIS_LIBPYTHON to a CPython %s libpython (and FEEDAXIS_PYTHON)",
                        FEEDAXIS_PYTHON_VERSION);
        if (load_libpython(libpython, which) != 0) return -1;
    }
    int (*is_initialized)(void) = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (!is_initialized()) {
        const char *python = setting("FEEDAXIS_PYTHON", FEEDAXIS_PYTHON, which, sizeof which);
        if (access(python, X_OK) != 0)
            return fail("cannot use %s as the Python: %s", which, strerror(errno));
        if (start_interpreter(0, python, which) != 0) return -1;
    }
    resolve_python_api();
    return py.ready ? 0 : fail("the libpython in this process lacks a function the layer calls");
}
#endif

/* pythonfmu's library keeps its interpreter state in a static shared_ptr, destroyed at exit
 * by a C++ static destructor, and then assigns nullptr to that destroyed shared_ptr in its
 * ELF destructor finalizePythonInterpreter: a write into the freed control block, which is
 * the exit-time heap corruption (valgrind: "Invalid read ... finalizePythonInterpreter",
 * then free() aborts in libgfortran's close_units). Calling it first, from an exit handler
 * registered after pythonfmu's, releases the state while it is alive; its later calls then
 * see an empty pointer. */
void release_pythonfmu_state(void)
{
    void (*release)(void) = (void (*)(void))real("finalizePythonInterpreter");
    if (release) release();
}

/* Unload pythonfmu's library (its state released first: release_pythonfmu_state). */
void unload_pythonfmu(void)
{
    release_pythonfmu_state();
    if (real_library) dlclose(real_library);
    real_library = NULL;
}

/* Start (or find) Python, then load pythonfmu's library from this library's folder;
 * ``folder``: the resource folder of the first instance (a local path). */
static void load(const char *folder)
{
    Dl_info self;
    if (start_python(folder) != 0) return;
    if (!dladdr((void *)&load, &self) || !self.dli_fname) {
        fail("cannot locate the FMU's binary folder");
        return;
    }
    char path[4096];
    snprintf(path, sizeof path, "%s", self.dli_fname);
    char *slash = strrchr(path, '/');
    snprintf(slash ? slash + 1 : path, sizeof path - (slash ? (size_t)(slash + 1 - path) : 0),
             "libpythonfmu-export.so");
    real_library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!real_library) {
        fail("cannot load %s: %s", path, dlerror());
        return;
    }
    /* Registered after pythonfmu's static destructors, so that it runs before them: at exit,
     * and when the host unloads this library (glibc binds a library's atexit handlers to it). */
    atexit(unloading);
    prepare_mirror();
}

/* The first fmi2Instantiate with valid arguments loads; later ones see its outcome. */
void load_once(const char *folder)
{
    static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
    static int tried;
    pthread_mutex_lock(&lock);
    if (!tried) load(folder);
    tried = 1;
    pthread_mutex_unlock(&lock);
}
