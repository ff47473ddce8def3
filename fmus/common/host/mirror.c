/* The Real inputs and outputs, kept here while stepping. pythonfmu turns every fmi2SetReal
 * and fmi2GetReal into a Python call that builds lists (about 6 of the 7.5 us an empty
 * pythonfmu FMU costs per step with set, step and get); in step complete the layer answers
 * them here and makes fmi2DoStep one Python call, to the slave's exchange function
 * (feedaxis_slave.claim: inputs in, outputs out, messages passed on), or none: where the
 * slave has a compiled step (physics/fmu_steps.py, in the FMU's compiled module), the layer
 * calls that C function on a block of numbers the slave packed (parameters and state),
 * without the GIL. A step it declines (a bad input) goes to the exchange function, which
 * says what is wrong. Any other call first hands pending inputs, and the outputs and state
 * of compiled steps, to the slave, and is followed by a fresh read (and a fresh pack). */
#define _GNU_SOURCE
#include "host.h"

#include <dlfcn.h>
#include <stdint.h>
#include <stdio.h>

static fmi2ValueReference input_vr[MAX_MIRRORED], output_vr[MAX_MIRRORED];
static size_t n_inputs, n_outputs;

/* Index the mirrored variables; ``mirrorable`` stays 0 (every call then goes through
 * pythonfmu) if an input or output is not a Real or there are too many. */
static int mirrorable;

void prepare_mirror(void)
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

void drop_exchange(Guard *g)
{
    g->native = NULL;
    g->block = NULL;
    g->native_offered = g->native_ready = g->native_ahead = 0;
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
void expect_slave(void)
{
    if (!py.ready || !mirrorable) return;
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *result = call_handoff("forget", py.tuple_new(0));
    if (result) py.decref(result);
    py.gil_release(gil);
}

/* After: take the exchange function of the slave pythonfmu has just constructed. Without
 * one (an adapter without it), pythonfmu serves every call. */
void claim_exchange(Guard *g)
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
    if (g->exchange) {
        PyObject *pack = py.get_attr(g->exchange, "native_pack");
        g->native_offered = pack != NULL;
        if (pack) py.decref(pack);
        if (py.err_occurred()) py.err_clear();
    }
    py.gil_release(gil);
}

/* The slave's answer to ``method`` of its exchange function, called with ``args`` (stolen);
 * a new reference or NULL. Holds the GIL. */
PyObject *ask_slave(Guard *g, const char *method, PyObject *args)
{
    PyObject *callable = py.get_attr(g->exchange, method);
    PyObject *answer = callable && args ? py.call(callable, args) : NULL;
    if (args) py.decref(args);
    if (callable) py.decref(callable);
    if (py.err_occurred()) py.err_clear();
    return answer;
}

/* The C function ``symbol`` of the library at ``path`` that Python has loaded, or NULL. */
static native_step find_step(const char *path, const char *symbol)
{
    void *library = path && symbol ? dlopen(path, RTLD_LAZY | RTLD_NOLOAD) : NULL;
    if (!library) return NULL;
    native_step step = (native_step)dlsym(library, symbol);
    dlclose(library); /* Python's import keeps it loaded */
    return step;
}

/* Have the slave fill the compiled step's block from its parameters and state
 * (AxisSlave._native_pack); g->native stays NULL without one. Holds the GIL. */
static void pack_native(Guard *g)
{
    g->native = NULL;
    g->native_ready = 1;
    PyObject *answer = ask_slave(g, "native_pack", py.tuple_new(0));
    if (answer && PyTuple_Check(answer) && py.tuple_size(answer) == 3) {
        const char *path = py.as_utf8(py.tuple_get(answer, 0));
        const char *symbol = py.as_utf8(py.tuple_get(answer, 1));
        long address = py.as_long(py.tuple_get(answer, 2));
        g->native = find_step(path, symbol);
        g->block = (double *)(uintptr_t)address;
        if (py.err_occurred()) {
            py.err_clear();
            g->native = NULL;
        }
        g->native_offered = g->native != NULL; /* a module without the step: Python steps */
    }
    if (answer) py.decref(answer);
}

