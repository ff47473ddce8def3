/* Value references and values: what a host gets wrong is refused with fmi2Error before
 * pythonfmu sees it (pythonfmu raises, which is fmi2Fatal, or crashes): a reference that is
 * no variable of the function's type, a NULL array, an output or (after initialisation) a
 * fixed parameter set, a Real that is not finite, a value outside the variable's declared
 * min and max (modelDescription.xml), a String that is NULL or not UTF-8. */
#include "host.h"

#include <string.h>

const FeedaxisVar *variable_of(fmi2ValueReference vr)
{
    for (size_t k = 0; k < FEEDAXIS_N_VARS; ++k)
        if (FEEDAXIS_VARS[k].vr == vr) return &FEEDAXIS_VARS[k];
    return NULL;
}

static const char *type_name(char type)
{
    switch (type) {
    case 'R': return "a Real";
    case 'I': return "an Integer";
    case 'B': return "a Boolean";
    default: return "a String";
    }
}

static const char *role_of(const FeedaxisVar *v)
{
    return v->kind == 'u' ? "input " : v->kind == 'o' ? "output " : "parameter ";
}

/* Whether every reference in ``vr`` is a variable of ``type``; refuses the call otherwise. */
int references_known(Guard *g, const char *function, char type, const fmi2ValueReference vr[],
                     size_t nvr, const void *values)
{
    if (nvr > 0 && (!vr || !values))
        return refuse(g, "%s: NULL value reference or value array for %zu values", function,
                      nvr), 0;
    for (size_t i = 0; i < nvr; ++i) {
        const FeedaxisVar *v = variable_of(vr[i]);
        if (!v)
            return refuse(g, "%s: value reference %u is not a variable of this FMU", function,
                          vr[i]), 0;
        if (v->type != type)
            return refuse(g, "%s: value reference %u is %s, %s variable, not %s", function,
                          vr[i], v->name, type_name(v->type), type_name(type)), 0;
    }
    return 1;
}

/* Whether every ``vr`` may be set in the instance's state (outputs never; fixed parameters
 * in instantiated and initialisation mode only); refuses the call otherwise. */
int settable(Guard *g, const fmi2ValueReference vr[], size_t nvr)
{
    for (size_t i = 0; i < nvr; ++i) {
        const FeedaxisVar *v = variable_of(vr[i]);
        if (v->kind == 'o') return refuse(g, "%s is an output and cannot be set", v->name), 0;
        if (v->kind == 'f' && g->mode != INSTANTIATED && g->mode != INITIALISATION)
            return refuse(g, "%s is a fixed parameter and cannot be set in %s", v->name,
                          MODE_NAMES[g->mode]), 0;
    }
    return 1;
}

/* Whether ``value`` lies within ``v``'s declared min and max; refuses the call otherwise. */
static int in_range(Guard *g, const char *function, const FeedaxisVar *v, double value)
{
    if (value >= v->min && value <= v->max) return 1;
    return refuse(g, "%s: %s%s = %.15g is %s its %s %.15g (modelDescription.xml)", function,
                  role_of(v), v->name, value, value < v->min ? "below" : "above",
                  value < v->min ? "min" : "max", value < v->min ? v->min : v->max), 0;
}

int reals_valid(Guard *g, const char *function, const fmi2ValueReference vr[], size_t nvr,
                const fmi2Real value[])
{
    for (size_t i = 0; i < nvr; ++i) {
        const FeedaxisVar *v = variable_of(vr[i]);
        if (!isfinite(value[i]))
            return refuse(g, "%s: %s%s must be finite, got %g", function, role_of(v), v->name,
                          value[i]), 0;
        if (!in_range(g, function, v, value[i])) return 0;
    }
    return 1;
}

int integers_valid(Guard *g, const char *function, const fmi2ValueReference vr[], size_t nvr,
                   const fmi2Integer value[])
{
    for (size_t i = 0; i < nvr; ++i)
        if (!in_range(g, function, variable_of(vr[i]), (double)value[i])) return 0;
    return 1;
}

/* The length of the UTF-8 sequence starting at ``s`` (RFC 3629: no overlong form, no
 * surrogate, nothing above U+10FFFF), or 0 if it is not one. */
static size_t utf8_sequence(const unsigned char *s)
{
    if (s[0] < 0x80) return 1;
    size_t n = s[0] >= 0xC2 && s[0] <= 0xDF ? 2 : s[0] >= 0xE0 && s[0] <= 0xEF ? 3
               : s[0] >= 0xF0 && s[0] <= 0xF4 ? 4 : 0;
    for (size_t i = 1; i < n; ++i)
        if ((s[i] & 0xC0) != 0x80) return 0;
    if ((s[0] == 0xE0 && s[1] < 0xA0) || (s[0] == 0xED && s[1] > 0x9F)
        || (s[0] == 0xF0 && s[1] < 0x90) || (s[0] == 0xF4 && s[1] > 0x8F))
        return 0;
    return n;
}

int strings_valid(Guard *g, const char *function, const fmi2ValueReference vr[], size_t nvr,
                  const fmi2String value[])
{
    for (size_t i = 0; i < nvr; ++i) {
        const char *name = variable_of(vr[i])->name;
        if (!value[i]) return refuse(g, "%s: NULL string for %s", function, name), 0;
        for (const unsigned char *s = (const unsigned char *)value[i]; *s;) {
            size_t n = utf8_sequence(s);
            if (n == 0)
                return refuse(g, "%s: the value for %s is not UTF-8 (byte %zu)", function, name,
                              (size_t)(s - (const unsigned char *)value[i])), 0;
            s += n;
        }
    }
    return 1;
}
