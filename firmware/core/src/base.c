// SPDX-License-Identifier: MIT
// Base adapters of the loop core: rFLEX over bytes, and CiA 402 drives plus the CiA 401
// bump-panel node over CANopen frames. Both feed the same odometry integrator
// (rflex_odometry_t: heading first, then translation) and the same bumper mask (bit p = panel p,
// the rFLEX DIO numbering).
#include "base.h"

#include <math.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>

// How often the rFLEX is asked for SYS_STATUS (brake, battery), in ticks: about every 2 s at
// 10 Hz. More often "overwhelms the driver" (protocols.md A.6).
#define SYS_STATUS_PERIOD_TICKS 20

// Answers in a row whose position stands still while the drive reports a velocity, before the
// drive's PDOs count as stale (a base fault): one could be a rounding, three are not.
#define STALE_ANSWERS_LIMIT 3
// Least movement a reported velocity implies within one period before a still position is
// implausible [counts]: below it a slow drive may legitimately stay on one count.
#define STALE_MIN_COUNTS 4.0
// Frames of no configured node within one tick, with the drives' answers missing, that make the
// bus flooded: 100 per 0.1 s is a fifth of a 500 kbit/s bus.
#define FLOOD_FRAMES_PER_TICK 100U

static bool is_rflex(const fw_loop_t* L) { return L->cfg.base_protocol == FW_BASE_RFLEX; }

// ---- rFLEX ------------------------------------------------------------------------------

static int rflex_send(fw_loop_t* L, const rflex_packet_t* pkt) {
  uint8_t buf[RFLEX_PACKET_BYTES(RFLEX_MAX_DATA)];
  const size_t n = rflex_encode(buf, sizeof buf, pkt, RFLEX_HOST_STRICT);
  if (n == 0) {
    return -1;
  }
  return L->io.vt->base_write(L->io.user, buf, n);
}

static void rflex_poll(fw_loop_t* L) {
  // Bounded: at most 16 reads of 1 KB per poll (about 3 s of reports at 115200 Bd).
  for (int i = 0; i < 16; ++i) {
    const ssize_t n = L->io.vt->base_read(L->io.user, L->rbuf, sizeof L->rbuf);
    if (n <= 0) {
      break;
    }
    L->base_packets += (int64_t)rflex_host_feed(&L->base, L->rbuf, (size_t)n);
  }
  L->bumper_mask = L->base.bumper_mask;
}

// ---- CANopen ----------------------------------------------------------------------------

static const char* drive_name(int i) { return i == 0 ? "translation" : "rotation"; }

// The clock the nodes' liveness is judged on [µs]: real time, the monotonic clock; lockstep, the
// ticks' (the utime of the tick whose period's frames are read: tick x period, paced by the
// emulator's periods), since the emulator's nodes send their heartbeats on simulated time. A
// loaded machine that stops the emulator for seconds, even between two frames of one period, then
// ages no heartbeat and the run does not depend on it.
static int64_t bus_clock(const fw_loop_t* L, int64_t now_us) { return L->cfg.lockstep ? L->data_utime : now_us; }

static void can_send_nmt(fw_loop_t* L, uint8_t command, uint8_t node, int* failed_node) {
  canopen_frame_t f;
  (void)canopen_encode_nmt(&f, command, node);
  if (L->io.vt->can_write(L->io.user, &f) != 0 && failed_node != NULL && *failed_node < 0) {
    *failed_node = node;
  }
}

