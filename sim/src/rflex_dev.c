// SPDX-License-Identifier: MIT
// The emulated rFLEX base: command handling, odometry and bump-panel reports, watchdog, pacing.
#include "sim/rflex_dev.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "byteq.h"
#include "sim/plant.h"

struct sim_rflex {
  sim_rflex_config_t cfg;
  rflex_decoder_t dec;
  sim_byteq_t out;
  uint8_t next_id;
  bool brake;
  // Axis commands as received, SI.
  double v_cmd_mps, omega_cmd_radps;
  double acc_trans_mps2, acc_rot_radps2;
  uint32_t torque[2];
  bool have_command;
  double last_cmd_s;
  bool watchdog_tripped;
  uint32_t odo_period_us;
  uint32_t odo_mask;
  double next_odo_s;
  uint32_t dio_period_us;
  uint8_t panels_reported[SIM_RFLEX_PANELS];
  double silent_until_s;
  sim_rflex_counters_t counters;
  uint8_t tx[RFLEX_MAX_STUFFED_BYTES];
};

void sim_rflex_config_default(sim_rflex_config_t* cfg) {
  rflex_b21r_params_default(&cfg->params);
  cfg->watchdog_s = 1.0;
  cfg->brake_at_power_up = true;
  cfg->battery_v = 24.6;
  cfg->paced = false;
  cfg->baud = 115200;
}

static void set_default_accels(sim_rflex_t* d) {
  d->acc_trans_mps2 = d->cfg.params.trans_acc_mps2;
  d->acc_rot_radps2 = (double)d->cfg.params.rot_acc_counts / d->cfg.params.rot_counts_per_rad;
}

sim_rflex_t* sim_rflex_create(const sim_rflex_config_t* cfg) {
  if (cfg == NULL || rflex_b21r_params_check(&cfg->params) != PROTO_OK ||
      !isfinite(cfg->watchdog_s) || cfg->watchdog_s < 0.0 || !isfinite(cfg->battery_v) ||
      cfg->battery_v < 1.2 || cfg->baud == 0) {
    return NULL;
  }
  sim_rflex_t* d = calloc(1, sizeof(*d));
  if (d == NULL) {
    return NULL;
  }
  d->cfg = *cfg;
  rflex_decoder_init_role(&d->dec, RFLEX_ROLE_DEVICE);  // host commands: raw 0x1B allowed
  sim_byteq_init(&d->out);
  d->brake = cfg->brake_at_power_up;
  set_default_accels(d);
  return d;
}

void sim_rflex_destroy(sim_rflex_t* d) { free(d); }

static uint32_t timestamp(double t_s) {
  // 4 ms ticks, wrapping like a free-running 32-bit counter.
  return (uint32_t)(uint64_t)floor(t_s / 0.004);
}

static int32_t wrap_counts(double value, double factor) {
  const double c = nearbyint(value * factor);
  // Encoders wrap at 32 bits: reduce modulo 2^32 and reinterpret as two's complement.
  const double m = fmod(c, 4294967296.0);
  const uint32_t u = (uint32_t)(int64_t)(m < 0.0 ? m + 4294967296.0 : m);
  int32_t s;
  memcpy(&s, &u, sizeof(s));
  return s;
}

static void send(sim_rflex_t* d, rflex_packet_t* pkt, double t_s) {
  const size_t n = rflex_encode(d->tx, sizeof(d->tx), pkt, RFLEX_DEVICE_STUFFED);
  if (n == 0 || !sim_byteq_push(&d->out, d->tx, n, t_s, d->cfg.baud)) {
    ++d->counters.queue_overflows;
  }
  ++d->next_id;
}

