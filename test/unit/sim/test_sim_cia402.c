// SPDX-License-Identifier: MIT
// The two emulated CiA 402 drives: NMT, the controlword state machine, SYNC-triggered TPDOs,
// heartbeat, EMCY on faults, RPDO watchdog; and the CiA 401 bump-panel node: NMT, TPDO1 on start,
// on change and by event timer, heartbeat, silence (hand-built frames and lib/proto's encoders).
#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>
#include <proto/canopen.h>

#include "sim/cia401_dev.h"
#include "sim/cia402_dev.h"

static sim_cia402_t* make(void) {
  sim_cia402_config_t cfg;
  sim_cia402_config_default(&cfg);
  sim_cia402_t* d = sim_cia402_create(&cfg);
  assert_non_null(d);
  return d;
}

static size_t drain_all(sim_cia402_t* d, canopen_frame_t* out, size_t cap) {
  size_t n = 0;
  canopen_frame_t f;
  while (sim_cia402_drain(d, &f)) {
    if (n < cap) {
      out[n] = f;
    }
    ++n;
  }
  return n;
}

// A frame written by hand: id, dlc, bytes.
static canopen_frame_t frame(uint32_t id, uint8_t dlc, const uint8_t* bytes) {
  canopen_frame_t f;
  memset(&f, 0, sizeof(f));
  f.id = id;
  f.dlc = dlc;
  if (dlc > 0) {
    memcpy(f.data, bytes, dlc);
  }
  return f;
}

static void rpdo(sim_cia402_t* d, uint8_t node, uint16_t cw, int32_t vel, double t) {
  canopen_frame_t f;
  assert_int_equal(canopen_encode_rpdo1(&f, node, cw, vel), PROTO_OK);
  assert_int_equal(sim_cia402_feed(d, &f, t), SIM_CIA402_EV_NONE);
}

static void enable_both(sim_cia402_t* d, double t) {
  const uint8_t start_all[2] = {0x01, 0x00};
  canopen_frame_t f = frame(0x000, 2, start_all);
  sim_cia402_feed(d, &f, t);
  for (uint8_t node = 1; node <= 2; ++node) {
    rpdo(d, node, CIA402_CW_SHUTDOWN, 0, t);
    rpdo(d, node, CIA402_CW_SWITCH_ON, 0, t);
    rpdo(d, node, CIA402_CW_ENABLE_OPERATION, 0, t);
  }
}

// Power-up: both drives send their boot-up heartbeat (0x701 / 0x702, state 0) and sit in
// pre-operational, where RPDOs are ignored and SYNC gets no TPDOs.
static void test_cia402_boot_up_then_preoperational(void** state) {
  (void)state;
  sim_cia402_t* d = make();
  canopen_frame_t out[8];
  assert_int_equal(drain_all(d, out, 8), 2);
  assert_int_equal(out[0].id, 0x701);
  assert_int_equal(out[0].dlc, 1);
  assert_int_equal(out[0].data[0], 0x00);
  assert_int_equal(out[1].id, 0x702);
  uint8_t nmt = 0;
  assert_int_equal(sim_cia402_drive_state(d, 1, NULL, &nmt), 0);
  assert_int_equal(nmt, CANOPEN_NMT_STATE_PREOP);
  rpdo(d, 1, CIA402_CW_SHUTDOWN, 0, 0.0);
  assert_int_equal(sim_cia402_get_counters(d)->ignored, 1);
  const canopen_frame_t sync = frame(0x080, 0, NULL);
  assert_int_equal(sim_cia402_feed(d, &sync, 0.0), SIM_CIA402_EV_SYNC);
  sim_cia402_sample_t s = {0};
  sim_cia402_emit_tpdos(d, &s, 0.0);
  assert_int_equal(drain_all(d, out, 8), 0);
  sim_cia402_destroy(d);
}

