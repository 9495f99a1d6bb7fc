// SPDX-License-Identifier: MIT
// The emulated B21r: plant and devices in lockstep or real time, faults, trace, control text.
#include "sim/emulator.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <rng/rng.h>

#define SIM_EMU_FROZEN_SLOTS 4   // PDOs of the hung node kept (TPDO1..TPDO4)
#define SIM_EMU_BABBLE_HZ 4000.0  // frames per second of a babbling node: half a 500 kbit/s bus
#define SIM_EMU_BABBLE_BURST 64U  // at most this many babble frames per read burst (bounded work)
#define SIM_EMU_BABBLE_COB 0x001U // a high-priority identifier: it wins every arbitration

struct sim_emu {
  sim_emu_config_t cfg;
  sim_plant_t* plant;
  sim_lms_t* laser;
  sim_rflex_t* rflex;
  sim_cia402_t* cia402;
  sim_cia401_t* bumpers;  // the CANopen base's bump-panel input node
  uint32_t substeps_per_period;
  uint64_t substeps_in_period;  // real time: substeps since the last trace point
  bool streaming;               // lockstep: time advances on cycle ends
  // Faults.
  double noise_laser;  // per byte of the laser line: line noise or a framing error
  double noise_base;   // the same on the rFLEX line
  double latency_s;
  int forced_panel;  // -1 = none
  rng_t corrupt_rng;
  // CAN bus faults (what a real bus does: its CRC never lets a damaged frame through).
  double can_error_fraction;  // a frame's transmission fails its CRC: error frame, retransmission
  double can_drop_fraction;   // a frame is lost (the receiver's buffer overran)
  uint32_t can_error_frames;  // error frames signalled, not yet taken by the transport
  bool bus_off;               // the host's CAN controller is off the bus: it sends and receives nothing
  double bus_off_until_s;     // simulated time its restart brings it back
  bool bus_off_pending;       // the bus-off error frame is yet to be taken by the transport
  bool bus_restart_pending;   // the restart's error frame likewise
  uint8_t stuck_node;         // 0 = none: the node whose application hangs
  double stuck_until_s;
  canopen_frame_t frozen[SIM_EMU_FROZEN_SLOTS];  // its PDOs as they were when it hung
  size_t n_frozen;
  uint8_t babble_id_node;     // 0 = none: a node floods the bus with high-priority frames
  double babble_until_s;
  double babble_next_s;       // simulated time of its next frame
  uint64_t babble_frames;
  // Trace.
  sim_trace_point_t* trace;
  size_t trace_len;
  uint32_t run;
};

void sim_emu_config_default(sim_emu_config_t* cfg) {
  cfg->mode = SIM_MODE_LOCKSTEP;
  cfg->base = SIM_BASE_RFLEX;
  cfg->period_s = 0.1;
  cfg->seed = 1;
  sim_plant_config_default(&cfg->plant);
  sim_lms_config_default(&cfg->laser);
  sim_rflex_config_default(&cfg->rflex);
  sim_cia402_config_default(&cfg->cia402);
  sim_cia401_config_default(&cfg->cia401);
  cfg->trace_capacity = 200000;
}

static double now(const sim_emu_t* e) {
  sim_plant_state_t s;
  sim_plant_get_state(e->plant, &s);
  return s.t_s;
}

static void laser_scan(void* user, double angle_min_rad, double increment_rad, size_t n,
                       double* out_m) {
  sim_emu_t* e = user;
  sim_plant_scan(e->plant, angle_min_rad, increment_rad, n, e->cfg.laser.max_range_m, out_m);
}

