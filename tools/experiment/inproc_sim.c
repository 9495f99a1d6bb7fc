// SPDX-License-Identifier: MIT
// In-process binding of the loop's I/O table to the ODE emulator (see inproc_sim.h).
#include "inproc_sim.h"

#include <stdio.h>
#include <string.h>

// Every call into the emulator goes through this, so its allocations can be counted apart.
#define SIM_CALL(s, call)                                                        \
  do {                                                                           \
    const uint64_t a0_ = (s)->opt.alloc_probe != NULL ? (s)->opt.alloc_probe() : 0; \
    call;                                                                        \
    if ((s)->opt.alloc_probe != NULL) {                                          \
      (s)->sim_allocs += (s)->opt.alloc_probe() - a0_;                           \
    }                                                                            \
  } while (0)

// Moves the emulator's pending output into the binding's buffers; true when any is waiting.
static bool pull(inproc_sim_t* s) {
  size_t n = 0;
  SIM_CALL(s, n = sim_emu_laser_read(s->emu, s->laser_buf + s->laser_fill, sizeof s->laser_buf - s->laser_fill));
  s->laser_fill += (uint32_t)n;
  if (!s->opt.canopen) {
    SIM_CALL(s, n = sim_emu_base_read(s->emu, s->base_buf + s->base_fill, sizeof s->base_buf - s->base_fill));
    s->base_fill += (uint32_t)n;
  } else {
    int got = 1;
    while (got == 1 && s->n_frames < sizeof s->frames / sizeof s->frames[0]) {
      SIM_CALL(s, got = sim_emu_can_read(s->emu, &s->frames[s->n_frames]));
      if (got == 1) {
        s->n_frames++;
      }
    }
    uint32_t errors = 0;
    SIM_CALL(s, errors = sim_emu_can_take_error_frames(s->emu));
    s->can_error_frames += errors;
    for (sim_emu_bus_event_t ev = SIM_EMU_BUS_NONE;;) {
      SIM_CALL(s, ev = sim_emu_can_take_bus_event(s->emu));
      if (ev == SIM_EMU_BUS_NONE) {
        break;
      }
      s->can_bus_off = ev == SIM_EMU_BUS_OFF;
    }
  }
  return s->laser_fill > 0 || s->base_fill > 0 || s->n_frames > 0;
}

static int64_t v_now(void* user) { return ++((inproc_sim_t*)user)->clock_us; }

static int v_wait(void* user, int64_t deadline_us) {
  inproc_sim_t* s = (inproc_sim_t*)user;
  if (pull(s)) {
    return 1;
  }
  if (deadline_us > s->clock_us) {
    s->clock_us = deadline_us;
  }
  return 0;
}

static int v_laser_poll(void* user, int64_t now_us, lms_scan_t* out) {
  (void)now_us;
  inproc_sim_t* s = (inproc_sim_t*)user;
  (void)pull(s);
  int got = 0;
  const uint8_t* p = s->laser_buf;
  size_t left = s->laser_fill;
  while (left > 0) {
    lms_event_t ev;
    const size_t k = lms_decoder_push(&s->dec, p, left, &ev);
    p += k;
    left -= k;
    if (ev.kind == LMS_EVENT_TELEGRAM && ev.telegram.cmd == LMS_REPLY_VALUES &&
        lms_parse_scan(&ev.telegram, 13, out) == PROTO_OK) {
      got = 1;
    }
  }
  s->laser_fill = 0;
  return got;
}

static void v_laser_stats(void* user, fw_laser_stats_t* out) {
  const inproc_sim_t* s = (const inproc_sim_t*)user;
  out->bytes_dropped = s->dec.counters.bytes_dropped;
  out->crc_errors = s->dec.counters.bad_crc;
  out->restarts = 0;
}

