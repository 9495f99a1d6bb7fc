// SPDX-License-Identifier: MIT
// CANopen frame codecs (CiA 402 drives, the CiA 401 bump-panel node), the CiA 402 state machine
// (host sequencer and emulated drive) and the heartbeat consumer.
#include <proto/canopen.h>

#include "bytes.h"

#include <math.h>
#include <string.h>

static bool node_ok(uint8_t node) { return node >= 1U && node <= CANOPEN_NODE_MAX; }

static void frame_start(canopen_frame_t* f, uint32_t id, uint8_t dlc) {
  memset(f, 0, sizeof *f);
  f->id = id;
  f->dlc = dlc;
}

proto_status_t canopen_encode_nmt(canopen_frame_t* f, uint8_t command, uint8_t node) {
  if (f == NULL || node > CANOPEN_NODE_MAX) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_NMT, 2);
  f->data[0] = command;
  f->data[1] = node;
  return PROTO_OK;
}

proto_status_t canopen_encode_sync(canopen_frame_t* f) {
  if (f == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_SYNC, 0);
  return PROTO_OK;
}

proto_status_t canopen_encode_rpdo1(canopen_frame_t* f, uint8_t node, uint16_t controlword,
                                    int32_t target_velocity) {
  if (f == NULL || !node_ok(node)) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_RPDO1 + node, 6);
  proto_put_le16(&f->data[0], controlword);
  proto_put_le32(&f->data[2], proto_u32(target_velocity));
  return PROTO_OK;
}

proto_status_t canopen_encode_tpdo1(canopen_frame_t* f, uint8_t node, uint16_t statusword,
                                    int32_t velocity_actual) {
  if (f == NULL || !node_ok(node)) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_TPDO1 + node, 6);
  proto_put_le16(&f->data[0], statusword);
  proto_put_le32(&f->data[2], proto_u32(velocity_actual));
  return PROTO_OK;
}

proto_status_t canopen_encode_tpdo2(canopen_frame_t* f, uint8_t node, int32_t position_actual) {
  if (f == NULL || !node_ok(node)) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_TPDO2 + node, 4);
  proto_put_le32(&f->data[0], proto_u32(position_actual));
  return PROTO_OK;
}

proto_status_t canopen_encode_heartbeat(canopen_frame_t* f, uint8_t node, uint8_t nmt_state) {
  if (f == NULL || !node_ok(node)) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_HEARTBEAT + node, 1);
  f->data[0] = nmt_state;
  return PROTO_OK;
}

proto_status_t canopen_encode_emcy(canopen_frame_t* f, uint8_t node, uint16_t error_code,
                                   uint8_t error_register, const uint8_t* vendor) {
  if (f == NULL || !node_ok(node)) {
    return PROTO_ERR_INVALID_ARG;
  }
  frame_start(f, CANOPEN_COB_EMCY + node, 8);
  proto_put_le16(&f->data[0], error_code);
  f->data[2] = error_register;
  if (vendor != NULL) {
    memcpy(&f->data[3], vendor, 5);
  }
  return PROTO_OK;
}

canopen_kind_t canopen_classify(const canopen_frame_t* f, uint8_t* node) {
  canopen_kind_t kind = CANOPEN_KIND_UNKNOWN;
  uint8_t n = 0;
  if (f != NULL && f->id <= 0x7FFU) {
    const uint32_t fn = f->id & 0x780U;
    const uint32_t id = f->id & 0x7FU;
    if (f->id == CANOPEN_COB_NMT) {
      kind = CANOPEN_KIND_NMT;
    } else if (f->id == CANOPEN_COB_SYNC) {
      kind = CANOPEN_KIND_SYNC;
    } else if (id != 0U) {
      n = (uint8_t)id;
      switch (fn) {
        case CANOPEN_COB_EMCY:
          kind = CANOPEN_KIND_EMCY;
          break;
        case CANOPEN_COB_TPDO1:
          kind = CANOPEN_KIND_TPDO1;
          break;
        case CANOPEN_COB_RPDO1:
          kind = CANOPEN_KIND_RPDO1;
          break;
        case CANOPEN_COB_TPDO2:
          kind = CANOPEN_KIND_TPDO2;
          break;
        case CANOPEN_COB_RPDO2:
          kind = CANOPEN_KIND_RPDO2;
          break;
        case CANOPEN_COB_HEARTBEAT:
          kind = CANOPEN_KIND_HEARTBEAT;
          break;
        default:
          n = 0;
          break;
      }
    }
  }
  if (node != NULL) {
    *node = n;
  }
  return kind;
}

