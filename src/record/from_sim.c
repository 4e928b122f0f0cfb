/* SPDX-License-Identifier: MIT */
/*
 * A simulated force curve as a file's curve and ground-truth row: the adapters between the simulation
 * (vafm_samples, vafm_params, vafm_curve_result) and the HDF5 layer (vafm_h5_curve, vafm_h5_truth). They
 * live in the recording layer so that src/h5 knows the file format only; the recorder, vafm listen and
 * the tests use them. Declared in record.h.
 */
#include <math.h>
#include <string.h>

#include "record/record.h"

void vafm_h5_curve_from_sim(vafm_h5_curve *c, const vafm_samples *s, const vafm_params *p,
                            const vafm_curve_result *r)
{
    memset(c, 0, sizeof *c);
    vafm_h5_meta_default(&c->meta);
    c->n = s->n;
    c->force_N = s->force_N;
    /* the z sensor's reading (the piezo's actual height through the sensor); an ideal piezo: the command */
    c->height_measured_m = s->height_measured_m ? s->height_measured_m : s->height_m;
    c->height_piezo_m = s->height_m;
    c->segment = s->segment;
    c->time_s = s->time_s;
    c->tip_position_m = s->tip_m;
    vafm_h5_meta *m = &c->meta;
    m->imaging_mode = "force-distance";
    m->software = "vafm";
    m->software_version = vafm_version();
    m->spring_constant_N_per_m = p->k_N_per_m;
    m->sensitivity_m_per_V = p->sensitivity_m_per_V; /* with "spring constant": vDeflection from force */
    if (p->trigger == VAFM_TRIGGER_FORCE)
        m->setpoint_N = p->setpoint_N;
    m->rate_approach_Hz = m->rate_retract_Hz = p->sample_rate_Hz;
    m->speed_approach_m_per_s = p->v_approach_m_per_s;
    m->speed_retract_m_per_s = p->v_retract_m_per_s;
    size_t na = 0, nr = 0;
    double hmin = INFINITY, hmax = -INFINITY;
    for (size_t i = 0; i < s->n; i++) {
        na += s->segment[i] == VAFM_SEG_APPROACH;
        nr += s->segment[i] == VAFM_SEG_RETRACT;
        if (s->height_m[i] < hmin)
            hmin = s->height_m[i];
        if (s->height_m[i] > hmax)
            hmax = s->height_m[i];
    }
    if (r)
        m->duration_s = r->duration_s;
    m->duration_approach_s = (double)na / p->sample_rate_Hz;
    m->duration_retract_s = (double)nr / p->sample_rate_Hz;
    if (s->n)
        m->z_range_m = hmax - hmin;
    m->segment_count = 2;
}

void vafm_h5_truth_from_sim(vafm_h5_truth *t, uint64_t point, const vafm_params *p, const vafm_curve_result *r)
{
    memset(t, 0, sizeof *t);
    t->point = point;
    t->T_K = p->T_K;
    t->v_m_per_s = p->v_retract_m_per_s;
    t->k_N_per_m = p->k_N_per_m;
    t->result = *r;
    t->E_star_Pa = p->E_star_Pa;
    t->gamma_J_per_m2 = p->gamma_J_per_m2;
    t->surface_height_m = r && !isnan(r->surface_height_m) ? r->surface_height_m : p->surface_height_m;
}
