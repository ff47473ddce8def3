/* feedaxis FMI host layer: the model-identifier library of every feedaxis FMU.
 *
 * pythonfmu's platform library (shipped next to this one as libpythonfmu-export.so) expects
 * the host to have loaded libpython, which only Python hosts do. This layer
 *   1. loads libpython RTLD_GLOBAL when the host has not (a plain C host such as
 *      fmuCheck or OMSimulator) and starts the interpreter that built the FMU (its
 *      program name finds the virtual environment, so numpy and scipy import) or, in a
 *      standalone FMU, the one the FMU carries (FEEDAXIS_RUNTIME), never finalising it:
 *      finalisation runs libgfortran's close_units on a heap pythonfmu has already
 *      damaged, and the process is ending anyway; a Python of another minor version than
 *      the one the layer is compiled against is refused;
 *   2. forwards every fmi2 function to pythonfmu's library, guarding the FMI state machine:
 *      a fixed parameter or an output set after initialisation is refused with fmi2Error,
 *      a call made after fmi2Fatal is refused without reaching pythonfmu (whose instance
 *      then holds freed Python objects), an error logged by the slave during a call turns
 *      that call's status into fmi2Error; what a host gets wrong is refused with fmi2Error
 *      before pythonfmu sees it (where pythonfmu would raise, which is fmi2Fatal, or crash):
 *      a value reference that is no variable of the function's type (references_known), a
 *      NULL array or state pointer, a serialisation buffer of the wrong size, a state buffer
 *      the slave cannot restore (state_refused);
 *   3. passes every message to the host's logger with a category (pythonfmu passes NULL),
 *      the instance name in front, never text containing '%' as the format;
 *   4. reuses freed instances through pythonfmu's fmi2Reset (its fmi2Instantiate leaks);
 *   5. keeps the Real inputs and outputs itself while stepping: fmi2SetReal and fmi2GetReal
 *      of them never reach Python, and fmi2DoStep is one Python call (the slave's exchange
 *      function, feedaxis_slave.claim) that takes the inputs and returns the outputs, where
 *      pythonfmu makes three, each building Python lists (about 6 of its 7.5 us per step).
 *      Any other call first hands pending inputs to the slave through pythonfmu;
 *   6. when the host unloads it (or at exit), gives its pooled instances back to pythonfmu
 *      and unloads pythonfmu's library (unloading): it does not pin itself in the process.
 *
 * Build-time constants (-D): FEEDAXIS_PYTHON_VERSION (major.minor of the C API compiled
 * against); FEEDAXIS_PYTHON (the interpreter to start) and FEEDAXIS_LIBPYTHON (its shared
 * library), which the environment variables of the same names override on the host; or, for
 * a standalone FMU, FEEDAXIS_RUNTIME (its CPython's folder in binaries/linux64),
 * FEEDAXIS_LIBPYTHON_NAME and FEEDAXIS_REQUIRED_MODULES (what a Python host must import).
 * The per-FMU variable table comes from feedaxis_fmi_vars.h. Python is reached only through
 * dlsym, so the library loads in a host without libpython.
 */
#define _GNU_SOURCE
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <ctype.h>
#include <dlfcn.h>
#include <errno.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h" /* the official FMI 2.0 headers (fmi2/): every export checked */
#include "feedaxis_fmi_vars.h"

#define EXPORT FMI2_Export

#define MAX_MIRRORED 16
#define HANDOFF_MODULE "feedaxis_fmu_handoff" /* feedaxis_slave.HANDOFF_MODULE */

enum mode { INSTANTIATED, INITIALISING, STEPPING, TERMINATED, FAILED, DEAD };

typedef struct {
    void *real;                        /* pythonfmu's component */
    fmi2CallbackFunctions host;        /* the host's callbacks */
    fmi2CallbackFunctions mine;        /* what pythonfmu calls */
    char *name;
    char *guid;
    char *resources;
    enum mode mode;
    int host_logging;
    fmi2Status worst_logged;           /* worst status logged during the current call */
    PyObject *exchange;                /* the slave's exchange function, or NULL */
    double inputs[MAX_MIRRORED];       /* the Real inputs, in the order of input_vr */
    double outputs[MAX_MIRRORED];      /* the Real outputs, in the order of output_vr */
    int inputs_current;                /* inputs[] hold the slave's inputs or newer ones */
    int inputs_pending;                /* inputs[] hold values the slave has not been given */
    int outputs_current;               /* outputs[] equal the slave's outputs */
    double last_successful_time;       /* fmi2LastSuccessfulTime */
    int wants_to_terminate;            /* fmi2Terminated: a step failed */
} Guard;

static void *real_library;
static char load_error[1024];

/* pythonfmu's function ``symbol`` (NULL before its library is loaded). */
static void *real(const char *symbol)
{
    return real_library ? dlsym(real_library, symbol) : NULL;
}

/* ---- the Python C API, found with dlsym (never linked: see the top) ------------------- */