// Frames of the bump-panel node: its TPDO1 sets the bumper mask exactly as the rFLEX DIO reports
// do; a boot-up means it restarted into pre-operational, where it sends no PDOs, so it is started
// again (its silence until then is a base fault, see fw_base_evaluate_faults).
static void bump_handle(fw_loop_t* L, const canopen_frame_t* f, canopen_kind_t kind, int64_t now_us) {
  fw_bump_node_t* b = &L->bump;
  b->frames++;
  if (kind == CANOPEN_KIND_TPDO1) {
    cia401_bumpers_t in;
    if (cia401_decode_bumpers(f, &in) != PROTO_OK) {
      b->bad_pdos++;  // says nothing about the panels: neither a contact nor a sign of life
      return;
    }
    b->mask = cia401_bumper_mask(&in);
    b->seen = true;
    b->pdo_new = true;
    b->last_us = now_us;
    b->pdos++;
    L->bumper_mask = b->mask;
    return;
  }
  canopen_heartbeat_t hb;
  if (kind == CANOPEN_KIND_HEARTBEAT) {
    (void)canopen_hb_feed(&b->hb, f, (uint64_t)now_us);
  }
  if (kind == CANOPEN_KIND_HEARTBEAT && canopen_decode_heartbeat(f, &hb) == PROTO_OK &&
      hb.nmt_state == CANOPEN_NMT_STATE_BOOTUP) {
    b->bootups++;
    can_send_nmt(L, CANOPEN_NMT_START, b->node, NULL);
  }
}

static void can_handle(fw_loop_t* L, const canopen_frame_t* f, int64_t now_us) {
  uint8_t node = 0;
  const canopen_kind_t kind = canopen_classify(f, &node);
  if (node != 0U && node == L->bump.node) {
    L->base_packets++;
    bump_handle(L, f, kind, now_us);
    return;
  }
  int i = -1;
  for (int k = 0; k < 2; ++k) {
    if (L->drive[k].node == node) {
      i = k;
    }
  }
  if (i < 0) {
    // Not ours: another node, or one babbling. Counted; a flood of them is judged each tick.
    if (kind != CANOPEN_KIND_SYNC && kind != CANOPEN_KIND_NMT) {
      L->can_foreign_frames++;
      L->can_foreign_tick++;
      L->can_foreign_id = f->id;
    }
    return;
  }
  fw_drive_t* d = &L->drive[i];
  L->base_packets++;
  switch (kind) {
    case CANOPEN_KIND_TPDO1: {
      canopen_tpdo1_t t;
      if (canopen_decode_tpdo1(f, &t) == PROTO_OK) {
        d->statusword = t.statusword;
        d->sw_seen = true;
        if (cia402_operation_enabled(t.statusword) && !cia402_fault(t.statusword)) {
          d->emcy_seen = false;  // a good statusword after the EMCY: the drive recovered
        }
        d->velocity = t.velocity_actual;
        d->tpdo1_new = true;
        d->tpdo1_count++;
      }
      break;
    }
    case CANOPEN_KIND_TPDO2: {
      canopen_tpdo2_t t;
      if (canopen_decode_tpdo2(f, &t) == PROTO_OK) {
        const double moves = fabs((double)d->velocity) * (double)L->period_us * 1e-6;
        if (d->have_position && t.position_actual == d->position && moves >= STALE_MIN_COUNTS) {
          d->stale_answers++;
          L->can_stale_pdos++;
        } else {
          d->stale_answers = 0;
        }
        d->have_position = true;
        d->position = t.position_actual;
        d->tpdo2_new = true;
        d->tpdo2_count++;
        rflex_motor_report_t r;
        memset(&r, 0, sizeof r);
        r.axis = (uint8_t)i;
        r.position = t.position_actual;
        r.velocity = d->velocity;
        if (rflex_odom_feed(&L->base.odometry, &r) == PROTO_OK) {
          L->base.report_new[i] = true;
        }
      }
      break;
    }
    case CANOPEN_KIND_EMCY: {
      canopen_emcy_t e;
      if (canopen_decode_emcy(f, &e) == PROTO_OK) {
        d->emcy_code = e.error_code;
        d->emcy_seen = e.error_code != 0U;
      }
      break;
    }
    case CANOPEN_KIND_HEARTBEAT:
      (void)canopen_hb_feed(&d->hb, f, (uint64_t)now_us);
      break;
    default:
      break;
  }
}

static void can_poll(fw_loop_t* L, int64_t now_us) {
  const int64_t t = bus_clock(L, now_us);
  for (int i = 0; i < 256; ++i) {
    canopen_frame_t f;
    if (L->io.vt->can_read(L->io.user, &f) != 1) {
      break;
    }
    can_handle(L, &f, t);
  }
}

