// SPDX-License-Identifier: MIT
// The reference side of the environment-equivalence test (test_env_equivalence.py): the
// unmodified controller loop (fw_loop) against the ODE emulator linked in-process, in lockstep,
// driven through its joystick input (B21R_TELEOP, deadman held) by a noisy state-feedback policy.
// The controller decides every tick (decision_ticks = 1). Writes every run as JSON: the start pose the controller asked the emulator for, and per step
// the raw joystick command in force, the executed (clamped) action, s, r, s' and terminal as the
// controller published them in its experiences. Runs after the first collision are not written:
// a bump stops the controller (safety supervisor) for several periods, so the next runs start
// from other emulator states than an environment reset gives. The learned state is also written
// as a checkpoint, with the predictions of a HEDGER loaded from it at the recorded states.
//
// usage: controller_trace <world> <corridor|obstacles> <seed> <runs> <max_steps_per_run> <out.json>
//                         <checkpoint path>
#define _POSIX_C_SOURCE 200809L
#include "fw/checkpoint.h"
#include "fw/config_task.h"
#include "fw/loop.h"
#include "fw/pubq.h"
#include "inproc_sim.h"

#include <hedger/hedger.h>
#include <rng/rng.h>
#include <tasks/decl.h>

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_TICKS 200000
#define MAX_STEPS 60000

typedef struct step_rec {
  int32_t run;
  double raw;
  b21r_experience_t e;
} step_rec_t;

typedef struct harness {
  fw_io_t inner;
  fw_io_vtable_t vt;
  double starts[64][3];
  int n_starts;
  double raw_by_tick[MAX_TICKS];
  step_rec_t steps[MAX_STEPS];
  int n_steps;
} harness_t;

static harness_t g;

// Records every start pose the controller asks for, then lets the emulator place the robot.
static int record_start(void* user, double x_m, double y_m, double theta_rad, uint64_t run) {
  (void)user;
  if (g.n_starts < 64) {
    g.starts[g.n_starts][0] = x_m;
    g.starts[g.n_starts][1] = y_m;
    g.starts[g.n_starts][2] = theta_rad;
    g.n_starts++;
  }
  return g.inner.vt->request_start_pose(g.inner.user, x_m, y_m, theta_rad, run);
}

static double clamp1(double x) { return x < -1.0 ? -1.0 : (x > 1.0 ? 1.0 : x); }

// The next joystick command from the newest state: a proportional law plus noise, with bursts of
// large random commands (they exercise the controller's acceleration clamp).
static double policy(int task, const double* s, rng_t* rng) {
  double a;
  if (task == 0) {
    a = 1.2 * s[2];  // target angle
  } else {
    a = 1.2 * s[0];  // goal bearing, bent away from a near obstacle ahead
    if (s[3] < 1.2 && fabs(s[2]) < 0.8) {
      a = s[2] > 0.0 ? -1.0 : 1.0;
    }
  }
  if (rng_uniform(rng) < 0.1) {
    return clamp1(rng_uniform_range(rng, -1.0, 1.0));
  }
  return clamp1(a + 0.3 * rng_normal(rng));
}

static void print_vec(FILE* f, const double* v, int n) {
  fputc('[', f);
  for (int i = 0; i < n; ++i) {
    fprintf(f, "%s%.17g", i ? ", " : "", v[i]);
  }
  fputc(']', f);
}

