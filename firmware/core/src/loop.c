// SPDX-License-Identifier: MIT
// The control loop: create/destroy, the tick, pacing, device start-up and shutdown.
//
// One tick reads top to bottom: sense (inputs, silence, faults, operator, the state) → safety
// (the supervisor's verdict and its reactions) → decide (the run's lifecycle and this step's
// action, run.c) → act (clamp, send) → learn (the step's update and between-run work, learning.c,
// only after the command went out) → publish (pose, scan, status).
#define _POSIX_C_SOURCE 200809L

#include "fw/loop.h"

#include "base.h"
#include "learning.h"
#include "operator.h"
#include "outputs.h"
#include "run.h"
#include "fw/config_task.h"
#include "fw/prefault.h"
#include "pi_mutex.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int64_t io_now(const fw_loop_t* L) { return L->io.vt->now_us(L->io.user); }

static bool all_finite(const double* v, uint32_t n) {
  for (uint32_t i = 0; i < n; ++i) {
    if (!isfinite(v[i])) {
      return false;
    }
  }
  return true;
}

// ---- set-up ---------------------------------------------------------------------------------

// The task as configured (fw/config_task.h): its declaration, specification, evaluation poses and
// the command limits. The configuration was validated: the task and its parameters exist.
static void setup_task(fw_loop_t* L) {
  const fw_config_t* cfg = &L->cfg;
  L->period_us = fw_config_period_us(cfg);
  L->dt_s = (double)L->period_us * 1e-6;
  L->omega_max = cfg->max_rotation_radps;
  char err[FW_CONFIG_ERR_MAX];
  (void)fw_config_task(cfg, &L->ep, &L->limits, err, sizeof err);
}

fw_loop_t* fw_loop_create(const fw_config_t* cfg, const fw_io_t* io, const fw_loop_outputs_t* out, char* err,
                          size_t err_cap) {
  if (fw_config_validate(cfg, err, err_cap) != 0) {
    return NULL;
  }
  if (io == NULL || io->vt == NULL || io->vt->now_us == NULL || io->vt->wait == NULL || io->vt->laser_poll == NULL) {
    snprintf(err, err_cap, "loop: incomplete I/O binding");
    return NULL;
  }
  fw_loop_t* L = (fw_loop_t*)calloc(1, sizeof *L);
  if (L == NULL) {
    snprintf(err, err_cap, "loop: out of memory");
    return NULL;
  }
  L->cfg = *cfg;
  L->io = *io;
  if (out != NULL) {
    L->out = *out;
  }
  setup_task(L);
  const fw_config_seeds_t seeds = fw_config_derive_seeds(cfg->seed);
  rng_seed(&L->pose_rng, seeds.pose);
  L->driver_seed_base = seeds.driver;

  if (fw_learning_init(L, err, err_cap) != 0) {
    free(L);
    return NULL;
  }
  L->save_handle = -1;
  L->held_run = -1;
  // The effective configuration as text, once, for B21R_CONFIG.
  size_t text_len = 0;
  FILE* text = open_memstream(&L->config_text, &text_len);
  if (text != NULL) {
    fw_config_print(cfg, text);
    fclose(text);
  }
  if (L->config_text == NULL) {
    snprintf(err, err_cap, "loop: out of memory");
    fw_learning_free(L);
    free(L);
    return NULL;
  }

  rflex_b21r_params_default(&L->rflex);
  L->rflex.trans_counts_per_m = cfg->distance_counts_per_m;
  L->rflex.rot_counts_per_rad = cfg->angle_counts_per_rad;
  L->rflex.trans_acc_mps2 = cfg->max_translation_accel_mps2;
  (void)rflex_host_init(&L->base, &L->rflex);
  L->drive[0].node = (uint8_t)cfg->can_node_translation;
  L->drive[1].node = (uint8_t)cfg->can_node_rotation;
  for (int i = 0; i < 2; ++i) {
    cia402_master_init(&L->drive[i].master);
    const double hb_s = cfg->can_heartbeat_timeout_s > 0.0 ? cfg->can_heartbeat_timeout_s : 1.0;
    (void)canopen_hb_init(&L->drive[i].hb, L->drive[i].node, (uint32_t)(hb_s * 1e6));
  }
  L->bump.node = (uint8_t)cfg->can_node_bumpers;
  L->bump_limit_ticks = fw_config_ticks(cfg, cfg->can_bumper_timeout_s);

  fw_pi_mutex_init(&L->mbox_mu);  // shared with the LCM receive thread
  atomic_init(&L->signal_number, 0);

  const fw_safety_config_t sc = {.lockstep = cfg->lockstep,
                                 .laser_limit_ticks = fw_config_ticks(cfg, cfg->laser_timeout_s),
                                 .base_limit_ticks = fw_config_ticks(cfg, cfg->base_timeout_s),
                                 .laser_limit_us = (int64_t)(cfg->laser_timeout_s * 1e6),
                                 .base_limit_us = (int64_t)(cfg->base_timeout_s * 1e6),
                                 .clear_ticks = cfg->safety_clear_ticks,
                                 .auto_resume = cfg->safety_auto_resume};
  fw_safety_init(&L->safety, &sc);
  fw_timing_init(&L->timing, L->period_us, (int64_t)llround(cfg->late_start_threshold_s * 1e6));
  L->mode = B21R_STATUS_T_MODE_STARTING;
  L->last_block.block = -1;
  L->status_countdown = 0;
  return L;
}

