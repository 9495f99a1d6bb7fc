// SPDX-License-Identifier: MIT
// In-process lockstep B21r for the loop-core tests (see fake_robot.h).
#define _POSIX_C_SOURCE 200809L
#include "fake_robot.h"

#include <math.h>
#include <string.h>
#include <time.h>

#define PANEL_FRONT 6  // a base bump panel (DIO 0x46)
#define FAKE_PI 3.14159265358979323846

static void push_base(fake_robot_t* f, const rflex_packet_t* p) {
  uint8_t buf[RFLEX_MAX_STUFFED_BYTES];
  const size_t n = rflex_encode(buf, sizeof buf, p, RFLEX_DEVICE_STUFFED);
  if (n > 0 && f->base_fill + n <= FAKE_BYTES) {
    memcpy(f->base_bytes + f->base_fill, buf, n);
    f->base_fill += (uint32_t)n;
  }
}

static void push_frame(fake_robot_t* f, const canopen_frame_t* fr) {
  if (f->n_frames < FAKE_FRAMES) {
    f->frame_ready_us[f->n_frames] = f->clock_us + f->can_lag_us + f->stall_extra_us;
    f->frames[f->n_frames++] = *fr;
  }
}

static bool frame_readable(const fake_robot_t* f) { return f->n_frames > 0 && f->frame_ready_us[0] <= f->clock_us; }

static void emit_scan(fake_robot_t* f) {
  if (f->laser_drop_ticks > 0) {
    f->laser_drop_ticks--;
    return;
  }
  float ranges[SYNTH_MAX_BEAMS];
  uint8_t no_return[SYNTH_MAX_BEAMS];
  const int n = synth_lidar_scan(&f->world, &f->lidar, &f->rng, f->robot.x_m, f->robot.y_m, f->robot.theta_rad, ranges,
                                 no_return, SYNTH_MAX_BEAMS);
  uint16_t* raw = f->last_raw;
  if (f->laser_stuck_ticks > 0 && f->last_n == n) {
    f->laser_stuck_ticks--;  // the same distances again
  } else {
    for (int i = 0; i < n; ++i) {
      raw[i] = no_return[i] != 0 ? lms_beam_status_raw(LMS_BEAM_NO_ECHO, 13) : lms_range_to_raw(ranges[i], LMS_UNIT_MM, 13);
    }
    f->last_n = n;
  }
  uint8_t tel[LMS_MAX_TELEGRAM_BYTES];
  const size_t len = lms_encode_scan_reply(tel, sizeof tel, raw, (size_t)n, LMS_UNIT_MM, 0, NULL, 0);
  if (len > 0 && f->laser_fill + len <= FAKE_BYTES) {
    memcpy(f->laser_bytes + f->laser_fill, tel, len);
    // Corruption: flip bytes of this telegram with the given probability (the CRC catches it).
    for (size_t i = 0; i < len; ++i) {
      if (f->corrupt_fraction > 0.0 && synth_rng_uniform(&f->rng) < f->corrupt_fraction) {
        f->laser_bytes[f->laser_fill + i] ^= 0x5A;
      }
    }
    f->laser_fill += (uint32_t)len;
    f->laser_telegrams++;
  }
}

static void emit_base(fake_robot_t* f) {
  if (f->base_silent_ticks > 0) {
    f->base_silent_ticks--;
    return;
  }
  const double pos[2] = {f->trans_pos_m * f->k_d, f->rot_pos_rad * f->k_a};
  const double vel[2] = {f->robot.v_mps * f->k_d, f->robot.omega_radps * f->k_a};
  if (!f->canopen) {
    for (uint8_t axis = 0; axis < 2; ++axis) {
      rflex_motor_report_t r;
      memset(&r, 0, sizeof r);
      r.timestamp = (uint32_t)f->ticks;
      r.axis = axis;
      r.position = f->nan_odometry ? INT32_MAX : (int32_t)lround(pos[axis]);
      r.velocity = (int32_t)lround(vel[axis]);
      rflex_packet_t p;
      (void)rflex_make_motor_report(&p, f->dev_id++, &r);
      push_base(f, &p);
    }
    return;
  }
  for (int i = 0; i < 2; ++i) {
    canopen_frame_t fr;
    const uint8_t node = (uint8_t)(i + 1);
    (void)canopen_encode_tpdo1(&fr, node, cia402_drive_statusword(&f->drive[i], true), (int32_t)lround(vel[i]));
    push_frame(f, &fr);
    (void)canopen_encode_tpdo2(&fr, node, (int32_t)lround(pos[i]));
    push_frame(f, &fr);
    (void)canopen_encode_heartbeat(&fr, node, CANOPEN_NMT_STATE_OPERATIONAL);  // one per period
    push_frame(f, &fr);
  }
}

