/* SPDX-License-Identifier: MIT */
/*
 * The runtime stiffness guard (sim.c): after every sample interval in contact, the step in use must stay
 * stable at the contact actually reached, which thermal motion may take stiffer than the scene predicted.
 * Its measure is ω·dt (K·dt/ζ for an overdamped integrator) with the local stiffness K = k + dF/du.
 *
 * Evaluating it takes a contact solve per sample: at a few integrator steps per sample (MS/s output) that
 * costs as much as a step or two. On the JKR and Hertz branches the stiffness grows strictly with u, so
 * vafm_guard_threshold() finds once, per step size, the u below which the measure cannot reach the limit,
 * and the guard solves only beyond it. The guard fires at exactly the states it fired at before.
 */
#ifndef VAFM_CORE_GUARD_H
#define VAFM_CORE_GUARD_H

#include "vafm/integrator.h"
#include "core/kernel.h"

/** The guard's measure at u (0 where K = k + dF/du ≤ 0); *sq is the solver's warm start, *Kl (may be NULL)
 *  receives K. */
double vafm_guard_measure(const vafm_kernel *K, const vafm_integrator_type *it, double dt, double u, double *sq,
                          double *Kl);

/** A u_ok such that every u ≤ u_ok gives a measure below it->stability_limit·(1 − 1e-6), for a contact
 *  whose stiffness grows along its branch (VAFM_CONTACT_MONOTONE: JKR, Hertz); −∞ (always evaluate) for
 *  any other contact or dt ≤ 0. Bisection: ~100 contact solves. */
double vafm_guard_threshold(const vafm_kernel *K, const vafm_integrator_type *it, double dt);

#endif
