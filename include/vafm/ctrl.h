/* SPDX-License-Identifier: MIT */
/**
 * @file ctrl.h
 * The always-on controller (issue #26): a contact-mode AFM controller whose state persists from creation to
 * destruction, over the simulation's live scene (vafm_sim_live_begin). It owns the coarse Z motor, the piezo
 * (Z extension within its range, XY within the scanner's range), the sample under the tip (a flat uniform
 * sample, or a force map's topography), the Z feedback and the detector, and turns the commands of a real
 * controller (engage, withdraw, move, z, feedback) into the support's motion, one output sample at a time.
 *
 * Geometry (SI, heights upward from the sample's substrate, docs/instrument.md):
 *   support height H = motor_z_m − piezo_z_m  (the undeflected tip; the piezo extends downward from the motor)
 *   gap            = H − surface(x, y)        (the live scene's height; contact near gap ≈ 0)
 * The motor starts far away (motor_z0_m, 200 µm by default); the piezo extends within [0, piezo_range_m]; x and y
 * lie within ±xy_range_m/2.
 *
 * Threading and real time: the object is not thread-safe. A paced thread calls vafm_ctrl_advance(); commands
 * (vafm_ctrl_engage, ...) are called between two advances by the same thread (a daemon's control thread hands
 * them over a ring) and take effect at the next sample boundary. Nothing after vafm_ctrl_new allocates, locks or
 * does I/O: commands, advance, status and events only touch the object's fixed state. Long operations (engage,
 * withdraw, move, z) are state machines that progress as the scene advances; they never block. What happened is
 * read after each advance from a fixed-size event queue (vafm_ctrl_event_pop) and from vafm_ctrl_status.
 *
 * Reproducibility: the lever's noise is stream `stream` of seed ^ VAFM_SIM_LIVE_KEY and the detector's its own
 * (vafm/detector.h), so the same commands at the same sample indices reproduce a session bit for bit.
 */
#ifndef VAFM_CTRL_H
#define VAFM_CTRL_H

#include <stddef.h>
#include <stdint.h>

#include "vafm/common.h"
#include "vafm/map.h"
#include "vafm/params.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct vafm_ctrl vafm_ctrl;

/** The controller's states (docs/instrument.md has the diagram). */
enum vafm_ctrl_state {
    VAFM_CTRL_IDLE = 0,        /**< feedback off, nothing under way (from start-up; the lever may touch the
                                    sample after a `z` command: status.in_contact) */
    VAFM_CTRL_APPROACHING = 1, /**< engage under way: baseline, piezo sweeps and motor steps */
    VAFM_CTRL_ENGAGED = 2,     /**< in contact, feedback on, holding the setpoint */
    VAFM_CTRL_WITHDRAWING = 3, /**< feedback off, piezo retracting (then the motor backing off) */
    VAFM_CTRL_WITHDRAWN = 4,   /**< withdraw done: feedback off, piezo retracted */
    VAFM_CTRL_CRASHED = 5,     /**< the force passed force_limit_N: feedback off, piezo retracted, the motor backed
                                    off one step; engage is refused until a withdraw */
};

/** Phases of an engage (status.engage_phase). */
enum vafm_ctrl_engage_phase {
    VAFM_CTRL_ENGAGE_NONE = 0,
    VAFM_CTRL_ENGAGE_BASELINE = 1, /**< piezo retracted: the free baseline of a relative setpoint */
    VAFM_CTRL_ENGAGE_EXTEND = 2,   /**< piezo extending at engage_speed_m_per_s, watching the setpoint */
    VAFM_CTRL_ENGAGE_RETRACT = 3,  /**< setpoint not met over the whole range: piezo back to 0 */
    VAFM_CTRL_ENGAGE_MOTOR = 4,    /**< one motor step toward the sample */
};

