/* feedaxis FMI host layer: the model-identifier library of every feedaxis FMU.
 *
 * pythonfmu's platform library (shipped next to this one as libpythonfmu-export.so) expects
 * the host to have loaded libpython, which only Python hosts do. This layer
 *   1. loads libpython RTLD_GLOBAL when the host has not (a plain C host such as
 *      fmuCheck or OMSimulator) and starts the interpreter that built the FMU (its
 *      program name finds the virtual environment, so numpy and scipy import), never
 *      finalising it: finalisation runs libgfortran's close_units on a heap pythonfmu has
 *      already damaged, and the process is ending anyway;
 *   2. forwards every fmi2 function to pythonfmu's library, guarding the FMI state machine:
 *      a fixed parameter or an output set after initialisation is refused with fmi2Error,
 *      a call made after fmi2Fatal is refused without reaching pythonfmu (whose instance
 *      then holds freed Python objects), an error logged by the slave during a call turns
 *      that call's status into fmi2Error;
 *   3. passes every message to the host's logger with a category (pythonfmu passes NULL),
 *      the instance name in front, never text containing '%' as the format;
 *   4. reuses freed instances through pythonfmu's fmi2Reset (its fmi2Instantiate leaks);
 *   5. keeps the Real inputs and outputs itself while stepping: fmi2SetReal and fmi2GetReal
 *      of them never reach Python, and fmi2DoStep is one Python call (the slave's exchange
 *      function, feedaxis_slave.claim) that takes the inputs and returns the outputs, where
 *      pythonfmu makes three, each building Python lists (about 6 of its 7.5 us per step).
 *      Any other call first hands pending inputs to the slave through pythonfmu.
 *
 * Build-time constants (-D): FEEDAXIS_PYTHON (the interpreter to start) and
 * FEEDAXIS_LIBPYTHON (its shared library); the environment variables of the same names
 * override them on the host. The per-FMU variable table comes from feedaxis_fmi_vars.h. Python is reached
 * only through dlsym, so the library loads in a host without libpython.
 */
#define _GNU_SOURCE
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "feedaxis_fmi_vars.h"

typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef int fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define EXPORT __attribute__((visibility("default")))

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
static pthread_once_t load_once = PTHREAD_ONCE_INIT;

/* ---- loading Python and pythonfmu's library ---------------------------------------- */

static const char *setting(const char *name, const char *built_in)
{
    const char *value = getenv(name);
    return value && *value ? value : built_in;
}

static void *real(const char *symbol)
{
    return real_library ? dlsym(real_library, symbol) : NULL;
}

static int start_python(void)
{
    int (*is_initialized)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (!is_initialized) {
        const char *libpython = setting("FEEDAXIS_LIBPYTHON", FEEDAXIS_LIBPYTHON);
        if (!*libpython) {
            snprintf(load_error, sizeof load_error, "the Python that built this FMU has no shared "
                     "libpython: set FEEDAXIS_LIBPYTHON to one (and FEEDAXIS_PYTHON)");
            return -1;
        }
        if (!dlopen(libpython, RTLD_NOW | RTLD_GLOBAL)) {
            snprintf(load_error, sizeof load_error,
                     "cannot load libpython (set FEEDAXIS_LIBPYTHON): %s", dlerror());
            return -1;
        }
        is_initialized = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
        if (!is_initialized) {
            snprintf(load_error, sizeof load_error, "%s is not a libpython", libpython);
            return -1;
        }
    }
    if (is_initialized()) return 0;

    void (*init_config)(PyConfig *) = dlsym(RTLD_DEFAULT, "PyConfig_InitPythonConfig");
    PyStatus (*set_string)(PyConfig *, wchar_t **, const char *) =
        dlsym(RTLD_DEFAULT, "PyConfig_SetBytesString");
    PyStatus (*initialize)(const PyConfig *) = dlsym(RTLD_DEFAULT, "Py_InitializeFromConfig");
    void (*clear)(PyConfig *) = dlsym(RTLD_DEFAULT, "PyConfig_Clear");
    int (*is_exception)(PyStatus) = dlsym(RTLD_DEFAULT, "PyStatus_Exception");
    PyThreadState *(*save_thread)(void) = dlsym(RTLD_DEFAULT, "PyEval_SaveThread");
    if (!init_config || !set_string || !initialize || !clear || !is_exception || !save_thread) {
        snprintf(load_error, sizeof load_error, "libpython lacks the PyConfig API (3.8 or newer)");
        return -1;
    }
    PyConfig config;
    init_config(&config);
    config.install_signal_handlers = 0;  /* the host owns SIGINT */
    config.parse_argv = 0;
    PyStatus status = set_string(&config, &config.program_name,
                                 setting("FEEDAXIS_PYTHON", FEEDAXIS_PYTHON));
    if (!is_exception(status)) status = initialize(&config);
    clear(&config);
    if (is_exception(status)) {
        snprintf(load_error, sizeof load_error, "cannot start Python (set FEEDAXIS_PYTHON): %s",
                 status.err_msg ? status.err_msg : "unknown error");
        return -1;
    }
    save_thread();  /* pythonfmu takes the GIL with PyGILState_Ensure */
    return 0;
}

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