static void handle_set_dir(sim_rflex_t* d, const rflex_packet_t* pkt, double t_s, int* cycle_end) {
  rflex_set_dir_t sd;
  if (rflex_parse_set_dir(pkt, &sd) != PROTO_OK) {
    ++d->counters.unanswered;
    return;
  }
  ++d->counters.set_dir;
  const double k = sd.axis == RFLEX_AXIS_TRANS ? d->cfg.params.trans_counts_per_m
                                               : d->cfg.params.rot_counts_per_rad;
  const double vel = (double)sd.vel_counts / k;
  const double acc = (double)sd.acc / k;
  if (sd.axis == RFLEX_AXIS_TRANS) {
    d->v_cmd_mps = vel;
    if (sd.acc > 0U) {
      d->acc_trans_mps2 = acc;
    }
  } else {
    d->omega_cmd_radps = vel;
    if (sd.acc > 0U) {
      d->acc_rot_radps2 = acc;
    }
    *cycle_end = 1;
  }
  d->torque[sd.axis] = sd.torque;
  d->have_command = true;
  d->last_cmd_s = t_s;
  d->watchdog_tripped = false;
}

static void handle_packet(sim_rflex_t* d, const rflex_packet_t* pkt, double t_s, int* cycle_end) {
  switch (rflex_classify(pkt)) {
    case RFLEX_MSG_SET_DIR:
      handle_set_dir(d, pkt, t_s, cycle_end);
      break;
    case RFLEX_MSG_BRAKE_SET:
      d->brake = true;
      break;
    case RFLEX_MSG_BRAKE_RELEASE:
      d->brake = false;
      break;
    case RFLEX_MSG_SET_DEFAULTS:
      d->v_cmd_mps = 0.0;
      d->omega_cmd_radps = 0.0;
      set_default_accels(d);
      break;
    case RFLEX_MSG_ODOMETRY_REQUEST: {
      uint32_t period = 0, mask = 0;
      if (rflex_parse_odometry_request(pkt, &period, &mask) == PROTO_OK) {
        d->odo_period_us = period;
        d->odo_mask = mask & 3U;
        d->next_odo_s = t_s;
      } else {
        ++d->counters.unanswered;
      }
      break;
    }
    case RFLEX_MSG_DIO_REQUEST: {
      uint32_t period = 0;
      if (rflex_parse_dio_request(pkt, &period) == PROTO_OK) {
        d->dio_period_us = period;
      } else {
        ++d->counters.unanswered;
      }
      break;
    }
    case RFLEX_MSG_SYS_STATUS: {
      if (pkt->dlen != 0U) {
        ++d->counters.unanswered;
        break;
      }
      rflex_sys_status_t st;
      st.timestamp = timestamp(t_s);
      st.voltage_raw = (uint32_t)lround((d->cfg.battery_v - d->cfg.params.power_offset_v) * 100.0);
      st.brake = d->brake ? 1U : 0U;
      rflex_packet_t reply;
      if (rflex_make_sys_status(&reply, d->next_id, &st) == PROTO_OK) {
        send(d, &reply, t_s);
      }
      break;
    }
    default:
      ++d->counters.unanswered;
      break;
  }
}

size_t sim_rflex_feed(sim_rflex_t* d, const uint8_t* bytes, size_t n, double t_s, int* cycle_end) {
  int end = 0;
  size_t used = 0;
  while (used < n && !end) {
    rflex_packet_t pkt;
    bool got = false;
    used += rflex_decoder_push(&d->dec, bytes + used, n - used, &pkt, &got);
    if (!got) {
      continue;
    }
    ++d->counters.packets_in;
    if (t_s < d->silent_until_s) {
      ++d->counters.ignored_silent;
      continue;
    }
    handle_packet(d, &pkt, t_s, &end);
  }
  if (cycle_end != NULL) {
    *cycle_end = end;
  }
  return used;
}

size_t sim_rflex_drain(sim_rflex_t* d, uint8_t* out, size_t cap, double t_s) {
  return sim_byteq_drain(&d->out, out, cap, t_s, d->cfg.paced);
}

