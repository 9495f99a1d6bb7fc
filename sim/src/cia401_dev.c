// SPDX-License-Identifier: MIT
// The emulated CiA 401 bump-panel input node: NMT, boot-up, heartbeat, TPDO1 on change and by
// event timer.
#include "sim/cia401_dev.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define CIA401_QUEUE 64U

struct sim_cia401 {
  sim_cia401_config_t cfg;
  uint8_t nmt_state;
  bool send_now;          // entered operational: send the inputs at the next poll
  bool sent_any;          // a TPDO1 went out since the node entered operational
  uint8_t sent[CIA401_BUMP_PANELS];  // inputs of the last TPDO1
  double last_pdo_s;
  double next_hb_s;
  double silent_until_s;
  canopen_frame_t queue[CIA401_QUEUE];
  size_t q_head, q_len;
  sim_cia401_counters_t counters;
};

void sim_cia401_config_default(sim_cia401_config_t* cfg) {
  cfg->node = CANOPEN_NODE_BUMPERS_DEFAULT;
  cfg->event_timer_s = CIA401_EVENT_TIMER_MS * 1e-3;
  cfg->heartbeat_s = 0.1;
}

static void push(sim_cia401_t* d, const canopen_frame_t* f, double t_s) {
  if (t_s < d->silent_until_s) {
    return;
  }
  if (d->q_len == CIA401_QUEUE) {
    ++d->counters.queue_overflows;
    return;
  }
  d->queue[(d->q_head + d->q_len) % CIA401_QUEUE] = *f;
  ++d->q_len;
  ++d->counters.frames_out;
}

static void boot(sim_cia401_t* d, double t_s) {
  canopen_frame_t f;
  if (canopen_encode_heartbeat(&f, d->cfg.node, CANOPEN_NMT_STATE_BOOTUP) == PROTO_OK) {
    push(d, &f, t_s);
  }
  d->nmt_state = CANOPEN_NMT_STATE_PREOP;
  d->send_now = false;
  d->sent_any = false;
}

static bool time_ok(double t) { return isfinite(t) && t >= 0.0; }

sim_cia401_t* sim_cia401_create(const sim_cia401_config_t* cfg) {
  if (cfg == NULL || cfg->node < 1U || cfg->node > CANOPEN_NODE_MAX || !time_ok(cfg->event_timer_s) ||
      !time_ok(cfg->heartbeat_s)) {
    return NULL;
  }
  sim_cia401_t* d = calloc(1, sizeof(*d));
  if (d == NULL) {
    return NULL;
  }
  d->cfg = *cfg;
  boot(d, 0.0);
  d->next_hb_s = cfg->heartbeat_s;
  return d;
}

void sim_cia401_destroy(sim_cia401_t* d) { free(d); }

void sim_cia401_feed(sim_cia401_t* d, const canopen_frame_t* f, double t_s) {
  ++d->counters.frames_in;
  if (t_s < d->silent_until_s) {
    ++d->counters.ignored_silent;
    return;
  }
  canopen_nmt_t nmt;
  if (canopen_decode_nmt(f, &nmt) != PROTO_OK || (nmt.node != 0U && nmt.node != d->cfg.node)) {
    ++d->counters.ignored;
    return;
  }
  switch (nmt.command) {
    case CANOPEN_NMT_START:
      if (d->nmt_state != CANOPEN_NMT_STATE_OPERATIONAL) {
        d->send_now = true;  // a host that starts the node learns its inputs at once
      }
      d->nmt_state = CANOPEN_NMT_STATE_OPERATIONAL;
      break;
    case CANOPEN_NMT_STOP:
      d->nmt_state = CANOPEN_NMT_STATE_STOPPED;
      break;
    case CANOPEN_NMT_PREOP:
      d->nmt_state = CANOPEN_NMT_STATE_PREOP;
      break;
    case CANOPEN_NMT_RESET_NODE:
    case CANOPEN_NMT_RESET_COMM:
      boot(d, t_s);
      break;
    default:
      ++d->counters.ignored;
      break;
  }
}

void sim_cia401_poll(sim_cia401_t* d, const uint8_t panels[CIA401_BUMP_PANELS], double t_s) {
  if (d->cfg.heartbeat_s > 0.0) {
    while (t_s + 1e-9 >= d->next_hb_s) {
      canopen_frame_t f;
      if (canopen_encode_heartbeat(&f, d->cfg.node, d->nmt_state) == PROTO_OK) {
        push(d, &f, t_s);
      }
      d->next_hb_s += d->cfg.heartbeat_s;
      if (d->next_hb_s < t_s) {
        d->next_hb_s = t_s + d->cfg.heartbeat_s;  // no burst after a long gap
      }
    }
  }
  if (d->nmt_state != CANOPEN_NMT_STATE_OPERATIONAL || t_s < d->silent_until_s) {
    return;
  }
  uint8_t in[CIA401_BUMP_PANELS];
  for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
    in[p] = (uint8_t)(panels[p] & CIA401_BUMP_SEGMENTS);
  }
  const bool changed = d->send_now || !d->sent_any || memcmp(in, d->sent, sizeof in) != 0;
  const bool timer = d->cfg.event_timer_s > 0.0 && t_s + 1e-9 >= d->last_pdo_s + d->cfg.event_timer_s;
  if (!changed && !timer) {
    return;
  }
  canopen_frame_t f;
  if (cia401_encode_bumpers(&f, d->cfg.node, in) != PROTO_OK) {
    return;
  }
  push(d, &f, t_s);
  ++d->counters.pdos;
  if (changed) {
    ++d->counters.pdos_on_change;
  }
  memcpy(d->sent, in, sizeof in);
  d->sent_any = true;
  d->send_now = false;
  d->last_pdo_s = t_s;
}

int sim_cia401_drain(sim_cia401_t* d, canopen_frame_t* f) {
  if (d->q_len == 0) {
    return 0;
  }
  *f = d->queue[d->q_head];
  d->q_head = (d->q_head + 1U) % CIA401_QUEUE;
  --d->q_len;
  return 1;
}

bool sim_cia401_operational(const sim_cia401_t* d) { return d->nmt_state == CANOPEN_NMT_STATE_OPERATIONAL; }

void sim_cia401_set_silent_until(sim_cia401_t* d, double t_s) {
  d->silent_until_s = t_s;
  if (t_s <= 0.0) {
    d->send_now = true;  // back: the inputs go out at the next poll, not an event timer later
  }
}

const sim_cia401_counters_t* sim_cia401_get_counters(const sim_cia401_t* d) { return &d->counters; }
