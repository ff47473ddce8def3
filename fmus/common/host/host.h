/* feedaxis FMI host layer: what its parts share.
 *
 * The layer is the model-identifier library of every feedaxis FMU; each file holds one job:
 *   python.c       loading libpython and pythonfmu's library, starting the interpreter
 *   logging.c      messages to the host's logger
 *   states.c       the FMI 2.0 state machine, as one table, checked before every call
 *   arguments.c    fmi2Instantiate's arguments (name, GUID, resource URI per RFC 3986)
 *   references.c   value references, and the values a set may take (finite, in range, UTF-8)
 *   mirror.c       the Real inputs and outputs kept here while stepping, the compiled steps
 *   exports.c      the fmi2 functions
 *   saved_states.c fmi2GetFMUstate and the other state functions
 *   unloading.c    the pool of freed instances, and unloading
 * and, in an FMI 3.0 FMU (FEEDAXIS_FMI3), over the fmi2 functions above:
 *   fmi3_states.c  the FMI 3.0 state machine, as one table
 *   fmi3_exports.c the fmi3 functions
 * See fmus/README.md for why a layer between the host and pythonfmu exists at all. */
#ifndef FEEDAXIS_HOST_H
#define FEEDAXIS_HOST_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stddef.h>

#ifdef FEEDAXIS_FMI3
/* An FMI 3.0 FMU: the fmi2 functions below are internal (hidden, not exported); the
 * fmi3 functions of fmi3_exports.c are its interface, checked against fmi3_states.c. */
#define FMI2_Export __attribute__((visibility("hidden")))
#endif
#include "fmi2Functions.h" /* the official FMI 2.0 headers (fmi2/): every export checked */
#include "feedaxis_fmi_vars.h"

#define EXPORT FMI2_Export
#define MAX_MIRRORED 16
#define HANDOFF_MODULE "feedaxis_fmu_handoff" /* feedaxis_slave.HANDOFF_MODULE */
#define MAX_PATH_LENGTH 4096

/* The FMI 2.0 co-simulation states an instance is in (the standard's section 4.2.4).
 * stepInProgress and stepCanceled are never entered: fmi2DoStep never returns fmi2Pending. */
enum mode { INSTANTIATED, INITIALISATION, STEP_COMPLETE, STEP_FAILED, TERMINATED, ERROR, FATAL,
            N_MODES };

/* A compiled step (physics/fmu_steps.py): 1 done, 0 declined (the block as it was). */
typedef int (*native_step)(double *block, double step_size, const double *inputs,
                           double *outputs);

typedef struct {
    void *real;                        /* pythonfmu's component */
    fmi2CallbackFunctions host;        /* the host's callbacks */
    fmi2CallbackFunctions mine;        /* what pythonfmu calls */
    char *name;
    char *guid;
    char *resources;                   /* the resource location pythonfmu was given */
    enum mode mode;
    int host_logging;
    fmi2Status worst_logged;           /* worst status logged during the current call */
    PyObject *exchange;                /* the slave's exchange function, or NULL */
    native_step native;                /* the slave's compiled step, or NULL (mirror.c) */
    double *block;                     /* its numbers, held by the slave */
    int native_offered;                /* the slave has a compiled step */
    int native_ready;                  /* block packed from the slave as it is now */
    int native_ahead;                  /* compiled steps the slave has not been told of */
    double inputs[MAX_MIRRORED];       /* the Real inputs, in the order of input_vr */
    double outputs[MAX_MIRRORED];      /* the Real outputs, in the order of output_vr */
    int inputs_current;                /* inputs[] hold the slave's inputs or newer ones */
    int inputs_pending;                /* inputs[] hold values the slave has not been given */
    int outputs_current;               /* outputs[] equal the slave's outputs */
    double last_successful_time;       /* fmi2LastSuccessfulTime */
    int wants_to_terminate;            /* fmi2Terminated: a step failed */
} Guard;