sim_emu_t* sim_emu_create(const sim_world_t* world, const sim_emu_config_t* cfg) {
  if (world == NULL || cfg == NULL || !(cfg->period_s > 0.0) || !isfinite(cfg->period_s) ||
      !(cfg->plant.dt_s > 0.0)) {
    return NULL;
  }
  const double ratio = cfg->period_s / cfg->plant.dt_s;
  const double steps = nearbyint(ratio);
  if (steps < 1.0 || steps > 100000.0 || fabs(ratio - steps) > 1e-9 * steps) {
    return NULL;
  }
  sim_emu_t* e = calloc(1, sizeof(*e));
  if (e == NULL) {
    return NULL;
  }
  e->cfg = *cfg;
  e->substeps_per_period = (uint32_t)steps;
  e->forced_panel = -1;
  uint64_t sm = cfg->seed;
  const bool paced = cfg->mode == SIM_MODE_REALTIME;
  e->cfg.laser.paced = paced;
  e->cfg.laser.seed = rng_splitmix64(&sm);
  e->cfg.rflex.paced = paced;
  rng_seed(&e->corrupt_rng, rng_splitmix64(&sm));
  e->plant = sim_plant_create(world, &e->cfg.plant);
  e->laser = sim_lms_create(&e->cfg.laser, &laser_scan, e);
  if (cfg->base == SIM_BASE_RFLEX) {
    e->rflex = sim_rflex_create(&e->cfg.rflex);
  } else {
    e->cia402 = sim_cia402_create(&e->cfg.cia402);
    e->bumpers = sim_cia401_create(&e->cfg.cia401);
  }
  if (cfg->trace_capacity > 0) {
    e->trace = calloc(cfg->trace_capacity, sizeof(*e->trace));
  }
  if (e->plant == NULL || e->laser == NULL || (e->rflex == NULL && (e->cia402 == NULL || e->bumpers == NULL)) ||
      (cfg->trace_capacity > 0 && e->trace == NULL)) {
    sim_emu_destroy(e);
    return NULL;
  }
  return e;
}

void sim_emu_destroy(sim_emu_t* e) {
  if (e == NULL) {
    return;
  }
  sim_lms_destroy(e->laser);
  sim_rflex_destroy(e->rflex);
  sim_cia402_destroy(e->cia402);
  sim_cia401_destroy(e->bumpers);
  sim_plant_destroy(e->plant);
  free(e->trace);
  free(e);
}

// ---- plant <-> devices -----------------------------------------------------------------------

static void apply_command(sim_emu_t* e, double t_s) {
  double v = 0.0, w = 0.0;
  sim_kin_limits_t lim;
  if (e->rflex != NULL) {
    sim_rflex_command_t c;
    sim_rflex_get_command(e->rflex, t_s, &c);
    v = c.v_mps;
    w = c.omega_radps;
    lim.accel_trans_mps2 = c.accel_trans_mps2;
    lim.accel_rot_radps2 = c.accel_rot_radps2;
  } else {
    sim_cia402_command_t c;
    sim_cia402_get_command(e->cia402, t_s, &c);
    v = c.v_mps;
    w = c.omega_radps;
    lim.accel_trans_mps2 = c.accel_trans_mps2;
    lim.accel_rot_radps2 = c.accel_rot_radps2;
  }
  sim_plant_set_limits(e->plant, &lim);
  sim_plant_set_command(e->plant, v, w);
}

_Static_assert(SIM_RFLEX_PANELS == CIA401_BUMP_PANELS, "one panel numbering for both bases");

// The 14 bump panels' segment bits, numbered as on the rFLEX base (0..5 upper enclosure, 6..13
// base skirt): the plant's contact and the injected `fault bumper`. Both bases report these.
static void bump_panels(const sim_emu_t* e, const sim_plant_state_t* s, uint8_t panels[SIM_RFLEX_PANELS]) {
  memset(panels, 0, SIM_RFLEX_PANELS);
  if (s->bumper_panel >= 0) {
    panels[6 + s->bumper_panel] = s->bumper_bits;  // base skirt panels follow the 6 upper ones
  }
  if (e->forced_panel >= 0) {
    panels[e->forced_panel] |= 0x0FU;
  }
}

static void rflex_sample(const sim_emu_t* e, sim_rflex_sample_t* out) {
  sim_plant_state_t s;
  sim_plant_get_state(e->plant, &s);
  memset(out, 0, sizeof(*out));
  out->odo_trans_m = s.odo_trans_m;
  out->odo_rot_rad = s.odo_rot_rad;
  out->odo_trans_at_reset_m = s.odo_trans_at_reset_m;
  out->odo_rot_at_reset_rad = s.odo_rot_at_reset_rad;
  out->v_mps = s.v_mps;
  out->omega_radps = s.omega_radps;
  bump_panels(e, &s, out->panels);
}

// CANopen: the bump-panel node sees the panels at t_s (it sends on change, by event timer and
// its heartbeats).
static void poll_bumpers(sim_emu_t* e, double t_s) {
  sim_plant_state_t s;
  sim_plant_get_state(e->plant, &s);
  uint8_t panels[SIM_RFLEX_PANELS];
  bump_panels(e, &s, panels);
  sim_cia401_poll(e->bumpers, panels, t_s);
}

