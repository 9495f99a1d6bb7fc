// SPDX-License-Identifier: MIT
// The tasks as reset/step environments over the emulated B21r (ODE) or the kinematic model.
#include "sim/env.h"

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <proto/lms200.h>
#include <proto/rflex.h>
#include <rng/rng.h>

#include "sim/emulator.h"
#include "sim/kinematic.h"
#include "sim/plant.h"
#include "sim/task_worlds.h"

#define ENV_PI 3.14159265358979323846
// Odometry and DIO report period requested from the base [µs]: the controller asks for its tick
// period (10 Hz); in lockstep the emulator reports once per period whatever the value.
#define ENV_REPORT_PERIOD_US 100000U
#define ENV_IO_BUF 4096U

struct sim_env {
  sim_env_config_t cfg;
  sim_world_t world;
  tasks_episode_t ep;
  rng_t start_rng;
  uint64_t seed;
  double dt_s;                 // control period
  // Episode.
  bool fresh;                  // no reset since the last seed: the robot was just powered up
  uint64_t episodes;           // resets since the last seed: the episode's run id, as the controller numbers runs
  bool running;                // an episode is in progress (reset done, not ended)
  uint32_t steps;
  double cmd_v;                // the command in force (what the clamp compares with)
  double cmd_w;
  double state[TASKS_MAX_STATE_DIM];
  // ODE back-end: the emulator and the controller's host side of its protocols.
  sim_emu_t* emu;
  rflex_b21r_params_t rflex;
  rflex_host_t host;
  rflex_odometry_t run_odom;   // the episode's odometry from (0, 0, 0), as the controller's run_odometry
  lms_decoder_t lms;
  lms_scan_t lms_scan;
  features_scan_t scan;
  uint8_t io[ENV_IO_BUF];
  // Kinematic back-end.
  sim_kin_state_t kin;
  sim_kin_limits_t kin_limits;
  uint32_t substeps;
  double substep_s;
  bool kin_collided;
};

static void fmt_err(char* err, size_t cap, const char* msg) {
  if (err != NULL && cap > 0U) {
    (void)snprintf(err, cap, "%s", msg);
  }
}

void sim_env_config_default(sim_env_config_t* cfg, const tasks_decl_t* task, sim_env_backend_t backend) {
  memset(cfg, 0, sizeof *cfg);
  cfg->task = task;
  cfg->backend = backend;
  if (task != NULL) {
    task->spec_default(cfg->spec);
  }
  tasks_command_limits_default(&cfg->limits);
  sim_lms_config_t lms;
  sim_lms_config_default(&lms);
  cfg->laser_noise_sigma_m = lms.noise_sigma_m;
  cfg->laser_error_code_prob = lms.error_code_prob;
}

static bool finite_pose(features_pose_t p) { return isfinite(p.x_m) && isfinite(p.y_m) && isfinite(p.theta_rad); }

static bool limits_ok(const tasks_command_limits_t* l) {
  return isfinite(l->max_translation_mps) && l->max_translation_mps > 0.0 && isfinite(l->max_rotation_radps) &&
         l->max_rotation_radps > 0.0 && isfinite(l->max_translation_accel_mps2) &&
         l->max_translation_accel_mps2 > 0.0 && isfinite(l->max_rotation_accel_radps2) &&
         l->max_rotation_accel_radps2 > 0.0;
}

// ---- ODE back-end: the host side of the protocols -----------------------------------------

static void send_rflex(sim_env_t* env, const rflex_packet_t* p) {
  uint8_t b[RFLEX_PACKET_BYTES(RFLEX_MAX_DATA)];
  const size_t n = rflex_encode(b, sizeof b, p, RFLEX_HOST_STRICT);
  sim_emu_base_write(env->emu, b, n);
}