static void push_bumpers(fake_robot_t* f) {
  if (!f->bump_operational || f->bump_absent || f->bump_silent_ticks > 0) {
    return;
  }
  canopen_frame_t fr;
  (void)cia401_encode_bumpers(&fr, CANOPEN_NODE_BUMPERS_DEFAULT, f->bump_panels);
  push_frame(f, &fr);
  f->bump_pdos++;
}

// The bump-panel node's periodic TPDO1 (its event timer is one period) and heartbeat, before the
// drives' TPDOs.
static void emit_bumpers(fake_robot_t* f) {
  if (f->bump_silent_ticks > 0) {
    f->bump_silent_ticks--;
    return;
  }
  push_bumpers(f);
  if (f->bump_hb_silent_ticks > 0) {
    f->bump_hb_silent_ticks--;
  } else if (f->bump_operational && !f->bump_absent) {
    canopen_frame_t fr;
    (void)canopen_encode_heartbeat(&fr, CANOPEN_NODE_BUMPERS_DEFAULT, CANOPEN_NMT_STATE_OPERATIONAL);
    push_frame(f, &fr);
  }
  if (f->can_stall_us > 0 && f->ticks == f->can_stall_period) {
    f->stall_extra_us = f->can_stall_us;
  }
}

static void set_bumper(fake_robot_t* f, bool pressed) {
  if (f->canopen) {
    f->bump_panels[PANEL_FRONT] = pressed ? 0x3U : 0x0U;
    push_bumpers(f);  // on change
    return;
  }
  rflex_dio_report_t d = {.timestamp = (uint32_t)f->ticks,
                          .address = (uint8_t)(RFLEX_DIO_BUMPER_FIRST + PANEL_FRONT),
                          .value = pressed ? 0x3U : 0x0U};
  rflex_packet_t p;
  (void)rflex_make_dio_report(&p, f->dev_id++, &d);
  push_base(f, &p);
}


// One control period: drive, collide, then emit the new period's data.
static void advance(fake_robot_t* f) {
  f->ticks++;
  f->stall_extra_us = 0;
  if (!f->paced) {
    f->clock_us += (int64_t)llround(f->dt_s * 1e6);
  }
  double v = f->v_cmd;
  double w = f->w_cmd;
  if (f->canopen) {
    v = cia402_drive_enabled(&f->drive[0]) ? (double)f->drive_target[0] / f->k_d : 0.0;
    w = cia402_drive_enabled(&f->drive[1]) ? (double)f->drive_target[1] / f->k_a : 0.0;
  }
  if (f->brake) {
    v = 0.0;
    w = 0.0;
  }
  const synth_robot_t before = f->robot;
  synth_drive_step(&f->robot, v, w, f->dt_s, &f->limits);
  const bool hit = synth_world_collides(&f->world, f->robot.x_m, f->robot.y_m, 0.26) != 0;
  if (hit) {
    // Contact: the body stops where it was (turning in place still happens).
    f->robot.x_m = before.x_m;
    f->robot.y_m = before.y_m;
    f->robot.v_mps = 0.0;
  }
  double dth = f->robot.theta_rad - before.theta_rad;
  while (dth > FAKE_PI) {
    dth -= 2.0 * FAKE_PI;
  }
  while (dth < -FAKE_PI) {
    dth += 2.0 * FAKE_PI;
  }
  f->rot_pos_rad += dth;
  f->trans_pos_m += hypot(f->robot.x_m - before.x_m, f->robot.y_m - before.y_m) * (f->robot.v_mps < 0.0 ? -1.0 : 1.0);
  bool pressed = hit;
  if (f->bumper_ticks > 0) {
    f->bumper_ticks--;
    pressed = true;
  }
  if (pressed != f->collided) {
    f->collided = pressed;
    set_bumper(f, pressed);
  }
  if (f->canopen) {
    for (int i = 0; i < 2; ++i) {
      if (f->drive[i].state == CIA402_FAULT) {
        // A faulted drive keeps reporting its statusword.
      }
    }
  }
  emit_scan(f);
  if (f->canopen) {
    emit_bumpers(f);
  }
  emit_base(f);
}

