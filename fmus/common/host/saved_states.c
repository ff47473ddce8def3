/* Saved states. The host holds a Saved: pythonfmu's state and the FMI state it was saved
 * in, so that fmi2SetFMUstate puts the instance back into that state, out of the error state
 * too (the standard: after fmi2Error a host may go on from a state saved while healthy). A
 * deserialised state takes step complete or instantiated, by whether the slave was
 * initialised when it was saved. What a host gets wrong is refused here: pythonfmu would
 * dereference a NULL pointer, copy past a buffer's end, or make a corrupt buffer
 * fmi2Fatal. */
#include "host.h"

#include <stdio.h>
#include <stdlib.h>

#define FROM_SLAVE N_MODES /* Saved.mode of a deserialised state */

typedef struct {
    fmi2FMUstate real; /* pythonfmu's */
    enum mode mode;    /* the state it was saved in, or FROM_SLAVE */
} Saved;

/* Whether the slave's model is built (it was initialised); 1 without an adapter to ask. */
static int slave_initialised(Guard *g)
{
    if (!g->exchange) return 1;
    PyGILState_STATE gil = py.gil_ensure();
    PyObject *answer = ask_slave(g, "initialised", py.tuple_new(0));
    int initialised = answer == py.true_;
    if (answer) py.decref(answer);
    py.gil_release(gil);
    return initialised;
}

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
    PyObject *args = py.tuple_new(1);
    if (args) py.tuple_set(args, 0, py.bytes_new(bytes, (Py_ssize_t)size));
    PyObject *answer = ask_slave(g, "state_error", args);
    int refused = answer != py.none;
    if (refused) {
        const char *text = answer && PyUnicode_Check(answer) ? py.as_utf8(answer) : NULL;
        snprintf(why, n, "%s", text ? text : "the state could not be checked");
    }
    if (answer) py.decref(answer);
    if (py.err_occurred()) py.err_clear();
    py.gil_release(gil);
    return refused;
}

/* pythonfmu's function ``symbol``, resolved once per call site. */
#define PYTHONFMU(function) \
    static function##TYPE *call_; \
    if (!call_) call_ = (function##TYPE *)real(#function)

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Guard *g = c;
    if (!admit(g, F_fmi2GetFMUstate)) return fmi2Error;
    if (!state) return refuse(g, "fmi2GetFMUstate: NULL pointer for the state");
    Saved *saved = *state ? *state : calloc(1, sizeof *saved);
    if (!saved) return refuse(g, "fmi2GetFMUstate: out of memory");
    PYTHONFMU(fmi2GetFMUstate);
    enum mode mode = g->mode;
    hand_over(g);
    begin(g);
    fmi2Status status = conclude(g, F_fmi2GetFMUstate, call_(g->real, &saved->real));
    if (status > fmi2Warning) {
        if (!*state) free(saved);
        return status;
    }
    saved->mode = mode;
    *state = saved;
    return status;
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    Guard *g = c;
    if (!admit(g, F_fmi2SetFMUstate)) return fmi2Error;
    if (!state) return refuse(g, "fmi2SetFMUstate: NULL state");
    Saved *saved = state;
    PYTHONFMU(fmi2SetFMUstate);
    hand_over(g);
    begin(g);
    fmi2Status status = conclude(g, F_fmi2SetFMUstate, call_(g->real, saved->real));
    slave_changed(g);
    if (status <= fmi2Warning) {
        g->mode = saved->mode != FROM_SLAVE ? saved->mode
                  : slave_initialised(g) ? STEP_COMPLETE : INSTANTIATED;
        g->wants_to_terminate = 0;
    }
    return status;
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state)
{
    Guard *g = c;
    if (!admit(g, F_fmi2FreeFMUstate)) return fmi2Error;
    if (!state) return refuse(g, "fmi2FreeFMUstate: NULL pointer for the state");
    if (!*state) return fmi2OK;  /* nothing to free */
    Saved *saved = *state;
    PYTHONFMU(fmi2FreeFMUstate);
    begin(g);
    fmi2Status status = conclude(g, F_fmi2FreeFMUstate, call_(g->real, &saved->real));
    free(saved);
    *state = NULL;
    return status;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size)
{
    Guard *g = c;
    if (!admit(g, F_fmi2SerializedFMUstateSize)) return fmi2Error;
    if (!state || !size) return refuse(g, "fmi2SerializedFMUstateSize: NULL state or size");
    PYTHONFMU(fmi2SerializedFMUstateSize);
    begin(g);
    return conclude(g, F_fmi2SerializedFMUstateSize,
                    call_(g->real, ((Saved *)state)->real, size));
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[],
                                        size_t size)
{
    Guard *g = c;
    size_t needed = 0;
    if (!admit(g, F_fmi2SerializeFMUstate)) return fmi2Error;
    if (!state || !bytes) return refuse(g, "fmi2SerializeFMUstate: NULL state or buffer");
    fmi2Status status = fmi2SerializedFMUstateSize(c, state, &needed);
    if (status > fmi2Warning) return status;
    if (needed != size)
        return refuse(g, "fmi2SerializeFMUstate: a buffer of %zu bytes for a state of %zu "
                         "(fmi2SerializedFMUstateSize)", size, needed);
    PYTHONFMU(fmi2SerializeFMUstate);
    begin(g);
    return conclude(g, F_fmi2SerializeFMUstate,
                    call_(g->real, ((Saved *)state)->real, bytes, size));
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                          fmi2FMUstate *state)
{
    char why[400];
    Guard *g = c;
    if (!admit(g, F_fmi2DeSerializeFMUstate)) return fmi2Error;
    if (!state) return refuse(g, "fmi2DeSerializeFMUstate: NULL pointer for the state");
    if (state_refused(g, bytes, size, why, sizeof why))
        return refuse(g, "fmi2DeSerializeFMUstate: %s", why);
    Saved *saved = calloc(1, sizeof *saved);
    if (!saved) return refuse(g, "fmi2DeSerializeFMUstate: out of memory");
    PYTHONFMU(fmi2DeSerializeFMUstate);
    begin(g);
    fmi2Status status = conclude(g, F_fmi2DeSerializeFMUstate,
                                 call_(g->real, bytes, size, &saved->real));
    if (status > fmi2Warning) {
        free(saved);
        return status;
    }
    saved->mode = FROM_SLAVE;
    *state = saved;
    return status;
}