// Reads everything the emulator sent: the newest scan into env->scan, the base's reports into
// the host view (odometry integrated when a report arrived, as the controller's tick does).
// Returns false when no complete scan or no odometry arrived.
static bool receive(sim_env_t* env) {
  bool got_scan = false;
  for (;;) {
    size_t n = sim_emu_laser_read(env->emu, env->io, sizeof env->io);
    if (n == 0U) {
      break;
    }
    const uint8_t* p = env->io;
    while (n > 0U) {
      lms_event_t ev;
      const size_t k = lms_decoder_push(&env->lms, p, n, &ev);
      p += k;
      n -= k;
      if (ev.kind == LMS_EVENT_TELEGRAM && ev.telegram.cmd == LMS_REPLY_VALUES &&
          lms_parse_scan(&ev.telegram, 13, &env->lms_scan) == PROTO_OK) {
        got_scan = true;
      }
    }
  }
  if (got_scan) {
    const lms_scan_t* r = &env->lms_scan;
    (void)features_scan_fill(&env->scan, (double)r->start_angle_rad, (double)r->step_rad, r->count, r->range_m,
                             r->beam_status);
  }
  for (;;) {
    const size_t n = sim_emu_base_read(env->emu, env->io, sizeof env->io);
    if (n == 0U) {
      break;
    }
    (void)rflex_host_feed(&env->host, env->io, n);
  }
  const bool got_odometry = env->host.report_new[0] || env->host.report_new[1];
  if (got_odometry) {
    (void)rflex_odom_update(&env->host.odometry);
  }
  (void)rflex_odom_follow(&env->run_odom, &env->host.odometry);
  env->host.report_new[0] = false;
  env->host.report_new[1] = false;
  return got_scan && got_odometry;
}

// Sends the command pair (translation, then rotation): in lockstep the rotation command ends the
// period, the emulator advances and sends the next period's data.
static bool command_period(sim_env_t* env, double v_mps, double w_radps) {
  rflex_packet_t pair[2];
  if (rflex_make_velocity(pair, &env->rflex, v_mps, w_radps, env->cfg.limits.max_translation_accel_mps2) !=
      PROTO_OK) {
    return false;
  }
  send_rflex(env, &pair[0]);
  send_rflex(env, &pair[1]);
  return receive(env);
}

static features_pose_t odom_pose(const sim_env_t* env) {
  const features_pose_t p = {env->run_odom.x_m, env->run_odom.y_m, env->run_odom.theta_rad};
  return p;
}

// Powers the emulated robot up with the controller's start-up sequence: laser stream, then the
// base (odometry reports, which starts the lockstep stream with the t_0 data, DIO reports,
// defaults, brake release, a status request).
static sim_env_status_t ode_power_up(sim_env_t* env) {
  sim_emu_destroy(env->emu);
  env->emu = NULL;
  sim_emu_config_t ec;
  sim_emu_config_default(&ec);
  ec.mode = SIM_MODE_LOCKSTEP;
  ec.base = SIM_BASE_RFLEX;
  ec.period_s = env->dt_s;
  ec.seed = env->seed;
  ec.laser.noise_sigma_m = env->cfg.laser_noise_sigma_m;
  ec.laser.error_code_prob = env->cfg.laser_error_code_prob;
  ec.rflex.params = env->rflex;
  ec.trace_capacity = 0U;
  env->emu = sim_emu_create(&env->world, &ec);
  if (env->emu == NULL) {
    return SIM_ENV_ERR_NO_MEMORY;
  }
  (void)lms_decoder_init(&env->lms, LMS_ROLE_HOST, 0);
  (void)rflex_host_init(&env->host, &env->rflex);
  uint8_t tel[16];
  sim_emu_laser_write(env->emu, tel, lms_encode_start_stream(tel, sizeof tel));
  rflex_packet_t p;
  (void)rflex_make_odometry_request(&p, ENV_REPORT_PERIOD_US, 3U);
  send_rflex(env, &p);
  (void)rflex_make_dio_request(&p, ENV_REPORT_PERIOD_US);
  send_rflex(env, &p);
  rflex_make_set_defaults(&p);
  send_rflex(env, &p);
  rflex_make_brake_release(&p);
  send_rflex(env, &p);
  rflex_make_sys_status_request(&p);
  send_rflex(env, &p);
  return receive(env) ? SIM_ENV_OK : SIM_ENV_ERR_DEVICE;
}

// ---- create / seed ------------------------------------------------------------------------