// CPU time of this thread: the benchmark subtracts it from the tick's CPU time, whatever else
// the machine runs.
static int64_t thread_cpu_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}

// Not inlined: the instruction budget of the firmware benchmark leaves it out by name (callgrind
// --toggle-collect=advance_timed).
__attribute__((noinline)) static void advance_timed(fake_robot_t* f) {
  const int64_t t0 = thread_cpu_ns();
  advance(f);
  f->busy_ns += thread_cpu_ns() - t0;
}

// ---- host -> device ---------------------------------------------------------------------

static void handle_host_packet(fake_robot_t* f, const rflex_packet_t* p) {
  switch (rflex_classify(p)) {
    case RFLEX_MSG_SET_DIR: {
      rflex_set_dir_t s;
      if (rflex_parse_set_dir(p, &s) != PROTO_OK) {
        return;
      }
      f->commands++;
      if (s.axis == RFLEX_AXIS_TRANS) {
        f->v_cmd = (double)s.vel_counts / f->k_d;
      } else {
        f->w_cmd = (double)s.vel_counts / f->k_a;
        if (f->streaming && !f->paced) {
          advance_timed(f);
        }
      }
      break;
    }
    case RFLEX_MSG_ODOMETRY_REQUEST: {
      uint32_t period = 0;
      uint32_t mask = 0;
      if (rflex_parse_odometry_request(p, &period, &mask) == PROTO_OK && mask != 0U && !f->streaming) {
        f->streaming = true;
        f->next_period_us = f->clock_us + (int64_t)llround(f->dt_s * 1e6);
        emit_scan(f);  // t_0
        emit_base(f);
      } else if (mask == 0U) {
        f->streaming = false;
      }
      break;
    }
    case RFLEX_MSG_BRAKE_SET:
      f->brake = true;
      break;
    case RFLEX_MSG_BRAKE_RELEASE:
      f->brake = false;
      break;
    case RFLEX_MSG_SYS_STATUS: {
      rflex_sys_status_t st = {.timestamp = (uint32_t)f->ticks, .voltage_raw = 2300U, .brake = f->brake ? 1U : 0U};
      rflex_packet_t reply;
      (void)rflex_make_sys_status(&reply, f->dev_id++, &st);
      push_base(f, &reply);
      break;
    }
    default:
      break;
  }
}