/* ---- python.c ---- */
extern struct PythonApi {
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
    PyObject *true_;
    int ready;
} py;
extern char load_error[1024];
void *real(const char *symbol);
void take_python_error(char *text, size_t size);
void load_once(const char *resource_folder);
int python_loaded(void);
void release_pythonfmu_state(void);
void unload_pythonfmu(void);

/* ---- logging.c ---- */
void tell_host(Guard *g, fmi2Status status, const char *category, const char *message);
void guard_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                  fmi2String category, fmi2String message, ...);
void log_before_instance(const fmi2CallbackFunctions *functions, fmi2String name,
                         fmi2Status status, const char *format, ...);

/* ---- states.c ---- */
enum function {
    F_fmi2SetDebugLogging, F_fmi2SetupExperiment, F_fmi2EnterInitializationMode,
    F_fmi2ExitInitializationMode, F_fmi2Terminate, F_fmi2Reset, F_fmi2GetReal,
    F_fmi2GetInteger, F_fmi2GetBoolean, F_fmi2GetString, F_fmi2SetReal, F_fmi2SetInteger,
    F_fmi2SetBoolean, F_fmi2SetString, F_fmi2GetFMUstate, F_fmi2SetFMUstate,
    F_fmi2FreeFMUstate, F_fmi2SerializedFMUstateSize, F_fmi2SerializeFMUstate,
    F_fmi2DeSerializeFMUstate, F_fmi2GetDirectionalDerivative, F_fmi2SetRealInputDerivatives,
    F_fmi2GetRealOutputDerivatives, F_fmi2DoStep, F_fmi2CancelStep, F_fmi2GetStatus,
    F_fmi2GetRealStatus, F_fmi2GetIntegerStatus, F_fmi2GetBooleanStatus,
    F_fmi2GetStringStatus, N_FUNCTIONS
};
extern const char *const MODE_NAMES[N_MODES];
int admit(Guard *g, enum function f);
void begin(Guard *g);
fmi2Status conclude(Guard *g, enum function f, fmi2Status status);
fmi2Status refuse(Guard *g, const char *format, ...);

/* ---- arguments.c ---- */
int instantiate_arguments_valid(fmi2String name, fmi2Type type, fmi2String guid,
                                fmi2String resources, const fmi2CallbackFunctions *functions,
                                char *folder, size_t size);

/* ---- references.c ---- */
const FeedaxisVar *variable_of(fmi2ValueReference vr);
int references_known(Guard *g, const char *function, char type, const fmi2ValueReference vr[],
                     size_t nvr, const void *values);
int settable(Guard *g, const fmi2ValueReference vr[], size_t nvr);
int reals_valid(Guard *g, const char *function, const fmi2ValueReference vr[], size_t nvr,
                const fmi2Real value[]);
int integers_valid(Guard *g, const char *function, const fmi2ValueReference vr[], size_t nvr,
                   const fmi2Integer value[]);
int strings_valid(Guard *g, const char *function, const fmi2ValueReference vr[], size_t nvr,
                  const fmi2String value[]);

/* ---- mirror.c ---- */
void prepare_mirror(void);
void drop_exchange(Guard *g);
void expect_slave(void);
void claim_exchange(Guard *g);
PyObject *ask_slave(Guard *g, const char *method, PyObject *args);
int load_mirror(Guard *g);
void hand_over(Guard *g);
void slave_changed(Guard *g);
int fast(Guard *g);
fmi2Status exchange_step(Guard *g, fmi2Real t, fmi2Real h);
int mirror_get(Guard *g, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]);
int mirror_set(Guard *g, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]);

/* ---- unloading.c ---- */
Guard *reuse(fmi2String name, fmi2String guid, fmi2String resources,
             const fmi2CallbackFunctions *functions, fmi2Boolean loggingOn);
int put_pooled(Guard *g);
void attach(Guard *g, fmi2String name, const fmi2CallbackFunctions *functions,
            fmi2Boolean loggingOn);
void release(Guard *g);
void unloading(void);

#endif