static ssize_t v_base_read(void* user, uint8_t* buf, size_t cap) {
  inproc_sim_t* s = (inproc_sim_t*)user;
  (void)pull(s);
  const size_t n = s->base_fill < cap ? s->base_fill : cap;
  memcpy(buf, s->base_buf, n);
  memmove(s->base_buf, s->base_buf + n, s->base_fill - n);
  s->base_fill -= (uint32_t)n;
  return (ssize_t)n;
}

static int v_base_write(void* user, const uint8_t* buf, size_t n) {
  inproc_sim_t* s = (inproc_sim_t*)user;
  SIM_CALL(s, sim_emu_base_write(s->emu, buf, n));
  return 0;
}

static int v_can_read(void* user, canopen_frame_t* frame) {
  inproc_sim_t* s = (inproc_sim_t*)user;
  if (s->n_frames == 0) {
    (void)pull(s);
  }
  if (s->n_frames == 0) {
    return 0;
  }
  *frame = s->frames[0];
  memmove(&s->frames[0], &s->frames[1], (s->n_frames - 1U) * sizeof s->frames[0]);
  s->n_frames--;
  return 1;
}

static void v_can_stats(void* user, fw_can_stats_t* out) {
  out->error_frames = ((const inproc_sim_t*)user)->can_error_frames;
  out->bus_off = ((const inproc_sim_t*)user)->can_bus_off;
}

static int v_can_write(void* user, const canopen_frame_t* frame) {
  inproc_sim_t* s = (inproc_sim_t*)user;
  SIM_CALL(s, sim_emu_can_write(s->emu, frame));
  return 0;
}

static int v_request_start_pose(void* user, double x_m, double y_m, double theta_rad, uint64_t run) {
  inproc_sim_t* s = (inproc_sim_t*)user;
  SIM_CALL(s, sim_emu_reset_run(s->emu, x_m, y_m, theta_rad, run));
  return 1;
}

// In one process no device can be lost: no health hook.
static const fw_io_vtable_t k_rflex = {.now_us = v_now,
                                       .wait = v_wait,
                                       .laser_poll = v_laser_poll,
                                       .laser_stats = v_laser_stats,
                                       .base_read = v_base_read,
                                       .base_write = v_base_write,
                                       .request_start_pose = v_request_start_pose};
static const fw_io_vtable_t k_can = {.now_us = v_now,
                                     .wait = v_wait,
                                     .laser_poll = v_laser_poll,
                                     .laser_stats = v_laser_stats,
                                     .can_read = v_can_read,
                                     .can_stats = v_can_stats,
                                     .can_write = v_can_write,
                                     .request_start_pose = v_request_start_pose};

fw_io_t inproc_sim_io(inproc_sim_t* s) {
  const fw_io_t io = {s->opt.canopen ? &k_can : &k_rflex, s};
  return io;
}

int inproc_sim_open(inproc_sim_t* s, const sim_world_t* world, const inproc_sim_options_t* opt, char* err,
                    size_t cap) {
  memset(s, 0, sizeof *s);
  s->opt = *opt;
  s->clock_us = 1000000;
  sim_emu_config_t cfg;
  sim_emu_config_default(&cfg);
  cfg.mode = SIM_MODE_LOCKSTEP;
  cfg.base = opt->canopen ? SIM_BASE_CANOPEN : SIM_BASE_RFLEX;
  cfg.seed = opt->seed;
  cfg.trace_capacity = opt->trace_capacity < 16 ? 16 : opt->trace_capacity;
  s->emu = sim_emu_create(world, &cfg);
  if (s->emu == NULL) {
    snprintf(err, cap, "cannot create the emulator (world '%s')", world->name);
    return -1;
  }
  (void)lms_decoder_init(&s->dec, LMS_ROLE_HOST, 0);
  uint8_t tel[16];
  const size_t n = lms_encode_start_stream(tel, sizeof tel);
  sim_emu_laser_write(s->emu, tel, n);
  return 0;
}

void inproc_sim_close(inproc_sim_t* s) {
  sim_emu_destroy(s->emu);
  s->emu = NULL;
}