static struct {
    PyGILState_STATE (*gil_ensure)(void);
    void (*gil_release)(PyGILState_STATE);
    PyObject *(*import)(const char *);
    PyObject *(*get_attr)(PyObject *, const char *);
    PyObject *(*call)(PyObject *, PyObject *);
    PyObject *(*tuple_new)(Py_ssize_t);
    int (*tuple_set)(PyObject *, Py_ssize_t, PyObject *);
    PyObject *(*tuple_get)(PyObject *, Py_ssize_t);
    Py_ssize_t (*tuple_size)(PyObject *);
    PyObject *(*list_get)(PyObject *, Py_ssize_t);
    Py_ssize_t (*list_size)(PyObject *);
    PyObject *(*dict_get)(PyObject *, const char *);
    PyObject *(*sys_get)(const char *);
    PyObject *(*from_double)(double);
    double (*as_double)(PyObject *);
    long (*as_long)(PyObject *);
    PyObject *(*from_string)(const char *);
    PyObject *(*from_path)(const char *);
    PyObject *(*bytes_new)(const char *, Py_ssize_t);
    const char *(*as_utf8)(PyObject *);
    void (*decref)(PyObject *);
    PyObject *(*err_occurred)(void);
    void (*err_fetch)(PyObject **, PyObject **, PyObject **);
    void (*err_clear)(void);
    PyObject *(*str)(PyObject *);
    int (*is_initialized)(void);
    PyObject *none;
    int ready;
} py;

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
        && FIND(none, "_Py_NoneStruct");
}

/* The pending Python exception's text in ``text``; clears it. Holds the GIL. */
static void take_python_error(char *text, size_t size)
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

/* ---- loading Python and pythonfmu's library ---------------------------------------- */

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
 * packages its step path imports) in <unpacked FMU>/binaries/linux64/FEEDAXIS_RUNTIME, found
 * from the resource location the host passes, never from a path of the build machine.
 * A C host: the layer starts that Python. A process where another standalone feedaxis FMU
 * started its own: this FMU's packages go behind that one's on sys.path. A Python host: its
 * own interpreter runs the FMU when it imports FEEDAXIS_REQUIRED_MODULES, else
 * fmi2Instantiate fails naming what is missing. */
#define RUNTIME_MARK "feedaxis_fmu_runtime" /* the module a standalone FMU's Python carries */

/* The local path of file URI ``uri`` (file:///p, file://localhost/p, file:/p), decoded. */
static int uri_path(const char *uri, char *path, size_t size)
{
    const char *p = strncmp(uri, "file://localhost/", 17) == 0 ? uri + 16
                    : strncmp(uri, "file:///", 8) == 0         ? uri + 7
                    : strncmp(uri, "file:/", 6) == 0           ? uri + 5 : NULL;
    size_t n = 0;
    for (; p && *p && n + 1 < size; ++p) {
        if (p[0] == '%' && isxdigit((unsigned char)p[1]) && isxdigit((unsigned char)p[2])) {
            char hex[3] = {p[1], p[2], 0};
            path[n++] = (char)strtol(hex, NULL, 16);
            p += 2;
        } else {
            path[n++] = *p;
        }
    }
    if (!p || *p) return -1;
    path[n] = 0;
    while (n > 1 && path[n - 1] == '/') path[--n] = 0;
    return 0;
}

static char runtime[4096]; /* this FMU's own CPython prefix */

