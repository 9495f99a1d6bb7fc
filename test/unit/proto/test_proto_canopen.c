// SPDX-License-Identifier: MIT
// CANopen codec: frame layouts (CiA 402 drives, the CiA 401 bump-panel node), classification,
// the CiA 402 state machine on both sides, the heartbeat consumer. With a directory argument it also writes the frames it encodes, with the
// signal values they carry, for the DBC agreement test (test_proto_dbc.py).
#include <proto/canopen.h>

#include "proto_test_util.h"

#include <b21r_test/alloc_counter.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

static const char* g_golden_dir;

static void expect_frame(const canopen_frame_t* f, uint32_t id, const char* hex) {
  uint8_t want[8];
  const size_t n = test_hex(hex, want, sizeof want);
  assert_int_equal(f->id, id);
  assert_int_equal(f->dlc, n);
  assert_memory_equal(f->data, want, n);
  for (size_t i = n; i < 8U; ++i) {
    assert_int_equal(f->data[i], 0);
  }
}

// Each encoder writes the documented COB-ID, DLC and little-endian layout.
static void test_canopen_encoders_exact_layout(void** state) {
  (void)state;
  canopen_frame_t f;
  assert_int_equal(canopen_encode_nmt(&f, CANOPEN_NMT_START, 0), PROTO_OK);
  expect_frame(&f, 0x000, "01 00");
  assert_int_equal(canopen_encode_nmt(&f, CANOPEN_NMT_RESET_NODE, 2), PROTO_OK);
  expect_frame(&f, 0x000, "81 02");
  assert_int_equal(canopen_encode_sync(&f), PROTO_OK);
  expect_frame(&f, 0x080, "");
  assert_int_equal(canopen_encode_rpdo1(&f, 1, 0x000F, -1000), PROTO_OK);
  expect_frame(&f, 0x201, "0f 00 18 fc ff ff");
  assert_int_equal(canopen_encode_tpdo1(&f, 2, 0x0237, 123456), PROTO_OK);
  expect_frame(&f, 0x182, "37 02 40 e2 01 00");
  assert_int_equal(canopen_encode_tpdo2(&f, 127, INT32_MIN), PROTO_OK);
  expect_frame(&f, 0x2FF, "00 00 00 80");
  assert_int_equal(canopen_encode_heartbeat(&f, 1, CANOPEN_NMT_STATE_OPERATIONAL), PROTO_OK);
  expect_frame(&f, 0x701, "05");
  const uint8_t vendor[5] = {1, 2, 3, 4, 5};
  assert_int_equal(canopen_encode_emcy(&f, 2, 0x2310, 0x03, vendor), PROTO_OK);
  expect_frame(&f, 0x082, "10 23 03 01 02 03 04 05");
  assert_int_equal(canopen_encode_emcy(&f, 2, 0, 0, NULL), PROTO_OK);
  expect_frame(&f, 0x082, "00 00 00 00 00 00 00 00");
}

// Node ids outside 1..127 (0..127 for NMT) and NULL frames are refused.
static void test_canopen_encoders_invalid_refused(void** state) {
  (void)state;
  canopen_frame_t f;
  assert_int_equal(canopen_encode_rpdo1(&f, 0, 0, 0), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_encode_tpdo1(&f, 128, 0, 0), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_encode_tpdo2(NULL, 1, 0), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_encode_heartbeat(&f, 0, 0), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_encode_emcy(&f, 200, 0, 0, NULL), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_encode_nmt(&f, 1, 128), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_encode_sync(NULL), PROTO_ERR_INVALID_ARG);
}

// Classification by COB-ID, with node ids; SDO and out-of-range ids are unknown.
static void test_canopen_classify_kinds(void** state) {
  (void)state;
  static const struct {
    uint32_t id;
    canopen_kind_t kind;
    uint8_t node;
  } cases[] = {{0x000, CANOPEN_KIND_NMT, 0},        {0x080, CANOPEN_KIND_SYNC, 0},
               {0x081, CANOPEN_KIND_EMCY, 1},       {0x0FF, CANOPEN_KIND_EMCY, 127},
               {0x182, CANOPEN_KIND_TPDO1, 2},      {0x201, CANOPEN_KIND_RPDO1, 1},
               {0x282, CANOPEN_KIND_TPDO2, 2},      {0x301, CANOPEN_KIND_RPDO2, 1},
               {0x701, CANOPEN_KIND_HEARTBEAT, 1},  {0x581, CANOPEN_KIND_UNKNOWN, 0},
               {0x601, CANOPEN_KIND_UNKNOWN, 0},    {0x380, CANOPEN_KIND_UNKNOWN, 0},
               {0x700, CANOPEN_KIND_UNKNOWN, 0},    {0x800, CANOPEN_KIND_UNKNOWN, 0},
               {0x100, CANOPEN_KIND_UNKNOWN, 0}};
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    canopen_frame_t f = {.id = cases[i].id, .dlc = 8};
    uint8_t node = 99;
    assert_int_equal(canopen_classify(&f, &node), cases[i].kind);
    assert_int_equal(node, cases[i].node);
  }
  assert_int_equal(canopen_classify(NULL, NULL), CANOPEN_KIND_UNKNOWN);
}

