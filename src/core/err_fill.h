/* SPDX-License-Identifier: MIT */
/*
 * Filling a vafm_error, for both libraries that hand one back: the core (vafm_err_set, status.c) and the C
 * client (clients/c/client.c). The client links libvafm but cannot reach its hidden functions, so the filler
 * is header-only: each library keeps its own copy and exports nothing.
 */
#ifndef VAFM_CORE_ERR_FILL_H
#define VAFM_CORE_ERR_FILL_H

#include <stdarg.h>
#include <stdio.h>

#include "vafm/common.h"

/** Fill err (if not NULL): code, field ("" for NULL) and the message fmt formats with ap. */
#if defined(__GNUC__)
__attribute__((format(printf, 4, 0)))
#endif
static inline void vafm_err_vset(vafm_error *err, int code, const char *field, const char *fmt, va_list ap)
{
    if (!err)
        return;
    err->code = code;
    snprintf(err->field, sizeof err->field, "%s", field ? field : "");
    vsnprintf(err->message, sizeof err->message, fmt, ap);
}

#endif