static void load(void)
{
    Dl_info self;
    if (start_python() != 0) return;
    if (!dladdr((void *)&load, &self) || !self.dli_fname) {
        snprintf(load_error, sizeof load_error, "cannot locate the FMU's binary folder");
        return;
    }
    char path[4096];
    snprintf(path, sizeof path, "%s", self.dli_fname);
    char *slash = strrchr(path, '/');
    snprintf(slash ? slash + 1 : path, sizeof path - (slash ? (size_t)(slash + 1 - path) : 0),
             "libpythonfmu-export.so");
    real_library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!real_library) {
        snprintf(load_error, sizeof load_error, "cannot load %s: %s", path, dlerror());
        return;
    }
    /* Registered after pythonfmu's static destructors, so that it runs before them: at exit,
     * and when the host unloads this library (glibc binds a library's atexit handlers to it). */
    atexit(unloading);
    prepare_mirror();
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

/* ---- the state machine ------------------------------------------------------------ */

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

/* ---- Real inputs and outputs kept here while stepping (item 5) ----------------------- */

/* The Python C API, found with dlsym once Python runs (never linked: see the top). */
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
    PyObject *(*from_double)(double);
    double (*as_double)(PyObject *);
    long (*as_long)(PyObject *);
    PyObject *(*from_string)(const char *);
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

static fmi2ValueReference input_vr[MAX_MIRRORED], output_vr[MAX_MIRRORED];
static size_t n_inputs, n_outputs;

#define FIND(field, symbol) (py.field = dlsym(RTLD_DEFAULT, symbol)) != NULL

/* Resolve the API and index the mirrored variables; py.ready stays 0 (every call then goes
 * through pythonfmu) if a symbol is missing or an input or output is not a Real. */
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
    py.ready = FIND(gil_ensure, "PyGILState_Ensure") && FIND(gil_release, "PyGILState_Release")
        && FIND(import, "PyImport_ImportModule") && FIND(get_attr, "PyObject_GetAttrString")
        && FIND(call, "PyObject_CallObject") && FIND(tuple_new, "PyTuple_New")
        && FIND(tuple_set, "PyTuple_SetItem") && FIND(tuple_get, "PyTuple_GetItem")
        && FIND(tuple_size, "PyTuple_Size") && FIND(list_get, "PyList_GetItem")
        && FIND(list_size, "PyList_Size") && FIND(from_double, "PyFloat_FromDouble")
        && FIND(as_double, "PyFloat_AsDouble") && FIND(as_long, "PyLong_AsLong")
        && FIND(from_string, "PyUnicode_FromString") && FIND(as_utf8, "PyUnicode_AsUTF8")
        && FIND(bytes_new, "PyBytes_FromStringAndSize")
        && FIND(decref, "Py_DecRef") && FIND(err_occurred, "PyErr_Occurred")
        && FIND(err_fetch, "PyErr_Fetch") && FIND(err_clear, "PyErr_Clear")
        && FIND(str, "PyObject_Str") && FIND(is_initialized, "Py_IsInitialized")
        && FIND(none, "_Py_NoneStruct");
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
    if (!py.ready) return;
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
    if (!py.ready) return;
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

static fmi2Status (*real_get_real)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
static fmi2Status (*real_set_real)(fmi2Component, const fmi2ValueReference *, size_t,
                                   const fmi2Real *);

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
    PyObject *type = NULL, *value = NULL, *traceback = NULL;
    py.err_fetch(&type, &value, &traceback);
    PyObject *text = value ? py.str(value) : NULL;
    const char *reason = text ? py.as_utf8(text) : NULL;
    char message[512];
    snprintf(message, sizeof message, "doStep: internal error in the slave's exchange: %s",
             reason ? reason : "(no message)");
    tell_host(g, fmi2Fatal, NULL, message);
    if (py.err_occurred()) py.err_clear();
    if (text) py.decref(text);
    if (type) py.decref(type);
    if (value) py.decref(value);
    if (traceback) py.decref(traceback);
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