sim_env_t* sim_env_create(const sim_env_config_t* cfg, char* err, size_t err_cap) {
  if (cfg == NULL || cfg->task == NULL ||
      (cfg->backend != SIM_ENV_ODE && cfg->backend != SIM_ENV_KINEMATIC)) {
    fmt_err(err, err_cap, "sim_env: unknown task or back-end");
    return NULL;
  }
  if (!limits_ok(&cfg->limits) || !isfinite(cfg->laser_noise_sigma_m) || cfg->laser_noise_sigma_m < 0.0 ||
      !(cfg->laser_error_code_prob >= 0.0 && cfg->laser_error_code_prob <= 1.0)) {
    fmt_err(err, err_cap, "sim_env: command limits must be finite and > 0, laser noise >= 0, error-code "
                          "probability in [0, 1]");
    return NULL;
  }
  sim_env_t* env = calloc(1, sizeof *env);
  if (env == NULL) {
    fmt_err(err, err_cap, "sim_env: out of memory");
    return NULL;
  }
  env->cfg = *cfg;
  // One rotation limit, as in the controller: the clamp's is also the task's action bound.
  tasks_spec_set_omega_max(cfg->task, env->cfg.spec, cfg->limits.max_rotation_radps);
  tasks_episode_init(&env->ep, cfg->task, env->cfg.spec);
  const sim_world_status_t ws = sim_world_from_task(cfg->task, env->cfg.spec, &env->world);
  env->dt_s = tasks_spec_dt_s(cfg->task, env->cfg.spec);
  if (ws != SIM_WORLD_OK || !(env->dt_s > 0.0) || !isfinite(env->dt_s)) {
    fmt_err(err, err_cap, "sim_env: the task spec is invalid (geometry or dt_s)");
    free(env);
    return NULL;
  }
  // The base speaks the controller's conversion factors; its acceleration is the clamp's.
  rflex_b21r_params_default(&env->rflex);
  env->rflex.trans_acc_mps2 = cfg->limits.max_translation_accel_mps2;
  // The kinematic model moves like the plant: the same substep and acceleration limits.
  sim_plant_config_t pc;
  sim_plant_config_default(&pc);
  env->substep_s = pc.dt_s;
  env->substeps = (uint32_t)lround(env->dt_s / pc.dt_s);
  env->kin_limits.accel_trans_mps2 = cfg->limits.max_translation_accel_mps2;
  env->kin_limits.accel_rot_radps2 = (double)env->rflex.rot_acc_counts / env->rflex.rot_counts_per_rad;
  if (env->substeps < 1U || fabs((double)env->substeps * pc.dt_s - env->dt_s) > 1e-9) {
    fmt_err(err, err_cap, "sim_env: dt_s must be a whole multiple of the emulator's 0.01 s substep");
    free(env);
    return NULL;
  }
  const sim_env_status_t st = sim_env_seed(env, 0U);
  if (st != SIM_ENV_OK) {
    fmt_err(err, err_cap, "sim_env: cannot start the emulator");
    sim_env_destroy(env);
    return NULL;
  }
  return env;
}

void sim_env_destroy(sim_env_t* env) {
  if (env == NULL) {
    return;
  }
  sim_emu_destroy(env->emu);
  free(env);
}

sim_env_status_t sim_env_seed(sim_env_t* env, uint64_t seed) {
  if (env == NULL) {
    return SIM_ENV_ERR_INVALID_ARG;
  }
  env->seed = seed;
  uint64_t st = seed;
  rng_seed(&env->start_rng, rng_splitmix64(&st));
  memset(&env->ep.start_cycle, 0, sizeof env->ep.start_cycle);  // training starts: a new cycle
  env->fresh = true;
  env->episodes = 0;
  env->running = false;
  env->cmd_v = 0.0;
  env->cmd_w = 0.0;
  if (env->cfg.backend == SIM_ENV_ODE) {
    return ode_power_up(env);
  }
  sim_kin_reset(&env->kin, env->world.starts[0].x_m, env->world.starts[0].y_m, env->world.starts[0].theta_rad);
  return SIM_ENV_OK;
}

// ---- reset / step -------------------------------------------------------------------------