// Every frame decodes back to what was encoded; short DLCs and wrong kinds are refused.
static void test_canopen_decoders_round_trip(void** state) {
  (void)state;
  canopen_frame_t f;
  canopen_rpdo1_t r;
  assert_int_equal(canopen_encode_rpdo1(&f, 2, 0x008F, INT32_MIN), PROTO_OK);
  assert_int_equal(canopen_decode_rpdo1(&f, &r), PROTO_OK);
  assert_int_equal(r.node, 2);
  assert_int_equal(r.controlword, 0x008F);
  assert_int_equal(r.target_velocity, INT32_MIN);
  canopen_tpdo1_t t1;
  assert_int_equal(canopen_encode_tpdo1(&f, 1, 0x0218, -7), PROTO_OK);
  assert_int_equal(canopen_decode_tpdo1(&f, &t1), PROTO_OK);
  assert_int_equal(t1.statusword, 0x0218);
  assert_int_equal(t1.velocity_actual, -7);
  assert_int_equal(canopen_decode_rpdo1(&f, &r), PROTO_ERR_FORMAT);
  f.dlc = 5;
  assert_int_equal(canopen_decode_tpdo1(&f, &t1), PROTO_ERR_FORMAT);
  canopen_tpdo2_t t2;
  assert_int_equal(canopen_encode_tpdo2(&f, 1, INT32_MAX), PROTO_OK);
  assert_int_equal(canopen_decode_tpdo2(&f, &t2), PROTO_OK);
  assert_int_equal(t2.position_actual, INT32_MAX);
  f.dlc = 8;  // longer DLCs are accepted
  assert_int_equal(canopen_decode_tpdo2(&f, &t2), PROTO_OK);
  canopen_heartbeat_t hb;
  assert_int_equal(canopen_encode_heartbeat(&f, 2, 0x85), PROTO_OK);  // toggle bit set
  assert_int_equal(canopen_decode_heartbeat(&f, &hb), PROTO_OK);
  assert_int_equal(hb.node, 2);
  assert_int_equal(hb.nmt_state, CANOPEN_NMT_STATE_OPERATIONAL);
  canopen_emcy_t e;
  const uint8_t vendor[5] = {9, 8, 7, 6, 5};
  assert_int_equal(canopen_encode_emcy(&f, 1, 0x8611, 0x81, vendor), PROTO_OK);
  assert_int_equal(canopen_decode_emcy(&f, &e), PROTO_OK);
  assert_int_equal(e.node, 1);
  assert_int_equal(e.error_code, 0x8611);
  assert_int_equal(e.error_register, 0x81);
  assert_memory_equal(e.vendor, vendor, 5);
  f.dlc = 7;
  assert_int_equal(canopen_decode_emcy(&f, &e), PROTO_ERR_FORMAT);
  canopen_nmt_t nmt;
  assert_int_equal(canopen_encode_nmt(&f, CANOPEN_NMT_PREOP, 0), PROTO_OK);
  assert_int_equal(canopen_decode_nmt(&f, &nmt), PROTO_OK);
  assert_int_equal(nmt.command, CANOPEN_NMT_PREOP);
  assert_int_equal(nmt.node, 0);
  f.dlc = 9;
  assert_int_equal(canopen_decode_nmt(&f, &nmt), PROTO_ERR_FORMAT);
  assert_int_equal(canopen_decode_nmt(NULL, &nmt), PROTO_ERR_INVALID_ARG);
}

