// SPDX-License-Identifier: MIT
// Two emulated CiA 402 drives on one CANopen bus: NMT, PDOs, heartbeat, EMCY, watchdog.
#include "sim/cia402_dev.h"
#include "sim/plant.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#define CIA402_QUEUE 512U
#define CIA402_EMCY_REGISTER 0x03U  // generic error + current

typedef struct drive {
  uint8_t node;
  uint8_t nmt_state;
  cia402_drive_t sm;
  int32_t target_counts;
  double last_rpdo_s;
  bool rpdo_seen;
  bool rpdo_expired;
} drive_t;

struct sim_cia402 {
  sim_cia402_config_t cfg;
  drive_t drive[2];  // [0] translation, [1] rotation
  double next_hb_s;
  double silent_until_s;
  canopen_frame_t queue[CIA402_QUEUE];
  size_t q_head, q_len;
  sim_cia402_counters_t counters;
};

void sim_cia402_config_default(sim_cia402_config_t* cfg) {
  cfg->node_trans = CANOPEN_NODE_TRANS_DEFAULT;
  cfg->node_rot = CANOPEN_NODE_ROT_DEFAULT;
  cfg->trans_counts_per_m = 103000.0;
  cfg->rot_counts_per_rad = 35000.0;
  cfg->heartbeat_s = 0.1;
  cfg->accel_trans_mps2 = 0.5;
  cfg->accel_rot_radps2 = 100000.0 / 35000.0;
  cfg->quick_stop_trans_mps2 = 1.5;
  cfg->quick_stop_rot_radps2 = 6.0;
  cfg->rpdo_timeout_s = 1.0;
  cfg->fault_code = 0x2310U;
}

static void push(sim_cia402_t* d, const canopen_frame_t* f, double t_s) {
  if (t_s < d->silent_until_s) {
    return;
  }
  if (d->q_len == CIA402_QUEUE) {
    ++d->counters.queue_overflows;
    return;
  }
  d->queue[(d->q_head + d->q_len) % CIA402_QUEUE] = *f;
  ++d->q_len;
  ++d->counters.frames_out;
}

static void boot(sim_cia402_t* d, drive_t* dr, double t_s) {
  cia402_drive_init(&dr->sm);
  dr->target_counts = 0;
  dr->rpdo_seen = false;
  dr->rpdo_expired = false;
  canopen_frame_t f;
  if (canopen_encode_heartbeat(&f, dr->node, CANOPEN_NMT_STATE_BOOTUP) == PROTO_OK) {
    push(d, &f, t_s);
  }
  dr->nmt_state = CANOPEN_NMT_STATE_PREOP;
}

static int finite_pos(double v) { return isfinite(v) && v > 0.0; }

sim_cia402_t* sim_cia402_create(const sim_cia402_config_t* cfg) {
  if (cfg == NULL || cfg->node_trans < 1U || cfg->node_trans > CANOPEN_NODE_MAX ||
      cfg->node_rot < 1U || cfg->node_rot > CANOPEN_NODE_MAX || cfg->node_trans == cfg->node_rot ||
      !finite_pos(cfg->trans_counts_per_m) || !finite_pos(cfg->rot_counts_per_rad) ||
      !isfinite(cfg->heartbeat_s) || cfg->heartbeat_s < 0.0 || !finite_pos(cfg->accel_trans_mps2) ||
      !finite_pos(cfg->accel_rot_radps2) || !finite_pos(cfg->quick_stop_trans_mps2) ||
      !finite_pos(cfg->quick_stop_rot_radps2) || !isfinite(cfg->rpdo_timeout_s) ||
      cfg->rpdo_timeout_s < 0.0) {
    return NULL;
  }
  sim_cia402_t* d = calloc(1, sizeof(*d));
  if (d == NULL) {
    return NULL;
  }
  d->cfg = *cfg;
  d->drive[0].node = cfg->node_trans;
  d->drive[1].node = cfg->node_rot;
  boot(d, &d->drive[0], 0.0);
  boot(d, &d->drive[1], 0.0);
  d->next_hb_s = cfg->heartbeat_s;
  return d;
}

void sim_cia402_destroy(sim_cia402_t* d) { free(d); }

static drive_t* find(sim_cia402_t* d, uint8_t node) {
  for (int i = 0; i < 2; ++i) {
    if (d->drive[i].node == node) {
      return &d->drive[i];
    }
  }
  return NULL;
}