// Common check of the decoders: the right kind and at least `min_dlc` bytes.
static proto_status_t check_frame(const canopen_frame_t* f, const void* out, canopen_kind_t want,
                                  uint8_t min_dlc, uint8_t* node) {
  if (f == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (canopen_classify(f, node) != want || f->dlc < min_dlc || f->dlc > 8U) {
    return PROTO_ERR_FORMAT;
  }
  return PROTO_OK;
}

proto_status_t canopen_decode_nmt(const canopen_frame_t* f, canopen_nmt_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_NMT, 2, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->command = f->data[0];
  out->node = f->data[1];
  return PROTO_OK;
}

proto_status_t canopen_decode_emcy(const canopen_frame_t* f, canopen_emcy_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_EMCY, 8, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->node = node;
  out->error_code = proto_le16(&f->data[0]);
  out->error_register = f->data[2];
  memcpy(out->vendor, &f->data[3], 5);
  return PROTO_OK;
}

proto_status_t canopen_decode_rpdo1(const canopen_frame_t* f, canopen_rpdo1_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_RPDO1, 6, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->node = node;
  out->controlword = proto_le16(&f->data[0]);
  out->target_velocity = proto_i32(proto_le32(&f->data[2]));
  return PROTO_OK;
}

proto_status_t canopen_decode_tpdo1(const canopen_frame_t* f, canopen_tpdo1_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_TPDO1, 6, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->node = node;
  out->statusword = proto_le16(&f->data[0]);
  out->velocity_actual = proto_i32(proto_le32(&f->data[2]));
  return PROTO_OK;
}

proto_status_t canopen_decode_tpdo2(const canopen_frame_t* f, canopen_tpdo2_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_TPDO2, 4, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->node = node;
  out->position_actual = proto_i32(proto_le32(&f->data[0]));
  return PROTO_OK;
}

proto_status_t canopen_decode_heartbeat(const canopen_frame_t* f, canopen_heartbeat_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_HEARTBEAT, 1, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->node = node;
  out->nmt_state = (uint8_t)(f->data[0] & 0x7FU);
  return PROTO_OK;
}

proto_status_t cia401_encode_bumpers(canopen_frame_t* f, uint8_t node, const uint8_t panels[CIA401_BUMP_PANELS]) {
  if (f == NULL || panels == NULL || !node_ok(node)) {
    return PROTO_ERR_INVALID_ARG;
  }
  for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
    if (panels[p] > CIA401_BUMP_SEGMENTS) {
      return PROTO_ERR_INVALID_ARG;
    }
  }
  frame_start(f, CANOPEN_COB_TPDO1 + node, CIA401_BUMP_TPDO1_DLC);
  // Input line 4p + s: two panels per 8-bit input group, the even panel in the low nibble.
  for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
    f->data[p / 2U] |= (uint8_t)((unsigned)panels[p] << ((p % 2U) * 4U));
  }
  return PROTO_OK;
}

proto_status_t cia401_decode_bumpers(const canopen_frame_t* f, cia401_bumpers_t* out) {
  uint8_t node = 0;
  const proto_status_t st = check_frame(f, out, CANOPEN_KIND_TPDO1, CIA401_BUMP_TPDO1_DLC, &node);
  if (st != PROTO_OK) {
    return st;
  }
  out->node = node;
  for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
    out->panels[p] = (uint8_t)(((unsigned)f->data[p / 2U] >> ((p % 2U) * 4U)) & CIA401_BUMP_SEGMENTS);
  }
  return PROTO_OK;
}

uint32_t cia401_bumper_mask(const cia401_bumpers_t* b) {
  uint32_t mask = 0;
  if (b != NULL) {
    for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
      if (b->panels[p] != 0U) {
        mask |= 1U << p;
      }
    }
  }
  return mask;
}