/* Whether fmi2GetReal of ``vr`` can be answered from the mirror; copies the values. */
static int get_mirrored(Guard *g, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
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

/* Whether fmi2SetReal of ``vr`` (all inputs) can be kept in the mirror; stores the values. */
static int set_mirrored(Guard *g, const fmi2ValueReference vr[], size_t nvr,
                        const fmi2Real value[])
{
    for (size_t i = 0; i < nvr; ++i)
        if (mirror_index(input_vr, n_inputs, vr[i]) < 0) return 0;
    if (!g->inputs_current && !load_mirror(g)) return 0;
    for (size_t i = 0; i < nvr; ++i) g->inputs[mirror_index(input_vr, n_inputs, vr[i])] = value[i];
    g->inputs_pending = 1;
    return 1;
}

/* ---- the fmi2 functions ------------------------------------------------------------ */

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

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
        void (*free_instance)(fmi2Component) = real("fmi2FreeInstance");
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
    static fmi2Status (*reset)(fmi2Component);
    if (!reset) reset = (fmi2Status(*)(fmi2Component))real("fmi2Reset");
    begin(g);
    expect_slave();
    if (finish(g, reset(g->real)) <= fmi2Warning) {
        claim_exchange(g);
        return g;
    }
    if (g->mode != DEAD) {
        void (*free_instance)(fmi2Component) = real("fmi2FreeInstance");
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
    pthread_once(&load_once, load);
    Guard *g = fmuType == fmi2CoSimulation && real_library
                   ? reuse(instanceName, guid, resources, functions, loggingOn) : NULL;
    if (g) return g;
    g = calloc(1, sizeof *g);
    if (!g) return NULL;
    attach(g, instanceName, functions, loggingOn);
    g->guid = strdup(guid);
    g->resources = strdup(resources);
    fmi2Component (*instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String,
                                 const fmi2CallbackFunctions *, fmi2Boolean, fmi2Boolean) =
        real("fmi2Instantiate");
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
    void (*free_instance)(fmi2Component) = real("fmi2FreeInstance");
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

#define FORWARD(function, when_failed, signature, ...)                                          \
    Guard *g = c;                                                                              \
    if (!g) return fmi2Error;                                                                  \
    if (!usable(g, #function, when_failed)) return fmi2Error;                                  \
    static fmi2Status(*call) signature; /* resolved once: dlsym costs a microsecond */     \
    if (!call) call = (fmi2Status(*) signature)real(#function);                                \
    hand_over_inputs(g);                                                                       \
    begin(g);                                                                                  \
    fmi2Status status = finish(g, call(g->real, ##__VA_ARGS__))

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol,
                                      fmi2Real start, fmi2Boolean stopDefined, fmi2Real stop)
{
    FORWARD(fmi2SetupExperiment, 0, (fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean,
                                     fmi2Real), tolDefined, tol, start, stopDefined, stop);
    g->last_successful_time = start;
    return status;
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c)
{
    FORWARD(fmi2EnterInitializationMode, 0, (fmi2Component));
    slave_changed(g);
    if (status <= fmi2Warning) g->mode = INITIALISING;
    return status;
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c)
{
    FORWARD(fmi2ExitInitializationMode, 0, (fmi2Component));
    slave_changed(g);
    if (status <= fmi2Warning) g->mode = STEPPING;
    if (fast(g)) load_mirror(g);
    return status;
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c)
{
    FORWARD(fmi2Terminate, 1, (fmi2Component));
    slave_changed(g);
    if (status <= fmi2Warning) g->mode = TERMINATED;
    return status;
}

EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    expect_slave();
    FORWARD(fmi2Reset, 1, (fmi2Component));
    slave_changed(g);
    if (status <= fmi2Warning) {
        g->mode = INSTANTIATED;
        g->wants_to_terminate = 0;
        claim_exchange(g);
    }
    return status;
}

/* ``mirrored``: a statement that may answer the call from the mirror (item 5), which knows
 * its references; a setter's mirror takes inputs only, which are always settable, so it
 * may come before the checks. ``code``: the variable type (references_known). */
#define GETTER(function, type, code, mirrored)                                                   \
    EXPORT fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                               type value[])                                                    \
    {                                                                                           \
        Guard *guard = c;                                                                       \
        if (guard) { mirrored }                                                                 \
        if (guard && guard->mode != DEAD && !references_known(guard, #function, code, vr, nvr,  \
                                                              value)) return fmi2Error;         \
        FORWARD(function, 1, (fmi2Component, const fmi2ValueReference *, size_t, type *), vr,   \
                nvr, value);                                                                    \
        return status;                                                                          \
    }

GETTER(fmi2GetReal, fmi2Real, 'R',
       if (fast(guard) && vr && value && get_mirrored(guard, vr, nvr, value)) return fmi2OK;)
GETTER(fmi2GetInteger, fmi2Integer, 'I', )
GETTER(fmi2GetBoolean, fmi2Boolean, 'B', )
GETTER(fmi2GetString, fmi2String, 'S', )

#define SETTER(function, type, code, mirrored)                                                   \
    EXPORT fmi2Status function(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,      \
                               const type value[])                                              \
    {                                                                                           \
        Guard *guard = c;                                                                       \
        if (guard) { mirrored }                                                                 \
        if (guard && guard->mode != DEAD && !(references_known(guard, #function, code, vr, nvr, \
                                                               value)                           \
                                              && settable(guard, vr, nvr))) return fmi2Error;   \
        FORWARD(function, 0, (fmi2Component, const fmi2ValueReference *, size_t, const type *), \
                vr, nvr, value);                                                                \
        slave_changed(g);                                                                       \
        return status;                                                                          \
    }

SETTER(fmi2SetReal, fmi2Real, 'R',
       if (fast(guard) && vr && value && set_mirrored(guard, vr, nvr, value)) return fmi2OK;)
SETTER(fmi2SetInteger, fmi2Integer, 'I', )
SETTER(fmi2SetBoolean, fmi2Boolean, 'B', )
SETTER(fmi2SetString, fmi2String, 'S', )

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
    FORWARD(fmi2GetFMUstate, 0, (fmi2Component, fmi2FMUstate *), state);
    return status;
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    if (c && !state) return refuse(c, "fmi2SetFMUstate: NULL state");
    FORWARD(fmi2SetFMUstate, 0, (fmi2Component, fmi2FMUstate), state);
    slave_changed(g);
    return status;
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    if (c && !state) return refuse(c, "fmi2FreeFMUstate: NULL pointer for the state");
    if (c && !*state) return fmi2OK;  /* nothing to free */
    FORWARD(fmi2FreeFMUstate, 1, (fmi2Component, fmi2FMUstate *), state);
    return status;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    if (c && (!state || !size)) return refuse(c, "fmi2SerializedFMUstateSize: NULL state or size");
    FORWARD(fmi2SerializedFMUstateSize, 0, (fmi2Component, fmi2FMUstate, size_t *), state, size);
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
    FORWARD(fmi2SerializeFMUstate, 0, (fmi2Component, fmi2FMUstate, fmi2Byte *, size_t), state,
            bytes, size);
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
    FORWARD(fmi2DeSerializeFMUstate, 0, (fmi2Component, const fmi2Byte *, size_t, fmi2FMUstate *),
            bytes, size, state);
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
    FORWARD(fmi2DoStep, 0, (fmi2Component, fmi2Real, fmi2Real, fmi2Boolean), t, h, no_set_prior);
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
        FORWARD(function, 1, (fmi2Component, fmi2StatusKind, type *), kind, value);             \
        return status;                                                                          \
    }

STATUS_GETTER(fmi2GetStatus, fmi2Status)
STATUS_GETTER(fmi2GetIntegerStatus, fmi2Integer)
STATUS_GETTER(fmi2GetStringStatus, fmi2String)

/* The two kinds pythonfmu answers are kept here: the layer may step without it. */
enum { LAST_SUCCESSFUL_TIME = 2, TERMINATED_KIND = 3 };

EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind kind, fmi2Real *value)
{
    Guard *guard = c;
    if (guard && kind == LAST_SUCCESSFUL_TIME && value && guard->mode != DEAD) {
        *value = guard->last_successful_time;
        return fmi2OK;
    }
    FORWARD(fmi2GetRealStatus, 1, (fmi2Component, fmi2StatusKind, fmi2Real *), kind, value);
    return status;
}

EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind kind,
                                       fmi2Boolean *value)
{
    Guard *guard = c;
    if (guard && kind == TERMINATED_KIND && value && guard->mode != DEAD) {
        *value = guard->wants_to_terminate;
        return fmi2OK;
    }
    FORWARD(fmi2GetBooleanStatus, 1, (fmi2Component, fmi2StatusKind, fmi2Boolean *), kind, value);
    return status;
}
