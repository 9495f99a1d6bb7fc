// SPDX-License-Identifier: MIT
// Kinds `explore_corridor` and `explore_goal`: learning without examples (paper Fig. 6 and
// Table I) comes down to how long random actions take to find the first reward. No learner is
// involved: until the first reward every Q-value is the same.
//
// One loop serves every task and every assumption the sensitivity study varies: the task is a
// tasks_episode_t (lib/tasks: the state from the pose, the speed policy, reward and termination)
// with the emulator's world built from the same spec (the contact test), so a new task needs only
// its entry in k_tasks below (and its kind in settings.c). Two back-ends: the idealised kinematic
// model (sim/kinematic.h, about 20 million steps a second) and the emulated B21r (sim/env.h: the
// controller's command clamp, ODE contacts, the corridor's goal declared from the laser's
// features; tens of thousands of steps a second).
#define _POSIX_C_SOURCE 200809L
#include "experiment.h"

#include <features/features.h>
#include <sim/env.h>
#include <sim/kinematic.h>
#include <sim/task_worlds.h>
#include <tasks/episode.h>
#include <tasks/tasks.h>

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const double k_pi = 3.14159265358979323846;

typedef struct explore_run {
  bool success;
  double time_s;     // robot time until the first reward (driving plus restarts), or the limit
  double driving_s;  // of which the robot drove
  int64_t episodes;  // attempts: a collision (restart) or the attempt's step limit ends one
  int64_t contacts;  // collisions (restart) or refused moves into a wall (stay)
} explore_run_t;

// ---- the tasks --------------------------------------------------------------------------------

// What the study needs of a task beyond tasks_episode_t: its specs under the settings, the paper's
// start pose, its world, and which distribution the paper drew (explore_rotation = auto).
typedef struct explore_task {
  int32_t kind;                 // exp_kind_t
  const tasks_decl_t* decl;     // the task's declaration (lib/tasks)
  exp_explore_rotation_t rotation_auto;
  bool always_walls;            // the walls are the task (corridor); else explore_arena_walls
  bool attempt_limit_default;   // explore_attempt_steps = -1: the task's step limit (else none)
  void (*specs)(const exp_settings_t* s, const fw_config_t* cfg, double dt, tasks_corridor_spec_t* c,
                tasks_obstacles_spec_t* o);
  // The paper's start pose; rng draws what that start leaves random (it may draw nothing).
  features_pose_t (*paper_start)(const exp_settings_t* s, const tasks_episode_t* ep, rng_t* rng);
} explore_task_t;

static void corridor_specs(const exp_settings_t* s, const fw_config_t* cfg, double dt,
                           tasks_corridor_spec_t* c, tasks_obstacles_spec_t* o) {
  (void)o;
  c->length_m = cfg->corridor_length_m;
  c->omega_max_radps = s->explore_omega_max_radps;
  c->dt_s = dt;
  if (cfg->max_steps_per_run > 0) {
    c->step_limit = (uint32_t)cfg->max_steps_per_run;
  }
  if (s->explore_v_wall_mps >= 0.0) {
    c->v_wall_mps = s->explore_v_wall_mps;
  }
  if (s->explore_v_mps >= 0.0) {
    c->v_centre_mps = s->explore_v_mps;
  }
  if (s->explore_goal_size_m >= 0.0) {
    c->goal_distance_m = s->explore_goal_size_m;
  }
}

// Fig. 6: on the centre line at start_x, heading uniform in the half-circle towards the goal.
static features_pose_t corridor_paper_start(const exp_settings_t* s, const tasks_episode_t* ep,
                                            rng_t* rng) {
  (void)ep;
  return (features_pose_t){s->explore_start_x_m, 0.0, rng_uniform_range(rng, -0.5 * k_pi, 0.5 * k_pi)};
}

static void goal_specs(const exp_settings_t* s, const fw_config_t* cfg, double dt, tasks_corridor_spec_t* c,
                       tasks_obstacles_spec_t* o) {
  (void)cfg;
  (void)c;
  o->n_obstacles = 0;  // "No obstacles were present"
  o->step_limit = 0;   // the time limit ends a run
  o->dt_s = dt;
  if (s->explore_v_mps >= 0.0) {
    o->v_mps = s->explore_v_mps;
  }
  if (s->explore_goal_size_m >= 0.0) {
    o->goal_radius_m = s->explore_goal_size_m;
  }
}