static int find_runtime(const char *resources)
{
    char folder[4096];
    if (uri_path(resources, folder, sizeof folder) != 0)
        return fail("the resource location %s is not a file URI: this standalone FMU finds its "
                    "own Python beside it", resources);
    char *slash = strrchr(folder, '/');
    if (slash) *slash = 0; /* the unpacked FMU */
    int length = snprintf(runtime, sizeof runtime, "%s/binaries/linux64/%s", folder,
                          FEEDAXIS_RUNTIME);
    if (length < 0 || (size_t)length >= sizeof runtime)
        return fail("the resource location %s is too long a path", resources);
    if (access(runtime, R_OK | X_OK) != 0)
        return fail("this standalone FMU's own Python is missing: %s: %s (resource location %s)",
                    runtime, strerror(errno), resources);
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

static int start_python(const char *resources)
{
    if (find_runtime(resources) != 0) return -1;
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

static int start_python(const char *resources)
{
    (void)resources;
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
static void release_pythonfmu_state(void)
{
    void (*release)(void) = (void (*)(void))real("finalizePythonInterpreter");
    if (release) release();
}

static void prepare_mirror(void);
static void unloading(void);

/* Start (or find) Python, then load pythonfmu's library from this library's folder. */
static void load(const char *resources)
{
    Dl_info self;
    if (start_python(resources) != 0) return;
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

/* The first fmi2Instantiate of this library loads; later ones see its outcome. */
static void load_once(const char *resources)
{
    static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
    static int tried;
    pthread_mutex_lock(&lock);
    if (!tried) load(resources);
    tried = 1;
    pthread_mutex_unlock(&lock);
}

/* ---- logging ---------------------------------------------------------------------- */

static const char *category_of(fmi2Status status)
{
    static const char *names[] = {"logAll", "logStatusWarning", "logStatusDiscard",
                                  "logStatusError", "logStatusFatal", "logAll"};
    return names[status <= fmi2Pending ? status : fmi2Error];
}

/* Every message starts with the instance name (the Python slave of a reused instance does
 * not know its new name). */
static void tell_host(Guard *g, fmi2Status status, const char *category, const char *message)
{
    if (!g->host.logger || (status < fmi2Warning && !g->host_logging)) return;
    size_t size = strlen(g->name) + strlen(message) + 3;
    char *text = malloc(size);
    if (!text) return;
    snprintf(text, size, "%s: %s", g->name, message);
    /* Plain text is its own format (hosts that ignore the arguments still read it); text
     * with a '%' goes as the argument of "%s". */
    g->host.logger(g->host.componentEnvironment, g->name, status,
                   category && *category ? category : category_of(status),
                   strchr(text, '%') ? "%s" : text, text);
    free(text);
}

/* pythonfmu passes each message as the format with no arguments: treat it as text. */
static void guard_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                         fmi2String category, fmi2String message, ...)
{
    Guard *g = env;
    (void)name;
    if (status > g->worst_logged && status <= fmi2Fatal) g->worst_logged = status;
    tell_host(g, status, category, message ? message : "");
}

static fmi2Status refuse(Guard *g, const char *format, ...)
{
    char message[512];
    va_list args;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    tell_host(g, fmi2Error, NULL, message);
    return fmi2Error;
}

/* ---- the state guard -------------------------------------------------------------- */

static const char *const MODE_NAMES[] = {"instantiated", "initialisation mode", "step mode",
                                         "terminated", "failed", "dead after fmi2Fatal"};

/* Whether a call may reach pythonfmu; refuses it with a message otherwise. */
static int usable(Guard *g, const char *function, int allowed_when_failed)
{
    if (g->mode == DEAD || (g->mode == FAILED && !allowed_when_failed)) {
        refuse(g, "%s refused: the instance is %s; only fmi2FreeInstance%s is allowed", function,
               MODE_NAMES[g->mode], g->mode == FAILED ? ", fmi2Terminate, fmi2Reset, fmi2Get*" : "");
        return 0;
    }
    return 1;
}

static void begin(Guard *g)
{
    g->worst_logged = fmi2OK;
}

/* The call's status: pythonfmu's, made worse by any error the slave logged meanwhile. */
static fmi2Status finish(Guard *g, fmi2Status status)
{
    if (g->worst_logged >= fmi2Error && status < g->worst_logged) status = g->worst_logged;
    if (status == fmi2Fatal) g->mode = DEAD;
    else if (status == fmi2Error) g->mode = FAILED;
    return status;
}

static int settable(Guard *g, const fmi2ValueReference vr[], size_t nvr)
{
    for (size_t i = 0; i < nvr; ++i) {
        for (size_t k = 0; k < FEEDAXIS_N_VARS; ++k) {
            if (FEEDAXIS_VARS[k].vr != vr[i]) continue;
            if (FEEDAXIS_VARS[k].kind == 'o') {
                refuse(g, "%s is an output and cannot be set", FEEDAXIS_VARS[k].name);
                return 0;
            }
            if (FEEDAXIS_VARS[k].kind == 'f' && g->mode != INSTANTIATED && g->mode != INITIALISING) {
                refuse(g, "%s is a fixed parameter and cannot be set in %s", FEEDAXIS_VARS[k].name,
                       MODE_NAMES[g->mode]);
                return 0;
            }
        }
    }
    return 1;
}

/* ---- value references: a host's bad reference is refused here (pythonfmu raises, which
 * is fmi2Fatal) ------------------------------------------------------------------------ */

static const char *type_name(char type)
{
    switch (type) {
    case 'R': return "a Real";
    case 'I': return "an Integer";
    case 'B': return "a Boolean";
    default: return "a String";
    }
}

/* Whether every reference in ``vr`` is a variable of ``type``; refuses the call otherwise. */
static int references_known(Guard *g, const char *function, char type,
                            const fmi2ValueReference vr[], size_t nvr, const void *values)
{
    if (nvr > 0 && (!vr || !values)) {
        refuse(g, "%s: NULL value reference or value array for %zu values", function, nvr);
        return 0;
    }
    for (size_t i = 0; i < nvr; ++i) {
        size_t k = 0;
        while (k < FEEDAXIS_N_VARS && FEEDAXIS_VARS[k].vr != vr[i]) ++k;
        if (k == FEEDAXIS_N_VARS) {
            refuse(g, "%s: value reference %u is not a variable of this FMU", function, vr[i]);
            return 0;
        }
        if (FEEDAXIS_VARS[k].type != type) {
            refuse(g, "%s: value reference %u is %s, %s variable, not %s", function, vr[i],
                   FEEDAXIS_VARS[k].name, type_name(FEEDAXIS_VARS[k].type), type_name(type));
            return 0;
        }
    }
    return 1;
}

/* ---- the mirror: Real inputs and outputs kept here while stepping (item 5) ------------ */

static fmi2ValueReference input_vr[MAX_MIRRORED], output_vr[MAX_MIRRORED];
static size_t n_inputs, n_outputs;

/* Index the mirrored variables; ``mirrorable`` stays 0 (every call then goes through
 * pythonfmu) if an input or output is not a Real or there are too many. */
static int mirrorable;

static void prepare_mirror(void)
{
    for (size_t k = 0; k < FEEDAXIS_N_VARS; ++k) {
        const FeedaxisVar *v = &FEEDAXIS_VARS[k];
        if (v->kind != 'u' && v->kind != 'o') continue;
        if (v->type != 'R') return;
        if (v->kind == 'u') {
            if (n_inputs == MAX_MIRRORED) return;
            input_vr[n_inputs++] = v->vr;
        } else {
            if (n_outputs == MAX_MIRRORED) return;
            output_vr[n_outputs++] = v->vr;
        }
    }
    mirrorable = 1;
}

static int mirror_index(const fmi2ValueReference list[], size_t n, fmi2ValueReference vr)
{
    for (size_t i = 0; i < n; ++i)
        if (list[i] == vr) return (int)i;
    return -1;
}

/* A tuple of the names of ``vrs`` (a new reference, or NULL). */
static PyObject *names_of(const fmi2ValueReference vrs[], size_t n)
{
    PyObject *names = py.tuple_new((Py_ssize_t)n);
    for (size_t i = 0; names && i < n; ++i) {
        for (size_t k = 0; k < FEEDAXIS_N_VARS; ++k) {
            if (FEEDAXIS_VARS[k].vr != vrs[i]) continue;
            py.tuple_set(names, (Py_ssize_t)i, py.from_string(FEEDAXIS_VARS[k].name));
            break;
        }
    }
    return names;
}

static void drop_exchange(Guard *g)
{
    if (!g->exchange) return;
    if (py.is_initialized()) {
        PyGILState_STATE gil = py.gil_ensure();
        py.decref(g->exchange);
        py.gil_release(gil);
    }
    g->exchange = NULL;
}

/* Call ``function`` of the adapter's hand-over module (feedaxis_slave._handoff) with
 * ``args`` (stolen); a new reference, or NULL (no slave constructed yet, or an error). */
static PyObject *call_handoff(const char *function, PyObject *args)
{
    PyObject *module = py.import(HANDOFF_MODULE);
    PyObject *callable = module ? py.get_attr(module, function) : NULL;
    PyObject *result = callable && args ? py.call(callable, args) : NULL;
    if (args) py.decref(args);
    if (callable) py.decref(callable);
    if (module) py.decref(module);
    if (py.err_occurred()) py.err_clear();
    return result;
}

/* Before pythonfmu constructs a slave: forget any slave constructed earlier on this thread. */
static void expect_slave(void)
{
    if (!py.ready || !mirrorable) return;
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *result = call_handoff("forget", py.tuple_new(0));
    if (result) py.decref(result);
    py.gil_release(gil);
}

/* After: take the exchange function of the slave pythonfmu has just constructed. Without
 * one (an adapter without it), pythonfmu serves every call. */
static void claim_exchange(Guard *g)
{
    drop_exchange(g);
    g->inputs_current = g->inputs_pending = g->outputs_current = 0;
    if (!py.ready || !mirrorable) return;
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *args = py.tuple_new(2);
    if (args) {
        py.tuple_set(args, 0, names_of(input_vr, n_inputs));
        py.tuple_set(args, 1, names_of(output_vr, n_outputs));
    }
    PyObject *exchange = call_handoff("claim", args);
    if (exchange && exchange != py.none) g->exchange = exchange;
    else if (exchange) py.decref(exchange);
    py.gil_release(gil);
}

static fmi2GetRealTYPE *real_get_real;
static fmi2SetRealTYPE *real_set_real;

/* Read the slave's inputs and outputs into the mirror (through pythonfmu). */
static int load_mirror(Guard *g)
{
    if (!real_get_real) real_get_real = real("fmi2GetReal");
    if (!real_get_real || real_get_real(g->real, input_vr, n_inputs, g->inputs) > fmi2Warning
        || real_get_real(g->real, output_vr, n_outputs, g->outputs) > fmi2Warning)
        return 0;
    g->inputs_current = g->outputs_current = 1;
    g->inputs_pending = 0;
    return 1;
}

/* Give the slave the inputs set here since its last step (through pythonfmu). */
static void hand_over_inputs(Guard *g)
{
    if (!g->inputs_pending) return;
    if (!real_set_real) real_set_real = real("fmi2SetReal");
    if (real_set_real) real_set_real(g->real, input_vr, n_inputs, g->inputs);
    g->inputs_pending = 0;
}

/* After a call that may change the slave, the mirror is read again before it is used. */
static void slave_changed(Guard *g)
{
    g->inputs_current = g->outputs_current = 0;
}

static int fast(Guard *g)
{
    return g->exchange && g->mode == STEPPING;
}

/* Log the (status, category, message) tuples the slave returned, as guard_logger does. */
static void pass_messages(Guard *g, PyObject *messages)
{
    Py_ssize_t n = py.list_size(messages);
    for (Py_ssize_t i = 0; i < n; ++i) {
        PyObject *item = py.list_get(messages, i);
        fmi2Status status = (fmi2Status)py.as_long(py.tuple_get(item, 0));
        PyObject *category = py.tuple_get(item, 1);
        const char *text = py.as_utf8(py.tuple_get(item, 2));
        if (status > g->worst_logged && status <= fmi2Fatal) g->worst_logged = status;
        tell_host(g, status, category && PyUnicode_Check(category) ? py.as_utf8(category) : NULL,
                  text ? text : "(message not readable)");
    }
}

static int read_outputs(Guard *g, PyObject *outputs)
{
    if (!outputs || !PyTuple_Check(outputs) || py.tuple_size(outputs) != (Py_ssize_t)n_outputs)
        return 0;
    for (size_t i = 0; i < n_outputs; ++i) {
        double value = py.as_double(py.tuple_get(outputs, (Py_ssize_t)i));
        if (value == -1.0 && py.err_occurred()) return 0;
        g->outputs[i] = value;
    }
    return 1;
}

/* A Python exception out of the exchange function is a bug: fmi2Fatal with its text. */
static fmi2Status exchange_failed(Guard *g)
{
    char reason[400], message[512];
    take_python_error(reason, sizeof reason);
    snprintf(message, sizeof message, "doStep: internal error in the slave's exchange: %s", reason);
    tell_host(g, fmi2Fatal, NULL, message);
    return fmi2Fatal;
}

/* fmi2DoStep as one Python call: inputs in, outputs out (pythonfmu: fmi2Discard on a
 * failed step, which finish() turns into the error the slave logged). */
static fmi2Status exchange_step(Guard *g, fmi2Real t, fmi2Real h)
{
    fmi2Status status = fmi2Discard;
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *args = py.tuple_new((Py_ssize_t)(2 + n_inputs));
    if (args) {
        py.tuple_set(args, 0, py.from_double(t));
        py.tuple_set(args, 1, py.from_double(h));
        for (size_t i = 0; i < n_inputs; ++i)
            py.tuple_set(args, (Py_ssize_t)(2 + i), py.from_double(g->inputs[i]));
    }
    PyObject *result = args ? py.call(g->exchange, args) : NULL;
    if (args) py.decref(args);
    if (!result) {
        status = exchange_failed(g);
    } else if (PyTuple_Check(result)) {
        status = read_outputs(g, result) ? fmi2OK : exchange_failed(g);
    } else if (PyList_Check(result) && py.list_size(result) == 2) {
        pass_messages(g, py.list_get(result, 1));
        PyObject *outputs = py.list_get(result, 0);
        if (outputs != py.none) status = read_outputs(g, outputs) ? fmi2OK : exchange_failed(g);
    } else {
        tell_host(g, fmi2Fatal, NULL, "doStep: the slave's exchange returned an unexpected value");
        status = fmi2Fatal;
    }
    if (result) py.decref(result);
    if (py.err_occurred()) py.err_clear();
    py.gil_release(gil);
    g->inputs_pending = 0;
    g->outputs_current = status <= fmi2Warning;
    return status;
}

/* Whether fmi2GetReal of ``vr`` is answered from the mirror (instance ``c`` stepping, every
 * ``vr`` a mirrored input or output, the mirror current); copies the values. */
static int mirror_get(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                      fmi2Real value[])
{
    Guard *g = c;
    if (!g || !fast(g) || !vr || !value) return 0; /* a NULL array: refused by the guard */
    for (size_t i = 0; i < nvr; ++i) {
        int k = mirror_index(output_vr, n_outputs, vr[i]);
        if (k >= 0 && g->outputs_current) continue;
        if (k < 0 && g->inputs_current && mirror_index(input_vr, n_inputs, vr[i]) >= 0) continue;
        return 0;
    }
    for (size_t i = 0; i < nvr; ++i) {
        int k = mirror_index(output_vr, n_outputs, vr[i]);
        value[i] = k >= 0 ? g->outputs[k] : g->inputs[mirror_index(input_vr, n_inputs, vr[i])];
    }
    return 1;
}

/* Whether fmi2SetReal of ``vr`` is kept in the mirror (instance ``c`` stepping, every ``vr`` a
 * mirrored input); stores the values, handed to the slave at the next step. */
static int mirror_set(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                      const fmi2Real value[])
{
    Guard *g = c;
    if (!g || !fast(g) || !vr || !value) return 0; /* a NULL array: refused by the guard */
    for (size_t i = 0; i < nvr; ++i)
        if (mirror_index(input_vr, n_inputs, vr[i]) < 0) return 0;
    if (!g->inputs_current && !load_mirror(g)) return 0;
    for (size_t i = 0; i < nvr; ++i) g->inputs[mirror_index(input_vr, n_inputs, vr[i])] = value[i];
    g->inputs_pending = 1;
    return 1;
}

/* ---- the fmi2 functions ------------------------------------------------------------ */

EXPORT const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
EXPORT const char *fmi2GetVersion(void) { return fmi2Version; }

/* Freed instances are kept (up to POOL_SIZE) and reused through pythonfmu's fmi2Reset, which
 * creates a fresh Python slave: pythonfmu's fmi2Instantiate leaks about 1.4 kB in findClass
 * (an MRO list and class-name strings) every time, its fmi2Reset nothing. */
#define POOL_SIZE 16
static Guard *pool[POOL_SIZE];
static size_t pooled;
static pthread_mutex_t pool_lock = PTHREAD_MUTEX_INITIALIZER;

static Guard *take_pooled(fmi2String guid, fmi2String resources)
{
    Guard *found = NULL;
    pthread_mutex_lock(&pool_lock);
    for (size_t i = 0; i < pooled; ++i) {
        if (strcmp(pool[i]->guid, guid) == 0 && strcmp(pool[i]->resources, resources) == 0) {
            found = pool[i];
            pool[i] = pool[--pooled];
            break;
        }
    }
    pthread_mutex_unlock(&pool_lock);
    return found;
}

static int put_pooled(Guard *g)
{
    int kept = 0;
    pthread_mutex_lock(&pool_lock);
    if (pooled < POOL_SIZE) {
        pool[pooled++] = g;
        kept = 1;
    }
    pthread_mutex_unlock(&pool_lock);
    return kept;
}

static void release(Guard *g)
{
    drop_exchange(g);
    free(g->name);
    free(g->guid);
    free(g->resources);
    free(g);
}

/* The host's callbacks and name on guard ``g`` (pythonfmu keeps a pointer to g->mine). */
static void attach(Guard *g, fmi2String name, const fmi2CallbackFunctions *functions,
                   fmi2Boolean loggingOn)
{
    g->host = *functions;
    g->mine = *functions;
    g->mine.logger = guard_logger;
    g->mine.componentEnvironment = g;
    free(g->name);
    g->name = strdup(name ? name : "");
    g->host_logging = loggingOn;
    g->mode = INSTANTIATED;
}

/* ---- unloading ---------------------------------------------------------------------- */

/* At exit, or when the host unloads this library (fmpy does at every fmi2FreeInstance): the
 * pooled instances go back to pythonfmu, whose state is released (release_pythonfmu_state)
 * and library unloaded, so that loading an FMU from fresh folders again and again keeps
 * nothing of the earlier copies (both libraries stayed mapped: 0.35 MB a copy). In a Python
 * host at exit Python is already finalised: only pythonfmu's state is released. */
static void unloading(void)
{
    int (*is_initialized)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (is_initialized && is_initialized()) {
        fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)real("fmi2FreeInstance");
        pthread_mutex_lock(&pool_lock);
        while (pooled > 0) {
            Guard *g = pool[--pooled];
            drop_exchange(g);
            if (free_instance) free_instance(g->real);
            release(g);
        }
        pthread_mutex_unlock(&pool_lock);
        release_pythonfmu_state();
        dlclose(real_library);
        real_library = NULL;
        return;
    }
    release_pythonfmu_state();
}

static Guard *reuse(fmi2String name, fmi2String guid, fmi2String resources,
                    const fmi2CallbackFunctions *functions, fmi2Boolean loggingOn)
{
    Guard *g = take_pooled(guid, resources);
    if (!g) return NULL;
    attach(g, name, functions, loggingOn);
    static fmi2ResetTYPE *reset;
    if (!reset) reset = (fmi2ResetTYPE *)real("fmi2Reset");
    begin(g);
    expect_slave();
    if (finish(g, reset(g->real)) <= fmi2Warning) {
        claim_exchange(g);
        return g;
    }
    if (g->mode != DEAD) {
        fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)real("fmi2FreeInstance");
        free_instance(g->real);
    }
    release(g);
    return NULL;
}

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid,
                                     fmi2String resources, const fmi2CallbackFunctions *functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    if (!functions || !functions->logger || !guid || !resources) return NULL;
    load_once(resources);
    Guard *g = fmuType == fmi2CoSimulation && real_library
                   ? reuse(instanceName, guid, resources, functions, loggingOn) : NULL;
    if (g) return g;
    g = calloc(1, sizeof *g);
    if (!g) return NULL;
    attach(g, instanceName, functions, loggingOn);
    g->guid = strdup(guid);
    g->resources = strdup(resources);
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)real("fmi2Instantiate");
    if (!instantiate) {
        tell_host(g, fmi2Fatal, NULL, *load_error ? load_error : "pythonfmu library incomplete");
    } else if (fmuType != fmi2CoSimulation) {
        tell_host(g, fmi2Error, NULL, "this FMU supports co-simulation only");
    } else {
        begin(g);
        expect_slave();
        g->real = instantiate(instanceName, fmuType, guid, resources, &g->mine, visible, 1);
        if (g->real && g->worst_logged < fmi2Error) {
            claim_exchange(g);
            return g;
        }
    }
    release(g);  /* a component pythonfmu returned with an error is leaked, never touched */
    return NULL;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Guard *g = c;
    if (!g) return;
    if (g->mode == DEAD) {
        release(g);
        return;
    }
    g->host.logger = NULL;  /* the host's callbacks end here */
    drop_exchange(g);
    if (put_pooled(g)) return;
    fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)real("fmi2FreeInstance");
    free_instance(g->real);
    release(g);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t n,
                                      const fmi2String categories[])
{
    Guard *g = c;
    (void)n;
    (void)categories;
    if (!g) return fmi2Error;
    g->host_logging = loggingOn;
    return fmi2OK;
}

