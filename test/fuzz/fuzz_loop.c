// SPDX-License-Identifier: MIT
// The loop fixture of the loop fuzz targets (see fuzz_loop.h).
#include "fuzz_loop.h"

#include "fuzz_util.h"

#include <tasks/decl.h>

#include <math.h>

static fuzz_loop_t* self(void* user) { return (fuzz_loop_t*)user; }

static const fw_io_vtable_t* fake_vt(fuzz_loop_t* fl) { return fake_robot_io(&fl->fake).vt; }

// The binding: the fake's functions, the base input from fl->input when set.
static int64_t w_now(void* u) { return fake_vt(self(u))->now_us(&self(u)->fake); }
static int w_wait(void* u, int64_t deadline_us) { return fake_vt(self(u))->wait(&self(u)->fake, deadline_us); }
static int w_laser_poll(void* u, int64_t now_us, lms_scan_t* out) {
  return fake_vt(self(u))->laser_poll(&self(u)->fake, now_us, out);
}
static void w_laser_stats(void* u, fw_laser_stats_t* out) { fake_vt(self(u))->laser_stats(&self(u)->fake, out); }
static ssize_t w_base_read(void* u, uint8_t* buf, size_t cap) {
  fuzz_loop_t* fl = self(u);
  return fl->input.base_read != NULL ? fl->input.base_read(fl->input.user, buf, cap)
                                     : fuzz_loop_fake_base_read(fl, buf, cap);
}
static int w_base_write(void* u, const uint8_t* buf, size_t n) {
  return fake_vt(self(u))->base_write(&self(u)->fake, buf, n);
}
static int w_can_read(void* u, canopen_frame_t* frame) {
  fuzz_loop_t* fl = self(u);
  return fl->input.can_read != NULL ? fl->input.can_read(fl->input.user, frame) : fuzz_loop_fake_can_read(fl, frame);
}
static int w_can_write(void* u, const canopen_frame_t* frame) {
  return fake_vt(self(u))->can_write(&self(u)->fake, frame);
}
static int w_start_pose(void* u, double x_m, double y_m, double theta_rad, uint64_t run) {
  return fake_vt(self(u))->request_start_pose(&self(u)->fake, x_m, y_m, theta_rad, run);
}

ssize_t fuzz_loop_fake_base_read(fuzz_loop_t* fl, uint8_t* buf, size_t cap) {
  return fake_vt(fl)->base_read(&fl->fake, buf, cap);
}

int fuzz_loop_fake_can_read(fuzz_loop_t* fl, canopen_frame_t* frame) {
  return fake_vt(fl)->can_read(&fl->fake, frame);
}

void fuzz_loop_config(fw_config_t* cfg, bool canopen) {
  fw_config_defaults(cfg);
  cfg->lockstep = true;
  cfg->lockstep_timeout_s = 1.0;
  cfg->reposition = FW_REPOSITION_EMULATOR;
  strcpy(cfg->emulator_control, "fake");
  strcpy(cfg->lcm_url, "none");
  cfg->base_protocol = canopen ? FW_BASE_CANOPEN : FW_BASE_RFLEX;
  cfg->task = (int32_t)tasks_obstacles_decl.id;
  cfg->laser_fov_deg = 100;
  cfg->queue_capacity = 16;
  cfg->status_period_ticks = 5;
  // The learner at its cheapest: the targets fuzz the loop's inputs, not the learning.
  cfg->hedger_capacity = 256;
  cfg->hedger_k_min = 2;
  cfg->hedger_k_max = 4;
  cfg->hedger_greedy_actions = 2;
  cfg->hedger_replay = false;
  cfg->phase_one_runs = 100000;
  cfg->phase_two_runs = 100000;
  cfg->eval_every_runs = 3;
  cfg->eval_starts = 2;
  cfg->max_steps_per_run = 40;
}

static void open_loop(fuzz_loop_t* fl, const fw_config_t* cfg) {
  memset(fl, 0, sizeof *fl);
  fl->cfg = *cfg;
  fake_robot_init(&fl->fake, cfg->base_protocol == FW_BASE_CANOPEN, 1.0 / cfg->tick_rate_hz, cfg->seed);
  FUZZ_CHECK(synth_lidar_config_lms200(&fl->fake.lidar, cfg->laser_fov_deg, 1.0) == 0);
  fl->vt = (fw_io_vtable_t){.now_us = w_now,
                            .wait = w_wait,
                            .laser_poll = w_laser_poll,
                            .laser_stats = w_laser_stats,
                            .request_start_pose = w_start_pose};
  if (cfg->base_protocol == FW_BASE_CANOPEN) {
    fl->vt.can_read = w_can_read;
    fl->vt.can_write = w_can_write;
  } else {
    fl->vt.base_read = w_base_read;
    fl->vt.base_write = w_base_write;
  }
  fl->q = fw_pubq_create((uint32_t)cfg->queue_capacity);
  FUZZ_CHECK(fl->q != NULL);
  const fw_io_t io = {&fl->vt, fl};
  const fw_loop_outputs_t out = {.queue = fl->q};
  char err[FW_LOOP_ERR_MAX];
  fl->loop = fw_loop_create(&fl->cfg, &io, &out, err, sizeof err);
  if (fl->loop == NULL || fw_loop_start(fl->loop, err, sizeof err) != 0) {
    fprintf(stderr, "fuzz_loop: %s\n", err);
    abort();
  }
}

bool fuzz_loop_ready(fuzz_loop_t* fl, const fw_config_t* cfg, const fuzz_base_input_t* input) {
  const bool fresh = fl->loop == NULL || fl->done;
  if (fresh) {
    fuzz_loop_close(fl);
    open_loop(fl, cfg);
  }
  fl->input = input != NULL ? *input : (fuzz_base_input_t){NULL, NULL, NULL};
  return fresh;
}

// Whatever the input, the base is commanded finite values within the configured limits (plus
// the rounding of the wire encodings: the rFLEX 0x1B workaround moves a value by <= 128 counts).
static void check_commands(const fuzz_loop_t* fl) {
  const fake_robot_t* f = &fl->fake;
  double v = f->v_cmd;
  double w = f->w_cmd;
  if (f->canopen) {
    v = (double)f->drive_target[0] / f->k_d;
    w = (double)f->drive_target[1] / f->k_a;
  }
  FUZZ_CHECK(isfinite(v) && isfinite(w));
  FUZZ_CHECK(fabs(v) <= fl->cfg.max_translation_mps + 130.0 / f->k_d);
  FUZZ_CHECK(fabs(w) <= fl->cfg.max_rotation_radps + 130.0 / f->k_a);
}

bool fuzz_loop_tick(fuzz_loop_t* fl) {
  if (fl->done) {
    return false;
  }
  const int64_t t = fw_loop_wait(fl->loop);
  fl->done = !fw_loop_tick(fl->loop, t);
  while (fw_pubq_peek(fl->q) != NULL) {
    fw_pubq_pop(fl->q);
  }
  check_commands(fl);
  fw_loop_stats_t st;
  fw_loop_get_stats(fl->loop, &st);
  FUZZ_CHECK(st.stop_reason >= 0 && st.stop_reason < FW_STOP_REASON_COUNT && st.mode >= 0 && st.mode <= 6);
  FUZZ_CHECK(st.phase == 1 || st.phase == 2);
  return !fl->done;
}

void fuzz_loop_close(fuzz_loop_t* fl) {
  fw_loop_destroy(fl->loop);
  fw_pubq_destroy(fl->q);
  fl->loop = NULL;
  fl->q = NULL;
}
