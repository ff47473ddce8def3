/* What one FMI version's part of the C host of the tests provides (fmi2_c_host.c for FMI
 * 2.0, fmi3_c_host.c for FMI 3.0) to the version-free host, fmi_c_host.c. Each function
 * returns the FMI status of the call it makes (0 is OK), and the FMU's log messages go to
 * print_log. */
#ifndef FMI_C_HOST_H
#define FMI_C_HOST_H

#include <stddef.h>

typedef void *Instance;

/* The FMI version's binaries folder (linux64, x86_64-linux). */
extern const char *const PLATFORM;

/* Find the FMI functions in the model-identifier library ``library`` (dlopen's handle);
 * the name of the first one missing, or NULL. */
const char *find_functions(void *library);

/* The resource location of the FMU unpacked in ``folder``, as the version's instantiate
 * function takes it (FMI 2.0: a file URI; FMI 3.0: a path ending in '/'). */
void resource_location(const char *folder, char *location, size_t size);

/* The version's co-simulation instantiate function with exactly these arguments (any may be
 * NULL); logging off, not visible. */
Instance instantiate(const char *name, const char *guid, const char *resources);

/* Initialisation at time 0 (FMI 2.0: setup experiment, enter and exit initialisation). */
int initialise(Instance instance);
int set_reals(Instance instance, const unsigned vr[], size_t n, const double values[]);
int get_reals(Instance instance, const unsigned vr[], size_t n, double values[]);
int do_step(Instance instance, double time_s, double step_s);
int terminate(Instance instance);
void free_instance(Instance instance);

/* fmi_c_host.c: print one message the FMU logs ("log STATUS CATEGORY MESSAGE"). */
void print_log(int status, const char *category, const char *message);

#endif