static void can_send_cycle(fw_loop_t* L, double v_mps, double w_radps, cia402_request_t req) {
  const double factor[2] = {L->cfg.distance_counts_per_m, L->cfg.angle_counts_per_rad};
  const double value[2] = {v_mps, w_radps};
  for (int i = 0; i < 2; ++i) {
    fw_drive_t* d = &L->drive[i];
    const uint16_t cw = cia402_master_controlword(&d->master, d->statusword, req);
    canopen_frame_t f;
    if (canopen_encode_rpdo1(&f, d->node, cw, canopen_counts_from_si(value[i], factor[i])) == PROTO_OK) {
      (void)L->io.vt->can_write(L->io.user, &f);
    }
  }
  // Answers still missing for the SYNCs sent so far: those beyond the ones already counted are
  // new (lost frames, or a late drive). A deficit that shrinks again (late answers) is forgotten.
  for (int i = 0; i < 2; ++i) {
    fw_drive_t* d = &L->drive[i];
    const uint32_t a = (int32_t)(d->tpdo1_count - d->tpdo2_count) < 0 ? d->tpdo1_count : d->tpdo2_count;
    const uint32_t deficit = (int32_t)(L->can_syncs_sent - a) > 0 ? L->can_syncs_sent - a : 0U;
    if (deficit > d->deficit) {
      L->can_unanswered_syncs += (int64_t)(deficit - d->deficit);
    }
    d->deficit = deficit;
  }
  canopen_frame_t sync;
  (void)canopen_encode_sync(&sync);
  if (L->io.vt->can_write(L->io.user, &sync) == 0) {
    L->can_syncs_sent++;
  }
}

// A TPDO1 and a TPDO2 of each drive arrived since the flags were last cleared.
static bool can_all_new(const fw_loop_t* L) {
  return L->drive[0].tpdo1_new && L->drive[0].tpdo2_new && L->drive[1].tpdo1_new && L->drive[1].tpdo2_new;
}

// Every SYNC sent since the NMT start has been answered by both drives' TPDO1 and TPDO2 (their
// transmission type is synchronous: one of each per SYNC). Arrival flags alone cannot tell the
// answer to this period's SYNC from an earlier answer still in flight (the socket and the laser's
// line are separate channels); counting can.
static bool can_drive_answered(const fw_loop_t* L, int i) {
  const fw_drive_t* d = &L->drive[i];
  return (int32_t)(d->tpdo1_count - L->can_syncs_sent) >= 0 && (int32_t)(d->tpdo2_count - L->can_syncs_sent) >= 0;
}

static bool can_all_answered(const fw_loop_t* L) { return can_drive_answered(L, 0) && can_drive_answered(L, 1); }

// ---- common -------------------------------------------------------------------------------

void fw_base_poll(fw_loop_t* L, int64_t now_us) {
  if (is_rflex(L)) {
    rflex_poll(L);
  } else {
    can_poll(L, now_us);
  }
}

bool fw_base_all_reports(const fw_loop_t* L) {
  if (is_rflex(L)) {
    return L->base.report_new[0] && L->base.report_new[1];
  }
  return L->cfg.lockstep ? can_all_answered(L) : can_all_new(L);
}

bool fw_base_any_report(const fw_loop_t* L) {
  if (is_rflex(L)) {
    return L->base.report_new[0] || L->base.report_new[1];
  }
  return L->drive[0].tpdo1_new || L->drive[0].tpdo2_new || L->drive[1].tpdo1_new || L->drive[1].tpdo2_new;
}

void fw_base_clear_flags(fw_loop_t* L) {
  L->base.report_new[0] = false;
  L->base.report_new[1] = false;
  for (int i = 0; i < 2; ++i) {
    L->drive[i].tpdo1_new = false;
    L->drive[i].tpdo2_new = false;
  }
  L->bump.pdo_new = false;
}