/** Events, read with vafm_ctrl_event_pop after an advance. */
enum vafm_ctrl_event_type {
    VAFM_CTRL_EV_ENGAGED = 1,     /**< engage reached the setpoint, feedback on (value: the force, N) */
    VAFM_CTRL_EV_FAILED = 2,      /**< engage failed (reason: enum vafm_ctrl_fail; value: motor z, m) */
    VAFM_CTRL_EV_CRASH = 3,       /**< the force passed force_limit_N (value: the force reached, N) */
    VAFM_CTRL_EV_Z_SATURATED = 4, /**< the feedback ran out of piezo range (value: the piezo z, m: 0 or the range) */
    VAFM_CTRL_EV_Z_RECOVERED = 5, /**< the feedback is back within the range */
    VAFM_CTRL_EV_XY_RANGE = 6,    /**< a move's target lies beyond the scanner's range (refused; value: the
                                       farthest coordinate asked, m) */
    VAFM_CTRL_EV_WITHDRAWN = 7,   /**< withdraw done (value: motor z, m) */
    VAFM_CTRL_EV_MOVED = 8,       /**< a move reached its target (value: the lateral distance travelled, m) */
    VAFM_CTRL_EV_Z_REACHED = 9,   /**< a `z` command reached its value (value: piezo z, m) */
    VAFM_CTRL_EV_LOST_CONTACT = 10, /**< engaged, the tip lost contact (value: the force, N) */
    VAFM_CTRL_EV_SIM_ERROR = 11,  /**< the simulation failed (reason: the VAFM_E* code); the lever restarts at
                                       rest where it was on the next stream */
    VAFM_CTRL_EV_OVERFLOW = 12,   /**< the queue was full: events were dropped (value: how many) */
};

/** Why an engage failed. */
enum vafm_ctrl_fail {
    VAFM_CTRL_FAIL_NONE = 0,
    VAFM_CTRL_FAIL_MOTOR_RANGE = 1, /**< the next motor step would pass motor_min_m: the sample is out of reach */
    VAFM_CTRL_FAIL_TIMEOUT = 2,     /**< engage_timeout_s passed without reaching the setpoint */
    VAFM_CTRL_FAIL_CRASH = 3,       /**< the force passed force_limit_N during the engage */
    VAFM_CTRL_FAIL_ABORTED = 4,     /**< a withdraw (or another command) interrupted it */
};

/** One event. */
typedef struct vafm_ctrl_event {
    int type;      /**< enum vafm_ctrl_event_type */
    int reason;    /**< enum vafm_ctrl_fail for FAILED, a VAFM_E* code for SIM_ERROR, else 0 */
    uint64_t sample; /**< the sample at which it happened: its index (a command's event: the count made so far) */
    double time_s; /**< its time, s (the time of that sample, as vafm_ctrl_samples.time_s; a command's: the last
                        sample's) */
    double value;  /**< see the event type */
} vafm_ctrl_event;

/** The event queue's capacity; beyond it events are dropped and counted (VAFM_CTRL_EV_OVERFLOW). */
#define VAFM_CTRL_EVENTS 64

/** How the setpoint is given. */
enum vafm_ctrl_unit { VAFM_CTRL_UNIT_N = 0 /**< force, N */, VAFM_CTRL_UNIT_V = 1 /**< deflection signal, V */ };

/** The controller's settings. Every field has a unit and an allowed range (vafm_ctrl_params_validate). */
typedef struct vafm_ctrl_params {
    /* coarse Z motor */
    double motor_z0_m;        /**< start height of the motor (the retracted tip above the substrate), m, [−1e-2, 1e-1]
                                   (default 200e-6) */
    double motor_min_m;       /**< lowest motor height, m, [−1e-2, 1e-1] (default 0): an engage that would step
                                   below it fails (motor range) */
    double motor_max_m;       /**< highest motor height, m, (motor_min_m, 1e-1] (default 10e-3) */
    double motor_step_m;      /**< motor step of an engage, m, (0, 1e-3] (default 5e-6; a step longer than the
                                   piezo range can skip the surface and crash) */
    double motor_speed_m_per_s; /**< motor speed during a step, m/s, (0, 1e-2] (default 100e-6) */
    /* piezo scanner */
    double piezo_range_m;     /**< Z extension range, m, (0, 1e-3] (default 10e-6) */
    double xy_range_m;        /**< XY range (full side, centred on 0), m, (0, 1e-2] (default 100e-6) */
    double xy_speed_m_per_s;  /**< default lateral speed of a move, m/s, (0, 1e-2] (default 10e-6) */
    double z_speed_m_per_s;   /**< piezo speed of retracts, withdraws and `z` moves, m/s, (0, 1e-2] (default 100e-6) */
    /* engage */
    double engage_speed_m_per_s; /**< piezo extension speed of the engage's search, m/s, (0, 1e-2] (default 20e-6) */
    double engage_timeout_s;  /**< engage gives up after this, s, (0, 1e5] (default 300) */
    double force_limit_N;     /**< a force beyond this is a crash, N, (0, 1e-3] (default 50e-9; must exceed the
                                   setpoint) */
    /* Z feedback */
    double setpoint;          /**< setpoint in setpoint_unit, [−100, 100] N or V, (default 2e-9 N) */
    int setpoint_unit;        /**< enum vafm_ctrl_unit (default N) */
    int setpoint_relative;    /**< 1: relative to the free baseline the engage measures (VAFM_BASELINE_SAMPLES
                                   samples), 0: absolute (a setpoint in V then counts from baseline_offset_V)
                                   (default 1) */
    double fb_p_m_per_N;      /**< proportional gain, m of piezo per N of error, [0, 1e3] (default 0) */
    double fb_i_m_per_N_s;    /**< integral gain, m/(N·s), [0, 1e12] (default 0: from fb_tau_s) */
    double fb_tau_s;          /**< with fb_i_m_per_N_s = 0: the integral loop's time constant, gain 1/(k·τ), s,
                                   [0, 1e3] (default 0: 10 sample intervals) */
    /* detector */
    double sum_V;             /**< photodiode sum signal, V, [0, 100] (default 5; reported) */
    uint64_t stream;          /**< the live scene's random stream (default 0) */
    uint8_t reserved[32];
} vafm_ctrl_params;