static void handle_frame(fake_robot_t* f, const canopen_frame_t* fr) {
  uint8_t node = 0;
  switch (canopen_classify(fr, &node)) {
    case CANOPEN_KIND_NMT: {
      canopen_nmt_t n;
      if (canopen_decode_nmt(fr, &n) == PROTO_OK && n.command == CANOPEN_NMT_START &&
          (n.node == 0U || n.node == CANOPEN_NODE_BUMPERS_DEFAULT) && !f->bump_operational) {
        f->bump_operational = true;
        push_bumpers(f);  // a started node sends its inputs at once
      }
      if (canopen_decode_nmt(fr, &n) == PROTO_OK && n.command == CANOPEN_NMT_START && !f->streaming && f->paced) {
        f->streaming = true;
        emit_scan(f);  // real time: the t_0 scan; TPDOs answer the SYNCs
      }
      break;
    }
    case CANOPEN_KIND_RPDO1: {
      canopen_rpdo1_t r;
      if (canopen_decode_rpdo1(fr, &r) == PROTO_OK && (r.node == 1 || r.node == 2)) {
        cia402_drive_apply_controlword(&f->drive[r.node - 1], r.controlword);
        f->drive_target[r.node - 1] = r.target_velocity;
      }
      break;
    }
    case CANOPEN_KIND_SYNC:
      f->commands++;
      if (f->paced) {
        break;  // the periods follow the clock (catch_up)
      }
      if (f->streaming) {
        advance_timed(f);
        break;
      }
      // Lockstep before streaming, as b21r-sim: time stands still and the SYNC is answered at the
      // current time; streaming starts at the SYNC that finds both drives enabled, with the t_0
      // scan and inputs first. The start's enable cycles therefore cost no period.
      if (cia402_drive_enabled(&f->drive[0]) && cia402_drive_enabled(&f->drive[1])) {
        f->streaming = true;
        emit_scan(f);
      }
      push_bumpers(f);
      emit_base(f);
      break;
    default:
      break;
  }
}

// ---- vtable -----------------------------------------------------------------------------

// Real time: the periods whose end the clock has passed.
static void catch_up(fake_robot_t* f) {
  while (f->paced && f->streaming && f->clock_us >= f->next_period_us) {
    advance_timed(f);
    f->next_period_us += (int64_t)llround(f->dt_s * 1e6);
  }
}

static int64_t v_now(void* user) {
  fake_robot_t* f = (fake_robot_t*)user;
  ++f->clock_us;  // time passes a little with every look at the clock
  catch_up(f);
  return f->clock_us;
}

static bool pending(const fake_robot_t* f) { return f->laser_fill > 0 || f->base_fill > 0 || frame_readable(f); }

static int v_wait(void* user, int64_t deadline_us) {
  fake_robot_t* f = (fake_robot_t*)user;
  if (pending(f)) {
    return 1;
  }
  if (f->n_frames > 0 && f->frame_ready_us[0] < deadline_us) {
    deadline_us = f->frame_ready_us[0];  // a lagging frame arrives first
  }
  if (f->wake != NULL && f->wake_at_us < deadline_us) {
    if (f->wake_at_us > f->clock_us) {
      f->clock_us = f->wake_at_us;
    }
    void (*wake)(void*) = f->wake;
    f->wake = NULL;
    wake(f->wake_user);
    catch_up(f);
    return 1;  // interrupted, as poll() by a signal or the handler's eventfd write
  }
  if (deadline_us > f->clock_us) {
    f->clock_us = deadline_us;  // a blocking wait that nothing interrupts
  }
  catch_up(f);
  return pending(f) ? 1 : 0;
}

static int v_laser_poll(void* user, int64_t now_us, lms_scan_t* out) {
  (void)now_us;
  fake_robot_t* f = (fake_robot_t*)user;
  int got = 0;
  const uint8_t* p = f->laser_bytes;
  size_t left = f->laser_fill;
  while (left > 0) {
    lms_event_t ev;
    const size_t k = lms_decoder_push(&f->lms_dec, p, left, &ev);
    p += k;
    left -= k;
    if (ev.kind == LMS_EVENT_TELEGRAM && ev.telegram.cmd == LMS_REPLY_VALUES &&
        lms_parse_scan(&ev.telegram, 13, out) == PROTO_OK) {
      got = 1;
    }
  }
  f->laser_fill = 0;
  return got;
}

static void v_laser_stats(void* user, fw_laser_stats_t* out) {
  const fake_robot_t* f = (const fake_robot_t*)user;
  out->bytes_dropped = f->lms_dec.counters.bytes_dropped;
  out->crc_errors = f->lms_dec.counters.bad_crc;
  out->restarts = 0;
}

