/* SPDX-License-Identifier: MIT */
/**
 * @file common.h
 * Export macro, status codes and the error detail record shared by every vafm module.
 *
 * Every function that can fail returns 0 or a negative VAFM_E* code. Functions that validate user input
 * also take an optional vafm_error* that receives the offending field, its value and the allowed range.
 * The library never aborts, exits or prints.
 */
#ifndef VAFM_COMMON_H
#define VAFM_COMMON_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(VAFM_BUILDING_LIB) && defined(__GNUC__)
#define VAFM_API __attribute__((visibility("default")))
#else
#define VAFM_API
#endif

/** Status codes: 0 is success, failures are negative. */
enum vafm_status {
    VAFM_OK = 0,          /**< success */
    VAFM_EINVAL = -1,     /**< a parameter or argument is outside its allowed range */
    VAFM_ENOMEM = -2,     /**< out of memory */
    VAFM_EUNSTABLE = -3,  /**< the time step is at or beyond the integrator's stability limit */
    VAFM_EIO = -4,        /**< an input/output operation failed */
    VAFM_EFORMAT = -5,    /**< a file or message does not follow its format */
    VAFM_ENOTSUP = -6,    /**< not supported (yet) */
    VAFM_EABORT = -7,     /**< stopped by the caller (a sink or progress callback asked to stop) */
    VAFM_ESTATE = -8,     /**< the call does not fit the object's current state */
    VAFM_ENOTFOUND = -9,  /**< a named item (preset, parameter, integrator...) does not exist */
    VAFM_EACCES = -10,    /**< a file cannot be written: permission denied or a read-only file system (the file
                               itself may be intact) */
};

/** Detail of the last validation failure: which field, and why. */
typedef struct vafm_error {
    int code;          /**< the VAFM_E* code returned */
    char field[64];    /**< offending field name ("k_N_per_m"), or "" */
    char message[320]; /**< human-readable message naming the value and the allowed range */
} vafm_error;

/** @return a static English description of a status code; never NULL. */
VAFM_API const char *vafm_strerror(int code);

/** @return the release version of the library actually linked (meson.build's), e.g. "0.6.1"; the API
 *  version it implements is vafm_version_api(). */
VAFM_API const char *vafm_version(void);

/** @return VAFM_API_VERSION_MAJOR << 16 | MINOR << 8 | PATCH of the library actually linked. */
VAFM_API unsigned vafm_version_api(void);

#ifdef __cplusplus
}
#endif
#endif