// NMT start (hand-built 000#0100) then controlwords 0x06, 0x07, 0x0F (hand-built RPDO1
// 201#060000000000 ...) walk the drive to OPERATION_ENABLED (statusword & 0x6F == 0x27); the
// TPDOs after a SYNC carry statusword, velocity and position in counts.
static void test_cia402_enable_sequence_and_tpdos(void** state) {
  (void)state;
  sim_cia402_t* d = make();
  canopen_frame_t out[16];
  (void)drain_all(d, out, 16);
  const uint8_t start_all[2] = {0x01, 0x00};
  canopen_frame_t f = frame(0x000, 2, start_all);
  sim_cia402_feed(d, &f, 0.0);
  const uint8_t cw06[6] = {0x06, 0x00, 0, 0, 0, 0};
  const uint8_t cw07[6] = {0x07, 0x00, 0, 0, 0, 0};
  const uint8_t cw0f[6] = {0x0F, 0x00, 0x2c, 0xc9, 0x00, 0x00};  // target 51500 counts/s
  uint16_t sw = 0;
  f = frame(0x201, 6, cw06);
  sim_cia402_feed(d, &f, 0.0);
  sim_cia402_drive_state(d, 1, &sw, NULL);
  assert_int_equal(cia402_state_from_statusword(sw), CIA402_READY_TO_SWITCH_ON);
  f = frame(0x201, 6, cw07);
  sim_cia402_feed(d, &f, 0.0);
  sim_cia402_drive_state(d, 1, &sw, NULL);
  assert_int_equal(cia402_state_from_statusword(sw), CIA402_SWITCHED_ON);
  f = frame(0x201, 6, cw0f);
  sim_cia402_feed(d, &f, 0.0);
  sim_cia402_drive_state(d, 1, &sw, NULL);
  assert_int_equal(sw & 0x6F, 0x27);
  assert_false(sim_cia402_ready(d));  // the rotation drive is not enabled yet
  rpdo(d, 2, CIA402_CW_SHUTDOWN, 0, 0.0);
  rpdo(d, 2, CIA402_CW_ENABLE_OPERATION, -10500, 0.0);  // 3 + 4 in one step
  assert_true(sim_cia402_ready(d));
  sim_cia402_command_t c;
  sim_cia402_get_command(d, 0.0, &c);
  assert_true(fabs(c.v_mps - 0.5) < 1e-12);
  assert_true(fabs(c.omega_radps + 0.3) < 1e-12);
  const canopen_frame_t sync = frame(0x080, 0, NULL);
  assert_int_equal(sim_cia402_feed(d, &sync, 0.0), SIM_CIA402_EV_SYNC);
  const sim_cia402_sample_t s = {.pos_trans_m = 1.0, .pos_rot_rad = -0.25, .v_mps = 0.5, .omega_radps = -0.3};
  sim_cia402_emit_tpdos(d, &s, 0.0);
  assert_int_equal(drain_all(d, out, 16), 4);
  assert_int_equal(out[0].id, 0x181);
  assert_int_equal(out[1].id, 0x281);
  assert_int_equal(out[2].id, 0x182);
  assert_int_equal(out[3].id, 0x282);
  canopen_tpdo1_t t1;
  canopen_tpdo2_t t2;
  assert_int_equal(canopen_decode_tpdo1(&out[0], &t1), PROTO_OK);
  assert_true(cia402_operation_enabled(t1.statusword));
  assert_true((t1.statusword & CIA402_SW_TARGET_REACHED) != 0);
  assert_int_equal(t1.velocity_actual, 51500);
  assert_int_equal(canopen_decode_tpdo2(&out[1], &t2), PROTO_OK);
  assert_int_equal(t2.position_actual, 103000);
  assert_int_equal(canopen_decode_tpdo1(&out[2], &t1), PROTO_OK);
  assert_int_equal(t1.velocity_actual, -10500);
  assert_int_equal(canopen_decode_tpdo2(&out[3], &t2), PROTO_OK);
  assert_int_equal(t2.position_actual, -8750);
  // Hand check of the TPDO1 layout: statusword LE, then velocity LE.
  assert_int_equal(out[0].dlc, 6);
  assert_int_equal(out[0].data[2] | (out[0].data[3] << 8), 51500);
  sim_cia402_destroy(d);
}

// Heartbeats follow the producer time (0.1 s) and carry the NMT state (0x05 operational).
static void test_cia402_heartbeat_every_period(void** state) {
  (void)state;
  sim_cia402_t* d = make();
  canopen_frame_t out[64];
  (void)drain_all(d, out, 64);
  enable_both(d, 0.0);
  int hb = 0;
  for (int k = 1; k <= 10; ++k) {
    sim_cia402_poll(d, 0.1 * k);
    const size_t n = drain_all(d, out, 64);
    for (size_t i = 0; i < n; ++i) {
      canopen_heartbeat_t h;
      if (canopen_decode_heartbeat(&out[i], &h) == PROTO_OK) {
        assert_int_equal(h.nmt_state, CANOPEN_NMT_STATE_OPERATIONAL);
        ++hb;
      }
    }
  }
  assert_int_equal(hb, 20);
  sim_cia402_destroy(d);
}

