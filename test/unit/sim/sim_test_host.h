// SPDX-License-Identifier: MIT
// A small scripted controller for the emulator tests: encodes real host commands with lib/proto
// and decodes everything the emulator sends back (laser, rFLEX, CAN), counting per kind.
#ifndef B21R_TEST_SIM_HOST_H
#define B21R_TEST_SIM_HOST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <proto/canopen.h>
#include <proto/lms200.h>
#include <proto/rflex.h>

#include "sim/emulator.h"

typedef struct host {
  sim_emu_t* emu;
  lms_decoder_t lms;
  rflex_decoder_t rflex;
  rflex_b21r_params_t params;
  rflex_odometry_t odo;
  uint64_t hash;  // FNV-1a over every byte/frame received, in order
  // Counts of the last host_read() call.
  // tpdo1 / heartbeats: the drives'; bump_*: the CiA 401 bump-panel node's (node 16).
  int scans, acks, lms_replies, motor_reports, dio_reports, sys_status, tpdo1, tpdo2, heartbeats,
      emcy, bump_pdos, bump_heartbeats, other;
  cia401_bumpers_t last_bump;
  lms_scan_t last_scan;
  rflex_dio_report_t last_dio;
  canopen_tpdo1_t last_tpdo1[2];
  canopen_tpdo2_t last_tpdo2[2];
  uint8_t buf[65536];
} host_t;

static inline void host_hash(host_t* h, const uint8_t* b, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    h->hash = (h->hash ^ b[i]) * 1099511628211ULL;
  }
}

static inline void host_init(host_t* h, sim_emu_t* emu) {
  memset(h, 0, sizeof(*h));
  h->emu = emu;
  (void)lms_decoder_init(&h->lms, LMS_ROLE_HOST, 0);
  rflex_decoder_init(&h->rflex);
  rflex_b21r_params_default(&h->params);
  (void)rflex_odom_init(&h->odo, &h->params);
  h->hash = 1469598103934665603ULL;
}

// Reads and decodes everything available; resets the per-call counts.
static inline void host_read(host_t* h) {
  h->scans = h->acks = h->lms_replies = h->motor_reports = h->dio_reports = h->sys_status = 0;
  h->tpdo1 = h->tpdo2 = h->heartbeats = h->emcy = h->bump_pdos = h->bump_heartbeats = h->other = 0;
  size_t n = sim_emu_laser_read(h->emu, h->buf, sizeof(h->buf));
  host_hash(h, h->buf, n);
  const uint8_t* p = h->buf;
  while (n > 0) {
    lms_event_t ev;
    const size_t k = lms_decoder_push(&h->lms, p, n, &ev);
    p += k;
    n -= k;
    if (ev.kind == LMS_EVENT_ACK) {
      ++h->acks;
    } else if (ev.kind == LMS_EVENT_TELEGRAM) {
      if (ev.telegram.cmd == LMS_REPLY_VALUES &&
          lms_parse_scan(&ev.telegram, 13, &h->last_scan) == PROTO_OK) {
        ++h->scans;
      } else {
        ++h->lms_replies;
      }
    }
  }
  n = sim_emu_base_read(h->emu, h->buf, sizeof(h->buf));
  host_hash(h, h->buf, n);
  size_t used = 0;
  while (used < n) {
    rflex_packet_t pkt;
    bool got = false;
    used += rflex_decoder_push(&h->rflex, h->buf + used, n - used, &pkt, &got);
    if (!got) {
      continue;
    }
    rflex_motor_report_t r;
    if (rflex_parse_motor_report(&pkt, &r) == PROTO_OK) {
      ++h->motor_reports;
      (void)rflex_odom_feed(&h->odo, &r);
      if (r.axis == RFLEX_AXIS_ROT) {
        (void)rflex_odom_update(&h->odo);
      }
    } else if (rflex_parse_dio_report(&pkt, &h->last_dio) == PROTO_OK) {
      ++h->dio_reports;
    } else if (rflex_classify(&pkt) == RFLEX_MSG_SYS_STATUS) {
      ++h->sys_status;
    } else {
      ++h->other;
    }
  }
  canopen_frame_t f;
  while (sim_emu_can_read(h->emu, &f)) {
    host_hash(h, (const uint8_t*)&f.id, sizeof(f.id));
    host_hash(h, &f.dlc, 1);
    host_hash(h, f.data, f.dlc);
    uint8_t node = 0;
    const canopen_kind_t kind = canopen_classify(&f, &node);
    if (node == CANOPEN_NODE_BUMPERS_DEFAULT) {
      if (kind == CANOPEN_KIND_TPDO1 && cia401_decode_bumpers(&f, &h->last_bump) == PROTO_OK) {
        ++h->bump_pdos;
      } else if (kind == CANOPEN_KIND_HEARTBEAT) {
        ++h->bump_heartbeats;
      } else {
        ++h->other;
      }
      continue;
    }
    switch (kind) {
      case CANOPEN_KIND_TPDO1:
        if (node >= 1 && node <= 2) {
          (void)canopen_decode_tpdo1(&f, &h->last_tpdo1[node - 1]);
        }
        ++h->tpdo1;
        break;
      case CANOPEN_KIND_TPDO2:
        if (node >= 1 && node <= 2) {
          (void)canopen_decode_tpdo2(&f, &h->last_tpdo2[node - 1]);
        }
        ++h->tpdo2;
        break;
      case CANOPEN_KIND_HEARTBEAT: ++h->heartbeats; break;
      case CANOPEN_KIND_EMCY: ++h->emcy; break;
      default: ++h->other; break;
    }
  }
}