int32_t canopen_counts_from_si(double value, double counts_per_unit) {
  const double c = value * counts_per_unit;
  if (!isfinite(c)) {
    return 0;
  }
  if (c >= 2147483647.0) {
    return INT32_MAX;
  }
  if (c <= -2147483647.0) {
    return -INT32_MAX;
  }
  return (int32_t)lround(c);
}

double canopen_si_from_counts(int32_t counts, double counts_per_unit) {
  if (!(counts_per_unit > 0.0 || counts_per_unit < 0.0)) {
    return 0.0;
  }
  return (double)counts / counts_per_unit;
}

// ---------------------------------------------------------------------------------------------
// CiA 402

cia402_state_t cia402_state_from_statusword(uint16_t sw) {
  // The standard's patterns: some states are identified with mask 0x4F, the others need the
  // quick-stop bit too (mask 0x6F).
  if ((sw & 0x4FU) == 0x00U) {
    return CIA402_NOT_READY_TO_SWITCH_ON;
  }
  if ((sw & 0x4FU) == 0x40U) {
    return CIA402_SWITCH_ON_DISABLED;
  }
  if ((sw & 0x6FU) == 0x21U) {
    return CIA402_READY_TO_SWITCH_ON;
  }
  if ((sw & 0x6FU) == 0x23U) {
    return CIA402_SWITCHED_ON;
  }
  if ((sw & 0x6FU) == 0x27U) {
    return CIA402_OPERATION_ENABLED;
  }
  if ((sw & 0x6FU) == 0x07U) {
    return CIA402_QUICK_STOP_ACTIVE;
  }
  if ((sw & 0x4FU) == 0x0FU) {
    return CIA402_FAULT_REACTION_ACTIVE;
  }
  if ((sw & 0x4FU) == 0x08U) {
    return CIA402_FAULT;
  }
  return CIA402_STATE_UNKNOWN;
}

const char* cia402_state_name(cia402_state_t state) {
  switch (state) {
    case CIA402_NOT_READY_TO_SWITCH_ON:
      return "not_ready_to_switch_on";
    case CIA402_SWITCH_ON_DISABLED:
      return "switch_on_disabled";
    case CIA402_READY_TO_SWITCH_ON:
      return "ready_to_switch_on";
    case CIA402_SWITCHED_ON:
      return "switched_on";
    case CIA402_OPERATION_ENABLED:
      return "operation_enabled";
    case CIA402_QUICK_STOP_ACTIVE:
      return "quick_stop_active";
    case CIA402_FAULT_REACTION_ACTIVE:
      return "fault_reaction_active";
    case CIA402_FAULT:
      return "fault";
    case CIA402_STATE_UNKNOWN:
      break;
  }
  return "unknown";
}

bool cia402_operation_enabled(uint16_t statusword) { return (statusword & 0x6FU) == 0x27U; }

bool cia402_fault(uint16_t statusword) { return (statusword & CIA402_SW_FAULT) != 0U; }

void cia402_master_init(cia402_master_t* m) {
  if (m != NULL) {
    memset(m, 0, sizeof *m);
  }
}

uint16_t cia402_master_controlword(cia402_master_t* m, uint16_t statusword, cia402_request_t req) {
  if (m == NULL) {
    return CIA402_CW_DISABLE_VOLTAGE;
  }
  const cia402_state_t s = cia402_state_from_statusword(statusword);
  uint16_t cw = CIA402_CW_DISABLE_VOLTAGE;
  switch (req) {
    case CIA402_REQ_ENABLE:
      switch (s) {
        case CIA402_SWITCH_ON_DISABLED:
          cw = CIA402_CW_SHUTDOWN;
          break;
        case CIA402_READY_TO_SWITCH_ON:
          cw = CIA402_CW_SWITCH_ON;
          break;
        case CIA402_SWITCHED_ON:
        case CIA402_OPERATION_ENABLED:
          cw = CIA402_CW_ENABLE_OPERATION;
          break;
        case CIA402_FAULT:
          // A reset acts on the rising edge of bit 7: hold it low for one cycle first.
          if ((m->last_controlword & CIA402_CW_FAULT_RESET) != 0U) {
            cw = CIA402_CW_DISABLE_VOLTAGE;
          } else {
            cw = CIA402_CW_FAULT_RESET;
            m->fault_resets++;
          }
          break;
        case CIA402_QUICK_STOP_ACTIVE:
        case CIA402_NOT_READY_TO_SWITCH_ON:
        case CIA402_FAULT_REACTION_ACTIVE:
        case CIA402_STATE_UNKNOWN:
          cw = CIA402_CW_DISABLE_VOLTAGE;
          break;
      }
      break;
    case CIA402_REQ_QUICK_STOP:
      cw = CIA402_CW_QUICK_STOP;
      break;
    case CIA402_REQ_DISABLE:
      cw = (s == CIA402_SWITCHED_ON || s == CIA402_OPERATION_ENABLED) ? CIA402_CW_SHUTDOWN
                                                                      : CIA402_CW_DISABLE_VOLTAGE;
      break;
  }
  m->last_controlword = cw;
  return cw;
}

