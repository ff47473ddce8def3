/* The co-simulation master's macro steps of one chunk, compiled (feedaxis.cosim.compiled_loop).
 *
 * The same steps as the master's Python loop (feedaxis.cosim.master.PythonSteps): for each
 * macro step k of the chunk, the varying system inputs are written into the signal array,
 * then every component whose ratio divides k + 1 gets its inputs (copied from the signals,
 * or read in place), fmi2SetReal, fmi2DoStep from (k + 1 - ratio) h over its step, and
 * fmi2GetReal into the signals (FMI 3.0: fmi3SetFloat64, fmi3DoStep, fmi3GetFloat64); a
 * status above Warning stops the chunk. After a step on the record grid the signal array
 * is appended to the rows. The FMUs' functions are called through the pointers fmpy loaded.
 */
#include <stdbool.h>
#include <stddef.h>
#include <string.h>
#include <time.h>

#define FMI_WARNING 1

typedef int (*Fmi2Values)(void *, const unsigned *, size_t, double *);
typedef int (*Fmi2DoStep)(void *, double, double, int);
typedef int (*Fmi3Values)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*Fmi3DoStep)(void *, double, double, bool, bool *, bool *, bool *, double *);

/* One component's part of the macro step (master.PlanEntry, flat). */
typedef struct {
    int fmi3;
    long ratio;
    void *set_values, *do_step, *get_values;
    void *component;
    const unsigned *in_vrs;
    size_t n_in;
    double *in_buf;
    const long *copy_from; /* in_buf[i] = signals[copy_from[i]], i < n_copies */
    size_t n_copies;
    const unsigned *out_vrs;
    size_t n_out;
    double *out_ptr;
    double step_s;
} Component;

/* The run: plan, signals, which inputs vary, the record grid, the macro step; ``fmu_s``
 * (NULL: no profiling) sums the seconds spent in FMU calls, ``timed_calls`` counts them. */
typedef struct {
    const Component *plan;
    size_t n_plan;
    double *signals;
    size_t n_signals;
    const long *varying;
    size_t n_varying;
    const long *records;
    size_t n_records;
    double h;
    double *fmu_s;
    long *timed_calls;
} Run;

typedef int (*Call)(const Component *, double);

static int set_inputs(const Component *c, double t)
{
    (void)t;
    if (c->fmi3)
        return ((Fmi3Values)c->set_values)(c->component, c->in_vrs, c->n_in, c->in_buf, c->n_in);
    return ((Fmi2Values)c->set_values)(c->component, c->in_vrs, c->n_in, c->in_buf);
}

static int step_from(const Component *c, double t)
{
    if (c->fmi3) {
        bool event, terminate, early;
        double last;
        return ((Fmi3DoStep)c->do_step)(c->component, t, c->step_s, true, &event, &terminate,
                                        &early, &last);
    }
    return ((Fmi2DoStep)c->do_step)(c->component, t, c->step_s, 1);
}

static int get_outputs(const Component *c, double t)
{
    (void)t;
    if (c->fmi3)
        return ((Fmi3Values)c->get_values)(c->component, c->out_vrs, c->n_out, c->out_ptr,
                                           c->n_out);
    return ((Fmi2Values)c->get_values)(c->component, c->out_vrs, c->n_out, c->out_ptr);
}

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

/* ``call`` of component ``c``, timed into the run's sums when profiling. */
static int run_call(const Run *run, Call call, const Component *c, double t)
{
    if (!run->fmu_s) return call(c, t);
    double started = now_s();
    int status = call(c, t);
    *run->fmu_s += now_s() - started;
    ++*run->timed_calls;
    return status;
}

/* Macro steps k_start .. k_end - 1. ``values`` holds the varying inputs' values, one row of
 * k_end - k_start per input; ``*row`` is the index into ``records`` of the next row to
 * record, advanced as rows are written to ``rows`` (n_signals each). Returns -1 when every
 * step is done, else the plan index of the component that failed, with ``*failed_step``
 * the index k + 1 of the macro step it failed in. */
int feedaxis_master_chunk(const Run *run, long k_start, long k_end, const double *values,
                          long *row, double *rows, long *failed_step)
{
    const long n = k_end - k_start;
    double *signals = run->signals;
    long next_record = (size_t)*row < run->n_records ? run->records[*row] : -1;
    for (long k = k_start; k < k_end; ++k) {
        for (size_t v = 0; v < run->n_varying; ++v)
            signals[run->varying[v]] = values[v * n + (k - k_start)];
        const long k1 = k + 1;
        for (size_t p = 0; p < run->n_plan; ++p) {
            const Component *c = &run->plan[p];
            if (k1 % c->ratio) continue;
            for (size_t i = 0; i < c->n_copies; ++i)
                c->in_buf[i] = signals[c->copy_from[i]];
            if (run_call(run, set_inputs, c, 0.0) > FMI_WARNING
                    || run_call(run, step_from, c, (double)(k1 - c->ratio) * run->h) > FMI_WARNING
                    || run_call(run, get_outputs, c, 0.0) > FMI_WARNING) {
                *failed_step = k1;
                return (int)p;
            }
        }
        if (k1 == next_record) {
            memcpy(rows, signals, run->n_signals * sizeof *signals);
            rows += run->n_signals;
            ++*row;
            next_record = (size_t)*row < run->n_records ? run->records[*row] : -1;
        }
    }
    return -1;
}

static int call_nothing(const Component *c, double t)
{
    (void)c;
    (void)t;
    return 0;
}

/* Seconds one timed call spends outside the interval it measures (the clock reads, the
 * sums): ``calls`` timed calls of a function doing nothing, less what the timer measured
 * inside (the loop's own increment and test, a cycle, left in). */
double feedaxis_timer_cost_s(long calls)
{
    double inside = 0.0;
    long counted = 0;
    Run run = {.fmu_s = &inside, .timed_calls = &counted};
    Call volatile nothing = call_nothing;
    double started = now_s();
    for (long i = 0; i < calls; ++i) run_call(&run, nothing, NULL, 0.0);
    return (now_s() - started - inside) / (double)calls;
}
