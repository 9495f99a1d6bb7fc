// SPDX-License-Identifier: MIT
// rFLEX packets: encoder (with the host's no-raw-ESC rule), typed messages, streaming decoder,
// odometry integration.
#include <proto/rflex.h>

#include "bytes.h"

#include <math.h>
#include <string.h>

static bool port_ok(uint8_t port) { return port >= RFLEX_PORT_SYS && port <= RFLEX_PORT_IR; }

uint8_t rflex_checksum(const rflex_packet_t* pkt) {
  uint8_t x = (uint8_t)(pkt->port ^ pkt->id ^ pkt->opcode ^ pkt->dlen);
  for (size_t i = 0; i < pkt->dlen; ++i) {
    x ^= pkt->data[i];
  }
  return x;
}

bool rflex_packet_has_esc(const rflex_packet_t* pkt) {
  if (pkt->port == RFLEX_ESC || pkt->id == RFLEX_ESC || pkt->opcode == RFLEX_ESC ||
      pkt->dlen == RFLEX_ESC || rflex_checksum(pkt) == RFLEX_ESC) {
    return true;
  }
  return memchr(pkt->data, RFLEX_ESC, pkt->dlen) != NULL;
}

size_t rflex_encode(uint8_t* buf, size_t cap, const rflex_packet_t* pkt, rflex_stuffing_t mode) {
  if (buf == NULL || pkt == NULL) {
    return 0;
  }
  if (mode == RFLEX_HOST_STRICT && rflex_packet_has_esc(pkt)) {
    return 0;
  }
  const bool stuff = mode == RFLEX_DEVICE_STUFFED;
  const uint8_t chk = rflex_checksum(pkt);
  size_t n = 0;
  // Writes one body byte, doubling a 0x1B as ESC NUL when stuffing; false when out of room.
#define PUT_BODY(b)                                 \
  do {                                              \
    const uint8_t b_ = (uint8_t)(b);                \
    const size_t need_ = (stuff && b_ == RFLEX_ESC) ? 2U : 1U; \
    if (n + need_ > cap) {                          \
      return 0;                                     \
    }                                               \
    buf[n++] = b_;                                  \
    if (need_ == 2U) {                              \
      buf[n++] = RFLEX_NUL;                         \
    }                                               \
  } while (0)
  if (cap < RFLEX_PACKET_BYTES(pkt->dlen)) {
    return 0;
  }
  buf[n++] = RFLEX_ESC;
  buf[n++] = RFLEX_STX;
  PUT_BODY(pkt->port);
  PUT_BODY(pkt->id);
  PUT_BODY(pkt->opcode);
  PUT_BODY(pkt->dlen);
  for (size_t i = 0; i < pkt->dlen; ++i) {
    PUT_BODY(pkt->data[i]);
  }
  PUT_BODY(chk);
#undef PUT_BODY
  if (n + 2U > cap) {
    return 0;
  }
  buf[n++] = RFLEX_ESC;
  buf[n++] = RFLEX_ETX;
  return n;
}

// ---------------------------------------------------------------------------------------------
// Parameters

void rflex_b21r_params_default(rflex_b21r_params_t* p) {
  if (p == NULL) {
    return;
  }
  p->trans_counts_per_m = 103000.0;
  p->rot_counts_per_rad = 35000.0;
  p->trans_acc_mps2 = 0.7;
  p->trans_torque = 30000U;
  p->rot_acc_counts = 100000U;
  p->rot_torque = 35000U;
  p->power_offset_v = 1.2;
  p->odom_max_step_m = 1.0;
  p->odom_max_step_rad = 1.0;
}

static bool positive(double x) { return isfinite(x) && x > 0.0; }

proto_status_t rflex_b21r_params_check(const rflex_b21r_params_t* p) {
  if (p == NULL || !positive(p->trans_counts_per_m) || !positive(p->rot_counts_per_rad) ||
      !positive(p->trans_acc_mps2) || !isfinite(p->power_offset_v) ||
      !positive(p->odom_max_step_m) || !positive(p->odom_max_step_rad)) {
    return PROTO_ERR_INVALID_ARG;
  }
  return PROTO_OK;
}

// ---------------------------------------------------------------------------------------------
// Host commands

static void pkt_start(rflex_packet_t* pkt, uint8_t port, uint8_t id, uint8_t opcode, uint8_t dlen) {
  memset(pkt, 0, sizeof *pkt);
  pkt->port = port;
  pkt->id = id;
  pkt->opcode = opcode;
  pkt->dlen = dlen;
}

proto_status_t rflex_make_set_dir(rflex_packet_t* pkt, uint8_t axis, uint32_t vel_mag,
                                  uint32_t acc, uint32_t torque, uint8_t dir) {
  if (pkt == NULL || axis > RFLEX_AXIS_ROT || dir > 1U) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_MOT, 0, RFLEX_OP_MOT_AXIS_SET_DIR, 14);
  pkt->data[0] = axis;
  proto_put_be32(&pkt->data[1], vel_mag);
  proto_put_be32(&pkt->data[5], acc);
  proto_put_be32(&pkt->data[9], torque);
  pkt->data[13] = dir;
  return PROTO_OK;
}