// Stack the tick may use (features, HEDGER's solver, message encoding), with a margin.
#define PREFAULT_STACK_BYTES (256U * 1024U)

// Writes the stack below the caller's frame; noinline, so that the array is below it.
static __attribute__((noinline)) void prefault_stack(void) {
  volatile uint8_t stack[PREFAULT_STACK_BYTES];
  for (size_t i = 0; i < sizeof stack; i += FW_PREFAULT_PAGE_BYTES) {
    stack[i] = 0;
  }
}

void fw_loop_prefault(fw_loop_t* L) {
  fw_prefault(L, sizeof *L);
  fw_prefault(L->agent_storage, L->agent_bytes);
  fw_prefault(L->jrec, L->jrec_cap);
  if (L->out.queue != NULL) {
    fw_pubq_prefault(L->out.queue);
  }
  if (L->out.checkpoints != NULL) {
    fw_ckpt_writer_prefault(L->out.checkpoints);
  }
  prefault_stack();
}

void fw_loop_destroy(fw_loop_t* L) {
  if (L == NULL) {
    return;
  }
  pthread_mutex_destroy(&L->mbox_mu);
  free(L->config_text);
  fw_learning_free(L);
  free(L);
}

int64_t fw_loop_period_us(const fw_loop_t* L) { return L->period_us; }

// ---- inputs ---------------------------------------------------------------------------------

static void take_scan(fw_loop_t* L) {
  const lms_scan_t* r = &L->scan_raw;
  features_scan_t* s = &L->scan;
  double angle_min = (double)r->start_angle_rad;
  double increment = (double)r->step_rad;
  uint16_t n = r->count;
  if (!r->geometry_known) {
    // Telegrams without the geometry: the configured field and resolution.
    (void)features_scan_set_lms200_geometry(s, L->cfg.laser_fov_deg, (double)L->cfg.laser_resolution_cdeg / 100.0);
    angle_min = s->angle_min_rad;
    increment = s->angle_increment_rad;
    n = n < s->n_beams ? n : s->n_beams;
  }
  (void)features_scan_fill(s, angle_min, increment, n, r->range_m, r->beam_status);
  L->have_scan = true;
  L->scan_new = true;
  L->laser_scans++;
}

// Beams with a return needed before a repeat counts as stuck: a scan of nothing but "no echo"
// (open space, a covered window) repeats legitimately.
#define LASER_STUCK_MIN_RETURNS 8U