// Table I: start_distance from the goal, pointing straight at it (no draw).
static features_pose_t goal_paper_start(const exp_settings_t* s, const tasks_episode_t* ep,
                                        rng_t* rng) {
  (void)rng;
  const tasks_obstacles_spec_t* o = tasks_episode_spec_const(ep);
  return (features_pose_t){o->goal_x_m - s->explore_start_distance_m, o->goal_y_m, 0.0};
}

static const explore_task_t k_tasks[] = {
    {EXP_EXPLORE_CORRIDOR, &tasks_corridor_decl, EXP_ROT_UNIFORM, true, true, corridor_specs,
     corridor_paper_start},
    {EXP_EXPLORE_GOAL, &tasks_obstacles_decl, EXP_ROT_NORMAL, false, false, goal_specs, goal_paper_start},
};

// ---- the random actions -----------------------------------------------------------------------

typedef struct explore_policy {
  bool random_rotation;             // else no rotation
  bool random_translation;          // else the task's own speed
  exp_explore_rotation_t rotation;  // a random rotation's distribution (resolved: never AUTO)
  exp_explore_translation_t translation;
  int64_t hold_ticks;               // a draw is held this many periods (>= 1)
  int64_t hold_left;                // periods left of the draw in force
  double w_radps;                   // the draw in force
  double v_mps;
} explore_policy_t;

static double clip(double x, double c) { return c > 0.0 ? fmin(fmax(x, -c), c) : x; }

// Draws the next action when the one in force has run out. Order of draws: rotation, then
// translation (the paper's studies draw one rotation per period, nothing else).
static void policy_draw(explore_policy_t* p, const exp_settings_t* s, rng_t* rng) {
  if (p->hold_left > 0) {
    p->hold_left--;
    return;
  }
  p->w_radps = 0.0;
  if (p->random_rotation) {
    const double w_max = s->explore_omega_max_radps;
    const double w_sd = sqrt(s->explore_omega_variance);
    const double w_clip = s->explore_omega_clip_radps;
    p->w_radps = p->rotation == EXP_ROT_UNIFORM ? rng_uniform_range(rng, -w_max, w_max)
                                                : clip(w_sd * rng_normal(rng), w_clip);
  }
  if (p->random_translation) {
    p->v_mps = p->translation == EXP_TRANS_UNIFORM
                   ? rng_uniform_range(rng, -s->explore_v_max_mps, s->explore_v_max_mps)
                   : clip(sqrt(s->explore_v_variance) * rng_normal(rng), s->explore_v_clip_mps);
  }
  p->hold_left = p->hold_ticks - 1;
}

// ---- one run ----------------------------------------------------------------------------------

typedef struct explore_ctx {
  const exp_settings_t* s;
  const explore_task_t* task;
  tasks_corridor_spec_t corridor;
  tasks_obstacles_spec_t obstacles;
  sim_world_t world;
  bool walls;
  double dt;
  explore_policy_t policy;
} explore_ctx_t;

// The specification of the study's task (the one of c->corridor and c->obstacles it declares).
static const void* ctx_spec(const explore_ctx_t* c) {
  return c->task->decl == &tasks_corridor_decl ? (const void*)&c->corridor : (const void*)&c->obstacles;
}

static features_pose_t start_pose(const explore_ctx_t* c, tasks_episode_t* ep, rng_t* rng) {
  switch (c->s->explore_start) {
    case EXP_START_ANY_HEADING: {
      features_pose_t p = c->task->paper_start(c->s, ep, rng);
      p.theta_rad = rng_uniform_range(rng, -k_pi, k_pi);
      return p;
    }
    case EXP_START_TRAINING:
      return tasks_episode_training_start(ep, rng);
    default:
      return c->task->paper_start(c->s, ep, rng);
  }
}

// The control periods a run may drive within its time limit once penalty_s of restarts was charged.
static int64_t steps_allowed(const explore_ctx_t* c, double penalty_s) {
  return (int64_t)ceil((c->s->explore_time_limit_s - penalty_s) / c->dt);
}