static void cia402_sample(const sim_emu_t* e, sim_cia402_sample_t* out) {
  sim_plant_state_t s;
  sim_plant_get_state(e->plant, &s);
  out->pos_trans_m = s.odo_trans_m;
  out->pos_rot_rad = s.odo_rot_rad;
  out->pos_trans_at_reset_m = s.odo_trans_at_reset_m;
  out->pos_rot_at_reset_rad = s.odo_rot_at_reset_rad;
  out->v_mps = s.v_mps;
  out->omega_radps = s.omega_radps;
}

static void record(sim_emu_t* e) {
  if (e->trace == NULL || e->trace_len >= e->cfg.trace_capacity) {
    return;
  }
  sim_plant_state_t s;
  sim_plant_get_state(e->plant, &s);
  sim_trace_point_t* p = &e->trace[e->trace_len++];
  p->t_s = s.t_s;
  p->x_m = s.x_m;
  p->y_m = s.y_m;
  p->theta_rad = s.theta_rad;
  p->run = e->run;
  p->collided = (uint8_t)s.collided;
}

// ---- lockstep --------------------------------------------------------------------------------

// Streaming needs the laser stream and the base's reports: rFLEX odometry on; CANopen both
// drives operational and (to start) enabled. A drive fault after the start does not stop time,
// so the controller keeps receiving scans while it handles the fault.
static bool stream_conditions(const sim_emu_t* e, bool starting) {
  if (!sim_lms_streaming(e->laser)) {
    return false;
  }
  if (e->rflex != NULL) {
    return sim_rflex_odometry_on(e->rflex);
  }
  return starting ? sim_cia402_ready(e->cia402) : sim_cia402_operational(e->cia402);
}

static void emit_period_data(sim_emu_t* e) {
  const double t = now(e);
  sim_lms_emit_scan(e->laser, t);
  if (e->rflex != NULL) {
    sim_rflex_sample_t s;
    rflex_sample(e, &s);
    sim_rflex_emit_odometry(e->rflex, &s, t);
  } else {
    // The period's bump-panel PDO is read before the drives' TPDOs (sim_emu_can_read drains the
    // node first), so the tick that has the period's odometry also has its bumpers.
    poll_bumpers(e, t);
    sim_cia402_sample_t s;
    cia402_sample(e, &s);
    sim_cia402_emit_tpdos(e->cia402, &s, t);
  }
}

static void advance_period(sim_emu_t* e) {
  for (uint32_t i = 0; i < e->substeps_per_period; ++i) {
    apply_command(e, now(e));
    sim_plant_step(e->plant, 1);
  }
  if (e->cia402 != NULL) {
    sim_cia402_poll(e->cia402, now(e));  // heartbeats, RPDO watchdog
  }
  record(e);
}

// Streaming starts as soon as both conditions hold, with the t_0 data, and needs no command: the
// host's first command (rFLEX velocity pair, CANopen SYNC) is the one that ends period 0. rFLEX
// sends the t_0 scan and odometry. CANopen sends the t_0 scan and the bump-panel inputs, not the
// drives' TPDOs: those answer SYNCs only, one TPDO1 and one TPDO2 per drive and SYNC, so that the
// host can match every answer to its SYNC; time has not moved since the last answer.
static void lockstep_check_start(sim_emu_t* e) {
  const bool cond = stream_conditions(e, !e->streaming);
  if (!cond) {
    e->streaming = false;
    return;
  }
  if (e->streaming) {
    return;
  }
  e->streaming = true;
  record(e);
  if (e->rflex != NULL) {
    emit_period_data(e);
  } else {
    const double t = now(e);
    sim_lms_emit_scan(e->laser, t);
    poll_bumpers(e, t);
  }
}

// ---- host input ------------------------------------------------------------------------------

void sim_emu_laser_write(sim_emu_t* e, const uint8_t* bytes, size_t n) {
  sim_lms_feed(e->laser, bytes, n, now(e));
  if (e->cfg.mode == SIM_MODE_LOCKSTEP) {
    lockstep_check_start(e);
  }
}

void sim_emu_base_write(sim_emu_t* e, const uint8_t* bytes, size_t n) {
  if (e->rflex == NULL) {
    return;
  }
  while (n > 0) {
    int cycle_end = 0;
    const size_t k = sim_rflex_feed(e->rflex, bytes, n, now(e), &cycle_end);
    bytes += k;
    n -= k;
    apply_command(e, now(e));
    if (e->cfg.mode != SIM_MODE_LOCKSTEP) {
      continue;
    }
    lockstep_check_start(e);
    if (cycle_end && e->streaming) {
      advance_period(e);
      emit_period_data(e);
    }
  }
}