int main(int argc, char** argv) {
  if (argc != 8) {
    fprintf(stderr, "usage: %s <world> <corridor|obstacles> <seed> <runs> <max_steps_per_run> <out.json> <ckpt>\n",
            argv[0]);
    return 2;
  }
  const char* world = argv[1];
  const int task = strcmp(argv[2], "obstacles") == 0 ? 1 : 0;
  const uint64_t seed = strtoull(argv[3], NULL, 10);
  const int runs = atoi(argv[4]);
  const int max_steps = atoi(argv[5]);
  static inproc_sim_t sim;
  static sim_world_t world_map;  // large: not on the stack
  char err[FW_LOOP_ERR_MAX];
  if (sim_world_load(world, &world_map, err, sizeof err) != SIM_WORLD_OK) {
    fprintf(stderr, "controller_trace: %s\n", err);
    return 1;
  }
  const inproc_sim_options_t opt = {.canopen = false, .seed = seed, .trace_capacity = 16, .alloc_probe = NULL};
  if (inproc_sim_open(&sim, &world_map, &opt, err, sizeof err) != 0) {
    fprintf(stderr, "controller_trace: %s\n", err);
    return 1;
  }
  fw_config_t c;
  fw_config_defaults(&c);
  c.task = task;
  c.seed = seed;
  c.lockstep = true;
  c.lockstep_timeout_s = 1.0;
  c.reposition = FW_REPOSITION_EMULATOR;
  strcpy(c.emulator_control, "in-process");
  c.phase_driver = FW_DRIVER_JOYSTICK;
  c.phase_one_runs = runs + 1;
  c.eval_every_runs = 100000;
  c.max_steps_per_run = max_steps;
  // Between runs the learner's backward replay keeps the robot standing for some periods (sliced
  // work); the environment's reset repeats only the zero-command periods of a run change.
  c.hedger_replay = false;
  // A decision every tick: each experience is one control tick, the environment's step (the
  // environment has no decisions; a Learner holds them over its steps).
  c.decision_ticks = 1;
  strncpy(c.checkpoint_file, argv[7], sizeof c.checkpoint_file - 1);
  remove(argv[7]);

  g.inner = inproc_sim_io(&sim);
  g.vt = *g.inner.vt;
  g.vt.request_start_pose = record_start;
  const fw_io_t io = {&g.vt, g.inner.user};
  fw_pubq_t* q = fw_pubq_create(4096);
  fw_loop_t* loop = q != NULL ? fw_loop_create(&c, &io, &(fw_loop_outputs_t){.queue = q}, err, sizeof err)
                              : NULL;
  if (loop == NULL) {
    fprintf(stderr, "controller_trace: %s\n", err);
    return 1;
  }
  size_t meta_cap = 0, payload_cap = 0;
  fw_loop_checkpoint_capacity(loop, &meta_cap, &payload_cap);
  fw_ckpt_writer_t* ckpt = fw_ckpt_writer_create(c.checkpoint_file, meta_cap, payload_cap, err, sizeof err);
  if (ckpt == NULL || fw_loop_start(loop, err, sizeof err) != 0) {
    fprintf(stderr, "controller_trace: %s\n", err);
    return 1;
  }
  fw_loop_attach_checkpoints(loop, ckpt);

  rng_t rng;
  rng_seed(&rng, seed ^ 0x5DEECE66DULL);
  double next = 0.0;
  int64_t tick = 0;
  int finished = 0;
  int collided = 0;
  while (finished < runs && !collided && tick < MAX_TICKS - 1) {
    const int64_t t = fw_loop_wait(loop);
    ++tick;
    b21r_teleop_t m;
    memset(&m, 0, sizeof m);
    m.seq = tick;
    m.deadman = 1;
    m.rotation_radps = next;
    fw_loop_post_teleop(loop, &m, t);
    g.raw_by_tick[tick] = next;
    if (!fw_loop_tick(loop, t)) {
      break;
    }
    const fw_msg_t* msg;
    while ((msg = fw_pubq_peek(q)) != NULL) {
      if (msg->kind == FW_MSG_EXPERIENCE && g.n_steps < MAX_STEPS) {
        const b21r_experience_t* e = &msg->u.experience;
        // The experience published in tick T is the step taken in tick T - 1.
        const int64_t acted = e->utime / fw_loop_period_us(loop) - 1;
        g.steps[g.n_steps].run = e->run_id;
        g.steps[g.n_steps].raw = acted >= 1 && acted < MAX_TICKS ? g.raw_by_tick[acted] : (double)NAN;
        g.steps[g.n_steps].e = *e;
        g.n_steps++;
        next = policy(task, e->s_next, &rng);
        // A terminal step without the goal's (positive) reward is a collision.
        collided = e->terminal && !(e->reward > 0.0);
        if (e->terminal || (max_steps > 0 && e->step_id + 1 >= max_steps)) {
          finished++;
        }
      }
      fw_pubq_pop(q);
    }
  }
  fw_ckpt_writer_flush(ckpt);

  // The learned state as the controller saved it, loaded into a fresh HEDGER.
  hedger_config_t hc;
  fw_config_hedger(&c, &hc);
  size_t meta_size = 0, payload_size = 0;
  if (fw_checkpoint_peek(c.checkpoint_file, &meta_size, &payload_size, err, sizeof err) != 1) {
    fprintf(stderr, "controller_trace: no checkpoint: %s\n", err);
    return 1;
  }
  uint8_t* meta = malloc(meta_size + 1);
  uint8_t* payload = malloc(payload_size + 1);
  hedger_t* h = NULL;
  if (meta == NULL || payload == NULL ||
      fw_checkpoint_read(c.checkpoint_file, meta, meta_size + 1, &meta_size, payload, payload_size + 1, &payload_size,
                         err, sizeof err) != 1 ||
      hedger_create(&h, &hc) != HEDGER_OK || hedger_load(h, payload, payload_size) != HEDGER_OK) {
    fprintf(stderr, "controller_trace: the checkpoint does not load: %s\n", err);
    return 1;
  }

  FILE* f = fopen(argv[6], "w");
  if (f == NULL) {
    perror(argv[6]);
    return 1;
  }
  const int dim = (int)tasks_by_id(task)->state_dim;  // the task's features (without the executed rotation)
  fprintf(f, "{\"task\": \"%s\", \"seed\": %llu, \"max_steps_per_run\": %d, \"collided\": %s,\n", argv[2],
          (unsigned long long)seed, max_steps, collided ? "true" : "false");
  fprintf(f, "\"checkpoint\": \"%s\", \"store_fill\": %u,\n\"runs\": [", c.checkpoint_file, hedger_size(h));
  int32_t run = -1;
  int written_runs = 0;
  for (int i = 0; i < g.n_steps; ++i) {
    const step_rec_t* r = &g.steps[i];
    if (r->e.run_id != run) {
      if (run >= 0) {
        fprintf(f, "]}");
      }
      run = r->e.run_id;
      if (run >= g.n_starts) {
        break;
      }
      fprintf(f, "%s\n {\"start\": ", written_runs ? "," : "");
      print_vec(f, g.starts[run], 3);
      fprintf(f, ", \"steps\": [");
      written_runs++;
    }
    const b21r_experience_t* e = &r->e;
    hedger_prediction_t p;
    (void)hedger_predict(h, e->s, e->action_radps, &p);
    fprintf(f, "%s\n  {\"raw\": %.17g, \"a\": %.17g, \"r\": %.17g, \"terminal\": %s, \"q\": %.17g, \"q_kind\": %d, \"s\": ",
            r == &g.steps[0] || g.steps[i - 1].e.run_id != run ? "" : ",", r->raw, e->action_radps, e->reward,
            e->terminal ? "true" : "false", p.value, (int)p.kind);
    print_vec(f, e->s, dim);
    fprintf(f, ", \"s_next\": ");
    print_vec(f, e->s_next, dim);
    fprintf(f, ", \"learner_s\": ");  // the learner's state: the features, then what state_rotation adds
    print_vec(f, e->s, e->state_dim);
    fputc('}', f);
  }
  if (run >= 0) {
    fprintf(f, "]}");
  }
  fprintf(f, "\n]}\n");
  fclose(f);
  hedger_destroy(h);
  free(meta);
  free(payload);
  fw_ckpt_writer_destroy(ckpt);
  fw_loop_destroy(loop);
  fw_pubq_destroy(q);
  inproc_sim_close(&sim);
  printf("controller_trace: %d runs, %d steps, %d ticks%s\n", written_runs, g.n_steps, (int)tick,
         collided ? " (stopped at the first collision)" : "");
  return 0;
}
