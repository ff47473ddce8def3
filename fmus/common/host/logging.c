/* Messages to the host's logger: every one with a category (pythonfmu passes NULL, which
 * ends an OMSimulator process) and the instance name in front (the Python slave of a reused
 * instance does not know its new name); text containing '%' never goes as the format. */
#include "host.h"

#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *category_of(fmi2Status status)
{
    static const char *names[] = {"logAll", "logStatusWarning", "logStatusDiscard",
                                  "logStatusError", "logStatusFatal", "logAll"};
    return names[status <= fmi2Pending ? status : fmi2Error];
}

/* Plain text is its own format (hosts that ignore the arguments still read it); text with a
 * '%' goes as the argument of "%s". */
static void pass_text(const fmi2CallbackFunctions *host, const char *name, fmi2Status status,
                      const char *category, const char *text)
{
    host->logger(host->componentEnvironment, name, status,
                 category && *category ? category : category_of(status),
                 strchr(text, '%') ? "%s" : text, text);
}

void tell_host(Guard *g, fmi2Status status, const char *category, const char *message)
{
    if (!g->host.logger || (status < fmi2Warning && !g->host_logging)) return;
    size_t size = strlen(g->name) + strlen(message) + 3;
    char *text = malloc(size);
    if (!text) return;
    snprintf(text, size, "%s: %s", g->name, message);
    pass_text(&g->host, g->name, status, category, text);
    free(text);
}

/* pythonfmu passes each message as the format with no arguments: treat it as text. */
void guard_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                  fmi2String category, fmi2String message, ...)
{
    Guard *g = env;
    (void)name;
    if (status > g->worst_logged && status <= fmi2Fatal) g->worst_logged = status;
    tell_host(g, status, category, message ? message : "");
}

/* An error of fmi2Instantiate, before there is an instance: through ``functions``' logger
 * when the host gave one, as instance ``name`` (or "" when it gave none). */
void log_before_instance(const fmi2CallbackFunctions *functions, fmi2String name,
                         fmi2Status status, const char *format, ...)
{
    if (!functions || !functions->logger) return;
    char text[1200];
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof text, format, args);
    va_end(args);
    pass_text(functions, name ? name : "", status, NULL, text);
}