/** Fill p with the defaults above. */
VAFM_API void vafm_ctrl_params_default(vafm_ctrl_params *p);

/** Check every field's range and their combination (motor limits, the start within them, force limit above the
 *  setpoint for the scene's spring and sensitivity). @return 0 or VAFM_EINVAL, err naming the field, its value
 *  and the allowed range. */
VAFM_API int vafm_ctrl_params_validate(const vafm_ctrl_params *p, const vafm_params *scene, vafm_error *err);

/** The controller's state, as `status` shows it. */
typedef struct vafm_ctrl_status {
    int state;               /**< enum vafm_ctrl_state */
    int engage_phase;        /**< enum vafm_ctrl_engage_phase */
    int last_fail;           /**< enum vafm_ctrl_fail of the last failed engage (0: none since) */
    uint64_t sample;         /**< samples made since the start (a carried state counts on: vafm_ctrl_carry) */
    double time_s;           /**< simulated time since the start, s (carried likewise; see clock_base_s) */
    double motor_z_m;        /**< motor height, m */
    double piezo_z_m;        /**< piezo extension, m, [0, piezo_range_m] */
    double x_m, y_m;         /**< tip position over the sample, m */
    double target_x_m, target_y_m; /**< where a move goes (= x, y when none) */
    int moving;              /**< 1 while a move is under way */
    double surface_m;        /**< the surface height under the tip, m */
    double gap_m;            /**< support height above that surface, m (motor_z − piezo_z − surface) */
    int in_contact;          /**< the lever touches the sample */
    int feedback;            /**< 1: Z feedback on */
    int saturated;           /**< 1: the feedback is at an end of the piezo range */
    double setpoint_N;       /**< the force the feedback holds (absolute, N; NaN before an engage measured the
                                  baseline of a relative setpoint) */
    double baseline_N;       /**< the free baseline measured by the last engage, N */
    double error_N;          /**< the error signal setpoint − force at the last sample, N */
    double force_N;          /**< measured force at the last sample, N */
    double deflection_m;     /**< measured deflection at the last sample, m */
    double signal_V;         /**< the deflection signal at the last sample, V */
    double sum_V;            /**< photodiode sum, V */
    double invols_m_per_V;   /**< InvOLS, m/V */
    double crash_force_N;    /**< the force reached at the last crash, N (NaN: none) */
    uint64_t motor_steps;    /**< motor steps of engages since the start */
    double clock_base_s;     /**< the clock's base: time_s = clock_base_s + (sample − clock_base_sample) × the
                                  sample interval (0 and 0 unless the state was carried, vafm_ctrl_carry: the time
                                  goes on across a change of the sample rate) */
    uint64_t clock_base_sample; /**< see clock_base_s */
    uint8_t reserved[16];
} vafm_ctrl_status;