// The bump-panel TPDO1 of the CiA 401 node: COB-ID 0x180 + node, 7 bytes, input line 4p + s
// (panel p, segment s), i.e. the even panel in the low nibble of byte p / 2.
static void test_cia401_bumpers_exact_layout(void** state) {
  (void)state;
  canopen_frame_t f;
  uint8_t panels[CIA401_BUMP_PANELS] = {0};
  assert_int_equal(cia401_encode_bumpers(&f, CANOPEN_NODE_BUMPERS_DEFAULT, panels), PROTO_OK);
  expect_frame(&f, 0x190, "00 00 00 00 00 00 00");
  panels[0] = 0x1;   // upper panel 0, segment 0: line 0
  panels[3] = 0xF;   // upper panel 3, all segments: lines 12..15
  panels[6] = 0x2;   // first skirt panel (rFLEX DIO 0x46), segment 1: line 25
  panels[13] = 0x8;  // last skirt panel, segment 3: line 55
  assert_int_equal(cia401_encode_bumpers(&f, 16, panels), PROTO_OK);
  expect_frame(&f, 0x190, "01 f0 00 02 00 00 80");
  assert_int_equal(cia401_encode_bumpers(&f, 127, panels), PROTO_OK);
  assert_int_equal(f.id, 0x1FF);
}

// Values beyond a panel's four segments, node ids outside 1..127 and NULLs are refused.
static void test_cia401_bumpers_invalid_refused(void** state) {
  (void)state;
  canopen_frame_t f;
  uint8_t panels[CIA401_BUMP_PANELS] = {0};
  assert_int_equal(cia401_encode_bumpers(&f, 0, panels), PROTO_ERR_INVALID_ARG);
  assert_int_equal(cia401_encode_bumpers(&f, 128, panels), PROTO_ERR_INVALID_ARG);
  assert_int_equal(cia401_encode_bumpers(NULL, 16, panels), PROTO_ERR_INVALID_ARG);
  assert_int_equal(cia401_encode_bumpers(&f, 16, NULL), PROTO_ERR_INVALID_ARG);
  panels[13] = 0x10;
  assert_int_equal(cia401_encode_bumpers(&f, 16, panels), PROTO_ERR_INVALID_ARG);
  cia401_bumpers_t b;
  assert_int_equal(cia401_decode_bumpers(NULL, &b), PROTO_ERR_INVALID_ARG);
  assert_int_equal(cia401_decode_bumpers(&f, NULL), PROTO_ERR_INVALID_ARG);
}

// Every panel value decodes back; the mask has bit p for each panel with any segment pressed;
// short DLCs (a drive's 6-byte TPDO1) and other kinds are refused.
static void test_cia401_bumpers_round_trip_and_mask(void** state) {
  (void)state;
  canopen_frame_t f;
  cia401_bumpers_t b;
  for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
    for (uint8_t v = 0; v <= CIA401_BUMP_SEGMENTS; ++v) {
      uint8_t panels[CIA401_BUMP_PANELS] = {0};
      panels[p] = v;
      panels[(p + 5U) % CIA401_BUMP_PANELS] = 0x3;
      assert_int_equal(cia401_encode_bumpers(&f, 16, panels), PROTO_OK);
      memset(&b, 0xAA, sizeof b);
      assert_int_equal(cia401_decode_bumpers(&f, &b), PROTO_OK);
      assert_int_equal(b.node, 16);
      assert_memory_equal(b.panels, panels, CIA401_BUMP_PANELS);
      const uint32_t want = (v != 0U ? 1U << p : 0U) | 1U << ((p + 5U) % CIA401_BUMP_PANELS);
      assert_int_equal(cia401_bumper_mask(&b), want);
    }
  }
  assert_int_equal(cia401_bumper_mask(NULL), 0);
  f.dlc = 8;  // longer DLCs are accepted
  assert_int_equal(cia401_decode_bumpers(&f, &b), PROTO_OK);
  f.dlc = 6;
  assert_int_equal(cia401_decode_bumpers(&f, &b), PROTO_ERR_FORMAT);
  (void)canopen_encode_tpdo1(&f, 16, 0x0237, 0);
  assert_int_equal(cia401_decode_bumpers(&f, &b), PROTO_ERR_FORMAT);
  (void)canopen_encode_heartbeat(&f, 16, CANOPEN_NMT_STATE_OPERATIONAL);
  f.dlc = 7;
  assert_int_equal(cia401_decode_bumpers(&f, &b), PROTO_ERR_FORMAT);
  f.id = 0x210;  // RPDO1 of node 16
  assert_int_equal(cia401_decode_bumpers(&f, &b), PROTO_ERR_FORMAT);
}