// Nearest value without a 0x1B byte: if byte k (the highest such) is 0x1B, the candidates are
// byte k = 0x1A with all lower bytes 0xFF, and byte k = 0x1C with all lower bytes 0x00. Ties go
// to the smaller value (toward zero). At most 256^k counts away.
static uint32_t clean_u32(uint32_t v) {
  for (int k = 3; k >= 0; --k) {
    const unsigned shift = 8U * (unsigned)k;
    if (((v >> shift) & 0xFFU) == RFLEX_ESC) {
      const uint32_t low_mask = shift == 0U ? 0U : (uint32_t)((1ULL << shift) - 1U);
      const uint32_t high = v & ~(low_mask | (0xFFU << shift));
      const uint32_t below = high | (0x1AU << shift) | low_mask;
      const uint32_t above = high | (0x1CU << shift);
      return (v - below <= above - v) ? below : above;
    }
  }
  return v;
}

static bool u32_clean(uint32_t v) { return clean_u32(v) == v; }

// Largest search for a clean velocity (or acceleration) that also gives a clean checksum; the
// checksum changes with the low byte, so a few steps always suffice.
#define NUDGE_SEARCH 64

proto_status_t rflex_make_axis_velocity(rflex_packet_t* pkt, uint8_t axis, int32_t vel_counts,
                                        uint32_t acc_counts, uint32_t torque,
                                        int32_t* nudge_counts) {
  if (pkt == NULL || axis > RFLEX_AXIS_ROT) {
    return PROTO_ERR_INVALID_ARG;
  }
  const uint8_t dir = vel_counts >= 0 ? 1U : 0U;
  const uint32_t mag = vel_counts >= 0 ? (uint32_t)vel_counts : 0U - (uint32_t)vel_counts;
  const uint32_t acc = clean_u32(acc_counts);
  const uint32_t tq = clean_u32(torque);
  // A zero velocity must stay exactly zero (a stop), so then the acceleration absorbs the nudge.
  const bool nudge_vel = mag != 0U;
  const uint32_t want = nudge_vel ? mag : acc_counts;
  const uint32_t base = nudge_vel ? clean_u32(mag) : acc;
  for (int32_t i = 0; i <= 2 * NUDGE_SEARCH; ++i) {
    // 0, -1, +1, -2, +2, ...: the smaller magnitude first.
    const int32_t d = (i % 2 == 1) ? -((i + 1) / 2) : i / 2;
    if (d < 0 && base < (uint32_t)(-d) + (nudge_vel ? 1U : 0U)) {
      continue;  // never cross zero (or make a velocity zero)
    }
    if (d > 0 && base > UINT32_MAX - (uint32_t)d) {
      continue;
    }
    const uint32_t v = d >= 0 ? base + (uint32_t)d : base - (uint32_t)(-d);
    if (!u32_clean(v)) {
      continue;
    }
    if (nudge_vel) {
      (void)rflex_make_set_dir(pkt, axis, v, acc, tq, dir);
    } else {
      (void)rflex_make_set_dir(pkt, axis, 0U, v, tq, dir);
    }
    if (!rflex_packet_has_esc(pkt)) {
      if (nudge_counts != NULL) {
        *nudge_counts = (int32_t)((int64_t)v - (int64_t)want);
      }
      return PROTO_OK;
    }
  }
  return PROTO_ERR_RANGE;
}

static int32_t counts_i32(double x) {
  if (!(x < 2147483647.0)) {
    return INT32_MAX;
  }
  if (!(x > -2147483647.0)) {
    return -INT32_MAX;
  }
  return (int32_t)lround(x);
}

static uint32_t counts_u32(double x) {
  if (!(x > 0.0)) {
    return 0U;
  }
  if (x >= 4294967295.0) {
    return UINT32_MAX;
  }
  return (uint32_t)llround(x);
}

proto_status_t rflex_make_velocity(rflex_packet_t out[2], const rflex_b21r_params_t* params,
                                   double v_mps, double omega_radps, double trans_acc_mps2) {
  if (out == NULL || rflex_b21r_params_check(params) != PROTO_OK || !isfinite(v_mps) ||
      !isfinite(omega_radps)) {
    return PROTO_ERR_INVALID_ARG;
  }
  const double acc = (isfinite(trans_acc_mps2) && trans_acc_mps2 > 0.0) ? trans_acc_mps2
                                                                       : params->trans_acc_mps2;
  proto_status_t st = rflex_make_axis_velocity(
      &out[0], RFLEX_AXIS_TRANS, counts_i32(v_mps * params->trans_counts_per_m),
      counts_u32(acc * params->trans_counts_per_m), params->trans_torque, NULL);
  if (st != PROTO_OK) {
    return st;
  }
  st = rflex_make_axis_velocity(&out[1], RFLEX_AXIS_ROT,
                                counts_i32(omega_radps * params->rot_counts_per_rad),
                                params->rot_acc_counts, params->rot_torque, NULL);
  return st;
}