/* Give the slave the outputs and state of the compiled steps taken since it was last told
 * (AxisSlave._native_unpack). Holds the GIL. */
static void unpack_native(Guard *g)
{
    if (!g->native_ahead) return;
    g->native_ahead = 0;
    PyObject *args = py.tuple_new((Py_ssize_t)n_outputs);
    for (size_t i = 0; args && i < n_outputs; ++i)
        py.tuple_set(args, (Py_ssize_t)i, py.from_double(g->outputs[i]));
    PyObject *answer = ask_slave(g, "native_unpack", args);
    if (answer) py.decref(answer);
}

static fmi2GetRealTYPE *real_get_real;
static fmi2SetRealTYPE *real_set_real;

/* Read the slave's inputs and outputs into the mirror (through pythonfmu). */
int load_mirror(Guard *g)
{
    if (!real_get_real) real_get_real = real("fmi2GetReal");
    if (!real_get_real || real_get_real(g->real, input_vr, n_inputs, g->inputs) > fmi2Warning
        || real_get_real(g->real, output_vr, n_outputs, g->outputs) > fmi2Warning)
        return 0;
    g->inputs_current = g->outputs_current = 1;
    g->inputs_pending = 0;
    return 1;
}

/* Give the slave the outputs and state of compiled steps and the inputs set here since its
 * last step (through pythonfmu), before a call that reaches it. */
void hand_over(Guard *g)
{
    if (g->native_ahead && py.is_initialized()) {
        PyGILState_STATE gil = py.gil_ensure();
        unpack_native(g);
        py.gil_release(gil);
    }
    if (!g->inputs_pending) return;
    if (!real_set_real) real_set_real = real("fmi2SetReal");
    if (real_set_real) real_set_real(g->real, input_vr, n_inputs, g->inputs);
    g->inputs_pending = 0;
}

/* After a call that may change the slave, the mirror is read again before it is used, and
 * the compiled step's block packed again. */
void slave_changed(Guard *g)
{
    g->inputs_current = g->outputs_current = 0;
    g->native_ready = 0;
}

int fast(Guard *g)
{
    return g->exchange && g->mode == STEP_COMPLETE;
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

/* fmi2DoStep by the compiled step where it takes it, without Python; else as one Python
 * call: inputs in, outputs out (pythonfmu: fmi2Discard on a failed step, which finish()
 * turns into the error the slave logged). */
fmi2Status exchange_step(Guard *g, fmi2Real t, fmi2Real h)
{
    if (g->native_offered && !g->native_ready) {
        PyGILState_STATE gil = py.gil_ensure();
        pack_native(g);
        py.gil_release(gil);
    }
    if (g->native && g->native(g->block, h, g->inputs, g->outputs)) {
        g->native_ahead = 1; /* the inputs stay pending: the slave has not seen them */
        g->outputs_current = 1;
        return fmi2OK;
    }
    fmi2Status status = fmi2Discard;
    PyGILState_STATE gil = py.gil_ensure();
    unpack_native(g);
    g->native_ready = 0; /* the slave steps: its state moves past the block's */
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
int mirror_get(Guard *g, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
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
int mirror_set(Guard *g, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    if (!g || !fast(g) || !vr || !value) return 0; /* a NULL array: refused by the guard */
    for (size_t i = 0; i < nvr; ++i)
        if (mirror_index(input_vr, n_inputs, vr[i]) < 0) return 0;
    if (!g->inputs_current && !load_mirror(g)) return 0;
    for (size_t i = 0; i < nvr; ++i) g->inputs[mirror_index(input_vr, n_inputs, vr[i])] = value[i];
    g->inputs_pending = 1;
    return 1;
}