void sim_emu_can_write(sim_emu_t* e, const canopen_frame_t* f) {
  if (e->cia402 == NULL || (e->bus_off && now(e) < e->bus_off_until_s)) {
    return;  // a controller off the bus sends nothing
  }
  const double t = now(e);
  sim_cia401_feed(e->bumpers, f, t);
  if (canopen_classify(f, NULL) == CANOPEN_KIND_NMT) {
    poll_bumpers(e, t);  // a started node sends its inputs at once
  }
  const sim_cia402_event_t ev = sim_cia402_feed(e->cia402, f, t);
  apply_command(e, t);
  if (e->cfg.mode != SIM_MODE_LOCKSTEP) {
    if (ev == SIM_CIA402_EV_SYNC) {
      sim_cia402_sample_t s;
      cia402_sample(e, &s);
      sim_cia402_emit_tpdos(e->cia402, &s, t);
    }
    return;
  }
  if (e->streaming && !stream_conditions(e, false)) {
    e->streaming = false;
  }
  if (ev != SIM_CIA402_EV_SYNC) {
    return;
  }
  if (e->streaming) {
    advance_period(e);
    emit_period_data(e);
    return;
  }
  // Not streaming: the answer at the current time. If the drives were enabled last (the laser
  // already streams), streaming starts here: the t_0 scan and inputs go first, time stands still.
  lockstep_check_start(e);
  if (!e->streaming) {
    poll_bumpers(e, t);
  }
  sim_cia402_sample_t s;
  cia402_sample(e, &s);
  sim_cia402_emit_tpdos(e->cia402, &s, t);
}

// ---- device output ---------------------------------------------------------------------------

// A disturbed serial line: each byte is hit with probability `fraction`; half the hits flip bits
// (noise within the frame), half are framing errors (the stop bit read as 0), which a Linux tty
// without IGNPAR or PARMRK delivers as a NUL byte.
static void corrupt(sim_emu_t* e, double fraction, uint8_t* bytes, size_t n) {
  if (!(fraction > 0.0)) {
    return;
  }
  for (size_t i = 0; i < n; ++i) {
    if (rng_uniform(&e->corrupt_rng) < fraction) {
      if (rng_uniform(&e->corrupt_rng) < 0.5) {
        bytes[i] = 0x00U;
      } else {
        bytes[i] ^= (uint8_t)(1U + rng_below(&e->corrupt_rng, 255U));
      }
    }
  }
}

size_t sim_emu_laser_read(sim_emu_t* e, uint8_t* out, size_t cap) {
  const size_t n = sim_lms_drain(e->laser, out, cap, now(e));
  corrupt(e, e->noise_laser, out, n);
  return n;
}

size_t sim_emu_base_read(sim_emu_t* e, uint8_t* out, size_t cap) {
  if (e->rflex == NULL) {
    return 0;
  }
  const size_t n = sim_rflex_drain(e->rflex, out, cap, now(e));
  corrupt(e, e->noise_base, out, n);
  return n;
}

// A node whose application hangs: its CAN controller keeps answering SYNCs from the transmit
// buffers, which hold the last PDOs it wrote (stale values); its heartbeat and EMCY producer
// stops. Returns false when the frame is not sent.
static bool stuck_node_filter(sim_emu_t* e, canopen_frame_t* f) {
  uint8_t node = 0;
  const canopen_kind_t kind = canopen_classify(f, &node);
  if (e->stuck_node == 0U || node != e->stuck_node || !(now(e) < e->stuck_until_s)) {
    return true;
  }
  if (kind == CANOPEN_KIND_HEARTBEAT || kind == CANOPEN_KIND_EMCY) {
    return false;
  }
  for (size_t i = 0; i < e->n_frozen; ++i) {
    if (e->frozen[i].id == f->id) {
      *f = e->frozen[i];
      return true;
    }
  }
  if (e->n_frozen < SIM_EMU_FROZEN_SLOTS) {
    e->frozen[e->n_frozen++] = *f;  // the value it hung with
  }
  return true;
}

// A babbling node: while it sends, it wins every arbitration, so its frames come first; it sends
// at SIM_EMU_BABBLE_HZ of simulated time (bounded: no burst is longer than SIM_EMU_BABBLE_BURST).
static bool babble_frame(sim_emu_t* e, canopen_frame_t* f) {
  const double t = now(e);
  if (e->babble_id_node == 0U || !(t < e->babble_until_s) || e->babble_next_s > t) {
    return false;
  }
  if (t - e->babble_next_s > (double)SIM_EMU_BABBLE_BURST / SIM_EMU_BABBLE_HZ) {
    e->babble_next_s = t - (double)SIM_EMU_BABBLE_BURST / SIM_EMU_BABBLE_HZ;  // the bus had no more room
  }
  e->babble_next_s += 1.0 / SIM_EMU_BABBLE_HZ;
  memset(f, 0, sizeof(*f));
  f->id = SIM_EMU_BABBLE_COB;
  f->dlc = 8;
  for (int i = 0; i < 8; ++i) {
    f->data[i] = (uint8_t)(e->babble_frames >> (8 * (i % 4)));
  }
  e->babble_frames++;
  return true;
}

