/* SPDX-License-Identifier: MIT */
#include <stdarg.h>
#include <stdio.h>
#include "vafm/common.h"
#include "core/err_fill.h"
#include "core/internal.h"
#include "vafm/version.h"

const char *vafm_strerror(int code)
{
    switch (code) {
    case VAFM_OK: return "success";
    case VAFM_EINVAL: return "invalid argument: a parameter is outside its allowed range";
    case VAFM_ENOMEM: return "out of memory";
    case VAFM_EUNSTABLE: return "time step at or beyond the integrator's stability limit";
    case VAFM_EIO: return "input/output error";
    case VAFM_EFORMAT: return "file or message does not follow its format";
    case VAFM_ENOTSUP: return "not supported (yet)";
    case VAFM_EABORT: return "stopped by the caller";
    case VAFM_ESTATE: return "call does not fit the current state";
    case VAFM_ENOTFOUND: return "no such item";
    case VAFM_EACCES: return "permission denied or read-only file system (not damage)";
    default: return "unknown error code";
    }
}

/* The release's version (meson.build), which names the files and packages; the API's version, which
 * changes only with the interface, is vafm_version_api(). 0.6.1 returned the API's, so it called itself
 * 0.6.0 in --version and in every file's "software version". */
#ifndef VAFM_PROJECT_VERSION
#error "meson.build defines VAFM_PROJECT_VERSION"
#endif

const char *vafm_version(void)
{
    return VAFM_PROJECT_VERSION;
}

unsigned vafm_version_api(void)
{
    return (VAFM_API_VERSION_MAJOR << 16) | (VAFM_API_VERSION_MINOR << 8) | VAFM_API_VERSION_PATCH;
}

void vafm_err_set(vafm_error *err, int code, const char *field, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    vafm_err_vset(err, code, field, fmt, ap);
    va_end(ap);
}

int vafm_buf_appendf(char *buf, size_t len, size_t *n, const char *fmt, ...)
{
    if (*n >= len)
        return VAFM_EINVAL;
    va_list ap;
    va_start(ap, fmt);
    int w = vsnprintf(buf + *n, len - *n, fmt, ap);
    va_end(ap);
    if (w < 0 || (size_t)w >= len - *n)
        return VAFM_EINVAL;
    *n += (size_t)w;
    return 0;
}
