/* SPDX-License-Identifier: MIT */
/*
 * The one list of the contact models and of the integrators (X-macros, LAMMPS-style registration in
 * one place). Each row names a type object defined in its own file (contact_<id>.c, integrator_<id>.c):
 * the object carries the model's knowledge (hooks and capability flags, contact.h / integrator.h); this
 * list only says that it exists, under which name, and the phrase `vafm params --help` shows for it.
 *
 *   X(id, "name", "help")    the object is vafm_contact_<id> / vafm_integrator_<id>; "name" must equal
 *                            the object's .name (test_contact checks it); "help" follows the name in
 *                            the parameter's doc (empty, or " (...)").
 *
 * Everything that lists the models is derived from these rows: lookup by name and listing
 * (vafm_contact_type_find/_at, vafm_integrator_find/_at), the parameter's choices and doc (params.c,
 * which the daemon's `get` reports), and the map's material choices (map.c). The separator is an
 * argument (SEP), so a list can be spelled as a string ("jkr|hertz|none") or as an initializer.
 * Adding a model: docs/architecture.md, "Recipe: a new contact model" / "Recipe: a new integrator".
 */
#ifndef VAFM_CORE_MODELS_H
#define VAFM_CORE_MODELS_H

#define VAFM_CONTACT_MODELS(X, SEP)              \
    X(jkr, "jkr", " (adhesive)") SEP             \
    X(hertz, "hertz", " (no adhesion)") SEP      \
    X(none, "none", " (free cantilever)")

#define VAFM_INTEGRATORS(X, SEP)                                \
    X(gjf, "gjf", " (default)") SEP                             \
    X(baoab, "baoab", "") SEP                                   \
    X(paper_vv, "paper-vv", " (the paper's Eq. 7 method)") SEP  \
    X(brownian, "brownian", " (overdamped)")

/* string forms: VAFM_CONTACT_MODELS(VAFM_MODEL_NAME, "|") is "jkr" "|" "hertz" "|" "none" */
#define VAFM_MODEL_NAME(id, name, help) name
#define VAFM_MODEL_DOC(id, name, help) name help

/** "jkr|hertz|none": the choices of a contact field (params.c, map.c). */
#define VAFM_CONTACT_CHOICES VAFM_CONTACT_MODELS(VAFM_MODEL_NAME, "|")
/** "contact model: jkr (adhesive), hertz (no adhesion), none (free cantilever)" */
#define VAFM_CONTACT_DOC "contact model: " VAFM_CONTACT_MODELS(VAFM_MODEL_DOC, ", ")
/** "gjf|baoab|paper-vv|brownian" */
#define VAFM_INTEGRATOR_CHOICES VAFM_INTEGRATORS(VAFM_MODEL_NAME, "|")
/** "time integrator: gjf (default), baoab, paper-vv (the paper's Eq. 7 method), brownian (overdamped)" */
#define VAFM_INTEGRATOR_DOC "time integrator: " VAFM_INTEGRATORS(VAFM_MODEL_DOC, ", ")

#endif