// True when the telegram repeats the previous one's distances bit for bit (FNV-1a over the
// count and the raw values; the scan index is left out: a frozen measurement stage may sit behind
// an interface that still counts). O(beams).
static bool scan_repeated(fw_loop_t* L) {
  const lms_scan_t* r = &L->scan_raw;
  uint64_t h = 1469598103934665603ULL;
  h = (h ^ r->count) * 1099511628211ULL;
  for (uint16_t i = 0; i < r->count && i < LMS_MAX_SCAN_VALUES; ++i) {
    h = (h ^ r->raw[i]) * 1099511628211ULL;
  }
  const bool same = h == L->scan_hash && (uint32_t)(r->count - r->no_return_count) >= LASER_STUCK_MIN_RETURNS;
  L->scan_hash = h;
  return same;
}

static void poll_inputs(fw_loop_t* L, int64_t now_us) {
  const int r = L->io.vt->laser_poll(L->io.user, now_us, &L->scan_raw);
  if (r == 1 && scan_repeated(L)) {
    // Not a new scan: the command is held as without one, and a laser that only repeats itself
    // stops the base after laser_timeout_s like a silent one (safety detail: "laser stuck").
    L->scan_repeats++;
    L->laser_repeated_scans++;
    L->scan_repeat_new = true;
  } else if (r == 1) {
    L->scan_repeats = 0;
    take_scan(L);
  } else if (r < 0 && !L->laser_error_logged) {
    L->laser_error_logged = true;
    fw_loop_log(L, 2, "b21r-controller: laser device error (%d) on %s", r, L->cfg.laser_device);
  }
  fw_base_poll(L, now_us);
}

// ---- the tick -------------------------------------------------------------------------------

/// What sensing found this tick.
typedef struct sensed {
  bool running;       ///< a run is under way
  bool run_starting;  ///< repositioned, the start pose stands: a run may start on this scan
  bool state_ok;      ///< a new scan gave a usable state (running or starting)
  bool state_finite;  ///< every value of the learner's state is finite (when state_ok is computed)
  bool odo_finite;
} sensed_t;

/// A command for the base.
typedef struct command {
  double v_mps;
  double w_radps;
  bool stopping;  ///< zero, decelerating at the configured limit
} command_t;

// The binding's view of the devices: losses (a stop), devices back (their start-up again), and
// commands its output queue refused (a base fault).
static void check_devices(fw_loop_t* L, int64_t now_us) {
  L->output_overflows = 0;
  if (L->io.vt->health == NULL) {
    return;
  }
  fw_io_health_t h;
  // Lockstep cannot resume a run whose emulator is gone: the loop ends instead (no reopening).
  const bool reopen = L->cfg.device_lost_action == FW_DEVICE_LOST_REOPEN && !L->cfg.lockstep;
  L->io.vt->health(L->io.user, now_us, reopen, &h);
  if ((h.reopened & FW_IO_DEVICE_BASE) != 0U) {
    fw_base_restart(L);
  }
  if (h.reopened != 0U) {
    fw_loop_log(L, 2, "b21r-controller: %s%s%s reopened", (h.reopened & FW_IO_DEVICE_LASER) != 0U ? "laser" : "",
                h.reopened == (FW_IO_DEVICE_LASER | FW_IO_DEVICE_BASE) ? " and " : "",
                (h.reopened & FW_IO_DEVICE_BASE) != 0U ? "base" : "");
  }
  L->devices_lost = h.lost;
  if (h.lost != 0U) {
    memcpy(L->io_lost_detail, h.detail, sizeof L->io_lost_detail);
  }
  L->output_overflows = h.output_overflows + L->output_overflows_waiting;
  L->output_overflows_waiting = 0;
  L->output_overflows_total += L->output_overflows;
}