// The bump-panel node's silence: a base fault, not a bumper stop. A silent node means contacts can
// no longer be seen (the base's safety chain is broken, like a drive whose heartbeat is lost), but
// nothing was hit: a bumper stop would end the run as a collision and teach the learner one.
// Lockstep counts ticks (the node's event timer runs on the emulator's time); real time, the
// monotonic clock. Writes the detail and returns true when silent.
static bool bump_silent(fw_loop_t* L, int64_t now_us, char* detail, size_t cap) {
  const fw_bump_node_t* b = &L->bump;
  const unsigned cob = CANOPEN_COB_TPDO1 + b->node;
  if (L->cfg.lockstep) {
    if (b->silent_ticks < L->bump_limit_ticks) {
      return false;
    }
    snprintf(detail, cap, "bump-panel node %u (CiA 401): no TPDO1 0x%03x for %d ticks (limit %d); bumpers not watched",
             (unsigned)b->node, cob, (int)b->silent_ticks, (int)L->bump_limit_ticks);
    return true;
  }
  const int64_t age_us = now_us - (b->seen ? b->last_us : L->can_start_us);
  const int64_t limit_us = (int64_t)(L->cfg.can_bumper_timeout_s * 1e6);
  if (age_us < limit_us) {
    return false;
  }
  snprintf(detail, cap, "bump-panel node %u (CiA 401): no TPDO1 0x%03x for %lld ms (limit %lld ms); bumpers not watched",
           (unsigned)b->node, cob, (long long)(age_us / 1000), (long long)(limit_us / 1000));
  return true;
}

// Faults of the bus itself or of a node's liveness, after the drives' own: a flood from an
// identifier of no configured node while the drives' answers stay away (a babbling node holds
// the bus), the bump-panel node's heartbeat lost. Writes the detail and returns true when one is
// present.
static bool can_node_faults(fw_loop_t* L, int64_t now_us, uint32_t foreign, char* detail, size_t cap) {
  fw_can_stats_t cs = {0};
  if (L->io.vt->can_stats != NULL) {
    L->io.vt->can_stats(L->io.user, &cs);
  }
  if (cs.bus_off) {
    // Named before the drives' silence it causes: the fault is this computer's interface.
    // (Restart advice in docs/robot.md: the detail has 128 bytes.)
    snprintf(detail, cap, "CAN bus-off: this computer's CAN controller left the bus (check termination, bit rate, wiring)");
    return true;
  }
  if (foreign >= FLOOD_FRAMES_PER_TICK && !fw_base_any_report(L)) {
    snprintf(detail, cap,
             "CAN bus flooded: %u frames of id 0x%03x (no configured node) in one tick, no drive answers (a babbling "
             "node)",
             (unsigned)foreign, (unsigned)L->can_foreign_id);
    return true;
  }
  const fw_bump_node_t* b = &L->bump;
  if (L->cfg.can_heartbeat_timeout_s > 0.0 && canopen_hb_expired(&b->hb, (uint64_t)now_us, (uint64_t)L->can_start_us)) {
    snprintf(detail, cap, "bump-panel node %u (CiA 401): heartbeat lost (none for %d ms)%s", (unsigned)b->node,
             (int)(L->cfg.can_heartbeat_timeout_s * 1e3), b->pdo_new ? ", its PDOs still arrive (stale)" : "");
    return true;
  }
  return false;
}