int sim_emu_can_read(sim_emu_t* e, canopen_frame_t* f) {
  if (e->cia402 == NULL) {
    return 0;
  }
  if (e->bus_off) {
    if (now(e) < e->bus_off_until_s) {
      // Off the bus the host receives nothing; the nodes' frames go by unheard.
      while (sim_cia401_drain(e->bumpers, f) || sim_cia402_drain(e->cia402, f)) {
      }
      return 0;
    }
    e->bus_off = false;
    e->bus_restart_pending = true;
  }
  if (babble_frame(e, f)) {
    return 1;
  }
  // The bump-panel node first: in lockstep its PDO of a period then precedes the drives' TPDOs.
  for (;;) {
    if (!sim_cia401_drain(e->bumpers, f) && !sim_cia402_drain(e->cia402, f)) {
      return 0;
    }
    if (e->babble_id_node != 0U && now(e) < e->babble_until_s) {
      continue;  // the babbler holds the bus: the other nodes' frames never win arbitration
    }
    if (!stuck_node_filter(e, f)) {
      continue;
    }
    if (e->can_drop_fraction > 0.0 && rng_uniform(&e->corrupt_rng) < e->can_drop_fraction) {
      continue;
    }
    // A bit error fails the receivers' CRC check: they signal an error frame and the sender
    // retransmits the same frame (error passive after 16 failures in a row: it then gets through
    // or the bus is switched off; here it gets through). No damaged payload is ever delivered.
    for (int tries = 0; tries < 16 && e->can_error_fraction > 0.0 &&
                        rng_uniform(&e->corrupt_rng) < e->can_error_fraction;
         ++tries) {
      e->can_error_frames++;
    }
    return 1;
  }
}

sim_emu_bus_event_t sim_emu_can_take_bus_event(sim_emu_t* e) {
  if (e->bus_off_pending) {
    e->bus_off_pending = false;
    return SIM_EMU_BUS_OFF;
  }
  if (e->bus_restart_pending) {
    e->bus_restart_pending = false;
    return SIM_EMU_BUS_RESTARTED;
  }
  return SIM_EMU_BUS_NONE;
}

uint32_t sim_emu_can_take_error_frames(sim_emu_t* e) {
  const uint32_t n = e->can_error_frames;
  e->can_error_frames = 0;
  return n;
}

// ---- real time -------------------------------------------------------------------------------

void sim_emu_run_until(sim_emu_t* e, double t_s) {
  if (e->cfg.mode != SIM_MODE_REALTIME) {
    return;
  }
  const double dt = e->cfg.plant.dt_s;
  sim_plant_state_t s;
  sim_plant_get_state(e->plant, &s);
  uint64_t step = s.substeps;
  while ((double)(step + 1U) * dt <= t_s) {
    apply_command(e, (double)step * dt);
    sim_plant_step(e->plant, 1);
    ++step;
    const double t = (double)step * dt;
    sim_lms_poll(e->laser, t);
    if (e->rflex != NULL) {
      sim_rflex_sample_t rs;
      rflex_sample(e, &rs);
      sim_rflex_poll(e->rflex, &rs, t);
    } else {
      sim_cia402_poll(e->cia402, t);
      poll_bumpers(e, t);
    }
    if (++e->substeps_in_period >= e->substeps_per_period) {
      e->substeps_in_period = 0;
      record(e);
    }
  }
  // Devices with their own clocks (the laser's mirror, the line) also see the time in between.
  sim_lms_poll(e->laser, t_s);
}

double sim_emu_time(const sim_emu_t* e) { return now(e); }

bool sim_emu_streaming(const sim_emu_t* e) {
  return e->cfg.mode == SIM_MODE_LOCKSTEP ? e->streaming : sim_lms_streaming(e->laser);
}

void sim_emu_state(const sim_emu_t* e, sim_plant_state_t* out) { sim_plant_get_state(e->plant, out); }