// The kinematic back-end. An attempt ends at the goal, at a collision (restart) or at the
// attempt's step limit; then the robot is put back at a start pose, explore_restart_s is charged
// and the clock runs on. With explore_collision = stay a move into a wall is refused instead: the
// robot stops where it was (heading turned) and the attempt goes on.
static explore_run_t kinematic_run(explore_ctx_t* c, uint64_t seed) {
  const exp_settings_t* s = c->s;
  tasks_episode_t ep;
  tasks_episode_init(&ep, c->task->decl, ctx_spec(c));
  sim_kin_limits_t lim;
  sim_kin_limits_default(&lim);
  if (!s->explore_accel_limits) {
    lim.accel_trans_mps2 = 0.0;
    lim.accel_rot_radps2 = 0.0;
  }
  const double radius = tasks_episode_robot_radius(&ep);
  const bool stay = s->explore_collision == EXP_COLLISION_STAY;
  rng_t rng;
  rng_seed(&rng, seed);
  explore_run_t r = {false, 0.0, 0.0, 0, 0};
  double penalty_s = 0.0;
  int64_t t = 0;
  int64_t max_steps = steps_allowed(c, penalty_s);
  double state[TASKS_MAX_STATE_DIM];
  while (t < max_steps) {
    if (r.episodes > 0) {
      penalty_s += s->explore_restart_s;
      max_steps = steps_allowed(c, penalty_s);
      if (t >= max_steps) {
        break;
      }
    }
    r.episodes++;
    const features_pose_t p0 = start_pose(c, &ep, &rng);
    sim_kin_state_t k;
    sim_kin_reset(&k, p0.x_m, p0.y_m, p0.theta_rad);
    (void)tasks_episode_observe_pose(&ep, (features_pose_t){k.x_m, k.y_m, k.theta_rad}, state);
    c->policy.hold_left = 0;
    for (uint32_t steps = 1; t < max_steps; ++steps) {
      const double v_policy = tasks_episode_speed_mps(&ep);
      policy_draw(&c->policy, s, &rng);
      const double v = c->policy.random_translation ? c->policy.v_mps : v_policy;
      const sim_kin_state_t before = k;
      sim_kin_step(&k, &lim, v, c->policy.w_radps, c->dt);
      ++t;
      uint8_t contact = c->walls && sim_world_disc_collides(&c->world, k.x_m, k.y_m, radius) ? 1U : 0U;
      if (contact != 0U) {
        r.contacts++;
        if (stay) {
          // The bumper stops the base: no move into the wall, the turn stands.
          k.x_m = before.x_m;
          k.y_m = before.y_m;
          k.v_mps = 0.0;
          contact = 0U;
        }
      }
      (void)tasks_episode_observe_pose(&ep, (features_pose_t){k.x_m, k.y_m, k.theta_rad}, state);
      const tasks_outcome_t o = tasks_episode_outcome(&ep, contact, steps);
      if (o.reason == TASKS_END_GOAL) {
        r.success = true;
        r.driving_s = (double)t * c->dt;
        r.time_s = r.driving_s + penalty_s;
        return r;
      }
      if (o.end_run) {
        break;
      }
    }
  }
  r.driving_s = (double)t * c->dt;
  r.time_s = r.driving_s + penalty_s;
  return r;
}