void fw_base_evaluate_faults(fw_loop_t* L, int64_t now_us) {
  now_us = bus_clock(L, now_us);
  uint32_t foreign = 0;
  if (!is_rflex(L)) {
    L->bump.silent_ticks = L->bump.pdo_new ? 0 : L->bump.silent_ticks + 1;
    foreign = L->can_foreign_tick;
    L->can_foreign_tick = 0;
  }
  L->base_fault = false;
  L->base_fault_detail[0] = '\0';
  if (L->output_overflows > 0U) {
    // The line does not take the commands as fast as they are sent: what the base executes is
    // no longer what the loop decided.
    L->base_fault = true;
    snprintf(L->base_fault_detail, sizeof L->base_fault_detail,
             "command output buffer full: %u packets refused (%lld in all); the base does not take commands",
             (unsigned)L->output_overflows, (long long)L->output_overflows_total);
    return;
  }
  if (is_rflex(L)) {
    // The rFLEX reports no faults; an engaged brake we did not ask for means its watchdog or an
    // emergency stop took the motors away.
    if (L->brake_expected_released && L->base.brake == 1) {
      L->base_fault = true;
      snprintf(L->base_fault_detail, sizeof L->base_fault_detail,
               "rFLEX reports the brake engaged (watchdog or emergency stop)");
    }
    return;
  }
  for (int i = 0; i < 2 && !L->base_fault; ++i) {
    fw_drive_t* d = &L->drive[i];
    const bool hb_expired = L->cfg.can_heartbeat_timeout_s > 0.0 &&
                            canopen_hb_expired(&d->hb, (uint64_t)now_us, (uint64_t)L->can_start_us);
    if (d->stale_answers >= STALE_ANSWERS_LIMIT) {
      // Named first: its statusword is as stale as its position, so it would say nothing.
      L->base_fault = true;
      snprintf(L->base_fault_detail, sizeof L->base_fault_detail,
               "%s drive (node %u): stale PDOs: position still for %d answers at %ld counts/s%s", drive_name(i),
               (unsigned)d->node, (int)d->stale_answers, (long)d->velocity, hb_expired ? ", heartbeat lost" : "");
      break;
    }
    if (d->emcy_seen || cia402_fault(d->statusword) || !cia402_operation_enabled(d->statusword) || hb_expired) {
      L->base_fault = true;
      char emcy[32] = "";
      if (d->emcy_seen) {
        snprintf(emcy, sizeof emcy, "EMCY 0x%04x, ", (unsigned)d->emcy_code);
      }
      snprintf(L->base_fault_detail, sizeof L->base_fault_detail, "%s drive (node %u): %sstatusword 0x%04x (%s)%s",
               drive_name(i), (unsigned)d->node, emcy, (unsigned)d->statusword,
               cia402_state_name(cia402_state_from_statusword(d->statusword)), hb_expired ? ", heartbeat lost" : "");
    }
  }
  if (!L->base_fault) {
    L->base_fault = can_node_faults(L, now_us, foreign, L->base_fault_detail, sizeof L->base_fault_detail);
  }
  if (!L->base_fault) {
    L->base_fault = bump_silent(L, now_us, L->base_fault_detail, sizeof L->base_fault_detail);
  }
}

void fw_base_command(fw_loop_t* L, double v_mps, double w_radps, bool stopping) {
  if (is_rflex(L)) {
    if (--L->sys_status_countdown <= 0) {
      // Asked before the velocity pair so that, in lockstep, its answer is not mixed with the
      // next period's reports (SYS_STATUS is answered at once, without advancing time).
      rflex_packet_t st;
      rflex_make_sys_status_request(&st);
      (void)rflex_send(L, &st);
      L->sys_status_countdown = SYS_STATUS_PERIOD_TICKS;
    }
    rflex_packet_t pair[2];
    // Stopping decelerates at the configured limit; otherwise the base's own acceleration.
    const double acc = stopping ? L->cfg.max_translation_accel_mps2 : L->rflex.trans_acc_mps2;
    if (rflex_make_velocity(pair, &L->rflex, v_mps, w_radps, acc) == PROTO_OK) {
      (void)rflex_send(L, &pair[0]);
      (void)rflex_send(L, &pair[1]);
    }
    return;
  }
  // CANopen: keep asking for "enabled" (a fault reset edge when a drive has recovered from a
  // fault), with zero velocity while stopped.
  can_send_cycle(L, v_mps, w_radps, CIA402_REQ_ENABLE);
}

uint64_t fw_base_bytes_dropped(const fw_loop_t* L) { return is_rflex(L) ? L->base.decoder.counters.bytes_dropped : 0U; }

uint64_t fw_base_checksum_errors(const fw_loop_t* L) {
  return is_rflex(L) ? L->base.decoder.counters.bad_checksum : 0U;
}

static int64_t now(const fw_loop_t* L) { return L->io.vt->now_us(L->io.user); }