static sensed_t sense(fw_loop_t* L, int64_t now_us) {
  sensed_t in = {false, false, false, true, true};
  check_devices(L, now_us);
  poll_inputs(L, now_us);
  fw_laser_stats_t ls = {0, 0, 0};
  if (L->io.vt->laser_stats != NULL) {
    L->io.vt->laser_stats(L->io.user, &ls);
  }
  const uint64_t bad = ls.bytes_dropped + ls.crc_errors;
  if (L->scan_new) {
    L->laser_bad_at_scan = bad;
    L->laser_silent_ticks = 0;
    L->last_scan_us = now_us;
  } else {
    L->laser_silent_ticks++;
  }
  if (fw_base_any_report(L)) {
    L->base_silent_ticks = 0;
    L->last_base_us = now_us;
    (void)rflex_odom_update(&L->base.odometry);
  } else {
    L->base_silent_ticks++;
  }
  fw_base_evaluate_faults(L, now_us);
  fw_operator_drain(L, now_us);
  in.running = fw_run_running(L);
  in.run_starting = L->mode == B21R_STATUS_T_MODE_REPOSITIONING && L->pose_requested && L->settle_ticks == 0 &&
                    L->scan_new && (!L->awaiting_confirm || L->confirm_pending) && fw_learning_idle(L);
  fw_run_odometry_update(L, in.run_starting);
  if (in.run_starting) {
    tasks_episode_begin(&L->ep, L->start_pose, fw_run_odom_pose(L));  // the run's frame
  }
  if (L->scan_new && (in.running || in.run_starting)) {
    const bool usable = fw_run_observe(L, &in.state_finite);
    in.state_ok = usable && in.state_finite;
  }
  const double odo[3] = {L->base.odometry.x_m, L->base.odometry.y_m, L->base.odometry.theta_rad};
  in.odo_finite = all_finite(odo, 3);
  return in;
}

static fw_safety_event_t supervise(fw_loop_t* L, const sensed_t* in, int64_t now_us, command_t* cmd) {
  fw_safety_inputs_t si;
  memset(&si, 0, sizeof si);
  si.laser_silent_ticks = L->laser_silent_ticks;
  si.laser_repeats = L->scan_repeats;
  si.base_silent_ticks = L->base_silent_ticks;
  si.laser_age_us = now_us - L->last_scan_us;
  si.base_age_us = now_us - L->last_base_us;
  if (L->io.vt->laser_stats != NULL) {
    fw_laser_stats_t ls;
    L->io.vt->laser_stats(L->io.user, &ls);
    si.laser_bad_since_scan = ls.bytes_dropped + ls.crc_errors - L->laser_bad_at_scan;
  }
  si.device_lost = L->lockstep_lost || L->devices_lost != 0U;
  si.device_lost_detail = L->devices_lost != 0U ? L->io_lost_detail : L->device_lost_detail;
  si.base_fault = L->base_fault;
  si.base_fault_detail = L->base_fault_detail;
  si.bumper_mask = L->bumper_mask;
  si.non_finite = !in->odo_finite || (L->scan_new && (in->running || in->run_starting) && !in->state_finite) ||
                  L->policy_fault;
  si.non_finite_where =
      !in->odo_finite ? "odometry" : (L->policy_fault && in->state_finite ? "the learned policy's action" : "task state");
  L->policy_fault = false;  // an event of the last tick: reported once
  // The joystick must hold the deadman while it drives, and already in the tick its run starts.
  si.deadman_required = fw_run_joystick_drives(L) ||
                        (in->run_starting && L->cfg.mode == FW_MODE_LEARN && L->cfg.phase_driver == FW_DRIVER_JOYSTICK &&
                         learn_plan(L->agent).kind == LEARN_RUN_TRAINING && learn_plan(L->agent).phase == 1);
  si.deadman_fresh = L->teleop_deadman && now_us - L->teleop_last_us <= (int64_t)(L->cfg.teleop_timeout_s * 1e6);
  si.teleop_out_of_range = L->teleop_range_newest;
  si.teleop_range_detail = L->teleop_range_detail;
  si.signal_number = atomic_load(&L->signal_number);
  si.operator_pause = L->paused;
  si.operator_resume = L->resume_now;
  L->resume_now = false;
  const fw_safety_event_t ev = fw_safety_update(&L->safety, &si);

  if (ev == FW_SAFETY_STOP_BEGAN) {
    fw_loop_log(L, 2, "b21r-controller: SAFETY STOP (%s): %s", fw_stop_reason_name(L->safety.reason), L->safety.detail);
    if (in->running) {
      if (L->safety.reason == FW_STOP_BUMPER && L->scan_new && in->state_ok && learn_has_transition(L->agent)) {
        // A bump ends the run as a collision: its last transition is learned, then the stop.
        fw_run_step(L, 1, &cmd->v_mps, &cmd->w_radps);
      } else {
        fw_run_abort(L, B21R_RUN_T_END_SAFETY_STOP, L->safety.reason, fw_stop_reason_name(L->safety.reason));
      }
    }
    L->mode = B21R_STATUS_T_MODE_STOPPED;
    L->status_now = true;
    if (L->safety.reason == FW_STOP_SIGNAL) {
      L->done = true;
      L->exit_status = 128 + si.signal_number;
    } else if (L->safety.reason == FW_STOP_DEVICE_LOST && L->devices_lost != 0U &&
               (L->cfg.lockstep || L->cfg.device_lost_action == FW_DEVICE_LOST_EXIT)) {
      fw_loop_log(L, 2, "b21r-controller: exiting with status %d (device_lost_action = %s)", FW_EXIT_DEVICE_LOST,
                  L->cfg.lockstep ? "exit in lockstep" : "exit");
      L->done = true;
      L->exit_status = FW_EXIT_DEVICE_LOST;
    } else if (L->lockstep_lost) {
      // In lockstep the loop cannot go on without the period's data.
      L->done = true;
      L->exit_status = FW_EXIT_LOCKSTEP_TIMEOUT;
    }
  } else if (ev == FW_SAFETY_STOPPED) {
    L->mode = B21R_STATUS_T_MODE_STOPPED;
    fw_run_request_pose_while_stopped(L);
  } else if (ev == FW_SAFETY_RESUMED) {
    fw_loop_log(L, 2, "b21r-controller: safety stop cleared; repositioning for the next run");
    fw_run_begin_repositioning(L);
  }
  if (L->shutdown_requested && !L->done) {
    fw_loop_log(L, 2, "b21r-controller: operator SHUTDOWN");
    fw_run_abort(L, B21R_RUN_T_END_SHUTDOWN, 0, "operator shutdown");
    L->mode = B21R_STATUS_T_MODE_DONE;
    L->done = true;
    L->exit_status = 0;
  }
  return ev;
}