// SI <-> counts: rounding to nearest, saturation, non-finite input gives 0.
static void test_canopen_counts_conversion(void** state) {
  (void)state;
  assert_int_equal(canopen_counts_from_si(0.5, 103000.0), 51500);
  assert_int_equal(canopen_counts_from_si(-0.3, 35000.0), -10500);
  assert_int_equal(canopen_counts_from_si(1.00001, 1.0), 1);
  assert_int_equal(canopen_counts_from_si(1e12, 1.0), INT32_MAX);
  assert_int_equal(canopen_counts_from_si(-1e12, 1.0), -INT32_MAX);
  assert_int_equal(canopen_counts_from_si(NAN, 1.0), 0);
  assert_int_equal(canopen_counts_from_si(INFINITY, 1.0), 0);
  ASSERT_NEAR(canopen_si_from_counts(51500, 103000.0), 0.5, 1e-15);
  ASSERT_NEAR(canopen_si_from_counts(5, 0.0), 0.0, 0.0);
}

// Statusword patterns of CiA 402 map to states (mask 0x4F / 0x6F), unknown ones are reported.
static void test_cia402_statusword_states(void** state) {
  (void)state;
  static const struct {
    uint16_t sw;
    cia402_state_t s;
  } cases[] = {{0x0000, CIA402_NOT_READY_TO_SWITCH_ON}, {0x0250, CIA402_SWITCH_ON_DISABLED},
               {0x0040, CIA402_SWITCH_ON_DISABLED},     {0x0231, CIA402_READY_TO_SWITCH_ON},
               {0x0233, CIA402_SWITCHED_ON},            {0x0237, CIA402_OPERATION_ENABLED},
               {0x0637, CIA402_OPERATION_ENABLED},      {0x0217, CIA402_QUICK_STOP_ACTIVE},
               {0x021F, CIA402_FAULT_REACTION_ACTIVE},  {0x0218, CIA402_FAULT},
               {0x0008, CIA402_FAULT},                  {0x0001, CIA402_STATE_UNKNOWN}};
  for (size_t i = 0; i < sizeof cases / sizeof cases[0]; ++i) {
    assert_int_equal(cia402_state_from_statusword(cases[i].sw), cases[i].s);
    assert_string_not_equal(cia402_state_name(cases[i].s), "");
  }
  assert_true(cia402_operation_enabled(0x0237));
  assert_false(cia402_operation_enabled(0x0233));
  assert_false(cia402_operation_enabled(0x0217));  // quick stop: bit 5 clear
  assert_true(cia402_fault(0x0218));
  assert_false(cia402_fault(0x0237));
}

// Runs master and drive against each other for one cycle; returns the controlword sent.
static uint16_t cycle(cia402_master_t* m, cia402_drive_t* d, cia402_request_t req) {
  const uint16_t cw = cia402_master_controlword(m, cia402_drive_statusword(d, false), req);
  cia402_drive_apply_controlword(d, cw);
  return cw;
}