// The ODE back-end (sim/env.h): the controller's command clamp (velocity and acceleration
// limits), the emulated base with contacts, and the goal declared from the laser's features
// (corridor) or odometry (goal task). A contact ends the attempt (the bumper); the emulator puts
// the robot at the next start pose (its two placing periods are not on the clock: only
// explore_restart_s is). Start poses are drawn as in the kinematic back-end.
static int ode_run(explore_ctx_t* c, uint64_t seed, explore_run_t* out, char* err, size_t err_cap) {
  const exp_settings_t* s = c->s;
  sim_env_config_t ec;
  sim_env_config_default(&ec, c->task->decl, SIM_ENV_ODE);
  memcpy(ec.spec, ctx_spec(c), c->task->decl->spec_size);
  if (!c->walls && c->task->decl == &tasks_obstacles_decl) {
    // The paper's open plane: an arena beyond anything a run can reach within its time limit.
    tasks_obstacles_spec_t* o = (tasks_obstacles_spec_t*)(void*)ec.spec;
    const double far_m = 10.0 + s->explore_time_limit_s * ec.limits.max_translation_mps;
    o->arena_min_x_m = o->goal_x_m - far_m;
    o->arena_max_x_m = o->goal_x_m + far_m;
    o->arena_min_y_m = o->goal_y_m - far_m;
    o->arena_max_y_m = o->goal_y_m + far_m;
  }
  // The action range: the controller clamps rotation commands to max_rotation_radps.
  ec.limits.max_rotation_radps = c->policy.rotation == EXP_ROT_UNIFORM ? s->explore_omega_max_radps
                                 : s->explore_omega_clip_radps > 0.0  ? s->explore_omega_clip_radps
                                                                      : 4.0;
  sim_env_t* env = sim_env_create(&ec, err, err_cap);
  if (env == NULL) {
    return -1;
  }
  tasks_episode_t ep;  // only to draw training starts like the kinematic back-end
  tasks_episode_init(&ep, c->task->decl, ec.spec);
  rng_t rng;
  rng_seed(&rng, seed);
  explore_run_t r = {false, 0.0, 0.0, 0, 0};
  if (sim_env_seed(env, seed) != SIM_ENV_OK) {
    snprintf(err, err_cap, "the emulator could not be created");
    sim_env_destroy(env);
    return -1;
  }
  double penalty_s = 0.0;
  int64_t t = 0;
  int64_t max_steps = steps_allowed(c, penalty_s);
  double state[TASKS_MAX_STATE_DIM];
  while (t < max_steps && !r.success) {
    if (r.episodes > 0) {
      penalty_s += s->explore_restart_s;
      max_steps = steps_allowed(c, penalty_s);
      if (t >= max_steps) {
        break;
      }
    }
    r.episodes++;
    const features_pose_t p0 = start_pose(c, &ep, &rng);
    sim_env_status_t st = sim_env_reset(env, SIM_ENV_START_POSE, 0, p0, state);
    c->policy.hold_left = 0;
    while (st == SIM_ENV_OK && t < max_steps) {
      policy_draw(&c->policy, s, &rng);
      sim_env_transition_t tr;
      st = sim_env_step(env, c->policy.w_radps, &tr);
      if (st != SIM_ENV_OK) {
        break;
      }
      ++t;
      r.contacts += tr.contact;
      if (tr.reason == TASKS_END_GOAL) {
        r.success = true;
        break;
      }
      if (tr.terminated || tr.truncated) {
        break;
      }
    }
    if (st != SIM_ENV_OK) {
      snprintf(err, err_cap, "emulator: %s (attempt %lld)", sim_env_status_str(st), (long long)r.episodes);
      sim_env_destroy(env);
      return -1;
    }
  }
  sim_env_destroy(env);
  r.driving_s = (double)t * c->dt;
  r.time_s = r.driving_s + penalty_s;
  *out = r;
  return 0;
}

static uint64_t run_seed(uint64_t seed, int32_t run) {
  uint64_t st = seed ^ ((uint64_t)(uint32_t)run * 0x9E3779B97F4A7C15ULL);
  return rng_splitmix64(&st);
}

static const char* const k_random_json[] = {"rotation", "translation", "both"};

static void write_settings(json_writer_t* w, const explore_ctx_t* c, const fw_config_t* cfg) {
  const exp_settings_t* s = c->s;
  json_num(w, "dt_s", c->dt);
  json_num(w, "time_limit_s", s->explore_time_limit_s);
  json_bool(w, "accel_limits", s->explore_accel_limits || s->explore_model == EXP_MODEL_ODE);
  json_str(w, "model", s->explore_model == EXP_MODEL_ODE ? "ode" : "kinematic");
  if (s->kind == EXP_EXPLORE_CORRIDOR) {
    json_num(w, "omega_max_radps", s->explore_omega_max_radps);
    json_num(w, "corridor_length_m", cfg->corridor_length_m);
    json_num(w, "start_x_m", s->explore_start_x_m);
  } else {
    json_num(w, "omega_variance", s->explore_omega_variance);
    json_num(w, "start_distance_m", s->explore_start_distance_m);
  }
  json_str(w, "random", k_random_json[s->explore_random]);
  const bool uniform_w = c->policy.rotation == EXP_ROT_UNIFORM;
  const bool uniform_v = c->policy.translation == EXP_TRANS_UNIFORM;
  json_str(w, "rotation", !c->policy.random_rotation ? "none" : uniform_w ? "uniform" : "normal");
  json_num(w, "omega_clip_radps", s->explore_omega_clip_radps);
  json_str(w, "translation", !c->policy.random_translation ? "policy" : uniform_v ? "uniform" : "normal");
  json_num(w, "v_max_mps", s->explore_v_max_mps);
  json_num(w, "v_variance", s->explore_v_variance);
  json_num(w, "v_clip_mps", s->explore_v_clip_mps);
  json_num(w, "hold_s", (double)c->policy.hold_ticks * c->dt);
  json_str(w, "collision", s->explore_collision == EXP_COLLISION_STAY ? "stay" : "restart");
  json_num(w, "restart_s", s->explore_restart_s);
  const bool corridor = c->task->decl == &tasks_corridor_decl;
  const uint32_t limit = corridor ? c->corridor.step_limit : c->obstacles.step_limit;
  json_int(w, "attempt_steps", limit);
  json_bool(w, "walls", c->walls);
  static const char* const starts[] = {"paper", "any_heading", "training"};
  json_str(w, "start", starts[s->explore_start]);
  if (corridor) {
    json_num(w, "v_centre_mps", c->corridor.v_centre_mps);
    json_num(w, "v_wall_mps", c->corridor.v_wall_mps);
    json_num(w, "goal_size_m", c->corridor.goal_distance_m);
  } else {
    json_num(w, "v_mps", c->obstacles.v_mps);
    json_num(w, "goal_size_m", c->obstacles.goal_radius_m);
  }
}