static void decide(fw_loop_t* L, fw_safety_event_t ev, const sensed_t* in, command_t* cmd) {
  cmd->stopping = true;
  if (L->safety.stopped || L->done || !(ev == FW_SAFETY_OK || ev == FW_SAFETY_RESUMED)) {
    return;
  }
  if (L->mode == B21R_STATUS_T_MODE_STARTING) {
    fw_run_begin_repositioning(L);
  }
  if (L->mode == B21R_STATUS_T_MODE_REPOSITIONING) {
    cmd->stopping = !fw_run_reposition(L, in->state_ok, &cmd->v_mps, &cmd->w_radps) || L->policy_fault;
  } else if (fw_run_running(L)) {
    if (L->scan_new && in->state_ok) {
      fw_run_step(L, 0, &cmd->v_mps, &cmd->w_radps);
      cmd->stopping = !fw_run_running(L) || L->policy_fault;
    } else {
      // No new scan (or features unusable) this tick: hold the command, learn nothing.
      L->held_ticks++;
      cmd->v_mps = L->cmd_v;
      cmd->w_radps = L->cmd_w;
      cmd->stopping = false;
    }
  }
}

static void act(fw_loop_t* L, command_t* cmd) {
  // A stop commands zero at once (the base decelerates at its own limit).
  if (cmd->stopping) {
    cmd->v_mps = 0.0;
    cmd->w_radps = 0.0;
  } else {
    // Limits; a non-finite value gives zero (the supervisor reports it next tick).
    (void)tasks_command_clamp(&L->limits, L->dt_s, L->cmd_v, L->cmd_w, &cmd->v_mps, &cmd->w_radps);
    if (fw_run_running(L)) {
      // The learner records what was executed: the clamped action.
      learn_executed(L->agent, cmd->w_radps, cmd->v_mps);
    }
  }
  fw_base_command(L, cmd->v_mps, cmd->w_radps, cmd->stopping);
  L->cmd_v = cmd->v_mps;
  L->cmd_w = cmd->w_radps;
}

