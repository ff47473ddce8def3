/* Freed instances kept for reuse, and unloading.
 *
 * Freed instances are kept (up to POOL_SIZE) and reused through pythonfmu's fmi2Reset, which
 * creates a fresh Python slave: pythonfmu's fmi2Instantiate leaks about 1.4 kB in findClass
 * (an MRO list and class-name strings) every time, its fmi2Reset nothing. When the host
 * unloads the library (or at exit), the pooled instances go back to pythonfmu and its
 * library is unloaded: the layer does not pin itself in the process. */
#define _GNU_SOURCE
#include "host.h"

#include <dlfcn.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

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

/* Keep freed instance ``g``; 0 when the pool is full. An instance freed twice (a host's
 * mistake, seen in OMSimulator after a failed initialisation) is kept once. */
int put_pooled(Guard *g)
{
    int kept = 0;
    pthread_mutex_lock(&pool_lock);
    for (size_t i = 0; i < pooled && !kept; ++i) kept = pool[i] == g;
    if (!kept && pooled < POOL_SIZE) {
        pool[pooled++] = g;
        kept = 1;
    }
    pthread_mutex_unlock(&pool_lock);
    return kept;
}

void release(Guard *g)
{
    drop_exchange(g);
    free(g->name);
    free(g->guid);
    free(g->resources);
    free(g);
}

/* The host's callbacks and name on guard ``g`` (pythonfmu keeps a pointer to g->mine). */
void attach(Guard *g, fmi2String name, const fmi2CallbackFunctions *functions,
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

/* At exit, or when the host unloads this library (fmpy does at every fmi2FreeInstance): the
 * pooled instances go back to pythonfmu, whose state is released (release_pythonfmu_state)
 * and library unloaded, so that loading an FMU from fresh folders again and again keeps
 * nothing of the earlier copies (both libraries stayed mapped: 0.35 MB a copy). In a Python
 * host at exit Python is already finalised: only pythonfmu's state is released. */
void unloading(void)
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
        unload_pythonfmu();
        return;
    }
    release_pythonfmu_state();
}

/* A pooled instance of the same FMU (GUID and resources), reset for ``name``, or NULL. */
Guard *reuse(fmi2String name, fmi2String guid, fmi2String resources,
             const fmi2CallbackFunctions *functions, fmi2Boolean loggingOn)
{
    Guard *g = take_pooled(guid, resources);
    if (!g) return NULL;
    attach(g, name, functions, loggingOn);
    static fmi2ResetTYPE *reset;
    if (!reset) reset = (fmi2ResetTYPE *)real("fmi2Reset");
    begin(g);
    expect_slave();
    if (conclude(g, F_fmi2Reset, reset(g->real)) <= fmi2Warning) {
        claim_exchange(g);
        return g;
    }
    if (g->mode != FATAL) {
        fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)real("fmi2FreeInstance");
        free_instance(g->real);
    }
    release(g);
    return NULL;
}