// An injected fault: EMCY 0x81 with code 0x2310, statusword fault, the drive stops; a rising
// edge of bit 7 resets it (EMCY 0x0000), after which it can be enabled again.
static void test_cia402_fault_sends_emcy_and_resets_on_edge(void** state) {
  (void)state;
  sim_cia402_t* d = make();
  canopen_frame_t out[16];
  enable_both(d, 0.0);
  (void)drain_all(d, out, 16);
  rpdo(d, 1, CIA402_CW_ENABLE_OPERATION, 51500, 0.0);
  assert_int_equal(sim_cia402_inject_fault(d, 1, 0.0), 0);
  assert_int_equal(sim_cia402_inject_fault(d, 9, 0.0), -1);
  assert_int_equal(drain_all(d, out, 16), 1);
  canopen_emcy_t em;
  assert_int_equal(canopen_decode_emcy(&out[0], &em), PROTO_OK);
  assert_int_equal(out[0].id, 0x81);
  assert_int_equal(em.error_code, 0x2310);
  uint16_t sw = 0;
  sim_cia402_drive_state(d, 1, &sw, NULL);
  assert_true(cia402_fault(sw));
  sim_cia402_command_t c;
  sim_cia402_get_command(d, 0.0, &c);
  assert_true(c.v_mps == 0.0);
  // Through proto's master sequencer: fault -> 0x00 then 0x80 (rising edge).
  cia402_master_t m;
  cia402_master_init(&m);
  m.last_controlword = 0x0F;
  for (int i = 0; i < 6; ++i) {
    sim_cia402_drive_state(d, 1, &sw, NULL);
    rpdo(d, 1, cia402_master_controlword(&m, sw, CIA402_REQ_ENABLE), 51500, 0.0);
  }
  sim_cia402_drive_state(d, 1, &sw, NULL);
  assert_true(cia402_operation_enabled(sw));
  const size_t n = drain_all(d, out, 16);
  int resets = 0;
  for (size_t i = 0; i < n; ++i) {
    if (canopen_decode_emcy(&out[i], &em) == PROTO_OK && em.error_code == 0) {
      ++resets;
    }
  }
  assert_int_equal(resets, 1);
  sim_cia402_get_command(d, 0.0, &c);
  assert_true(fabs(c.v_mps - 0.5) < 1e-12);
  sim_cia402_destroy(d);
}

// RPDO watchdog: 1 s without RPDO1 stops the drive's target (counted); the next RPDO1 resumes.
static void test_cia402_rpdo_timeout_stops_drive(void** state) {
  (void)state;
  sim_cia402_t* d = make();
  enable_both(d, 0.0);
  rpdo(d, 1, CIA402_CW_ENABLE_OPERATION, 51500, 0.0);
  sim_cia402_poll(d, 0.9);
  sim_cia402_command_t c;
  sim_cia402_get_command(d, 0.9, &c);
  assert_true(c.v_mps > 0.0);
  sim_cia402_poll(d, 1.1);
  sim_cia402_get_command(d, 1.1, &c);
  assert_true(c.v_mps == 0.0);
  assert_true(fabs(c.accel_trans_mps2 - 1.5) < 1e-12);  // quick-stop ramp
  assert_int_equal(sim_cia402_get_counters(d)->rpdo_timeouts, 2);
  rpdo(d, 1, CIA402_CW_ENABLE_OPERATION, 51500, 1.2);
  sim_cia402_get_command(d, 1.2, &c);
  assert_true(c.v_mps > 0.0);
  sim_cia402_destroy(d);
}