static void publish(fw_loop_t* L) {
  fw_out_run_end(L);
  fw_out_pose(L);
  if (L->scan_new) {
    fw_out_scan(L);
  }
  if (--L->status_countdown <= 0 || L->status_now) {
    fw_out_status(L);
    L->status_countdown = L->cfg.status_period_ticks;
    L->status_now = false;
  }
  fw_out_release_reports(L, false);
  fw_out_notify(L);
}

bool fw_loop_tick(fw_loop_t* L, int64_t now_us) {
  L->tick_count++;
  if (!L->cfg.lockstep && L->tick_deadline_us > 0) {
    // Scheduled starts that passed before this tick started get no tick of their own: they are
    // the missed periods fw_timing_record_start counts, and the schedule skips them.
    fw_timing_record_start(&L->timing, L->tick_deadline_us, now_us);
    if (now_us >= L->next_deadline_us) {
      L->next_deadline_us += ((now_us - L->next_deadline_us) / L->period_us + 1) * L->period_us;
    }
  }
  // In lockstep, time is the emulator's: tick × period, so identical runs log identical times.
  L->utime = L->cfg.lockstep ? L->tick_count * L->period_us : now_us;
  L->data_utime = L->utime;

  const sensed_t in = sense(L, now_us);
  command_t cmd = {0.0, 0.0, true};
  const fw_safety_event_t ev = supervise(L, &in, now_us, &cmd);
  decide(L, ev, &in, &cmd);
  act(L, &cmd);
  fw_learning_after_command(L);
  publish(L);

  L->scan_new = false;
  L->scan_repeat_new = false;
  fw_base_clear_flags(L);
  L->confirm_pending = false;
  const int64_t end_us = io_now(L);
  // Overrun: the tick ended after the next scheduled start (lockstep: it took longer than a period).
  const bool overrun = L->cfg.lockstep ? (end_us - now_us > L->period_us)
                                       : (L->tick_deadline_us > 0 && end_us > L->tick_deadline_us + L->period_us);
  fw_timing_record(&L->timing, end_us - now_us, overrun);
  return !L->done;
}

// ---- pacing ---------------------------------------------------------------------------------

// lockstep_realtime_factor: holds the tick (its data has arrived; the emulator waits for the
// command) until tick k is due at k × period / factor after the first paced tick, so recorders
// over UDP keep up. The inputs are the same, only later: the experiences do not change. A slow
// tick is not caught up by bursts (the origin moves), so the rate never exceeds the cap.
static int64_t pace_lockstep(fw_loop_t* L, int64_t now) {
  const double factor = L->cfg.lockstep_realtime_factor;
  if (!(factor > 0.0) || L->lockstep_lost) {
    return now;
  }
  const int64_t step_us = (int64_t)((double)L->period_us / factor);
  if (L->pace_ticks == 0 || now > L->pace_origin_us + (L->pace_ticks + 1) * step_us) {
    L->pace_origin_us = now;  // first tick, or behind by more than a tick: restart the schedule
    L->pace_ticks = 0;
  }
  const int64_t due = L->pace_origin_us + L->pace_ticks * step_us;
  while (now < due) {
    (void)L->io.vt->wait(L->io.user, due);  // wakes early on input: wait again until due
    now = io_now(L);
  }
  L->pace_ticks++;
  return now;
}