sim_env_status_t sim_env_reset(sim_env_t* env, sim_env_start_t start, uint32_t eval_index, features_pose_t pose,
                               double* state) {
  if (env == NULL || state == NULL) {
    return SIM_ENV_ERR_INVALID_ARG;
  }
  features_pose_t p;
  switch (start) {
    case SIM_ENV_START_TRAINING:
      p = tasks_episode_training_start(&env->ep, &env->start_rng);
      break;
    case SIM_ENV_START_EVAL:
      p = tasks_episode_eval_start(&env->ep, eval_index);
      break;
    case SIM_ENV_START_POSE:
      p = pose;
      break;
    default:
      return SIM_ENV_ERR_INVALID_ARG;
  }
  if (!finite_pose(p) || sim_world_disc_collides(&env->world, p.x_m, p.y_m, tasks_episode_robot_radius(&env->ep))) {
    return SIM_ENV_ERR_INVALID_ARG;
  }
  p.theta_rad = features_angle_wrap(p.theta_rad);
  int ok = 0;
  if (env->cfg.backend == SIM_ENV_ODE) {
    // The controller's ticks between runs: the one that ends the previous run commands zero, the
    // next places the robot and commands zero, the one after that starts the run.
    if (!env->fresh && !command_period(env, 0.0, 0.0)) {
      return SIM_ENV_ERR_DEVICE;
    }
    // The run id as the controller passes it: the episode's sensor noise is the controller's run's.
    sim_emu_reset_run(env->emu, p.x_m, p.y_m, p.theta_rad, env->episodes);
    if (!command_period(env, 0.0, 0.0)) {
      return SIM_ENV_ERR_DEVICE;
    }
    env->run_odom = env->host.odometry;  // the episode's odometry starts here, at (0, 0, 0)
    rflex_odom_set_pose(&env->run_odom, 0.0, 0.0, 0.0);
    tasks_episode_begin(&env->ep, p, odom_pose(env));
    ok = tasks_episode_observe(&env->ep, &env->scan, odom_pose(env), env->state);
  } else {
    sim_kin_reset(&env->kin, p.x_m, p.y_m, p.theta_rad);
    env->kin_collided = false;
    tasks_episode_begin(&env->ep, p, p);
    ok = tasks_episode_observe_pose(&env->ep, p, env->state);
  }
  env->fresh = false;
  env->episodes++;
  env->cmd_v = 0.0;
  env->cmd_w = 0.0;
  env->steps = 0U;
  env->running = ok != 0;
  memcpy(state, env->state, sizeof env->state[0] * env->ep.state_dim);
  return SIM_ENV_OK;
}

sim_env_status_t sim_env_step(sim_env_t* env, double omega_radps, sim_env_transition_t* out) {
  if (env == NULL || out == NULL || !isfinite(omega_radps)) {
    return SIM_ENV_ERR_INVALID_ARG;
  }
  if (!env->running) {
    return SIM_ENV_ERR_STATE;
  }
  // The controller's command: the task's speed for the newest state, the action, then the clamp.
  double v = tasks_episode_speed_mps(&env->ep);
  double w = omega_radps;
  (void)tasks_command_clamp(&env->cfg.limits, env->dt_s, env->cmd_v, env->cmd_w, &v, &w);
  uint8_t contact = 0U;
  int ok = 0;
  if (env->cfg.backend == SIM_ENV_ODE) {
    if (!command_period(env, v, w)) {
      env->running = false;
      return SIM_ENV_ERR_DEVICE;
    }
    contact = env->host.bumper_mask != 0U ? 1U : 0U;
    ok = tasks_episode_observe(&env->ep, &env->scan, odom_pose(env), env->state);
  } else {
    for (uint32_t i = 0U; i < env->substeps; ++i) {
      sim_kin_step(&env->kin, &env->kin_limits, v, w, env->substep_s);
    }
    const double r = tasks_episode_robot_radius(&env->ep);
    contact = sim_world_disc_collides(&env->world, env->kin.x_m, env->kin.y_m, r) ? 1U : 0U;
    env->kin_collided = env->kin_collided || contact != 0U;
    const features_pose_t p = {env->kin.x_m, env->kin.y_m, env->kin.theta_rad};
    ok = tasks_episode_observe_pose(&env->ep, p, env->state);
  }
  env->cmd_v = v;
  env->cmd_w = w;
  env->steps++;
  const tasks_outcome_t o = tasks_episode_outcome(&env->ep, contact, env->steps);
  memset(out, 0, sizeof *out);
  memcpy(out->state, env->state, sizeof env->state[0] * env->ep.state_dim);
  out->reward = o.reward;
  out->terminated = o.terminal;
  out->truncated = (uint8_t)(o.end_run != 0U && o.terminal == 0U ? 1U : 0U);
  out->reason = o.reason;
  out->contact = contact;
  out->state_ok = (uint8_t)(ok != 0 ? 1U : 0U);
  if (!ok && o.end_run == 0U) {
    out->truncated = 1U;
  }
  out->action_radps = w;
  out->translation_mps = v;
  out->steps = env->steps;
  env->running = out->terminated == 0U && out->truncated == 0U;
  return SIM_ENV_OK;
}