int exp_run_explore(const exp_settings_t* s, const fw_config_t* cfg, const exp_task_t* task, char* err,
                    size_t err_cap) {
  explore_ctx_t c;
  memset(&c, 0, sizeof c);
  c.s = s;
  for (size_t i = 0; i < sizeof k_tasks / sizeof k_tasks[0]; ++i) {
    if (k_tasks[i].kind == s->kind) {
      c.task = &k_tasks[i];
    }
  }
  if (c.task == NULL) {
    snprintf(err, err_cap, "no exploration study for this kind");
    return -1;
  }
  c.dt = (double)fw_config_period_us(cfg) * 1e-6;
  tasks_corridor_spec_default(&c.corridor);
  tasks_obstacles_spec_default(&c.obstacles);
  c.task->specs(s, cfg, c.dt, &c.corridor, &c.obstacles);
  if (s->explore_attempt_steps >= 0) {
    c.corridor.step_limit = (uint32_t)s->explore_attempt_steps;
    c.obstacles.step_limit = (uint32_t)s->explore_attempt_steps;
  } else if (!c.task->attempt_limit_default) {
    c.corridor.step_limit = 0;
    c.obstacles.step_limit = 0;
  }
  c.walls = c.task->always_walls || s->explore_arena_walls;
  if (sim_world_from_task(c.task->decl, ctx_spec(&c), &c.world) != SIM_WORLD_OK) {
    snprintf(err, err_cap, "the task's world cannot be built from these settings");
    return -1;
  }
  c.policy.random_rotation = s->explore_random != EXP_RANDOM_TRANSLATION;
  c.policy.random_translation = s->explore_random != EXP_RANDOM_ROTATION;
  c.policy.rotation = s->explore_rotation == EXP_ROT_AUTO ? c.task->rotation_auto
                                                           : (exp_explore_rotation_t)s->explore_rotation;
  c.policy.translation = (exp_explore_translation_t)s->explore_translation;
  const double hold = floor(s->explore_hold_s / c.dt + 0.5);
  c.policy.hold_ticks = hold < 1.0 ? 1 : (int64_t)hold;

  explore_run_t* runs = calloc((size_t)s->explore_runs, sizeof *runs);
  if (runs == NULL) {
    snprintf(err, err_cap, "out of memory");
    return -1;
  }
  struct timespec t0;
  struct timespec t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  for (int32_t i = 0; i < s->explore_runs; ++i) {
    const uint64_t rs = run_seed(task->seed, i);
    if (s->explore_model == EXP_MODEL_ODE) {
      if (ode_run(&c, rs, &runs[i], err, err_cap) != 0) {
        free(runs);
        return -1;
      }
    } else {
      runs[i] = kinematic_run(&c, rs);
    }
  }
  clock_gettime(CLOCK_MONOTONIC, &t1);
  char tmp[EXP_STR_MAX * 2];
  FILE* f = exp_open_result(task->out_path, tmp, sizeof tmp, err, err_cap);
  if (f == NULL) {
    free(runs);
    return -1;
  }
  json_writer_t w;
  json_begin(&w, f);
  json_object(&w, NULL);
  exp_write_header(&w, s, cfg, task);
  json_object(&w, "explore");
  json_num(&w, "wall_time_s", (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec));
  write_settings(&w, &c, cfg);
  json_array(&w, "runs");
  for (int32_t i = 0; i < s->explore_runs; ++i) {
    json_object(&w, NULL);
    json_bool(&w, "success", runs[i].success);
    json_num(&w, "time_s", runs[i].time_s);
    json_int(&w, "episodes", runs[i].episodes);
    json_num(&w, "driving_s", runs[i].driving_s);
    json_int(&w, "contacts", runs[i].contacts);
    json_end_object(&w);
  }
  json_end_array(&w);
  json_end_object(&w);
  json_end_object(&w);
  free(runs);
  return exp_commit_result(f, tmp, task->out_path, err, err_cap);
}