/** One block of controller samples; arrays owned by the controller, valid during the callback. */
typedef struct vafm_ctrl_samples {
    size_t n;                 /**< samples in the block */
    uint64_t first;           /**< index of the first since the start */
    const double *time_s;     /**< time since the start, s */
    const double *motor_z_m;  /**< motor height, m */
    const double *piezo_z_m;  /**< piezo extension, m */
    const double *x_m, *y_m;  /**< tip position, m */
    const double *gap_m;      /**< support height above the local surface (the live scene's), m */
    const double *deflection_m; /**< measured deflection, m */
    const double *force_N;    /**< measured force, N */
    const double *signal_V;   /**< deflection signal, V */
    const double *error_N;    /**< feedback error setpoint − force (0 with feedback off), N */
    const double *surface_m;  /**< ground truth: surface height under the tip, m */
    const uint8_t *state;     /**< enum vafm_ctrl_state after the sample */
} vafm_ctrl_samples;

/** Receives controller sample blocks; its return value is ignored (the instrument stays on). */
typedef void (*vafm_ctrl_sample_fn)(void *user, const vafm_ctrl_samples *block);

/** Create a controller over scene `scene` (the lever, contact, temperature, sample rate, detector), with
 *  settings cp (NULL: defaults) and the sample `map` (NULL: a flat uniform sample of the scene's material;
 *  else its topography, vafm_map_surface_at, on the scene's material — the map is borrowed and must outlive
 *  the controller). The scene is checked for the forces the controller can reach (up to twice force_limit_N).
 *  The lever starts free at rest (thermal) at motor_z0_m above the surface under (0, 0).
 *  @return 0, VAFM_EINVAL / VAFM_EUNSTABLE (err names the field) or VAFM_ENOMEM; *out owned by the caller. */
VAFM_API int vafm_ctrl_new(vafm_ctrl **out, const vafm_params *scene, const vafm_ctrl_params *cp,
                           const vafm_map_spec *map, vafm_error *err);

/** Carry the state of controller src into dst, a controller just made by vafm_ctrl_new over new settings (a new
 *  scene, ctrl settings or sample) that has not advanced yet: what a real instrument keeps when a setting
 *  changes. After it dst goes on where src was; destroy src then (its lever may have been handed to dst):
 *  - the clock: dst's sample count and time continue from src's (a new sample rate applies from here on and
 *    moves status.clock_base_s there; at the same rate the times are the same as without the carry);
 *  - the state (idle, approaching, engaged, withdrawing, withdrawn, crashed) and what is under way: an engage,
 *    a withdraw, a move or a `z` goes on, at the new settings' speeds (a move keeps a speed it was given);
 *    the feedback (on/off, its integrator: the piezo z; its last error), the baseline (and a start-up baseline
 *    being measured), the last failure, the crash force, the motor steps, the events not yet popped;
 *  - motor z and its target, piezo z and its target, x and y (and a move's target);
 *  - the setpoint: a relative one is the new setting over the carried baseline, an absolute one the new
 *    setting (unchanged settings: the same force);
 *  - the lever: when the scenes differ only in what the live scene does not use (the ramp, trigger, dwell, piezo
 *    model and other curve-only values) and the surface under the tip is the same, dst takes src's lever over
 *    as it is (position, velocity, contact, random stream): the session goes on bit for bit as if nothing had
 *    changed. Otherwise (another lever, temperature, rate, contact, surface...) the lever starts at thermal
 *    equilibrium at the carried support height, on the contact branch if it touched the sample, on the next
 *    random stream. The detector's chain carries (drift, 1/f noise, its noise stream) when the scene's detector
 *    settings are the same, else it restarts on that stream.
 *  What the new settings make impossible is clamped and reported as the controller's events, never silently:
 *  a piezo z beyond a smaller piezo_range_m comes to the range (VAFM_CTRL_EV_Z_SATURATED; the feedback, if on,
 *  is saturated there); x or y beyond a smaller xy_range_m comes to its edge, and a move whose target lies
 *  beyond it stops (VAFM_CTRL_EV_XY_RANGE, value: the coordinate beyond); a new surface pressing the tip further
 *  than the scene's force range (2·force_limit_N / k below the surface) is a crash (VAFM_CTRL_EV_CRASH, value:
 *  k × that depth, N; the lever starts at that depth) — a lesser one past force_limit_N is seen as a crash at the
 *  next sample as ever. Not for the hot path (though it allocates nothing).
 *  @return 0, VAFM_EINVAL (no controller, the same twice, or a support beyond ±1 m of the new surface) or
 *  VAFM_ESTATE (dst has advanced already, or is carried into), err says which: dst is then unchanged. */
VAFM_API int vafm_ctrl_carry(vafm_ctrl *dst, vafm_ctrl *src, vafm_error *err);

/** Destroy; NULL-safe; sets *c to NULL. */
VAFM_API void vafm_ctrl_destroy(vafm_ctrl **c);