void cia402_drive_init(cia402_drive_t* d) {
  if (d != NULL) {
    memset(d, 0, sizeof *d);
    d->state = CIA402_SWITCH_ON_DISABLED;
  }
}

static void drive_goto(cia402_drive_t* d, cia402_state_t s) {
  if (d->state != s) {
    d->state = s;
    d->transitions++;
  }
}

// Controlword commands, decoded with the CiA 402 bit patterns (bits 0-3 and 7).
typedef enum cw_cmd {
  CW_NONE,
  CW_SHUTDOWN,
  CW_SWITCH_ON,
  CW_ENABLE_OP,
  CW_DISABLE_VOLTAGE,
  CW_QUICK_STOP,
} cw_cmd_t;

static cw_cmd_t cw_decode(uint16_t cw) {
  if ((cw & 0x0082U) == 0x0000U) {
    return CW_DISABLE_VOLTAGE;  // xxxx xx0x with bit 7 clear (bit 7 set is fault reset).
  }
  if ((cw & 0x0086U) == 0x0002U) {
    return CW_QUICK_STOP;
  }
  if ((cw & 0x0087U) == 0x0006U) {
    return CW_SHUTDOWN;
  }
  if ((cw & 0x008FU) == 0x0007U) {
    return CW_SWITCH_ON;  // also "disable operation" from OPERATION_ENABLED
  }
  if ((cw & 0x008FU) == 0x000FU) {
    return CW_ENABLE_OP;
  }
  return CW_NONE;
}

void cia402_drive_apply_controlword(cia402_drive_t* d, uint16_t controlword) {
  if (d == NULL) {
    return;
  }
  const bool reset_edge = (controlword & CIA402_CW_FAULT_RESET) != 0U &&
                          (d->last_controlword & CIA402_CW_FAULT_RESET) == 0U;
  d->last_controlword = controlword;
  if (d->state == CIA402_FAULT || d->state == CIA402_FAULT_REACTION_ACTIVE) {
    if (reset_edge && !d->fault_active) {
      drive_goto(d, CIA402_SWITCH_ON_DISABLED);
    } else if (!reset_edge) {
      d->ignored_commands++;
    }
    return;
  }
  const cw_cmd_t cmd = cw_decode(controlword);
  const cia402_state_t s = d->state;
  bool ok = true;
  switch (cmd) {
    case CW_SHUTDOWN:
      if (s == CIA402_SWITCH_ON_DISABLED || s == CIA402_SWITCHED_ON ||
          s == CIA402_OPERATION_ENABLED || s == CIA402_READY_TO_SWITCH_ON) {
        drive_goto(d, CIA402_READY_TO_SWITCH_ON);  // transitions 2, 6, 8
      } else {
        ok = false;
      }
      break;
    case CW_SWITCH_ON:
      if (s == CIA402_READY_TO_SWITCH_ON || s == CIA402_OPERATION_ENABLED ||
          s == CIA402_SWITCHED_ON) {
        drive_goto(d, CIA402_SWITCHED_ON);  // transitions 3, 5
      } else {
        ok = false;
      }
      break;
    case CW_ENABLE_OP:
      if (s == CIA402_SWITCHED_ON || s == CIA402_READY_TO_SWITCH_ON ||
          s == CIA402_QUICK_STOP_ACTIVE || s == CIA402_OPERATION_ENABLED) {
        drive_goto(d, CIA402_OPERATION_ENABLED);  // transitions 4, 3+4, 16
      } else {
        ok = false;
      }
      break;
    case CW_DISABLE_VOLTAGE:
      drive_goto(d, CIA402_SWITCH_ON_DISABLED);  // transitions 7, 9, 10, 12
      break;
    case CW_QUICK_STOP:
      if (s == CIA402_OPERATION_ENABLED) {
        drive_goto(d, CIA402_QUICK_STOP_ACTIVE);  // transition 11
      } else if (s == CIA402_READY_TO_SWITCH_ON || s == CIA402_SWITCHED_ON) {
        drive_goto(d, CIA402_SWITCH_ON_DISABLED);  // transitions 7, 10
      } else if (s != CIA402_QUICK_STOP_ACTIVE && s != CIA402_SWITCH_ON_DISABLED) {
        ok = false;
      }
      break;
    case CW_NONE:
      ok = false;
      break;
  }
  if (!ok) {
    d->ignored_commands++;
  }
}

