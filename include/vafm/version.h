/* SPDX-License-Identifier: MIT */
#ifndef VAFM_VERSION_H
#define VAFM_VERSION_H

/* Read by meson (cc.get_define) to set the shared-library soversion. */
#define VAFM_API_VERSION_MAJOR 0
#define VAFM_API_VERSION_MINOR 8
#define VAFM_API_VERSION_PATCH 0

#endif