// The host sequencer walks the emulated drive 0x06 -> 0x07 -> 0x0F to operation enabled,
// resets a fault with a rising bit 7 only after the fault condition clears, quick-stops and
// disables.
static void test_cia402_master_drive_enable_fault_quickstop(void** state) {
  (void)state;
  cia402_master_t m;
  cia402_drive_t d;
  cia402_master_init(&m);
  cia402_drive_init(&d);
  assert_int_equal(d.state, CIA402_SWITCH_ON_DISABLED);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x06);
  assert_int_equal(d.state, CIA402_READY_TO_SWITCH_ON);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x07);
  assert_int_equal(d.state, CIA402_SWITCHED_ON);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x0F);
  assert_true(cia402_drive_enabled(&d));
  assert_true(cia402_operation_enabled(cia402_drive_statusword(&d, true)));
  assert_int_equal(cia402_drive_statusword(&d, true) & CIA402_SW_TARGET_REACHED,
                   CIA402_SW_TARGET_REACHED);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x0F);  // stays enabled
  // Fault: the master asks for a reset but the drive stays in FAULT while the cause persists.
  cia402_drive_set_fault(&d, 0x2310);
  assert_int_equal(d.state, CIA402_FAULT);
  assert_true(cia402_fault(cia402_drive_statusword(&d, false)));
  assert_false(cia402_drive_enabled(&d));
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x80);
  assert_int_equal(d.state, CIA402_FAULT);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x00);  // bit 7 low again for a new edge
  cia402_drive_set_fault(&d, 0);                              // cause cleared
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x80);
  assert_int_equal(d.state, CIA402_SWITCH_ON_DISABLED);
  assert_int_equal(m.fault_resets, 2);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x06);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x07);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x0F);
  assert_true(cia402_drive_enabled(&d));
  // Quick stop, then enable operation brings it back (transition 16).
  assert_int_equal(cycle(&m, &d, CIA402_REQ_QUICK_STOP), 0x02);
  assert_int_equal(d.state, CIA402_QUICK_STOP_ACTIVE);
  assert_int_equal(cia402_state_from_statusword(cia402_drive_statusword(&d, false)),
                   CIA402_QUICK_STOP_ACTIVE);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_ENABLE), 0x00);  // master goes via disable voltage
  assert_int_equal(d.state, CIA402_SWITCH_ON_DISABLED);
  for (int i = 0; i < 3; ++i) {
    (void)cycle(&m, &d, CIA402_REQ_ENABLE);
  }
  assert_true(cia402_drive_enabled(&d));
  cia402_drive_apply_controlword(&d, CIA402_CW_QUICK_STOP);
  cia402_drive_apply_controlword(&d, CIA402_CW_ENABLE_OPERATION);
  assert_true(cia402_drive_enabled(&d));
  // Disable: shutdown from enabled goes to READY; then disable voltage.
  assert_int_equal(cycle(&m, &d, CIA402_REQ_DISABLE), 0x06);
  assert_int_equal(d.state, CIA402_READY_TO_SWITCH_ON);
  assert_int_equal(cycle(&m, &d, CIA402_REQ_DISABLE), 0x00);
  assert_int_equal(d.state, CIA402_SWITCH_ON_DISABLED);
  // Commands that are invalid in the current state are ignored and counted.
  const uint64_t ignored = d.ignored_commands;
  cia402_drive_apply_controlword(&d, CIA402_CW_SWITCH_ON);
  assert_int_equal(d.state, CIA402_SWITCH_ON_DISABLED);
  assert_int_equal(d.ignored_commands, ignored + 1U);
}

// Every drive state reports a statusword that decodes to the same state.
static void test_cia402_drive_statusword_consistent(void** state) {
  (void)state;
  cia402_drive_t d;
  cia402_drive_init(&d);
  for (int s = CIA402_NOT_READY_TO_SWITCH_ON; s <= CIA402_FAULT; ++s) {
    d.state = (cia402_state_t)s;
    const uint16_t sw = cia402_drive_statusword(&d, false);
    assert_int_equal(cia402_state_from_statusword(sw), s);
    assert_int_equal(sw & CIA402_SW_REMOTE, CIA402_SW_REMOTE);
  }
}

// Heartbeat consumer: silence from the start or after the last heartbeat expires; other nodes'
// heartbeats are not consumed; boot-ups are counted.
static void test_canopen_heartbeat_consumer_timeout(void** state) {
  (void)state;
  canopen_hb_consumer_t c;
  assert_int_equal(canopen_hb_init(&c, 1, 100000), PROTO_OK);
  assert_false(canopen_hb_expired(&c, 50000, 0));
  assert_true(canopen_hb_expired(&c, 100001, 0));
  canopen_frame_t f;
  (void)canopen_encode_heartbeat(&f, 2, CANOPEN_NMT_STATE_OPERATIONAL);
  assert_false(canopen_hb_feed(&c, &f, 90000));
  (void)canopen_encode_heartbeat(&f, 1, CANOPEN_NMT_STATE_BOOTUP);
  assert_true(canopen_hb_feed(&c, &f, 90000));
  (void)canopen_encode_heartbeat(&f, 1, CANOPEN_NMT_STATE_OPERATIONAL);
  assert_true(canopen_hb_feed(&c, &f, 150000));
  assert_int_equal(c.nmt_state, CANOPEN_NMT_STATE_OPERATIONAL);
  assert_false(canopen_hb_expired(&c, 250000, 0));
  assert_true(canopen_hb_expired(&c, 250001, 0));
  assert_int_equal(c.count, 2);
  assert_int_equal(c.bootups, 1);
  (void)canopen_encode_rpdo1(&f, 1, 0, 0);
  assert_false(canopen_hb_feed(&c, &f, 260000));
  assert_int_equal(canopen_hb_init(&c, 0, 1), PROTO_ERR_INVALID_ARG);
  assert_int_equal(canopen_hb_init(&c, 1, 0), PROTO_ERR_INVALID_ARG);
}