// protocols.md A.7, recommended sequence: odometry on, DIO on, defaults, brake release, status.
// Zero velocities follow with every tick. Report period = the tick period [µs], nudged by 1 µs
// if a byte would be 0x1B. Only queues packets: never waits.
static int rflex_start_sequence(fw_loop_t* L) {
  rflex_packet_t p;
  uint32_t period = (uint32_t)L->period_us;
  while (rflex_make_odometry_request(&p, period, 3U) != PROTO_OK) {
    period++;
  }
  int rc = rflex_send(L, &p);
  uint32_t dio_period = 100000U;
  while (rflex_make_dio_request(&p, dio_period) != PROTO_OK) {
    dio_period++;
  }
  rc |= rflex_send(L, &p);
  rflex_make_set_defaults(&p);
  rc |= rflex_send(L, &p);
  rflex_make_brake_release(&p);
  rc |= rflex_send(L, &p);
  rflex_make_sys_status_request(&p);
  rc |= rflex_send(L, &p);
  return rc;
}

// Starts the drives and the bump-panel node (each by its id: other nodes on the bus stay as they are).
// The SYNC/answer count starts again: a started drive answers every SYNC that follows.
static void can_nmt_start(fw_loop_t* L, int* failed_node) {
  L->can_syncs_sent = 0;
  for (int i = 0; i < 2; ++i) {
    L->drive[i].tpdo1_count = 0;
    L->drive[i].tpdo2_count = 0;
  }
  for (int i = 0; i < 2; ++i) {
    can_send_nmt(L, CANOPEN_NMT_START, L->drive[i].node, failed_node);
  }
  can_send_nmt(L, CANOPEN_NMT_START, L->bump.node, failed_node);
}

// The supervision of the nodes starts again (NMT start): the bump-panel node's PDO and heartbeat,
// the drives' plausibility and answer counts.
static void can_supervision_reset(fw_loop_t* L) {
  fw_bump_node_t* b = &L->bump;
  b->seen = false;
  b->pdo_new = false;
  b->silent_ticks = 0;
  const double hb_s = L->cfg.can_heartbeat_timeout_s > 0.0 ? L->cfg.can_heartbeat_timeout_s : 1.0;
  (void)canopen_hb_init(&b->hb, b->node, (uint32_t)(hb_s * 1e6));
  for (int i = 0; i < 2; ++i) {
    L->drive[i].have_position = false;
    L->drive[i].stale_answers = 0;
    L->drive[i].deficit = 0;
  }
}