void sim_emu_reset(sim_emu_t* e, double x_m, double y_m, double theta_rad) {
  sim_plant_reset(e->plant, x_m, y_m, theta_rad);
  ++e->run;
  record(e);
}

void sim_emu_reset_run(sim_emu_t* e, double x_m, double y_m, double theta_rad, uint64_t run_stream) {
  uint64_t st = e->cfg.laser.seed ^ (run_stream * 0x9E3779B97F4A7C15ULL + 0xD1B54A32D192ED03ULL);
  sim_lms_reseed(e->laser, rng_splitmix64(&st));
  sim_emu_reset(e, x_m, y_m, theta_rad);
}

double sim_emu_latency_s(const sim_emu_t* e) { return e->latency_s; }

sim_lms_t* sim_emu_laser(sim_emu_t* e) { return e->laser; }
sim_rflex_t* sim_emu_rflex(sim_emu_t* e) { return e->rflex; }
sim_cia402_t* sim_emu_cia402(sim_emu_t* e) { return e->cia402; }
sim_cia401_t* sim_emu_cia401(sim_emu_t* e) { return e->bumpers; }
sim_plant_t* sim_emu_plant(sim_emu_t* e) { return e->plant; }

const sim_trace_point_t* sim_emu_trace(const sim_emu_t* e, size_t* n_points) {
  *n_points = e->trace_len;
  return e->trace;
}

int sim_emu_write_svg(const sim_emu_t* e, const char* path) {
  char title[96];
  (void)snprintf(title, sizeof(title), "%u run(s), %.1f s simulated", e->run + 1U, now(e));
  return sim_svg_write(path, sim_plant_world(e->plant), e->trace, e->trace_len,
                       sim_plant_get_config(e->plant)->robot_radius_m, title);
}

// ---- control text ----------------------------------------------------------------------------

#define SPLIT_TOKEN_CAP 512  // longest token kept (paths for `svg`), including the NUL

// Splits line into at most cap whitespace-separated tokens (copied into storage).
static size_t split(const char* line, char storage[][SPLIT_TOKEN_CAP], size_t cap) {
  size_t n = 0;
  const char* p = line;
  while (*p != '\0' && n < cap) {
    while (*p == ' ' || *p == '\t' || *p == '\r' || *p == '\n') {
      ++p;
    }
    if (*p == '\0') {
      break;
    }
    size_t k = 0;
    while (*p != '\0' && *p != ' ' && *p != '\t' && *p != '\r' && *p != '\n') {
      if (k + 1 < SPLIT_TOKEN_CAP) {
        storage[n][k++] = *p;
      }
      ++p;
    }
    storage[n][k] = '\0';
    ++n;
  }
  return n;
}

static bool number(const char* s, double* out) {
  char* end = NULL;
  errno = 0;
  const double v = strtod(s, &end);
  if (end == s || *end != '\0' || errno == ERANGE || !isfinite(v)) {
    return false;
  }
  *out = v;
  return true;
}

// A decimal unsigned 64-bit integer, digits only.
static bool unsigned_number(const char* s, uint64_t* out) {
  if (*s < '0' || *s > '9') {
    return false;
  }
  char* end = NULL;
  errno = 0;
  const unsigned long long v = strtoull(s, &end, 10);
  if (*end != '\0' || errno == ERANGE) {
    return false;
  }
  *out = (uint64_t)v;
  return true;
}

static sim_emu_ctrl_t reply_error(char* reply, size_t cap, const char* why) {
  (void)snprintf(reply, cap, "error %s", why);
  return SIM_EMU_CTRL_ERROR;
}

static sim_emu_ctrl_t reply_ok(char* reply, size_t cap) {
  (void)snprintf(reply, cap, "ok");
  return SIM_EMU_CTRL_OK;
}