// NMT reset node: boot-up again, drive back in SWITCH_ON_DISABLED, pre-operational; silence
// suppresses every frame in both directions.
static void test_cia402_reset_node_and_silence(void** state) {
  (void)state;
  sim_cia402_t* d = make();
  canopen_frame_t out[16];
  enable_both(d, 0.0);
  (void)drain_all(d, out, 16);
  canopen_frame_t f;
  assert_int_equal(canopen_encode_nmt(&f, CANOPEN_NMT_RESET_NODE, 2), PROTO_OK);
  sim_cia402_feed(d, &f, 0.0);
  assert_int_equal(drain_all(d, out, 16), 1);
  assert_int_equal(out[0].id, 0x702);
  uint16_t sw = 0;
  uint8_t nmt = 0;
  sim_cia402_drive_state(d, 2, &sw, &nmt);
  assert_int_equal(nmt, CANOPEN_NMT_STATE_PREOP);
  assert_int_equal(cia402_state_from_statusword(sw), CIA402_SWITCH_ON_DISABLED);
  assert_false(sim_cia402_ready(d));
  sim_cia402_set_silent_until(d, 5.0);
  assert_int_equal(canopen_encode_nmt(&f, CANOPEN_NMT_START, 0), PROTO_OK);
  sim_cia402_feed(d, &f, 1.0);
  sim_cia402_poll(d, 1.0);
  assert_int_equal(drain_all(d, out, 16), 0);
  sim_cia402_drive_state(d, 2, NULL, &nmt);
  assert_int_equal(nmt, CANOPEN_NMT_STATE_PREOP);  // the start was ignored
  sim_cia402_destroy(d);
}

// ---- the bump-panel node ----

// Collects the node's frames: TPDO1s decoded into *last, counted by kind.
typedef struct bump_out {
  int pdos, heartbeats, other;
  cia401_bumpers_t last;
  uint8_t last_hb_state;
} bump_out_t;

static bump_out_t bump_drain(sim_cia401_t* d) {
  bump_out_t o;
  memset(&o, 0, sizeof o);
  canopen_frame_t f;
  while (sim_cia401_drain(d, &f)) {
    uint8_t node = 0;
    const canopen_kind_t kind = canopen_classify(&f, &node);
    assert_int_equal(node, CANOPEN_NODE_BUMPERS_DEFAULT);
    if (kind == CANOPEN_KIND_TPDO1) {
      assert_int_equal(f.id, 0x190);
      assert_int_equal(cia401_decode_bumpers(&f, &o.last), PROTO_OK);
      ++o.pdos;
    } else if (kind == CANOPEN_KIND_HEARTBEAT) {
      o.last_hb_state = f.data[0];
      ++o.heartbeats;
    } else {
      ++o.other;
    }
  }
  return o;
}

static void nmt(sim_cia401_t* d, uint8_t command, uint8_t node, double t) {
  canopen_frame_t f;
  assert_int_equal(canopen_encode_nmt(&f, command, node), PROTO_OK);
  sim_cia401_feed(d, &f, t);
}

// Boot-up, silence in pre-operational; NMT start for another node does nothing, for this node
// (or all) the inputs go out at once; then on every change and, unchanged, every 100 ms.
static void test_cia401_start_change_and_event_timer(void** state) {
  (void)state;
  sim_cia401_config_t cfg;
  sim_cia401_config_default(&cfg);
  assert_int_equal(cfg.node, 16);
  sim_cia401_t* d = sim_cia401_create(&cfg);
  assert_non_null(d);
  uint8_t panels[CIA401_BUMP_PANELS] = {0};
  bump_out_t o = bump_drain(d);
  assert_int_equal(o.heartbeats, 1);
  assert_int_equal(o.last_hb_state, CANOPEN_NMT_STATE_BOOTUP);
  sim_cia401_poll(d, panels, 0.05);
  assert_int_equal(bump_drain(d).pdos, 0);  // pre-operational: no PDOs
  nmt(d, CANOPEN_NMT_START, 1, 0.05);
  sim_cia401_poll(d, panels, 0.05);
  assert_int_equal(bump_drain(d).pdos, 0);
  assert_false(sim_cia401_operational(d));
  nmt(d, CANOPEN_NMT_START, 16, 0.06);
  assert_true(sim_cia401_operational(d));
  sim_cia401_poll(d, panels, 0.06);
  o = bump_drain(d);
  assert_int_equal(o.pdos, 1);
  assert_int_equal(cia401_bumper_mask(&o.last), 0);
  sim_cia401_poll(d, panels, 0.07);
  assert_int_equal(bump_drain(d).pdos, 0);  // unchanged, timer not run out
  panels[9] = 0x24;                         // bits above the 4 segments are not inputs
  sim_cia401_poll(d, panels, 0.08);
  o = bump_drain(d);
  assert_int_equal(o.pdos, 1);
  assert_int_equal(o.last.panels[9], 0x4);
  sim_cia401_poll(d, panels, 0.17);
  o = bump_drain(d);
  assert_int_equal(o.pdos, 0);
  assert_int_equal(o.heartbeats, 1);  // the heartbeat due at 0.1 s
  assert_int_equal(o.last_hb_state, CANOPEN_NMT_STATE_OPERATIONAL);
  sim_cia401_poll(d, panels, 0.18);  // 100 ms after the last PDO
  o = bump_drain(d);
  assert_int_equal(o.pdos, 1);
  assert_int_equal(o.heartbeats, 0);
  assert_int_equal(o.last.panels[9], 0x4);
  // Periodic: 10 PDOs in a second of 10 ms polls, one heartbeat per 100 ms.
  int pdos = 0, hbs = 0;
  for (int i = 1; i <= 100; ++i) {
    sim_cia401_poll(d, panels, 0.18 + 0.01 * i);
    o = bump_drain(d);
    pdos += o.pdos;
    hbs += o.heartbeats;
  }
  assert_int_equal(pdos, 10);
  assert_int_equal(hbs, 10);
  const sim_cia401_counters_t* c = sim_cia401_get_counters(d);
  assert_int_equal(c->pdos, 13);
  assert_int_equal(c->pdos_on_change, 2);
  sim_cia401_destroy(d);
}