int64_t fw_loop_wait(fw_loop_t* L) {
  int64_t now = io_now(L);
  if (L->cfg.lockstep) {
    // The tick waits for every device's data of the period, however long the machine takes:
    // a lockstep run never depends on wall time. Only a device that stays silent for
    // lockstep_timeout_s ends the loop, with its name.
    const int64_t deadline = now + (int64_t)(L->cfg.lockstep_timeout_s * 1e6);
    L->data_utime = (L->tick_count + 1) * L->period_us;  // the data awaited are the next tick's
    for (;;) {
      poll_inputs(L, now);
      if ((L->scan_new || L->scan_repeat_new) && fw_base_all_reports(L)) {
        break;
      }
      if (fw_loop_signalled(L) != 0) {
        break;  // SIGINT/SIGTERM: the tick stops the base now, not when a stalled emulator answers
      }
      if (L->io.vt->health != NULL) {
        // A device that is gone will not deliver: the tick reports it at once.
        fw_io_health_t h;
        L->io.vt->health(L->io.user, now, false, &h);
        L->output_overflows_waiting += h.output_overflows;
        if (h.lost != 0U) {
          break;
        }
      }
      if (now >= deadline) {
        fw_loop_log(L, 2, "b21r-controller: lockstep: no %s data within %.1f s (%s); the emulator stopped answering",
                    !L->scan_new ? "laser" : "base", L->cfg.lockstep_timeout_s,
                    !L->scan_new ? L->cfg.laser_device
                                 : (L->cfg.base_protocol == FW_BASE_RFLEX ? L->cfg.base_device : "CAN bus"));
        snprintf(L->device_lost_detail, sizeof L->device_lost_detail, "lockstep: no %s data within %.1f s",
                 !L->scan_new ? "laser" : "base", L->cfg.lockstep_timeout_s);
        L->lockstep_lost = true;
        break;
      }
      (void)L->io.vt->wait(L->io.user, deadline);
      now = io_now(L);
    }
    now = pace_lockstep(L, now);
    L->tick_deadline_us = now;
    return now;
  }
  if (L->next_deadline_us == 0) {
    L->next_deadline_us = now;
  }
  while (now < L->next_deadline_us) {
    (void)L->io.vt->wait(L->io.user, L->next_deadline_us);
    now = io_now(L);
    poll_inputs(L, now);
  }
  // The tick serves the oldest scheduled start (it skips those that pass before it starts).
  L->tick_deadline_us = L->next_deadline_us;
  L->next_deadline_us += L->period_us;
  return now;
}

int fw_loop_run(fw_loop_t* L) {
  for (;;) {
    const int64_t t = fw_loop_wait(L);
    if (!fw_loop_tick(L, t)) {
      break;
    }
  }
  return L->exit_status;
}

// ---- start-up and shutdown ------------------------------------------------------------------

int fw_loop_start(fw_loop_t* L, char* err, size_t err_cap) {
  fw_out_config(L);  // first in every log, even when a device does not start
  L->data_utime = L->cfg.lockstep ? L->period_us : 0;  // the start's data are the first tick's
  if (fw_base_start_signalled(L, "the start (before any device was started)", err, err_cap)) {
    return FW_LOOP_START_SIGNALLED;  // e.g. during the real-time set-up: the brake stays on
  }
  const int base_rc = fw_base_start(L, err, err_cap);
  if (base_rc != 0) {
    return base_rc;
  }
  // The first scan (the laser driver may first have to find the LMS200's baud rate) and the
  // first odometry. Real time: zero commands keep the base's watchdog fed meanwhile. Lockstep:
  // no command at all. The emulator sends the t_0 scan (and rFLEX odometry) by itself once the
  // laser streams, and every command would advance it by one period: one sent while that data is
  // still on its way would leave a second period's data in flight, which a later tick would take
  // for its own (a tick behind, by the machine's timing). The CANopen base's answers to the
  // start-up SYNCs must all be in.
  // 20 s for the devices to come up; lockstep waits at least as long as a tick waits for the
  // emulator (lockstep_timeout_s), as the CANopen enable cycles before this do.
  const int64_t start = io_now(L);
  const double limit_s = L->cfg.lockstep && L->cfg.lockstep_timeout_s > 20.0 ? L->cfg.lockstep_timeout_s : 20.0;
  const int64_t limit_us = (int64_t)(limit_s * 1e6);
  int64_t next_cmd = start;
  for (;;) {
    const int64_t now = io_now(L);
    poll_inputs(L, now);
    if (fw_base_any_report(L)) {
      (void)rflex_odom_update(&L->base.odometry);
    }
    // The arrival flags are kept: the first tick then runs at once on this data (in lockstep
    // the emulator waits for our first command before it sends more).
    if (L->have_scan && L->base.odometry.baseline && (!L->cfg.lockstep || fw_base_all_reports(L))) {
      break;
    }
    if (fw_base_start_signalled(L, L->have_scan ? "the start (waiting for the first odometry)"
                                                : "the start (waiting for the laser's first scan)",
                                err, err_cap)) {
      return FW_LOOP_START_SIGNALLED;
    }
    if (now - start > limit_us) {
      snprintf(err, err_cap, "%s: no %s within %g s (device %s); check the cable, the power and the *_device keys",
               !L->have_scan ? "laser" : "base", !L->have_scan ? "scan" : "odometry", limit_s,
               !L->have_scan ? L->cfg.laser_device
                             : (L->cfg.base_protocol == FW_BASE_RFLEX ? L->cfg.base_device : "CAN bus"));
      return -1;
    }
    if (!L->cfg.lockstep && now >= next_cmd) {
      fw_base_command(L, 0.0, 0.0, true);  // keeps the base's watchdog fed
      next_cmd = now + L->period_us;
    }
    (void)L->io.vt->wait(L->io.user, now + 20000);
  }
  L->last_scan_us = io_now(L);
  L->last_base_us = L->last_scan_us;
  L->started = true;
  return 0;
}