/** Advance by up to max_samples output samples (the live scene's sample_rate_Hz), handing them to fn (may be
 *  NULL) in blocks. Never allocates, locks or does I/O. @return the samples made (≥ 0), or a negative VAFM_E*
 *  code (the simulation failed: an event says so and the lever restarts; the next call goes on). */
VAFM_API long vafm_ctrl_advance(vafm_ctrl *c, size_t max_samples, vafm_ctrl_sample_fn fn, void *user);

/** The output sample interval, s. */
VAFM_API double vafm_ctrl_sample_interval_s(const vafm_ctrl *c);

/** Fill st with the current state. @return 0 or VAFM_EINVAL. */
VAFM_API int vafm_ctrl_status_get(const vafm_ctrl *c, vafm_ctrl_status *st);

/** The settings in use (a copy). */
VAFM_API const vafm_ctrl_params *vafm_ctrl_params_get(const vafm_ctrl *c);

/** Pop the oldest event. @return 1 if one was popped into ev, 0 if the queue is empty. */
VAFM_API int vafm_ctrl_event_pop(vafm_ctrl *c, vafm_ctrl_event *ev);

/** Engage: the auto-approach. Baseline (relative setpoint), then repeat {extend the piezo over its range at
 *  engage_speed_m_per_s watching the setpoint; retract it; one motor step} until the setpoint is reached, then
 *  feedback on (ENGAGED). Fails (FAILED event, state IDLE, piezo retracting) on motor range or timeout; a force
 *  beyond force_limit_N is a crash. @return 0, or VAFM_ESTATE (already engaged or approaching; crashed: withdraw
 *  first). */
VAFM_API int vafm_ctrl_engage(vafm_ctrl *c);

/** Withdraw: feedback off, the piezo retracts at z_speed_m_per_s, then the motor backs off motor_steps steps
 *  (0: none); WITHDRAWN then. Interrupts an engage (FAILED, aborted) or a move. Clears a crash. @return 0 or
 *  VAFM_EINVAL (motor_steps beyond the motor's range). */
VAFM_API int vafm_ctrl_withdraw(vafm_ctrl *c, unsigned motor_steps);

/** Move the tip to (x_m, y_m) at speed_m_per_s (≤ 0: xy_speed_m_per_s) in a straight line: under feedback the
 *  piezo z follows the topography, else the support keeps its height (the gap changes with the surface).
 *  @return 0, VAFM_EINVAL (a coordinate beyond ±xy_range_m/2: refused, with an XY_RANGE event; or the speed
 *  beyond 1e-2 m/s) or VAFM_ESTATE (during an engage). */
VAFM_API int vafm_ctrl_move(vafm_ctrl *c, double x_m, double y_m, double speed_m_per_s, vafm_error *err);

/** Piezo to extension z_m at z_speed_m_per_s with the feedback off. @return 0, VAFM_EINVAL (outside
 *  [0, piezo_range_m]) or VAFM_ESTATE (during an engage or a withdraw). */
VAFM_API int vafm_ctrl_z(vafm_ctrl *c, double z_m, vafm_error *err);

/** Feedback on or off. On holds the setpoint (a relative setpoint counts from the last baseline, or, before any
 *  engage, from the free baseline at creation: the first VAFM_BASELINE_SAMPLES samples). @return 0 or VAFM_ESTATE
 *  (during an engage or a withdraw). */
VAFM_API int vafm_ctrl_feedback(vafm_ctrl *c, int on);

/** New setpoint (value, enum vafm_ctrl_unit, relative 0/1) and gains (P m/N, I m/(N·s), τ s, each as in
 *  vafm_ctrl_params; NaN keeps a value), checked as vafm_ctrl_params_validate checks them; effective at the next
 *  sample. @return 0 or VAFM_EINVAL (err names the field). */
VAFM_API int vafm_ctrl_feedback_set(vafm_ctrl *c, double setpoint, int unit, int relative, double p_m_per_N,
                                    double i_m_per_N_s, double tau_s, vafm_error *err);

/** Names: "idle", "approaching", ...; the event type ("engaged", ...) and failure reason ("motor-range",
 *  ...). @return a static string, "?" for an unknown value. */
VAFM_API const char *vafm_ctrl_state_name(int state);
VAFM_API const char *vafm_ctrl_event_name(int type);
VAFM_API const char *vafm_ctrl_fail_name(int reason);

#ifdef __cplusplus
}
#endif
#endif