// Silence: nothing (PDO, heartbeat) until its end, and frames are ignored; stop and reset: no
// PDOs, a reset sends boot-up and needs a new start. Invalid configurations are refused.
static void test_cia401_silence_stop_and_reset(void** state) {
  (void)state;
  sim_cia401_config_t cfg;
  sim_cia401_config_default(&cfg);
  sim_cia401_t* d = sim_cia401_create(&cfg);
  uint8_t panels[CIA401_BUMP_PANELS] = {0};
  nmt(d, CANOPEN_NMT_START, 0, 0.0);
  sim_cia401_poll(d, panels, 0.0);
  assert_int_equal(bump_drain(d).pdos, 1);
  sim_cia401_set_silent_until(d, 0.5);
  panels[0] = 0x1;
  for (int i = 1; i < 50; ++i) {
    sim_cia401_poll(d, panels, 0.01 * i);
  }
  nmt(d, CANOPEN_NMT_STOP, 16, 0.3);  // ignored while silent
  bump_out_t o = bump_drain(d);
  assert_int_equal(o.pdos + o.heartbeats + o.other, 0);
  assert_true(sim_cia401_operational(d));
  sim_cia401_poll(d, panels, 0.5);
  o = bump_drain(d);
  assert_int_equal(o.pdos, 1);
  assert_int_equal(o.last.panels[0], 0x1);
  nmt(d, CANOPEN_NMT_STOP, 16, 0.6);
  panels[0] = 0x0;
  sim_cia401_poll(d, panels, 0.8);
  o = bump_drain(d);
  assert_int_equal(o.pdos, 0);
  assert_int_equal(o.last_hb_state, CANOPEN_NMT_STATE_STOPPED);
  nmt(d, CANOPEN_NMT_RESET_NODE, 16, 0.85);
  o = bump_drain(d);
  assert_int_equal(o.heartbeats, 1);
  assert_int_equal(o.last_hb_state, CANOPEN_NMT_STATE_BOOTUP);
  assert_false(sim_cia401_operational(d));
  sim_cia401_destroy(d);
  cfg.node = 0;
  assert_null(sim_cia401_create(&cfg));
  sim_cia401_config_default(&cfg);
  cfg.event_timer_s = -1.0;
  assert_null(sim_cia401_create(&cfg));
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_cia402_boot_up_then_preoperational),
      cmocka_unit_test(test_cia402_enable_sequence_and_tpdos),
      cmocka_unit_test(test_cia402_heartbeat_every_period),
      cmocka_unit_test(test_cia402_fault_sends_emcy_and_resets_on_edge),
      cmocka_unit_test(test_cia402_rpdo_timeout_stops_drive),
      cmocka_unit_test(test_cia402_reset_node_and_silence),
      cmocka_unit_test(test_cia401_start_change_and_event_timer),
      cmocka_unit_test(test_cia401_silence_stop_and_reset),
  };
  return cmocka_run_group_tests_name("sim.cia402", tests, NULL, NULL);
}