void cia402_drive_set_fault(cia402_drive_t* d, uint16_t error_code) {
  if (d == NULL) {
    return;
  }
  if (error_code != 0U) {
    d->fault_active = true;
    d->error_code = error_code;
    drive_goto(d, CIA402_FAULT);  // transitions 13 + 14 (the reaction is instantaneous here)
  } else {
    d->fault_active = false;
  }
}

uint16_t cia402_drive_statusword(const cia402_drive_t* d, bool target_reached) {
  if (d == NULL) {
    return 0;
  }
  uint16_t sw = CIA402_SW_REMOTE;
  switch (d->state) {
    case CIA402_NOT_READY_TO_SWITCH_ON:
    case CIA402_STATE_UNKNOWN:
      break;
    case CIA402_SWITCH_ON_DISABLED:
      sw |= CIA402_SW_SWITCH_ON_DISABLED | CIA402_SW_VOLTAGE_ENABLED;
      break;
    case CIA402_READY_TO_SWITCH_ON:
      sw |= 0x21U | CIA402_SW_VOLTAGE_ENABLED;
      break;
    case CIA402_SWITCHED_ON:
      sw |= 0x23U | CIA402_SW_VOLTAGE_ENABLED;
      break;
    case CIA402_OPERATION_ENABLED:
      sw |= 0x27U | CIA402_SW_VOLTAGE_ENABLED;
      break;
    case CIA402_QUICK_STOP_ACTIVE:
      sw |= 0x07U | CIA402_SW_VOLTAGE_ENABLED;
      break;
    case CIA402_FAULT_REACTION_ACTIVE:
      sw |= 0x0FU | CIA402_SW_VOLTAGE_ENABLED;
      break;
    case CIA402_FAULT:
      sw |= 0x08U | CIA402_SW_VOLTAGE_ENABLED;
      break;
  }
  if (target_reached) {
    sw |= CIA402_SW_TARGET_REACHED;
  }
  return (uint16_t)sw;
}

bool cia402_drive_enabled(const cia402_drive_t* d) {
  return d != NULL && d->state == CIA402_OPERATION_ENABLED;
}

// ---------------------------------------------------------------------------------------------
// Heartbeat consumer

proto_status_t canopen_hb_init(canopen_hb_consumer_t* c, uint8_t node, uint32_t timeout_us) {
  if (c == NULL || !node_ok(node) || timeout_us == 0U) {
    return PROTO_ERR_INVALID_ARG;
  }
  memset(c, 0, sizeof *c);
  c->node = node;
  c->timeout_us = timeout_us;
  return PROTO_OK;
}

bool canopen_hb_feed(canopen_hb_consumer_t* c, const canopen_frame_t* f, uint64_t now_us) {
  canopen_heartbeat_t hb;
  if (c == NULL || canopen_decode_heartbeat(f, &hb) != PROTO_OK || hb.node != c->node) {
    return false;
  }
  c->seen = true;
  c->nmt_state = hb.nmt_state;
  c->last_us = now_us;
  c->count++;
  if (hb.nmt_state == CANOPEN_NMT_STATE_BOOTUP) {
    c->bootups++;
  }
  return true;
}

bool canopen_hb_expired(const canopen_hb_consumer_t* c, uint64_t now_us, uint64_t since_us) {
  if (c == NULL) {
    return true;
  }
  const uint64_t ref = c->seen ? c->last_us : since_us;
  return now_us > ref && now_us - ref > c->timeout_us;
}