int fw_loop_shutdown(fw_loop_t* L) {
  fw_loop_log(L, 2, "b21r-controller: shutting down: zero command, brake set, devices off, final checkpoint");
  fw_run_abort(L, B21R_RUN_T_END_SHUTDOWN, 0, "shutdown");
  fw_base_shutdown(L);
  if (L->io.vt->laser_stop != NULL) {
    L->io.vt->laser_stop(L->io.user);
  }
  // The learned state as it is now: nothing learned is lost, even mid-run.
  fw_learning_finish_now(L);
  fw_out_run_end(L);
  fw_learning_checkpoint_now(L);
  L->mode = B21R_STATUS_T_MODE_DONE;
  L->status_now = true;
  fw_out_status(L);
  int rc = 0;
  if (L->out.checkpoints != NULL) {
    fw_ckpt_writer_flush(L->out.checkpoints);
    if (fw_ckpt_writer_counters(L->out.checkpoints).failed > 0) {
      rc = -1;
    }
  }
  fw_out_release_reports(L, true);
  fw_out_notify(L);
  return rc;
}

void fw_loop_get_stats(const fw_loop_t* L, fw_loop_stats_t* out) {
  memset(out, 0, sizeof *out);
  out->ticks = L->tick_count;
  out->steps = learn_steps(L->agent);
  out->experiences_dropped = L->exp_dropped;
  out->run_id = learn_run_id(L->agent);
  out->runs_finished = L->runs_finished;
  out->runs_aborted = L->runs_aborted;
  const learn_schedule_progress_t* sp = &learn_schedule(L->agent)->p;
  out->training_runs = sp->training_runs;
  out->eval_blocks = sp->eval_blocks;
  out->phase = sp->phase;
  out->mode = fw_out_status_mode(L);
  out->stop_reason = L->safety.reason;
  out->safety_stops = L->safety.stops;
  for (int i = 0; i < FW_STOP_REASON_COUNT; ++i) {
    out->stops_by_reason[i] = L->safety.stops_by_reason[i];
  }
  out->held_ticks = L->held_ticks;
  out->teleop_accepted = L->teleop_accepted;
  out->teleop_rejected = L->teleop_rejected;
  out->commands_accepted = L->commands_accepted;
  out->commands_rejected = L->commands_rejected;
  out->store_fill = learn_learner_stats(learn_get_learner(L->agent)).fill;
  out->done = L->done;
  out->last_block = L->last_block;
  out->best_example_steps = sp->best_example_steps;
  out->selection = learn_selection_get(L->agent);
  out->mean_example_steps = sp->example_runs > 0 ? sp->example_steps_sum / (double)sp->example_runs : 0.0;
  out->last_run_steps = L->last_run_steps;
  out->last_run_goal = L->last_run_goal;
  out->learn_ticks = L->learn_ticks;
  out->checkpoints_submitted = L->checkpoints_submitted;
  const fw_timing_t* t = &L->timing;
  out->tick_max_ever_us = t->max_ever_us;
  out->tick_overruns = t->overruns;
  out->late_max_ever_us = t->late_max_ever_us;
  out->late_starts = t->late_starts;
  out->missed_periods = t->missed_periods;
  out->gap_max_ever_us = t->gap_max_ever_us;
  out->exit_status = L->exit_status;
}