static void apply_nmt(sim_cia402_t* d, drive_t* dr, uint8_t command, double t_s) {
  switch (command) {
    case CANOPEN_NMT_START:
      dr->nmt_state = CANOPEN_NMT_STATE_OPERATIONAL;
      break;
    case CANOPEN_NMT_STOP:
      dr->nmt_state = CANOPEN_NMT_STATE_STOPPED;
      break;
    case CANOPEN_NMT_PREOP:
      dr->nmt_state = CANOPEN_NMT_STATE_PREOP;
      break;
    case CANOPEN_NMT_RESET_NODE:
    case CANOPEN_NMT_RESET_COMM:
      boot(d, dr, t_s);
      break;
    default:
      ++d->counters.ignored;
      break;
  }
}

static void emcy(sim_cia402_t* d, const drive_t* dr, uint16_t code, uint8_t reg, double t_s) {
  canopen_frame_t f;
  if (canopen_encode_emcy(&f, dr->node, code, reg, NULL) == PROTO_OK) {
    push(d, &f, t_s);
    ++d->counters.emcy;
  }
}

sim_cia402_event_t sim_cia402_feed(sim_cia402_t* d, const canopen_frame_t* f, double t_s) {
  ++d->counters.frames_in;
  if (t_s < d->silent_until_s) {
    ++d->counters.ignored_silent;
    return SIM_CIA402_EV_NONE;
  }
  uint8_t node = 0;
  switch (canopen_classify(f, &node)) {
    case CANOPEN_KIND_NMT: {
      canopen_nmt_t nmt;
      if (canopen_decode_nmt(f, &nmt) != PROTO_OK) {
        ++d->counters.ignored;
        break;
      }
      for (int i = 0; i < 2; ++i) {
        if (nmt.node == 0U || nmt.node == d->drive[i].node) {
          apply_nmt(d, &d->drive[i], nmt.command, t_s);
        }
      }
      break;
    }
    case CANOPEN_KIND_SYNC:
      ++d->counters.syncs;
      return SIM_CIA402_EV_SYNC;
    case CANOPEN_KIND_RPDO1: {
      drive_t* dr = find(d, node);
      canopen_rpdo1_t r;
      if (dr == NULL || dr->nmt_state != CANOPEN_NMT_STATE_OPERATIONAL ||
          canopen_decode_rpdo1(f, &r) != PROTO_OK) {
        ++d->counters.ignored;
        break;
      }
      ++d->counters.rpdos;
      const cia402_state_t before = dr->sm.state;
      cia402_drive_apply_controlword(&dr->sm, r.controlword);
      if (before == CIA402_FAULT && dr->sm.state != CIA402_FAULT) {
        emcy(d, dr, 0x0000U, 0x00U, t_s);  // error reset
      }
      dr->target_counts = r.target_velocity;
      dr->last_rpdo_s = t_s;
      dr->rpdo_seen = true;
      dr->rpdo_expired = false;
      break;
    }
    default:
      ++d->counters.ignored;
      break;
  }
  return SIM_CIA402_EV_NONE;
}

int sim_cia402_drain(sim_cia402_t* d, canopen_frame_t* f) {
  if (d->q_len == 0) {
    return 0;
  }
  *f = d->queue[d->q_head];
  d->q_head = (d->q_head + 1U) % CIA402_QUEUE;
  --d->q_len;
  return 1;
}

static bool drive_running(const drive_t* dr) {
  return dr->nmt_state == CANOPEN_NMT_STATE_OPERATIONAL && cia402_drive_enabled(&dr->sm) &&
         !dr->rpdo_expired;
}

void sim_cia402_emit_tpdos(sim_cia402_t* d, const sim_cia402_sample_t* s, double t_s) {
  for (int i = 0; i < 2; ++i) {
    drive_t* dr = &d->drive[i];
    if (dr->nmt_state != CANOPEN_NMT_STATE_OPERATIONAL) {
      continue;
    }
    const double k = i == 0 ? d->cfg.trans_counts_per_m : d->cfg.rot_counts_per_rad;
    const double vel = i == 0 ? s->v_mps : s->omega_radps;
    const int32_t vel_counts = canopen_counts_from_si(vel, k);
    const bool reached =
        drive_running(dr) && llabs((long long)vel_counts - (long long)dr->target_counts) <= 1LL;
    // Positions wrap at 32 bits like a real encoder count (canopen_counts_from_si saturates).
    const int32_t pos_counts = i == 0 ? sim_plant_axis_counts(s->pos_trans_at_reset_m, s->pos_trans_m, k)
                                      : sim_plant_axis_counts(s->pos_rot_at_reset_rad, s->pos_rot_rad, k);
    canopen_frame_t f;
    if (canopen_encode_tpdo1(&f, dr->node, cia402_drive_statusword(&dr->sm, reached), vel_counts) ==
        PROTO_OK) {
      push(d, &f, t_s);
    }
    if (canopen_encode_tpdo2(&f, dr->node, pos_counts) == PROTO_OK) {
      push(d, &f, t_s);
    }
  }
}