double sim_env_driver_action(const sim_env_t* env, tasks_driver_t* driver) {
  return tasks_episode_driver_action(&env->ep, driver);
}

// ---- inspection ---------------------------------------------------------------------------

void sim_env_get_truth(const sim_env_t* env, sim_env_truth_t* out) {
  memset(out, 0, sizeof *out);
  if (env->cfg.backend == SIM_ENV_ODE) {
    sim_plant_state_t s;
    sim_emu_state(env->emu, &s);
    out->pose.x_m = s.x_m;
    out->pose.y_m = s.y_m;
    out->pose.theta_rad = s.theta_rad;
    out->odom_pose = tasks_episode_pose_in_task(&env->ep, odom_pose(env));
    out->v_mps = s.v_mps;
    out->omega_radps = s.omega_radps;
    out->collided = (uint8_t)(s.collided != 0 ? 1U : 0U);
    out->time_s = s.t_s;
    return;
  }
  out->pose.x_m = env->kin.x_m;
  out->pose.y_m = env->kin.y_m;
  out->pose.theta_rad = env->kin.theta_rad;
  out->odom_pose = out->pose;
  out->v_mps = env->kin.v_mps;
  out->omega_radps = env->kin.omega_radps;
  out->collided = (uint8_t)(env->kin_collided ? 1U : 0U);
}

size_t sim_env_laser_view(sim_env_t* env, double* angle_min_rad, double* increment_rad, double* ranges_m,
                          size_t cap) {
  if (env->cfg.backend == SIM_ENV_ODE) {
    const features_scan_t* s = &env->scan;
    const size_t n = s->n_beams < cap ? s->n_beams : cap;
    *angle_min_rad = s->angle_min_rad;
    *increment_rad = s->angle_increment_rad;
    for (size_t i = 0U; i < n; ++i) {
      ranges_m[i] = s->no_return[i] != 0U ? (double)NAN : (double)s->ranges_m[i];
    }
    return n;
  }
  // Kinematic: an ideal scan (no noise, every beam to the first solid) from the true pose.
  const tasks_episode_t* ep = &env->ep;
  const features_laser_mount_t* m = tasks_episode_laser_mount(ep);
  const double c = cos(env->kin.theta_rad), s = sin(env->kin.theta_rad);
  const double lx = env->kin.x_m + c * m->x_m - s * m->y_m;
  const double ly = env->kin.y_m + s * m->x_m + c * m->y_m;
  const size_t n = cap < 181U ? cap : 181U;
  *angle_min_rad = -0.5 * ENV_PI;
  *increment_rad = ENV_PI / 180.0;
  for (size_t i = 0U; i < n; ++i) {
    const double r = sim_world_raycast(&env->world, lx, ly,
                                       env->kin.theta_rad + m->yaw_rad + *angle_min_rad + (double)i * *increment_rad,
                                       FEATURES_LMS200_MAX_VALID_RANGE_M);
    ranges_m[i] = isfinite(r) ? r : (double)NAN;
  }
  return n;
}

const sim_world_t* sim_env_world(const sim_env_t* env) { return &env->world; }

const tasks_episode_t* sim_env_episode(const sim_env_t* env) { return &env->ep; }

const sim_env_config_t* sim_env_get_config(const sim_env_t* env) { return &env->cfg; }

void sim_env_state_bounds(const sim_env_t* env, double* low, double* high) {
  tasks_episode_state_bounds(&env->ep, low, high);
}

const char* sim_env_status_str(sim_env_status_t status) {
  switch (status) {
    case SIM_ENV_OK:
      return "ok";
    case SIM_ENV_ERR_INVALID_ARG:
      return "invalid argument";
    case SIM_ENV_ERR_STATE:
      return "no episode in progress (call reset first; an ended episode needs a new reset)";
    case SIM_ENV_ERR_DEVICE:
      return "the emulator sent no scan or odometry for a period";
    case SIM_ENV_ERR_NO_MEMORY:
      return "out of memory";
  }
  return "unknown status";
}