static ssize_t v_base_read(void* user, uint8_t* buf, size_t cap) {
  fake_robot_t* f = (fake_robot_t*)user;
  const size_t n = f->base_fill < cap ? f->base_fill : cap;
  memcpy(buf, f->base_bytes, n);
  memmove(f->base_bytes, f->base_bytes + n, f->base_fill - n);
  f->base_fill -= (uint32_t)n;
  return (ssize_t)n;
}

static int v_base_write(void* user, const uint8_t* buf, size_t n) {
  fake_robot_t* f = (fake_robot_t*)user;
  while (n > 0) {
    rflex_packet_t p;
    bool got = false;
    const size_t k = rflex_decoder_push(&f->host_dec, buf, n, &p, &got);
    buf += k;
    n -= k;
    if (got) {
      handle_host_packet(f, &p);
    }
  }
  return 0;
}

static int v_can_read(void* user, canopen_frame_t* frame) {
  fake_robot_t* f = (fake_robot_t*)user;
  if (!frame_readable(f)) {
    return 0;
  }
  *frame = f->frames[0];
  memmove(&f->frames[0], &f->frames[1], (f->n_frames - 1U) * sizeof f->frames[0]);
  memmove(&f->frame_ready_us[0], &f->frame_ready_us[1], (f->n_frames - 1U) * sizeof f->frame_ready_us[0]);
  f->n_frames--;
  return 1;
}

static int v_can_write(void* user, const canopen_frame_t* frame) {
  handle_frame((fake_robot_t*)user, frame);
  return 0;
}

static int v_request_start_pose(void* user, double x_m, double y_m, double theta_rad, uint64_t run) {
  fake_robot_t* f = (fake_robot_t*)user;
  f->start_pose_run = run;
  f->robot.x_m = x_m;
  f->robot.y_m = y_m;
  f->robot.theta_rad = theta_rad;
  f->robot.v_mps = 0.0;
  f->robot.omega_radps = 0.0;
  f->start_pose_requests++;
  if (f->collided) {
    f->collided = false;
    set_bumper(f, false);
  }
  return 1;
}

static const fw_io_vtable_t k_rflex_vt = {
    .now_us = v_now,
    .wait = v_wait,
    .laser_poll = v_laser_poll,
    .laser_stats = v_laser_stats,
    .laser_stop = NULL,
    .base_read = v_base_read,
    .base_write = v_base_write,
    .can_read = NULL,
    .can_write = NULL,
    .request_start_pose = v_request_start_pose,
};

static const fw_io_vtable_t k_can_vt = {
    .now_us = v_now,
    .wait = v_wait,
    .laser_poll = v_laser_poll,
    .laser_stats = v_laser_stats,
    .laser_stop = NULL,
    .base_read = NULL,
    .base_write = NULL,
    .can_read = v_can_read,
    .can_write = v_can_write,
    .request_start_pose = v_request_start_pose,
};

void fake_robot_init(fake_robot_t* f, bool canopen, double dt_s, uint64_t seed) {
  memset(f, 0, sizeof *f);
  synth_world_init(&f->world);
  (void)synth_world_add_corridor(&f->world, 10.0, 2.0);
  (void)synth_lidar_config_lms200(&f->lidar, 180, 1.0);
  synth_rng_seed(&f->rng, seed);
  f->robot.x_m = 1.0;
  f->limits.acc_mps2 = 0.7;
  f->limits.acc_radps2 = 2.86;
  f->dt_s = dt_s;
  f->k_d = 103000.0;
  f->k_a = 35000.0;
  f->canopen = canopen;
  f->clock_us = 1000000;
  (void)lms_decoder_init(&f->lms_dec, LMS_ROLE_HOST, 0);
  rflex_decoder_init_role(&f->host_dec, RFLEX_ROLE_DEVICE);
  cia402_drive_init(&f->drive[0]);
  cia402_drive_init(&f->drive[1]);
}

fw_io_t fake_robot_io(fake_robot_t* f) {
  const fw_io_t io = {f->canopen ? &k_can_vt : &k_rflex_vt, f};
  return io;
}