void sim_cia402_poll(sim_cia402_t* d, double t_s) {
  if (d->cfg.heartbeat_s > 0.0) {
    while (t_s + 1e-9 >= d->next_hb_s) {
      for (int i = 0; i < 2; ++i) {
        canopen_frame_t f;
        if (canopen_encode_heartbeat(&f, d->drive[i].node, d->drive[i].nmt_state) == PROTO_OK) {
          push(d, &f, t_s);
        }
      }
      d->next_hb_s += d->cfg.heartbeat_s;
      if (d->next_hb_s < t_s) {
        d->next_hb_s = t_s + d->cfg.heartbeat_s;  // no burst after a long gap
      }
    }
  }
  if (d->cfg.rpdo_timeout_s > 0.0) {
    for (int i = 0; i < 2; ++i) {
      drive_t* dr = &d->drive[i];
      if (dr->rpdo_seen && !dr->rpdo_expired && t_s - dr->last_rpdo_s > d->cfg.rpdo_timeout_s) {
        dr->rpdo_expired = true;
        ++d->counters.rpdo_timeouts;
      }
    }
  }
}

void sim_cia402_get_command(sim_cia402_t* d, double t_s, sim_cia402_command_t* out) {
  (void)t_s;
  const drive_t* tr = &d->drive[0];
  const drive_t* rot = &d->drive[1];
  const bool run_t = drive_running(tr);
  const bool run_r = drive_running(rot);
  out->v_mps = run_t ? canopen_si_from_counts(tr->target_counts, d->cfg.trans_counts_per_m) : 0.0;
  out->omega_radps = run_r ? canopen_si_from_counts(rot->target_counts, d->cfg.rot_counts_per_rad) : 0.0;
  out->accel_trans_mps2 = run_t ? d->cfg.accel_trans_mps2 : d->cfg.quick_stop_trans_mps2;
  out->accel_rot_radps2 = run_r ? d->cfg.accel_rot_radps2 : d->cfg.quick_stop_rot_radps2;
}

bool sim_cia402_ready(const sim_cia402_t* d) {
  for (int i = 0; i < 2; ++i) {
    if (d->drive[i].nmt_state != CANOPEN_NMT_STATE_OPERATIONAL ||
        !cia402_drive_enabled(&d->drive[i].sm)) {
      return false;
    }
  }
  return true;
}

bool sim_cia402_operational(const sim_cia402_t* d) {
  return d->drive[0].nmt_state == CANOPEN_NMT_STATE_OPERATIONAL &&
         d->drive[1].nmt_state == CANOPEN_NMT_STATE_OPERATIONAL;
}

int sim_cia402_inject_fault(sim_cia402_t* d, uint8_t node, double t_s) {
  drive_t* dr = find(d, node);
  if (dr == NULL) {
    return -1;
  }
  cia402_drive_set_fault(&dr->sm, d->cfg.fault_code);
  emcy(d, dr, d->cfg.fault_code, CIA402_EMCY_REGISTER, t_s);
  cia402_drive_set_fault(&dr->sm, 0);  // transient: a fault reset recovers the drive
  return 0;
}

void sim_cia402_set_silent_until(sim_cia402_t* d, double t_s) { d->silent_until_s = t_s; }

int sim_cia402_drive_state(const sim_cia402_t* d, uint8_t node, uint16_t* statusword,
                           uint8_t* nmt_state) {
  for (int i = 0; i < 2; ++i) {
    if (d->drive[i].node == node) {
      if (statusword != NULL) {
        *statusword = cia402_drive_statusword(&d->drive[i].sm, false);
      }
      if (nmt_state != NULL) {
        *nmt_state = d->drive[i].nmt_state;
      }
      return 0;
    }
  }
  return -1;
}

const sim_cia402_counters_t* sim_cia402_get_counters(const sim_cia402_t* d) { return &d->counters; }