// Writes the golden frames for the DBC test (skipped without a directory): one line per frame, "<msg> <id> <hex data> sig=value ...".
static void test_canopen_golden_frames_written(void** state) {
  (void)state;
  if (g_golden_dir == NULL) {
    skip();
  }
  char path[1024];
  snprintf(path, sizeof path, "%s/canopen_frames.txt", g_golden_dir);
  FILE* out = fopen(path, "w");
  assert_non_null(out);
  canopen_frame_t f;
  // Writes one frame line with its signals (a printf-style tail of "name=value" pairs).
#define EMIT(msg, ...)                                        \
  do {                                                        \
    fprintf(out, "%s 0x%03X ", (msg), (unsigned)f.id);        \
    for (unsigned i_ = 0; i_ < f.dlc; ++i_) {                 \
      fprintf(out, "%02x", f.data[i_]);                      \
    }                                                         \
    fprintf(out, " " __VA_ARGS__);                            \
    fputc('\n', out);                                         \
  } while (0)
  static const char* const axis[3] = {"", "Trans", "Rot"};
  static const int32_t velocities[] = {0, 1, -1, 51500, -10500, INT32_MAX, INT32_MIN};
  static const uint16_t words[] = {0x0006, 0x0007, 0x000F, 0x0080, 0x0002, 0x0237, 0x0218};
  char name[32];
  for (uint8_t node = 1; node <= 2; ++node) {
    for (size_t i = 0; i < sizeof velocities / sizeof velocities[0]; ++i) {
      const uint16_t w = words[i];
      const int32_t v = velocities[i];
      (void)canopen_encode_rpdo1(&f, node, w, v);
      snprintf(name, sizeof name, "RPDO1_%s", axis[node]);
      // The DBC splits the controlword and the statusword into their CiA 402 bit fields.
      EMIT(name, "Command=%u OpModeSpecific=%u FaultReset=%u Halt=%u ControlwordHigh=%u TargetVelocity=%d",
           w & 0xFU, (w >> 4) & 0x7U, (w >> 7) & 1U, (w >> 8) & 1U, (unsigned)(w >> 9), (int)v);
      (void)canopen_encode_tpdo1(&f, node, w, v);
      snprintf(name, sizeof name, "TPDO1_%s", axis[node]);
      EMIT(name,
           "DriveState=%u Warning=%u ManufacturerBit8=%u Remote=%u TargetReached=%u InternalLimitActive=%u "
           "OpModeSpecific=%u ManufacturerBits14=%u VelocityActual=%d",
           w & 0x7FU, (w >> 7) & 1U, (w >> 8) & 1U, (w >> 9) & 1U, (w >> 10) & 1U, (w >> 11) & 1U, (w >> 12) & 3U,
           (unsigned)(w >> 14), (int)v);
      (void)canopen_encode_tpdo2(&f, node, v);
      snprintf(name, sizeof name, "TPDO2_%s", axis[node]);
      EMIT(name, "PositionActual=%d", (int)v);
    }
    static const uint8_t states[] = {0x00, 0x04, 0x05, 0x7F};
    for (size_t i = 0; i < sizeof states; ++i) {
      (void)canopen_encode_heartbeat(&f, node, states[i]);
      snprintf(name, sizeof name, "Heartbeat_%s", axis[node]);
      EMIT(name, "NMTState=%u Toggle=0", (unsigned)states[i]);
    }
    const uint8_t vendor[5] = {0x11, 0x22, 0x33, 0x44, 0x55};
    (void)canopen_encode_emcy(&f, node, 0x2310, 0x03, vendor);
    snprintf(name, sizeof name, "EMCY_%s", axis[node]);
    // Error register 0x03 = generic + current, as bit fields.
    EMIT(name,
         "ErrorCode=%u ErrGeneric=1 ErrCurrent=1 ErrVoltage=0 ErrTemperature=0 ErrCommunication=0 "
         "ErrDeviceProfile=0 ErrReserved=0 ErrManufacturer=0 VendorData=%llu",
         0x2310U, 0x5544332211ULL);
    (void)canopen_encode_emcy(&f, node, 0, 0x84, NULL);
    EMIT(name,
         "ErrorCode=0 ErrGeneric=0 ErrCurrent=0 ErrVoltage=1 ErrTemperature=0 ErrCommunication=0 "
         "ErrDeviceProfile=0 ErrReserved=0 ErrManufacturer=1 VendorData=0");
  }
  // The bump-panel node: one frame per panel and segment value, plus mixed ones.
  for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
    for (uint8_t v = 1; v <= CIA401_BUMP_SEGMENTS; v = (uint8_t)(v * 2U + (p % 2U))) {
      uint8_t panels[CIA401_BUMP_PANELS] = {0};
      panels[p] = v;
      panels[CIA401_BUMP_PANELS - 1U - p] |= 0x1;
      (void)cia401_encode_bumpers(&f, CANOPEN_NODE_BUMPERS_DEFAULT, panels);
      char sig[CIA401_BUMP_PANELS * 16];
      size_t used = 0;
      for (unsigned q = 0; q < CIA401_BUMP_PANELS; ++q) {
        used += (size_t)snprintf(sig + used, sizeof sig - used, "%sBumpPanel%02u=%u", q > 0 ? " " : "", q,
                                 (unsigned)panels[q]);
      }
      EMIT("TPDO1_Bumpers", "%s", sig);
    }
  }
  static const uint8_t bump_states[] = {0x00, 0x04, 0x05, 0x7F};
  for (size_t i = 0; i < sizeof bump_states; ++i) {
    (void)canopen_encode_heartbeat(&f, CANOPEN_NODE_BUMPERS_DEFAULT, bump_states[i]);
    EMIT("Heartbeat_Bumpers", "NMTState=%u Toggle=0", (unsigned)bump_states[i]);
  }
  static const uint8_t cmds[] = {0x01, 0x02, 0x80, 0x81, 0x82};
  for (size_t i = 0; i < sizeof cmds; ++i) {
    (void)canopen_encode_nmt(&f, cmds[i], (uint8_t)i);
    EMIT("NMT", "NMT_Command=%u NMT_Node=%u", (unsigned)cmds[i], (unsigned)i);
  }
  (void)canopen_encode_sync(&f);
  EMIT("SYNC", "%s", "");