/* The state guard around a call forwarded to pythonfmu: refuse it when the instance may not
 * take it, hand over pending inputs, and make the call's status the worse of pythonfmu's and
 * what the slave logged meanwhile. Declares ``g`` and ``status``. */
#define FORWARD(function, when_failed, ...)                                                     \
    Guard *g = c;                                                                              \
    if (!g) return fmi2Error;                                                                  \
    if (!usable(g, #function, when_failed)) return fmi2Error;                                  \
    static function##TYPE *call; /* resolved once: dlsym costs a microsecond */                \
    if (!call) call = (function##TYPE *)real(#function);                                       \
    hand_over_inputs(g);                                                                       \
    begin(g);                                                                                  \
    fmi2Status status = finish(g, call(g->real, ##__VA_ARGS__))

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol,
                                      fmi2Real start, fmi2Boolean stopDefined, fmi2Real stop)
{
    FORWARD(fmi2SetupExperiment, 0, tolDefined, tol, start, stopDefined, stop);
    g->last_successful_time = start;
    return status;
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    FORWARD(fmi2EnterInitializationMode, 0);
    slave_changed(g);
    if (status <= fmi2Warning) g->mode = INITIALISING;
    return status;
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    FORWARD(fmi2ExitInitializationMode, 0);
    slave_changed(g);
    if (status <= fmi2Warning) g->mode = STEPPING;
    if (fast(g)) load_mirror(g);
    return status;
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    FORWARD(fmi2Terminate, 1);
    slave_changed(g);
    if (status <= fmi2Warning) g->mode = TERMINATED;
    return status;
}

EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    expect_slave();
    FORWARD(fmi2Reset, 1);
    slave_changed(g);
    if (status <= fmi2Warning) {
        g->mode = INSTANTIATED;
        g->wants_to_terminate = 0;
        claim_exchange(g);
    }
    return status;
}

/* Whether instance ``c`` may take a get of ``vr`` (variables of type ``code``, see
 * references_known) now; refuses it with a message otherwise. */
static int may_get(fmi2Component c, const char *function, char code,
                   const fmi2ValueReference vr[], size_t nvr, const void *value)
{
    Guard *g = c;
    return !g || g->mode == DEAD || references_known(g, function, code, vr, nvr, value);
}

/* ``code``: the variable type the function takes (references_known). */
#define GETTER(function, type, code)                                                            \
    EXPORT fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                               type value[])                                                    \
    {                                                                                           \
        if (!may_get(c, #function, code, vr, nvr, value)) return fmi2Error;                     \
        FORWARD(function, 1, vr, nvr, value);                                                   \
        return status;                                                                          \
    }

GETTER(fmi2GetInteger, fmi2Integer, 'I')
GETTER(fmi2GetBoolean, fmi2Boolean, 'B')
GETTER(fmi2GetString, fmi2String, 'S')

/* Whether instance ``c`` may take a set of ``vr`` (variables of type ``code``) now; refuses it
 * with a message otherwise. */
static int may_set(fmi2Component c, const char *function, char code,
                   const fmi2ValueReference vr[], size_t nvr, const void *value)
{
    Guard *g = c;
    return !g || g->mode == DEAD
           || (references_known(g, function, code, vr, nvr, value) && settable(g, vr, nvr));
}

#define SETTER(function, type, code)                                                            \
    EXPORT fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                               const type value[])                                              \
    {                                                                                           \
        if (!may_set(c, #function, code, vr, nvr, value)) return fmi2Error;                     \
        FORWARD(function, 0, vr, nvr, value);                                                   \
        slave_changed(g);                                                                       \
        return status;                                                                          \
    }

SETTER(fmi2SetInteger, fmi2Integer, 'I')
SETTER(fmi2SetBoolean, fmi2Boolean, 'B')
SETTER(fmi2SetString, fmi2String, 'S')

/* Reals: while stepping, the mirror answers the Real inputs and outputs (mirror_get,
 * mirror_set: their references are known Reals); any other Real goes through the guard as
 * the other types do. */
EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                              fmi2Real value[])
{
    if (mirror_get(c, vr, nvr, value)) return fmi2OK;
    if (!may_get(c, "fmi2GetReal", 'R', vr, nvr, value)) return fmi2Error;
    FORWARD(fmi2GetReal, 1, vr, nvr, value);
    return status;
}

EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                              const fmi2Real value[])
{
    if (mirror_set(c, vr, nvr, value)) return fmi2OK; /* inputs only: always settable */
    if (!may_set(c, "fmi2SetReal", 'R', vr, nvr, value)) return fmi2Error;
    FORWARD(fmi2SetReal, 0, vr, nvr, value);
    slave_changed(g);
    return status;
}

/* ---- saved states: what a host got wrong is refused here (pythonfmu would dereference a
 * NULL pointer, copy past a buffer's end, or make a corrupt buffer fmi2Fatal) ------------- */

/* Why the slave cannot restore ``size`` bytes (AxisSlave.state_error, reached through the
 * exchange function), as a message written to ``why``; 0 when it can. */
static int state_refused(Guard *g, const fmi2Byte bytes[], size_t size, char *why, size_t n)
{
    if (!bytes || size == 0) {
        snprintf(why, n, "an empty buffer is not a state");
        return 1;
    }
    if (!g->exchange) return 0;  /* no adapter to ask: pythonfmu parses (the adapter never raises) */
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *check = py.get_attr(g->exchange, "state_error");
    PyObject *args = check ? py.tuple_new(1) : NULL;
    if (args) py.tuple_set(args, 0, py.bytes_new(bytes, (Py_ssize_t)size));
    PyObject *answer = args ? py.call(check, args) : NULL;
    int refused = answer != py.none;
    if (refused) {
        const char *text = answer && PyUnicode_Check(answer) ? py.as_utf8(answer) : NULL;
        snprintf(why, n, "%s", text ? text : "the state could not be checked");
    }
    if (answer) py.decref(answer);
    if (args) py.decref(args);
    if (check) py.decref(check);
    if (py.err_occurred()) py.err_clear();
    py.gil_release(gil);
    return refused;
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    if (c && !state) return refuse(c, "fmi2GetFMUstate: NULL pointer for the state");
    FORWARD(fmi2GetFMUstate, 0, state);
    return status;
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    if (c && !state) return refuse(c, "fmi2SetFMUstate: NULL state");
    FORWARD(fmi2SetFMUstate, 0, state);
    slave_changed(g);
    return status;
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    if (c && !state) return refuse(c, "fmi2FreeFMUstate: NULL pointer for the state");
    if (c && !*state) return fmi2OK;  /* nothing to free */
    FORWARD(fmi2FreeFMUstate, 1, state);
    return status;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    if (c && (!state || !size)) return refuse(c, "fmi2SerializedFMUstateSize: NULL state or size");
    FORWARD(fmi2SerializedFMUstateSize, 0, state, size);
    return status;
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[],
                                        size_t size)
{
    size_t needed = 0;
    if (c && (!state || !bytes)) return refuse(c, "fmi2SerializeFMUstate: NULL state or buffer");
    if (c && ((Guard *)c)->mode != DEAD && fmi2SerializedFMUstateSize(c, state, &needed) == fmi2OK
        && needed != size)
        return refuse(c, "fmi2SerializeFMUstate: a buffer of %zu bytes for a state of %zu "
                         "(fmi2SerializedFMUstateSize)", size, needed);
    FORWARD(fmi2SerializeFMUstate, 0, state, bytes, size);
    return status;
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                          fmi2FMUstate *state)
{
    char why[400];
    Guard *guard = c;
    if (guard && !state) return refuse(guard, "fmi2DeSerializeFMUstate: NULL pointer for the state");
    if (guard && guard->mode != DEAD && state_refused(guard, bytes, size, why, sizeof why))
        return refuse(guard, "fmi2DeSerializeFMUstate: %s", why);
    FORWARD(fmi2DeSerializeFMUstate, 0, bytes, size, state);
    return status;
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[],
                                               size_t nu, const fmi2ValueReference z[], size_t nz,
                                               const fmi2Real dv[], fmi2Real dz[])
{
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    return c ? refuse(c, "fmi2GetDirectionalDerivative is not provided") : fmi2Error;
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                              size_t nvr, const fmi2Integer order[],
                                              const fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return c ? refuse(c, "fmi2SetRealInputDerivatives is not provided (canInterpolateInputs "
                         "is false)") : fmi2Error;
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                               size_t nvr, const fmi2Integer order[],
                                               fmi2Real value[])
{
    (void)vr, (void)nvr, (void)order, (void)value;
    return c ? refuse(c, "fmi2GetRealOutputDerivatives is not provided "
                         "(maxOutputDerivativeOrder is 0)") : fmi2Error;
}

/* Bookkeeping after a step from ``t`` over ``h`` that ended with ``status``. */
static fmi2Status stepped(Guard *g, fmi2Real t, fmi2Real h, fmi2Status status)
{
    if (status == fmi2Discard) g->mode = FAILED;
    g->last_successful_time = status <= fmi2Warning ? t + h : t;
    if (status > fmi2Warning) g->wants_to_terminate = 1;
    return status;
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior)
{
    Guard *guard = c;
    if (guard && guard->mode != STEPPING && guard->mode != DEAD && guard->mode != FAILED)
        return refuse(guard, "fmi2DoStep refused in %s", MODE_NAMES[guard->mode]);
    if (guard && fast(guard) && (guard->inputs_current || load_mirror(guard))) {
        begin(guard);
        return stepped(guard, t, h, finish(guard, exchange_step(guard, t, h)));
    }
    FORWARD(fmi2DoStep, 0, t, h, no_set_prior);
    slave_changed(g);
    return stepped(g, t, h, status);
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c)
{
    return c ? refuse(c, "fmi2CancelStep: fmi2DoStep never returns fmi2Pending") : fmi2Error;
}

#define STATUS_GETTER(function, type)                                                            \
    EXPORT fmi2Status function(fmi2Component c, const fmi2StatusKind kind, type *value)         \
    {                                                                                           \
        FORWARD(function, 1, kind, value);                                                      \
        return status;                                                                          \
    }

STATUS_GETTER(fmi2GetStatus, fmi2Status)
STATUS_GETTER(fmi2GetIntegerStatus, fmi2Integer)
STATUS_GETTER(fmi2GetStringStatus, fmi2String)

/* The two kinds pythonfmu answers are kept here: the layer may step without it. */

EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *value)
{
    Guard *guard = c;
    if (guard && kind == fmi2LastSuccessfulTime && value && guard->mode != DEAD) {
        *value = guard->last_successful_time;
        return fmi2OK;
    }
    FORWARD(fmi2GetRealStatus, 1, kind, value);
    return status;
}

EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind,
                                       fmi2Boolean *value)
{
    Guard *guard = c;
    if (guard && kind == fmi2Terminated && value && guard->mode != DEAD) {
        *value = guard->wants_to_terminate;
        return fmi2OK;
    }
    FORWARD(fmi2GetBooleanStatus, 1, kind, value);
    return status;
}