bool fw_base_start_signalled(fw_loop_t* L, const char* during, char* err, size_t err_cap) {
  const int sig = fw_loop_signalled(L);
  if (sig == 0) {
    return false;
  }
  snprintf(err, err_cap, "stopped by signal %d (%s) during %s", sig,
           sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal", during);
  L->exit_status = 128 + sig;  // as a tick that sees the signal sets it
  return true;
}

// Waits (bounded) for the bump-panel node's first TPDO1: it sends one when started and then
// every event timer, so a node that says nothing is missing, misconfigured or not powered.
static int can_wait_bumpers(fw_loop_t* L, char* err, size_t err_cap) {
  const double wait_s = L->cfg.can_bumper_timeout_s * 2.0 > 1.0 ? L->cfg.can_bumper_timeout_s * 2.0 : 1.0;
  const int64_t deadline = now(L) + (int64_t)(wait_s * 1e6);
  int64_t next_cycle = now(L) + L->period_us;
  while (!L->bump.seen) {
    const int64_t t = now(L);
    if (fw_base_start_signalled(L, "the CANopen start (waiting for the bump-panel node)", err, err_cap)) {
      return FW_LOOP_START_SIGNALLED;
    }
    if (t >= deadline) {
      const fw_bump_node_t* b = &L->bump;
      snprintf(err, err_cap,
               "CANopen: bump-panel node %u (CiA 401 digital inputs, TPDO1 COB-ID 0x%03x) sent no inputs within "
               "%.1f s of NMT start (%s); check can_node_bumpers, the node's power and its wiring: the robot does "
               "not drive without its bumpers",
               (unsigned)b->node, (unsigned)(CANOPEN_COB_TPDO1 + b->node), wait_s,
               b->bad_pdos > 0U ? "its TPDO1 is shorter than 7 bytes"
               : b->frames > 0U ? "its heartbeat arrives, no TPDO1"
                                : "nothing at all from that id");
      return -1;
    }
    if (!L->cfg.lockstep && t >= next_cycle) {
      // Real time: keep the drives' RPDO watchdogs fed. In lockstep a SYNC would advance the
      // emulator; its node answers the NMT start at once, so waiting is enough.
      can_send_cycle(L, 0.0, 0.0, CIA402_REQ_ENABLE);
      next_cycle = t + L->period_us;
    }
    can_poll(L, t);
    if (!L->bump.seen) {
      (void)L->io.vt->wait(L->io.user, next_cycle < deadline ? next_cycle : deadline);
    }
  }
  fw_base_clear_flags(L);
  return 0;
}

void fw_base_restart(fw_loop_t* L) {
  // The device's counters start again from its own zero: the pose stays, the baseline is new.
  L->base.odometry.have_trans = false;
  L->base.odometry.have_rot = false;
  L->base.odometry.baseline = false;
  if (is_rflex(L)) {
    (void)rflex_start_sequence(L);
    L->brake_expected_released = true;
    L->sys_status_countdown = SYS_STATUS_PERIOD_TICKS;
    return;
  }
  L->can_start_us = bus_clock(L, now(L));
  can_supervision_reset(L);
  for (int i = 0; i < 2; ++i) {
    cia402_master_init(&L->drive[i].master);
    L->drive[i].emcy_seen = false;
    L->drive[i].sw_seen = false;
    L->drive[i].statusword = 0;
    const double hb_s = L->cfg.can_heartbeat_timeout_s > 0.0 ? L->cfg.can_heartbeat_timeout_s : 1.0;
    (void)canopen_hb_init(&L->drive[i].hb, L->drive[i].node, (uint32_t)(hb_s * 1e6));
  }
  can_nmt_start(L, NULL);
}

// The error of a lockstep start whose SYNC stayed unanswered for wait_s: the drives that did not
// answer, what came from them, and any frames of ids no can_node_* key names (a typo's hint).
static void can_start_unanswered(const fw_loop_t* L, double wait_s, char* err, size_t err_cap) {
  char who[160] = "";
  size_t used = 0;
  for (int i = 0; i < 2; ++i) {
    if (!can_drive_answered(L, i)) {
      const int n = snprintf(who + used, sizeof who - used, "%sdrive node %u (%s, can_node_%s; %s)",
                             used > 0 ? " and " : "", (unsigned)L->drive[i].node, drive_name(i), drive_name(i),
                             L->drive[i].sw_seen ? "its TPDOs stopped" : "nothing from that id");
      used = n > 0 && (size_t)n < sizeof who - used ? used + (size_t)n : sizeof who - 1;
    }
  }
  char foreign[96] = "";
  if (L->can_foreign_frames > 0) {
    snprintf(foreign, sizeof foreign, "; %lld frames came from ids no can_node_* key names (the last COB-ID 0x%03x)",
             (long long)L->can_foreign_frames, (unsigned)L->can_foreign_id);
  }
  snprintf(err, err_cap,
           "CANopen: SYNC %u of the start unanswered for %g s (lockstep_timeout_s) by %s%s; check the can_node_* "
           "keys against the emulator's node ids and that the emulator runs (b21r-sim --lockstep)",
           (unsigned)L->can_syncs_sent, wait_s, who, foreign);
}

int fw_base_start(fw_loop_t* L, char* err, size_t err_cap) {
  if (is_rflex(L)) {
    if (L->io.vt->base_read == NULL || L->io.vt->base_write == NULL) {
      snprintf(err, err_cap, "base_protocol = rflex but the I/O binding has no serial base");
      return -1;
    }
    if (rflex_start_sequence(L) != 0) {
      snprintf(err, err_cap, "rFLEX base: cannot write the start-up packets to %s", L->cfg.base_device);
      return -1;
    }
    L->brake_expected_released = true;
    L->sys_status_countdown = SYS_STATUS_PERIOD_TICKS;
    return 0;
  }
  if (L->io.vt->can_read == NULL || L->io.vt->can_write == NULL) {
    snprintf(err, err_cap, "base_protocol = canopen but the I/O binding has no CAN bus");
    return -1;
  }
  L->can_start_us = bus_clock(L, now(L));
  can_supervision_reset(L);
  int failed_node = -1;
  can_nmt_start(L, &failed_node);
  if (failed_node >= 0) {
    snprintf(err, err_cap, "CANopen: cannot send NMT start to node %d", failed_node);
    return -1;
  }
  // Walk both drives to OPERATION ENABLED: one controlword step per SYNC cycle. Each cycle waits
  // for the whole answer (both TPDOs of both drives), so the last one gives the odometry its
  // baseline: the loop's start then needs no SYNC of its own (in lockstep every later SYNC
  // advances the emulator by one period, see fw_loop_start). Real time: a cycle lasts at most
  // 0.5 s and a drive that does not answer gets the next. Lockstep: the emulator answers these
  // SYNCs at its current time (it streams once the drives are enabled and the laser streams), and
  // a cycle waits for its answer as a tick waits for the period's data, up to lockstep_timeout_s:
  // a loaded machine may stall the emulator for longer than the 40 cycles of 0.5 s, and a drive
  // that does not answer at all is named at once.
  const int64_t cycle_us = L->cfg.lockstep ? (int64_t)(L->cfg.lockstep_timeout_s * 1e6) : 500000;
  for (int cycle = 0; cycle < 40; ++cycle) {
    can_send_cycle(L, 0.0, 0.0, CIA402_REQ_ENABLE);
    const int64_t deadline = now(L) + cycle_us;
    for (;;) {
      const int64_t t = now(L);
      can_poll(L, t);  // before the deadline is judged: frames that came during the last wait count
      if (fw_base_start_signalled(L, "the CANopen start (enabling the drives)", err, err_cap)) {
        return FW_LOOP_START_SIGNALLED;
      }
      if (fw_base_all_reports(L) || t >= deadline) {
        break;
      }
      (void)L->io.vt->wait(L->io.user, deadline);
    }
    if (L->cfg.lockstep && !can_all_answered(L)) {
      can_start_unanswered(L, (double)cycle_us / 1e6, err, err_cap);
      return -1;
    }
    const bool ok = cia402_operation_enabled(L->drive[0].statusword) && cia402_operation_enabled(L->drive[1].statusword);
    if (fw_base_any_report(L)) {
      (void)rflex_odom_update(&L->base.odometry);
    }
    fw_base_clear_flags(L);
    if (ok) {
      return can_wait_bumpers(L, err, err_cap);
    }
  }
  snprintf(err, err_cap,
           "CANopen: drives not enabled after 40 SYNC cycles (node %u statusword 0x%04x %s, node %u statusword "
           "0x%04x %s)",
           (unsigned)L->drive[0].node, (unsigned)L->drive[0].statusword,
           L->drive[0].sw_seen ? cia402_state_name(cia402_state_from_statusword(L->drive[0].statusword)) : "never seen",
           (unsigned)L->drive[1].node, (unsigned)L->drive[1].statusword,
           L->drive[1].sw_seen ? cia402_state_name(cia402_state_from_statusword(L->drive[1].statusword)) : "never seen");
  return -1;
}

void fw_base_shutdown(fw_loop_t* L) {
  if (is_rflex(L)) {
    // protocols.md A.7 shutdown: zero velocity, brake set, reports off, defaults.
    fw_base_command(L, 0.0, 0.0, true);
    rflex_packet_t p;
    rflex_make_brake_set(&p);
    (void)rflex_send(L, &p);
    L->brake_expected_released = false;
    if (rflex_make_odometry_request(&p, 0U, 0U) == PROTO_OK) {
      (void)rflex_send(L, &p);
    }
    if (rflex_make_dio_request(&p, 0U) == PROTO_OK) {
      (void)rflex_send(L, &p);
    }
    rflex_make_set_defaults(&p);
    (void)rflex_send(L, &p);
    return;
  }
  // Zero, then disable the drives (no torque) and stop the nodes.
  can_send_cycle(L, 0.0, 0.0, CIA402_REQ_ENABLE);
  can_send_cycle(L, 0.0, 0.0, CIA402_REQ_DISABLE);
  for (int i = 0; i < 2; ++i) {
    can_send_nmt(L, CANOPEN_NMT_STOP, L->drive[i].node, NULL);
  }
  can_send_nmt(L, CANOPEN_NMT_STOP, L->bump.node, NULL);
}