static sim_emu_ctrl_t control_fault(sim_emu_t* e, char tok[][SPLIT_TOKEN_CAP], size_t n, char* reply,
                                    size_t cap) {
  if (n == 2 && strcmp(tok[1], "clear") == 0) {
    sim_lms_set_silent_until(e->laser, 0.0);
    if (e->rflex != NULL) {
      sim_rflex_set_silent_until(e->rflex, 0.0);
    } else {
      sim_cia402_set_silent_until(e->cia402, 0.0);
      sim_cia401_set_silent_until(e->bumpers, 0.0);
    }
    sim_lms_set_stuck_until(e->laser, 0.0);
    e->noise_laser = 0.0;
    e->noise_base = 0.0;
    e->can_error_fraction = 0.0;
    e->can_drop_fraction = 0.0;
    e->stuck_node = 0;
    e->n_frozen = 0;
    e->babble_id_node = 0;
    if (e->bus_off) {
      e->bus_off = false;
      e->bus_restart_pending = true;
    }
    e->latency_s = 0.0;
    e->forced_panel = -1;
    return reply_ok(reply, cap);
  }
  if (n == 4 && (strcmp(tok[1], "node_stuck") == 0 || strcmp(tok[1], "babble") == 0)) {
    uint64_t node = 0;
    double ms = 0.0;
    if (e->cia402 == NULL) {
      return reply_error(reply, cap, "node_stuck and babble need the canopen base");
    }
    if (!unsigned_number(tok[2], &node) || node < 1U || node > 127U || !number(tok[3], &ms) || ms < 0.0) {
      return reply_error(reply, cap, "usage: fault node_stuck|babble <node 1..127> <ms>");
    }
    if (tok[1][0] == 'n') {
      e->stuck_node = (uint8_t)node;
      e->stuck_until_s = now(e) + ms * 1e-3;
      e->n_frozen = 0;
    } else {
      e->babble_id_node = (uint8_t)node;
      e->babble_until_s = now(e) + ms * 1e-3;
      e->babble_next_s = now(e);
    }
    return reply_ok(reply, cap);
  }
  double v = 0.0;
  if (n != 3) {
    return reply_error(reply, cap,
                       "usage: fault laser_drop|laser_stuck|corrupt|noise_laser|noise_base|can_errors|can_drop|bus_off|base_silent|"
                       "drive_fault|latency|bumper|bumper_silent <value> | fault node_stuck|babble <node> <ms> | "
                       "fault clear");
  }
  const char* kind = tok[1];
  if (strcmp(kind, "bumper") == 0) {
    char* end = NULL;
    errno = 0;
    const long p = strtol(tok[2], &end, 0);
    if (end == tok[2] || *end != '\0' || errno != 0) {
      return reply_error(reply, cap, "bumper panel must be 0..13 or 0x40..0x4d");
    }
    const long panel = p >= 0x40 ? p - 0x40 : p;
    if (panel < 0 || panel >= SIM_RFLEX_PANELS) {
      return reply_error(reply, cap, "bumper panel must be 0..13 or 0x40..0x4d");
    }
    e->forced_panel = (int)panel;  // reported with the next period's data (DIO on)
    return reply_ok(reply, cap);
  }
  if (!number(tok[2], &v) || v < 0.0) {
    return reply_error(reply, cap, "value must be a non-negative number");
  }
  const double t = now(e);
  if (strcmp(kind, "laser_drop") == 0) {
    sim_lms_set_silent_until(e->laser, t + v * 1e-3);
  } else if (strcmp(kind, "laser_stuck") == 0) {
    sim_lms_set_stuck_until(e->laser, t + v * 1e-3);
  } else if (strcmp(kind, "corrupt") == 0) {
    if (v > 1.0) {
      return reply_error(reply, cap, "corrupt fraction must be in [0, 1]");
    }
    e->noise_laser = v;
    e->noise_base = v;
    e->can_error_fraction = v;  // on the bus: failed CRCs, error frames, retransmissions
  } else if (strcmp(kind, "noise_laser") == 0 || strcmp(kind, "noise_base") == 0) {
    if (v > 1.0) {
      return reply_error(reply, cap, "noise fraction must be in [0, 1]");
    }
    *(kind[6] == 'l' ? &e->noise_laser : &e->noise_base) = v;
  } else if (strcmp(kind, "can_errors") == 0) {
    if (e->cia402 == NULL || v > 1.0) {
      return reply_error(reply, cap, "can_errors needs the canopen base and a fraction in [0, 1]");
    }
    e->can_error_fraction = v;
  } else if (strcmp(kind, "bus_off") == 0) {
    if (e->cia402 == NULL) {
      return reply_error(reply, cap, "bus_off needs the canopen base");
    }
    e->bus_off = true;
    e->bus_off_until_s = t + v * 1e-3;
    e->bus_off_pending = true;
    e->bus_restart_pending = false;
  } else if (strcmp(kind, "can_drop") == 0) {
    if (e->cia402 == NULL || v > 1.0) {
      return reply_error(reply, cap, "can_drop needs the canopen base and a fraction in [0, 1]");
    }
    e->can_drop_fraction = v;
  } else if (strcmp(kind, "base_silent") == 0) {
    if (e->rflex != NULL) {
      sim_rflex_set_silent_until(e->rflex, t + v * 1e-3);
    } else {
      sim_cia402_set_silent_until(e->cia402, t + v * 1e-3);
    }
  } else if (strcmp(kind, "bumper_silent") == 0) {
    if (e->bumpers == NULL) {
      return reply_error(reply, cap, "bumper_silent needs the canopen base");
    }
    sim_cia401_set_silent_until(e->bumpers, t + v * 1e-3);
  } else if (strcmp(kind, "latency") == 0) {
    e->latency_s = v * 1e-3;
  } else if (strcmp(kind, "drive_fault") == 0) {
    if (e->cia402 == NULL) {
      return reply_error(reply, cap, "drive_fault needs the canopen base");
    }
    if (v > 127.0 || sim_cia402_inject_fault(e->cia402, (uint8_t)v, t) != 0) {
      return reply_error(reply, cap, "no drive with that node id");
    }
  } else {
    return reply_error(reply, cap, "unknown fault");
  }
  return reply_ok(reply, cap);
}