static inline void host_laser(host_t* h, const uint8_t* req, size_t n) {
  sim_emu_laser_write(h->emu, req, n);
}

static inline void host_rflex_packet(host_t* h, const rflex_packet_t* pkt) {
  uint8_t b[RFLEX_MAX_STUFFED_BYTES];
  const size_t n = rflex_encode(b, sizeof(b), pkt, RFLEX_HOST_STRICT);
  sim_emu_base_write(h->emu, b, n);
}

static inline void host_velocity(host_t* h, double v, double w) {
  rflex_packet_t p[2];
  (void)rflex_make_velocity(p, &h->params, v, w, 0.0);
  host_rflex_packet(h, &p[0]);
  host_rflex_packet(h, &p[1]);
}

// The recommended rFLEX start-up (protocols.md A.7) plus starting the laser stream.
static inline void host_rflex_startup(host_t* h) {
  uint8_t req[32];
  host_laser(h, req, lms_encode_start_stream(req, sizeof(req)));
  rflex_packet_t p;
  (void)rflex_make_odometry_request(&p, 100000, 3);
  host_rflex_packet(h, &p);
  (void)rflex_make_dio_request(&p, 100000);
  host_rflex_packet(h, &p);
  rflex_make_set_defaults(&p);
  host_rflex_packet(h, &p);
  rflex_make_brake_release(&p);
  host_rflex_packet(h, &p);
}

static inline void host_can(host_t* h, const canopen_frame_t* f) { sim_emu_can_write(h->emu, f); }

static inline void host_can_cycle(host_t* h, uint16_t cw, double v, double w) {
  canopen_frame_t f;
  (void)canopen_encode_rpdo1(&f, 1, cw, canopen_counts_from_si(v, 103000.0));
  host_can(h, &f);
  (void)canopen_encode_rpdo1(&f, 2, cw, canopen_counts_from_si(w, 35000.0));
  host_can(h, &f);
  (void)canopen_encode_sync(&f);
  host_can(h, &f);
}

// NMT start, then the enable sequence one controlword per cycle (each cycle ends in a SYNC),
// then the laser stream; returns after the first SYNC with both drives enabled.
static inline void host_canopen_startup(host_t* h) {
  uint8_t req[32];
  canopen_frame_t f;
  (void)canopen_encode_nmt(&f, CANOPEN_NMT_START, 0);
  host_can(h, &f);
  host_can_cycle(h, CIA402_CW_SHUTDOWN, 0.0, 0.0);
  host_can_cycle(h, CIA402_CW_SWITCH_ON, 0.0, 0.0);
  host_laser(h, req, lms_encode_start_stream(req, sizeof(req)));
  host_can_cycle(h, CIA402_CW_ENABLE_OPERATION, 0.0, 0.0);
}

#endif  // B21R_TEST_SIM_HOST_H