void rflex_make_brake_set(rflex_packet_t* pkt) {
  pkt_start(pkt, RFLEX_PORT_MOT, 0, RFLEX_OP_MOT_BRAKE_SET, 0);
}

void rflex_make_brake_release(rflex_packet_t* pkt) {
  pkt_start(pkt, RFLEX_PORT_MOT, 0, RFLEX_OP_MOT_BRAKE_RELEASE, 0);
}

void rflex_make_set_defaults(rflex_packet_t* pkt) {
  pkt_start(pkt, RFLEX_PORT_MOT, 0, RFLEX_OP_MOT_SET_DEFAULTS, 0);
}

void rflex_make_sys_status_request(rflex_packet_t* pkt) {
  pkt_start(pkt, RFLEX_PORT_SYS, 0, RFLEX_OP_SYS_STATUS, 0);
}

// Typed host builders other than SET_DIR carry caller values verbatim; refuse rather than send
// a raw 0x1B the base could take for a marker.
static proto_status_t host_clean(const rflex_packet_t* pkt) {
  return rflex_packet_has_esc(pkt) ? PROTO_ERR_RANGE : PROTO_OK;
}

proto_status_t rflex_make_odometry_request(rflex_packet_t* pkt, uint32_t period, uint32_t axis_mask) {
  if (pkt == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_MOT, 0, RFLEX_OP_MOT_SYSTEM_REPORT_REQ, 8);
  proto_put_be32(&pkt->data[0], period);
  proto_put_be32(&pkt->data[4], axis_mask);
  return host_clean(pkt);
}

proto_status_t rflex_make_dio_request(rflex_packet_t* pkt, uint32_t period) {
  if (pkt == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_DIO, 0, RFLEX_OP_DIO_REPORTS_REQ, 4);
  proto_put_be32(&pkt->data[0], period);
  return host_clean(pkt);
}

proto_status_t rflex_make_sonar_run(rflex_packet_t* pkt, uint32_t echo_delay, uint32_t ping_delay,
                                    uint32_t set_delay, uint8_t mode) {
  if (pkt == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_SONAR, 4, RFLEX_OP_SONAR_RUN, 13);
  proto_put_be32(&pkt->data[0], echo_delay);
  proto_put_be32(&pkt->data[4], ping_delay);
  proto_put_be32(&pkt->data[8], set_delay);
  pkt->data[12] = mode;
  return host_clean(pkt);
}

void rflex_make_sonar_off(rflex_packet_t* pkt) { (void)rflex_make_sonar_run(pkt, 0, 0, 0, 0); }

proto_status_t rflex_make_ir_run(rflex_packet_t* pkt, const uint32_t values[5], uint8_t run) {
  if (pkt == NULL || values == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_IR, 0, RFLEX_OP_IR_RUN, 21);
  for (size_t i = 0; i < 5U; ++i) {
    proto_put_be32(&pkt->data[4U * i], values[i]);
  }
  pkt->data[20] = run;
  return host_clean(pkt);
}

void rflex_make_ir_off(rflex_packet_t* pkt) {
  static const uint32_t zeros[5] = {0, 0, 0, 0, 0};
  (void)rflex_make_ir_run(pkt, zeros, 0);
}

// ---------------------------------------------------------------------------------------------
// Device reports

proto_status_t rflex_make_motor_report(rflex_packet_t* pkt, uint8_t id, const rflex_motor_report_t* r) {
  if (pkt == NULL || r == NULL || r->axis > RFLEX_AXIS_ROT) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_MOT, id, RFLEX_OP_MOT_SYSTEM_REPORT, 25);
  proto_put_be32(&pkt->data[0], r->rv);
  proto_put_be32(&pkt->data[4], r->timestamp);
  pkt->data[8] = r->axis;
  proto_put_be32(&pkt->data[9], proto_u32(r->position));
  proto_put_be32(&pkt->data[13], proto_u32(r->velocity));
  proto_put_be32(&pkt->data[17], r->acceleration);
  proto_put_be32(&pkt->data[21], r->torque);
  return PROTO_OK;
}

proto_status_t rflex_make_sys_status(rflex_packet_t* pkt, uint8_t id, const rflex_sys_status_t* s) {
  if (pkt == NULL || s == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_SYS, id, RFLEX_OP_SYS_STATUS, 9);
  proto_put_be32(&pkt->data[0], s->timestamp);
  proto_put_be32(&pkt->data[4], s->voltage_raw);
  pkt->data[8] = s->brake;
  return PROTO_OK;
}