void sim_rflex_get_command(sim_rflex_t* d, double t_s, sim_rflex_command_t* out) {
  if (d->have_command && d->cfg.watchdog_s > 0.0 && t_s - d->last_cmd_s > d->cfg.watchdog_s) {
    if (!d->watchdog_tripped) {
      d->watchdog_tripped = true;
      ++d->counters.watchdog_trips;
    }
  }
  const bool stop = d->brake || d->watchdog_tripped;
  out->v_mps = stop ? 0.0 : d->v_cmd_mps;
  out->omega_radps = stop ? 0.0 : d->omega_cmd_radps;
  out->accel_trans_mps2 = d->acc_trans_mps2;
  out->accel_rot_radps2 = d->acc_rot_radps2;
}

bool sim_rflex_odometry_on(const sim_rflex_t* d) { return d->odo_period_us > 0U && d->odo_mask != 0U; }

void sim_rflex_emit_dio(sim_rflex_t* d, const sim_rflex_sample_t* s, double t_s) {
  if (d->dio_period_us == 0U || t_s < d->silent_until_s) {
    return;
  }
  for (unsigned i = 0; i < SIM_RFLEX_PANELS; ++i) {
    if (s->panels[i] == d->panels_reported[i]) {
      continue;
    }
    rflex_dio_report_t r;
    r.timestamp = timestamp(t_s);
    r.address = (uint8_t)(RFLEX_DIO_BUMPER_FIRST + i);
    r.value = s->panels[i];
    rflex_packet_t pkt;
    if (rflex_make_dio_report(&pkt, d->next_id, &r) == PROTO_OK) {
      send(d, &pkt, t_s);
      ++d->counters.dio_reports;
    }
    d->panels_reported[i] = s->panels[i];
  }
}

void sim_rflex_emit_odometry(sim_rflex_t* d, const sim_rflex_sample_t* s, double t_s) {
  if (t_s < d->silent_until_s) {
    return;
  }
  if (sim_rflex_odometry_on(d)) {
    for (uint8_t axis = 0; axis < 2U; ++axis) {
      if ((d->odo_mask & (1U << axis)) == 0U) {
        continue;
      }
      const bool trans = axis == RFLEX_AXIS_TRANS;
      const double k = trans ? d->cfg.params.trans_counts_per_m : d->cfg.params.rot_counts_per_rad;
      rflex_motor_report_t r;
      r.rv = 0;
      r.timestamp = timestamp(t_s);
      r.axis = axis;
      r.position = trans ? sim_plant_axis_counts(s->odo_trans_at_reset_m, s->odo_trans_m, k)
                         : sim_plant_axis_counts(s->odo_rot_at_reset_rad, s->odo_rot_rad, k);
      r.velocity = wrap_counts(trans ? s->v_mps : s->omega_radps, k);
      r.acceleration = (uint32_t)lround((trans ? d->acc_trans_mps2 : d->acc_rot_radps2) * k);
      r.torque = d->torque[axis];
      rflex_packet_t pkt;
      if (rflex_make_motor_report(&pkt, d->next_id, &r) == PROTO_OK) {
        send(d, &pkt, t_s);
        ++d->counters.reports;
      }
    }
  }
  sim_rflex_emit_dio(d, s, t_s);
}

void sim_rflex_poll(sim_rflex_t* d, const sim_rflex_sample_t* s, double t_s) {
  if (sim_rflex_odometry_on(d) && t_s >= d->next_odo_s) {
    sim_rflex_emit_odometry(d, s, t_s);
    const double period_s = (double)d->odo_period_us * 1e-6;
    d->next_odo_s += period_s;
    if (d->next_odo_s < t_s) {
      d->next_odo_s = t_s + period_s;  // fell behind (e.g. after a silence): no burst
    }
  } else {
    sim_rflex_emit_dio(d, s, t_s);
  }
}

void sim_rflex_set_silent_until(sim_rflex_t* d, double t_s) {
  d->silent_until_s = t_s;
  if (t_s > 0.0) {
    sim_byteq_clear(&d->out);
  }
}

bool sim_rflex_brake(const sim_rflex_t* d) { return d->brake; }

const sim_rflex_counters_t* sim_rflex_get_counters(const sim_rflex_t* d) { return &d->counters; }
