/* fmi2Instantiate's arguments, checked before anything uses them (pythonfmu aborts the host
 * on a NULL instance name and crashes on resource locations it does not parse, and on a
 * folder that does not exist). */
#include "host.h"

#include <ctype.h>
#include <errno.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <unistd.h>

static int hex_value(char c)
{
    return isdigit((unsigned char)c) ? c - '0' : tolower((unsigned char)c) - 'a' + 10;
}

/* The local path of file URI ``uri`` in ``path``, decoded; -1 if it is not one. RFC 3986 and
 * RFC 8089: the scheme "file" in any case, then "//" and an authority that is empty or
 * "localhost" (any case) and an absolute path, or the absolute path alone ("file:/p");
 * percent-escapes %XX of any octet but NUL; a trailing '/' dropped. Query or fragment: no. */
int uri_path(const char *uri, char *path, size_t size)
{
    if (strncasecmp(uri, "file:", 5) != 0) return -1;
    const char *p = uri + 5;
    if (p[0] == '/' && p[1] == '/') {
        p += 2;
        const char *end = strchr(p, '/');
        if (!end) return -1;
        size_t authority = (size_t)(end - p);
        if (authority != 0 && !(authority == 9 && strncasecmp(p, "localhost", 9) == 0))
            return -1; /* another host's file */
        p = end;
    }
    if (*p != '/') return -1;
    size_t n = 0;
    for (; *p; ++p) {
        char c = *p;
        if (c == '?' || c == '#') return -1;
        if (c == '%') {
            if (!isxdigit((unsigned char)p[1]) || !isxdigit((unsigned char)p[2])) return -1;
            c = (char)(16 * hex_value(p[1]) + hex_value(p[2]));
            if (c == 0) return -1;
            p += 2;
        }
        if (n + 1 >= size) return -1;
        path[n++] = c;
    }
    path[n] = 0;
    while (n > 1 && path[n - 1] == '/') path[--n] = 0;
    return 0;
}

/* Log an error of fmi2Instantiate's arguments; 0. */
#define WRONG(...) (log_before_instance(functions, name, fmi2Error, __VA_ARGS__), 0)

/* Whether fmi2Instantiate may go on with these arguments; logs why not (through the host's
 * logger, when there is one). On success ``folder`` holds the resource folder's path. */
int instantiate_arguments_valid(fmi2String name, fmi2Type type, fmi2String guid,
                                fmi2String resources, const fmi2CallbackFunctions *functions,
                                char *folder, size_t size)
{
    struct stat info;
    if (!functions || !functions->logger) return 0; /* nobody to tell */
    if (!name || !*name)
        return WRONG("fmi2Instantiate: the instance name is %s", name ? "empty" : "NULL");
    if (type != fmi2CoSimulation)
        return WRONG("fmi2Instantiate: this FMU supports co-simulation only (fmuType %d)",
                     (int)type);
    if (!guid || strcmp(guid, FEEDAXIS_GUID) != 0)
        return WRONG("fmi2Instantiate: GUID %s is not this FMU's (%s, in its "
                     "modelDescription.xml)", guid ? guid : "NULL", FEEDAXIS_GUID);
    if (!resources || uri_path(resources, folder, size) != 0)
        return WRONG("fmi2Instantiate: the resource location %s is not a local file URI "
                     "(file:///path, file:/path or file://localhost/path, %%-escapes)",
                     resources ? resources : "NULL");
    errno = 0;
    if (stat(folder, &info) != 0 || !S_ISDIR(info.st_mode))
        return WRONG("fmi2Instantiate: the resource location %s is no folder: %s: %s",
                     resources, folder, errno ? strerror(errno) : "not a directory");
    char marker[MAX_PATH_LENGTH + 32];
    snprintf(marker, sizeof marker, "%s/slavemodule.txt", folder);
    if (access(marker, R_OK) != 0)
        return WRONG("fmi2Instantiate: the resource location %s is not this FMU's resources "
                     "folder (no readable slavemodule.txt)", resources);
    return 1;
}
