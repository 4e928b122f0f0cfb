/* SPDX-License-Identifier: MIT */
/* The only place where SI meets reduced units (physics notes, "Units"). */
#include <math.h>

#include "vafm/params.h"
#include "vafm/units.h"

vafm_scale vafm_units_scale(const vafm_params *p)
{
    vafm_scale s;
    s.length_m = p->R_m;
    const double eta = vafm_params_eta_per_s(p); /* eta_per_s, or 2π f0 / Q */
    s.time_s = 1.0 / eta;
    s.force_N = p->E_star_Pa * p->R_m * p->R_m;
    s.energy_J = s.force_N * p->R_m;
    s.speed_m_per_s = p->R_m * eta;
    s.stiffness_N_per_m = p->E_star_Pa * p->R_m;
    return s;
}

void vafm_units_reduce(const vafm_params *p, vafm_reduced *r)
{
    vafm_scale s = vafm_units_scale(p);
    const double m = vafm_params_mass_kg(p), eta = vafm_params_eta_per_s(p);
    r->m = m * eta * eta / s.stiffness_N_per_m;
    r->eta_cont = p->eta_cont_per_s / eta;
    r->k = p->k_N_per_m / s.stiffness_N_per_m;
    r->kT = VAFM_KB_J_PER_K * p->T_K / s.energy_J;
    r->gamma = p->gamma_J_per_m2 / s.stiffness_N_per_m;
    r->v_approach = p->v_approach_m_per_s / s.speed_m_per_s;
    r->v_retract = p->v_retract_m_per_s / s.speed_m_per_s;
}

void vafm_units_from_reduced(vafm_params *p, const vafm_reduced *r)
{
    double ER = p->E_star_Pa * p->R_m;
    p->f0_Hz = p->Q = 0; /* the scene is then given by m_kg and eta_per_s */
    p->eta_per_s = sqrt(r->m * ER / p->m_kg);
    p->eta_cont_per_s = r->eta_cont * p->eta_per_s;
    p->k_N_per_m = r->k * ER;
    p->T_K = r->kT * ER * p->R_m * p->R_m / VAFM_KB_J_PER_K;
    p->gamma_J_per_m2 = r->gamma * ER;
    p->v_approach_m_per_s = r->v_approach * p->R_m * p->eta_per_s;
    p->v_retract_m_per_s = r->v_retract * p->R_m * p->eta_per_s;
}