#undef EMIT
  assert_int_equal(fclose(out), 0);
}

// The master's per-cycle work allocates nothing.
static void test_canopen_no_allocation(void** state) {
  (void)state;
  cia402_master_t m;
  cia402_drive_t d;
  cia402_master_init(&m);
  cia402_drive_init(&d);
  canopen_frame_t f;
  canopen_tpdo1_t t;
  alloc_counter_begin();
  for (int i = 0; i < 10000; ++i) {
    const uint16_t cw = cycle(&m, &d, CIA402_REQ_ENABLE);
    (void)canopen_encode_rpdo1(&f, 1, cw, i);
    (void)canopen_encode_tpdo1(&f, 1, cia402_drive_statusword(&d, false), i);
    (void)canopen_decode_tpdo1(&f, &t);
    const uint8_t panels[CIA401_BUMP_PANELS] = {(uint8_t)(i & 0xF)};
    cia401_bumpers_t b;
    (void)cia401_encode_bumpers(&f, 16, panels);
    (void)cia401_decode_bumpers(&f, &b);
  }
  assert_int_equal(alloc_counter_end(), 0);
}

int main(int argc, char** argv) {
  g_golden_dir = argc > 1 ? argv[1] : NULL;
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_canopen_encoders_exact_layout),
      cmocka_unit_test(test_canopen_encoders_invalid_refused),
      cmocka_unit_test(test_canopen_classify_kinds),
      cmocka_unit_test(test_canopen_decoders_round_trip),
      cmocka_unit_test(test_cia401_bumpers_exact_layout),
      cmocka_unit_test(test_cia401_bumpers_invalid_refused),
      cmocka_unit_test(test_cia401_bumpers_round_trip_and_mask),
      cmocka_unit_test(test_canopen_counts_conversion),
      cmocka_unit_test(test_cia402_statusword_states),
      cmocka_unit_test(test_cia402_master_drive_enable_fault_quickstop),
      cmocka_unit_test(test_cia402_drive_statusword_consistent),
      cmocka_unit_test(test_canopen_heartbeat_consumer_timeout),
      cmocka_unit_test(test_canopen_golden_frames_written),
      cmocka_unit_test(test_canopen_no_allocation),
  };
  return cmocka_run_group_tests_name("proto.canopen", tests, NULL, NULL);
}