proto_status_t rflex_make_dio_report(rflex_packet_t* pkt, uint8_t id, const rflex_dio_report_t* d) {
  if (pkt == NULL || d == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  pkt_start(pkt, RFLEX_PORT_DIO, id, RFLEX_OP_DIO_REPORT, 7);
  proto_put_be32(&pkt->data[0], d->timestamp);
  pkt->data[4] = d->address;
  proto_put_be16(&pkt->data[5], d->value);
  return PROTO_OK;
}

static bool is_msg(const rflex_packet_t* pkt, uint8_t port, uint8_t opcode, uint8_t min_dlen) {
  return pkt->port == port && pkt->opcode == opcode && pkt->dlen >= min_dlen;
}

proto_status_t rflex_parse_motor_report(const rflex_packet_t* pkt, rflex_motor_report_t* out) {
  if (pkt == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_msg(pkt, RFLEX_PORT_MOT, RFLEX_OP_MOT_SYSTEM_REPORT, 25)) {
    return PROTO_ERR_FORMAT;
  }
  out->rv = proto_be32(&pkt->data[0]);
  out->timestamp = proto_be32(&pkt->data[4]);
  out->axis = pkt->data[8];
  out->position = proto_i32(proto_be32(&pkt->data[9]));
  out->velocity = proto_i32(proto_be32(&pkt->data[13]));
  out->acceleration = proto_be32(&pkt->data[17]);
  out->torque = proto_be32(&pkt->data[21]);
  return PROTO_OK;
}

proto_status_t rflex_parse_sys_status(const rflex_packet_t* pkt, rflex_sys_status_t* out) {
  if (pkt == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_msg(pkt, RFLEX_PORT_SYS, RFLEX_OP_SYS_STATUS, 9)) {
    return PROTO_ERR_FORMAT;
  }
  out->timestamp = proto_be32(&pkt->data[0]);
  out->voltage_raw = proto_be32(&pkt->data[4]);
  out->brake = pkt->data[8];
  return PROTO_OK;
}

proto_status_t rflex_parse_dio_report(const rflex_packet_t* pkt, rflex_dio_report_t* out) {
  if (pkt == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_msg(pkt, RFLEX_PORT_DIO, RFLEX_OP_DIO_REPORT, 7)) {
    return PROTO_ERR_FORMAT;
  }
  out->timestamp = proto_be32(&pkt->data[0]);
  out->address = pkt->data[4];
  out->value = proto_be16(&pkt->data[5]);
  return PROTO_OK;
}

double rflex_battery_volts(uint32_t voltage_raw, double offset_v) {
  return (double)voltage_raw / 100.0 + offset_v;
}

int rflex_dio_bumper_panel(uint8_t address) {
  if (address >= RFLEX_DIO_BUMPER_FIRST &&
      address < RFLEX_DIO_BUMPER_FIRST + RFLEX_DIO_BUMPER_COUNT) {
    return (int)address - (int)RFLEX_DIO_BUMPER_FIRST;
  }
  return -1;
}

// ---------------------------------------------------------------------------------------------
// Device-side command parsing

rflex_msg_kind_t rflex_classify(const rflex_packet_t* pkt) {
  if (pkt == NULL) {
    return RFLEX_MSG_UNKNOWN;
  }
  switch (pkt->port) {
    case RFLEX_PORT_SYS:
      if (pkt->opcode == RFLEX_OP_SYS_STATUS) {
        return RFLEX_MSG_SYS_STATUS;
      }
      if (pkt->opcode == RFLEX_OP_SYS_LCD_DUMP) {
        return RFLEX_MSG_SYS_LCD_DUMP;
      }
      break;
    case RFLEX_PORT_MOT:
      switch (pkt->opcode) {
        case RFLEX_OP_MOT_AXIS_SET_DIR:
          return RFLEX_MSG_SET_DIR;
        case RFLEX_OP_MOT_AXIS_SET_POS:
          return RFLEX_MSG_SET_POS;
        case RFLEX_OP_MOT_SET_DEFAULTS:
          return RFLEX_MSG_SET_DEFAULTS;
        case RFLEX_OP_MOT_BRAKE_SET:
          return RFLEX_MSG_BRAKE_SET;
        case RFLEX_OP_MOT_BRAKE_RELEASE:
          return RFLEX_MSG_BRAKE_RELEASE;
        case RFLEX_OP_MOT_SYSTEM_REPORT:
          return RFLEX_MSG_MOTOR_REPORT;
        case RFLEX_OP_MOT_SYSTEM_REPORT_REQ:
          return RFLEX_MSG_ODOMETRY_REQUEST;
        default:
          break;
      }
      break;
    case RFLEX_PORT_JSTK:
      if (pkt->opcode == RFLEX_OP_JSTK_GET_STATE) {
        return RFLEX_MSG_JSTK;
      }
      break;
    case RFLEX_PORT_SONAR:
      if (pkt->opcode == RFLEX_OP_SONAR_RUN) {
        return RFLEX_MSG_SONAR_RUN;
      }
      if (pkt->opcode == RFLEX_OP_SONAR_REPORT) {
        return RFLEX_MSG_SONAR_REPORT;
      }
      break;
    case RFLEX_PORT_DIO:
      if (pkt->opcode == RFLEX_OP_DIO_REPORTS_REQ) {
        return RFLEX_MSG_DIO_REQUEST;
      }
      if (pkt->opcode == RFLEX_OP_DIO_REPORT) {
        return RFLEX_MSG_DIO_REPORT;
      }
      break;
    case RFLEX_PORT_IR:
      if (pkt->opcode == RFLEX_OP_IR_RUN) {
        return RFLEX_MSG_IR_RUN;
      }
      if (pkt->opcode == RFLEX_OP_IR_REPORT) {
        return RFLEX_MSG_IR_REPORT;
      }
      break;
    default:
      break;
  }
  return RFLEX_MSG_UNKNOWN;
}

proto_status_t rflex_parse_set_dir(const rflex_packet_t* pkt, rflex_set_dir_t* out) {
  if (pkt == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_msg(pkt, RFLEX_PORT_MOT, RFLEX_OP_MOT_AXIS_SET_DIR, 14)) {
    return PROTO_ERR_FORMAT;
  }
  out->axis = pkt->data[0];
  out->vel_mag = proto_be32(&pkt->data[1]);
  out->acc = proto_be32(&pkt->data[5]);
  out->torque = proto_be32(&pkt->data[9]);
  out->dir = pkt->data[13];
  const int32_t mag = out->vel_mag > (uint32_t)INT32_MAX ? INT32_MAX : (int32_t)out->vel_mag;
  // Any nonzero direction byte counts as "positive", as the drivers only ever send 0 or 1.
  out->vel_counts = out->dir != 0U ? mag : -mag;
  return out->axis > RFLEX_AXIS_ROT ? PROTO_ERR_RANGE : PROTO_OK;
}

proto_status_t rflex_parse_odometry_request(const rflex_packet_t* pkt, uint32_t* period,
                                            uint32_t* axis_mask) {
  if (pkt == NULL || period == NULL || axis_mask == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_msg(pkt, RFLEX_PORT_MOT, RFLEX_OP_MOT_SYSTEM_REPORT_REQ, 8)) {
    return PROTO_ERR_FORMAT;
  }
  *period = proto_be32(&pkt->data[0]);
  *axis_mask = proto_be32(&pkt->data[4]);
  return PROTO_OK;
}

proto_status_t rflex_parse_dio_request(const rflex_packet_t* pkt, uint32_t* period) {
  if (pkt == NULL || period == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  const bool dio = is_msg(pkt, RFLEX_PORT_DIO, RFLEX_OP_DIO_REPORTS_REQ, 4);
  // Older drivers send "DIO off" to the SONAR port (opcode 0, DLEN 4).
  const bool legacy = pkt->port == RFLEX_PORT_SONAR && pkt->opcode == RFLEX_OP_SONAR_RUN &&
                      pkt->dlen == 4U;
  if (!dio && !legacy) {
    return PROTO_ERR_FORMAT;
  }
  *period = proto_be32(&pkt->data[0]);
  return PROTO_OK;
}

proto_status_t rflex_parse_sonar_run(const rflex_packet_t* pkt, uint32_t* echo_delay,
                                     uint32_t* ping_delay, uint32_t* set_delay, uint8_t* mode) {
  if (pkt == NULL || echo_delay == NULL || ping_delay == NULL || set_delay == NULL || mode == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_msg(pkt, RFLEX_PORT_SONAR, RFLEX_OP_SONAR_RUN, 13)) {
    return PROTO_ERR_FORMAT;
  }
  *echo_delay = proto_be32(&pkt->data[0]);
  *ping_delay = proto_be32(&pkt->data[4]);
  *set_delay = proto_be32(&pkt->data[8]);
  *mode = pkt->data[12];
  return PROTO_OK;
}

// ---------------------------------------------------------------------------------------------
// Streaming decoder

void rflex_decoder_init_role(rflex_decoder_t* dec, rflex_role_t role) {
  if (dec != NULL) {
    memset(dec, 0, sizeof *dec);
    dec->role = (uint8_t)(role == RFLEX_ROLE_DEVICE ? RFLEX_ROLE_DEVICE : RFLEX_ROLE_HOST);
  }
}

void rflex_decoder_init(rflex_decoder_t* dec) { rflex_decoder_init_role(dec, RFLEX_ROLE_HOST); }

static void rx_drop_front(rflex_decoder_t* dec, size_t n) {
  memmove(dec->buf, dec->buf + n, dec->fill - n);
  dec->fill = (uint16_t)(dec->fill - n);
  memset(&dec->scan, 0, sizeof dec->scan);  // a new candidate is scanned from its start
}

void rflex_decoder_reset(rflex_decoder_t* dec) {
  if (dec == NULL) {
    return;
  }
  if (dec->pending > 0U) {
    rx_drop_front(dec, dec->pending);
    dec->pending = 0;
  }
  dec->counters.bytes_dropped += dec->fill;
  dec->fill = 0;
  memset(&dec->scan, 0, sizeof dec->scan);
}

// Verdict of one interpretation of the candidate at the front of the buffer.
typedef enum verdict { V_NEED_MORE, V_OK, V_BAD_PORT, V_BAD_CHECKSUM, V_BAD_FRAMING } verdict_t;

// Checks an unstuffed body (PORT..CHK, n bytes) and copies it into *out on success.
static verdict_t check_body(const uint8_t* body, size_t n, rflex_packet_t* out) {
  if (n < 5U || !port_ok(body[0])) {
    return n >= 1U && !port_ok(body[0]) ? V_BAD_PORT : V_BAD_FRAMING;
  }
  if ((size_t)body[3] + 5U != n) {
    return V_BAD_FRAMING;
  }
  uint8_t x = 0;
  for (size_t i = 0; i + 1U < n; ++i) {
    x ^= body[i];
  }
  if (x != body[n - 1U]) {
    return V_BAD_CHECKSUM;
  }
  out->port = body[0];
  out->id = body[1];
  out->opcode = body[2];
  out->dlen = body[3];
  memcpy(out->data, &body[4], body[3]);
  return V_OK;
}

// Raw interpretation: DLEN framing, no de-stuffing (what hosts send).
static verdict_t interpret_raw(const uint8_t* buf, size_t fill, rflex_packet_t* out, size_t* used,
                               bool* had_esc) {
  if (fill < 3U) {
    return V_NEED_MORE;
  }
  if (!port_ok(buf[2])) {
    return V_BAD_PORT;
  }
  if (fill < 6U) {
    return V_NEED_MORE;
  }
  const size_t total = RFLEX_PACKET_BYTES(buf[5]);
  if (fill < total) {
    return V_NEED_MORE;
  }
  if (buf[total - 2U] != RFLEX_ESC || buf[total - 1U] != RFLEX_ETX) {
    return V_BAD_FRAMING;
  }
  const verdict_t v = check_body(&buf[2], total - 4U, out);
  if (v == V_OK) {
    *used = total;
    *had_esc = memchr(&buf[2], RFLEX_ESC, total - 4U) != NULL;
  }
  return v;
}

// Stuffed interpretation: ESC NUL -> 0x1B, ESC SOH dropped, ESC ETX ends (what the base sends).
// Incremental: the de-stuffed body and the scan position of the candidate at the front of the
// buffer live in dec->scan and carry over between calls, so each byte is examined once; a
// verdict other than V_NEED_MORE is final for the candidate (more bytes cannot repair it) and is
// kept until the candidate is dropped (rx_drop_front resets the scan).
static verdict_t interpret_stuffed(rflex_decoder_t* dec, rflex_packet_t* out, size_t* used, bool* had_stuffing) {
  rflex_stuffed_scan_t* st = &dec->scan;
  if (st->verdict != (uint8_t)V_NEED_MORE) {
    return (verdict_t)st->verdict;
  }
  if (st->pos < 2U) {
    st->pos = 2U;
  }
  const size_t fill = dec->fill;
  verdict_t v = V_NEED_MORE;
  size_t i = st->pos;
  while (i < fill && v == V_NEED_MORE) {
    uint8_t b = dec->buf[i];
    if (b == RFLEX_ESC) {
      if (i + 1U >= fill) {
        break;  // resume at this ESC once its partner has arrived
      }
      const uint8_t next = dec->buf[i + 1U];
      i += 2U;
      if (next == RFLEX_ETX) {
        v = check_body(st->body, st->n, out);
        if (v == V_OK) {
          *used = i;
          *had_stuffing = st->stuffed != 0U;
        }
        break;
      }
      if (next == RFLEX_SOH) {
        st->stuffed = 1U;
        continue;
      }
      if (next != RFLEX_NUL) {
        v = V_BAD_FRAMING;
        break;
      }
      st->stuffed = 1U;
      b = RFLEX_ESC;
    } else {
      ++i;
    }
    if (st->n == 0U && !port_ok(b)) {
      v = V_BAD_PORT;
    } else if (st->n >= sizeof st->body || (st->n >= 4U && st->n >= (size_t)st->body[3] + 5U)) {
      // Longer than DLEN says (PORT ID OP DLEN data CHK) without an ESC ETX: not a packet.
      v = V_BAD_FRAMING;
    } else {
      st->body[st->n++] = b;
    }
  }
  st->pos = (uint16_t)i;
  st->verdict = (uint8_t)v;
  return v;
}

typedef enum rx_result { RX_NEED_MORE, RX_DROPPED, RX_PACKET } rx_result_t;

static rx_result_t rx_scan(rflex_decoder_t* dec, rflex_packet_t* out) {
  if (dec->fill == 0U) {
    return RX_NEED_MORE;
  }
  if (dec->buf[0] != RFLEX_ESC) {
    size_t n = 1;
    while (n < dec->fill && dec->buf[n] != RFLEX_ESC) {
      ++n;
    }
    dec->counters.bytes_garbage += n;
    dec->counters.bytes_dropped += n;
    rx_drop_front(dec, n);
    return RX_DROPPED;
  }
  if (dec->fill < 2U) {
    return RX_NEED_MORE;
  }
  if (dec->buf[1] != RFLEX_STX) {
    // ESC ESC restarts the hunt at the second ESC; ESC x is garbage.
    dec->counters.bytes_garbage++;
    dec->counters.bytes_dropped++;
    rx_drop_front(dec, 1);
    return RX_DROPPED;
  }
  size_t used = 0;
  bool flag = false;
  const verdict_t vs = interpret_stuffed(dec, out, &used, &flag);
  if (vs == V_OK) {
    dec->counters.packets_ok++;
    if (flag) {
      dec->counters.packets_stuffed++;
    }
    dec->pending = (uint16_t)used;
    return RX_PACKET;
  }
  // The base always stuffs its output (protocols.md A.2): the host role never falls back to raw
  // framing, which would accept a stuffed packet that lost a byte with its fields shifted.
  const verdict_t vr =
      dec->role == RFLEX_ROLE_DEVICE ? interpret_raw(dec->buf, dec->fill, out, &used, &flag) : vs;
  if (vr == V_OK) {
    dec->counters.packets_ok++;
    if (flag) {
      dec->counters.packets_raw_esc++;
    }
    dec->pending = (uint16_t)used;
    return RX_PACKET;
  }
  if (vs == V_NEED_MORE || vr == V_NEED_MORE) {
    if (dec->fill < RFLEX_DECODER_BUF_BYTES) {
      return RX_NEED_MORE;
    }
    dec->counters.too_long++;
  } else if (vs == V_BAD_PORT && vr == V_BAD_PORT) {
    dec->counters.bad_port++;
  } else if (vs == V_BAD_CHECKSUM || vr == V_BAD_CHECKSUM) {
    dec->counters.bad_checksum++;
  } else {
    dec->counters.bad_framing++;
  }
  // Drop only the ESC of the false start: a real packet may begin inside the candidate.
  dec->counters.bytes_dropped++;
  rx_drop_front(dec, 1);
  return RX_DROPPED;
}

size_t rflex_decoder_push(rflex_decoder_t* dec, const uint8_t* bytes, size_t len,
                          rflex_packet_t* out, bool* got_packet) {
  if (got_packet != NULL) {
    *got_packet = false;
  }
  if (dec == NULL || out == NULL || got_packet == NULL || (bytes == NULL && len > 0U)) {
    return len;
  }
  if (dec->pending > 0U) {
    rx_drop_front(dec, dec->pending);
    dec->pending = 0;
  }
  size_t used = 0;
  for (;;) {
    const rx_result_t r = rx_scan(dec, out);
    if (r == RX_PACKET) {
      *got_packet = true;
      return used;
    }
    if (r == RX_DROPPED) {
      continue;
    }
    if (used == len) {
      return used;
    }
    dec->buf[dec->fill++] = bytes[used++];
    dec->counters.bytes_in++;
  }
}

// ---------------------------------------------------------------------------------------------
// Odometry

proto_status_t rflex_odom_init(rflex_odometry_t* odo, const rflex_b21r_params_t* params) {
  if (odo == NULL || rflex_b21r_params_check(params) != PROTO_OK) {
    return PROTO_ERR_INVALID_ARG;
  }
  memset(odo, 0, sizeof *odo);
  odo->params = *params;
  return PROTO_OK;
}

proto_status_t rflex_odom_feed(rflex_odometry_t* odo, const rflex_motor_report_t* report) {
  if (odo == NULL || report == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (report->axis == RFLEX_AXIS_TRANS) {
    odo->trans_latest = report->position;
    odo->have_trans = true;
    odo->v_mps = (double)report->velocity / odo->params.trans_counts_per_m;
  } else if (report->axis == RFLEX_AXIS_ROT) {
    odo->rot_latest = report->position;
    odo->have_rot = true;
    odo->omega_radps = (double)report->velocity / odo->params.rot_counts_per_rad;
  } else {
    return PROTO_ERR_RANGE;
  }
  return PROTO_OK;
}

static const double k_pi = 3.14159265358979323846;

static double wrap_pi(double a) {
  double r = remainder(a, 2.0 * k_pi);
  if (r <= -k_pi) {
    r += 2.0 * k_pi;
  }
  return r;
}

// Difference of two counters with int32 wrap-around (modular subtraction).
static int32_t wrap_diff(int32_t now, int32_t before) {
  return proto_i32((uint32_t)now - (uint32_t)before);
}

bool rflex_odom_update(rflex_odometry_t* odo) {
  if (odo == NULL || !odo->have_trans || !odo->have_rot) {
    return false;
  }
  if (!odo->baseline) {
    odo->trans_used = odo->trans_latest;
    odo->rot_used = odo->rot_latest;
    odo->baseline = true;
    return true;
  }
  const double dtheta =
      (double)wrap_diff(odo->rot_latest, odo->rot_used) / odo->params.rot_counts_per_rad;
  const double d =
      (double)wrap_diff(odo->trans_latest, odo->trans_used) / odo->params.trans_counts_per_m;
  odo->trans_used = odo->trans_latest;
  odo->rot_used = odo->rot_latest;
  // Heading first, then translation along the new heading (Player's rule).
  if (fabs(dtheta) > odo->params.odom_max_step_rad) {
    odo->rejected_rot++;
  } else {
    odo->theta_rad = wrap_pi(odo->theta_rad + dtheta);
  }
  if (fabs(d) > odo->params.odom_max_step_m) {
    odo->rejected_trans++;
  } else {
    odo->x_m += d * cos(odo->theta_rad);
    odo->y_m += d * sin(odo->theta_rad);
  }
  odo->updates++;
  return true;
}

bool rflex_odom_follow(rflex_odometry_t* odo, const rflex_odometry_t* source) {
  if (odo == NULL || source == NULL) {
    return false;
  }
  odo->have_trans = source->have_trans;
  odo->have_rot = source->have_rot;
  odo->trans_latest = source->trans_latest;
  odo->rot_latest = source->rot_latest;
  return rflex_odom_update(odo);
}

void rflex_odom_set_pose(rflex_odometry_t* odo, double x_m, double y_m, double theta_rad) {
  if (odo == NULL) {
    return;
  }
  odo->x_m = x_m;
  odo->y_m = y_m;
  odo->theta_rad = isfinite(theta_rad) ? wrap_pi(theta_rad) : 0.0;
}

// ---------------------------------------------------------------------------------------------
// Host view of the base

proto_status_t rflex_host_init(rflex_host_t* host, const rflex_b21r_params_t* params) {
  if (host == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  memset(host, 0, sizeof *host);
  rflex_decoder_init(&host->decoder);
  host->brake = -1;
  return rflex_odom_init(&host->odometry, params);
}

rflex_msg_kind_t rflex_host_handle(rflex_host_t* host, const rflex_packet_t* pkt) {
  host->packets++;
  const rflex_msg_kind_t kind = rflex_classify(pkt);
  switch (kind) {
    case RFLEX_MSG_MOTOR_REPORT: {
      rflex_motor_report_t r;
      if (rflex_parse_motor_report(pkt, &r) == PROTO_OK && rflex_odom_feed(&host->odometry, &r) == PROTO_OK) {
        host->report_new[r.axis] = true;
      }
      break;
    }
    case RFLEX_MSG_SYS_STATUS: {
      rflex_sys_status_t st;
      // DLEN 0 is the host's own request echoed by nobody; only replies carry the fields.
      if (pkt->dlen >= 9U && rflex_parse_sys_status(pkt, &st) == PROTO_OK) {
        host->brake = st.brake != 0U ? 1 : 0;
        host->battery_v = rflex_battery_volts(st.voltage_raw, host->odometry.params.power_offset_v);
      }
      break;
    }
    case RFLEX_MSG_DIO_REPORT: {
      rflex_dio_report_t d;
      if (rflex_parse_dio_report(pkt, &d) == PROTO_OK) {
        const int panel = rflex_dio_bumper_panel(d.address);
        if (panel >= 0) {
          if ((d.value & 0x0FU) != 0U) {
            host->bumper_mask |= 1U << (unsigned)panel;
          } else {
            host->bumper_mask &= ~(1U << (unsigned)panel);
          }
        }
      }
      break;
    }
    default:
      break;  // sonar, IR, joystick and unknown reports are not used
  }
  return kind;
}

size_t rflex_host_feed(rflex_host_t* host, const uint8_t* bytes, size_t n) {
  size_t handled = 0U;
  while (n > 0U) {
    rflex_packet_t pkt;
    bool got = false;
    const size_t k = rflex_decoder_push(&host->decoder, bytes, n, &pkt, &got);
    bytes += k;
    n -= k;
    if (got) {
      (void)rflex_host_handle(host, &pkt);
      ++handled;
    }
  }
  return handled;
}