sim_emu_ctrl_t sim_emu_control(sim_emu_t* e, const char* line, char* reply, size_t cap) {
  char tok[6][SPLIT_TOKEN_CAP];
  const size_t n = split(line, tok, 6);
  if (n == 0) {
    return reply_error(reply, cap, "empty command");
  }
  if (strcmp(tok[0], "pose") == 0 && n == 1) {
    sim_plant_state_t s;
    sim_plant_get_state(e->plant, &s);
    (void)snprintf(reply, cap, "ok %.6f %.9f %.9f %.9f %d", s.t_s, s.x_m, s.y_m, s.theta_rad,
                   s.collided);
    return SIM_EMU_CTRL_OK;
  }
  if (strcmp(tok[0], "reset") == 0) {
    double x, y, th;
    uint64_t run_stream = 0;
    if ((n != 4 && n != 5) || !number(tok[1], &x) || !number(tok[2], &y) || !number(tok[3], &th) ||
        (n == 5 && !unsigned_number(tok[4], &run_stream))) {
      return reply_error(reply, cap, "usage: reset <x_m> <y_m> <theta_rad> [<run>]");
    }
    // Within the coordinates a world may use: far beyond them ODE's numbers lose their meaning.
    if (!(fabs(x) <= SIM_WORLD_MAX_ABS && fabs(y) <= SIM_WORLD_MAX_ABS && fabs(th) <= SIM_WORLD_MAX_ABS)) {
      (void)snprintf(reply, cap, "error reset: x, y and theta must lie within +-%g (m, rad)", SIM_WORLD_MAX_ABS);
      return SIM_EMU_CTRL_ERROR;
    }
    if (n == 5) {
      sim_emu_reset_run(e, x, y, th, run_stream);
    } else {
      sim_emu_reset(e, x, y, th);
    }
    return reply_ok(reply, cap);
  }
  if (strcmp(tok[0], "fault") == 0) {
    return control_fault(e, tok, n, reply, cap);
  }
  if (strcmp(tok[0], "status") == 0 && n == 1) {
    sim_plant_state_t s;
    sim_plant_get_state(e->plant, &s);
    const uint64_t reports = e->rflex != NULL ? sim_rflex_get_counters(e->rflex)->reports
                                              : sim_cia402_get_counters(e->cia402)->frames_out;
    const uint64_t trips = e->rflex != NULL ? sim_rflex_get_counters(e->rflex)->watchdog_trips
                                            : sim_cia402_get_counters(e->cia402)->rpdo_timeouts;
    (void)snprintf(reply, cap, "ok t=%.3f streaming=%d scans=%llu base_reports=%llu contacts=%llu watchdog_trips=%llu",
                   s.t_s, sim_emu_streaming(e) ? 1 : 0,
                   (unsigned long long)sim_lms_get_counters(e->laser)->scans,
                   (unsigned long long)reports, (unsigned long long)s.contacts_total, (unsigned long long)trips);
    return SIM_EMU_CTRL_OK;
  }
  if (strcmp(tok[0], "svg") == 0 && n == 2) {
    if (sim_emu_write_svg(e, tok[1]) != 0) {
      (void)snprintf(reply, cap, "error cannot write the picture: %s", strerror(errno));
      return SIM_EMU_CTRL_ERROR;
    }
    return reply_ok(reply, cap);
  }
  if (strcmp(tok[0], "quit") == 0 && n == 1) {
    (void)snprintf(reply, cap, "ok bye");
    return SIM_EMU_CTRL_QUIT;
  }
  return reply_error(reply, cap, "unknown command (reset, pose, fault, status, svg, quit)");
}
