// SPDX-License-Identifier: MIT
// libFuzzer target: CANopen frame decoding (drives and the CiA 401 bump-panel node) and the
// CiA 402 state machines fed with arbitrary frames (each 11 input bytes: id (2), dlc (1),
// data (8)).
#include <proto/canopen.h>

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

static void check(int ok) {
  if (!ok) {
    abort();
  }
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  cia402_drive_t drive;
  cia402_master_t master;
  canopen_hb_consumer_t hb;
  cia402_drive_init(&drive);
  cia402_master_init(&master);
  check(canopen_hb_init(&hb, 1, 100000) == PROTO_OK);
  uint64_t now = 0;
  for (size_t off = 0; off + 11 <= size; off += 11) {
    canopen_frame_t f;
    f.id = (uint32_t)(data[off] | (data[off + 1] << 8)) & 0xFFFU;
    f.dlc = data[off + 2] % 10U;  // sometimes invalid on purpose
    memcpy(f.data, data + off + 3, 8);
    uint8_t node = 0;
    const canopen_kind_t kind = canopen_classify(&f, &node);
    check(node <= CANOPEN_NODE_MAX);
    canopen_nmt_t nmt;
    canopen_emcy_t emcy;
    canopen_rpdo1_t r1;
    canopen_tpdo1_t t1;
    canopen_tpdo2_t t2;
    canopen_heartbeat_t h;
    (void)canopen_decode_nmt(&f, &nmt);
    (void)canopen_decode_emcy(&f, &emcy);
    if (canopen_decode_rpdo1(&f, &r1) == PROTO_OK) {
      check(kind == CANOPEN_KIND_RPDO1);
      cia402_drive_apply_controlword(&drive, r1.controlword);
      // Re-encoding gives the same bytes.
      canopen_frame_t g;
      check(canopen_encode_rpdo1(&g, r1.node, r1.controlword, r1.target_velocity) == PROTO_OK);
      check(g.id == f.id && memcmp(g.data, f.data, 6) == 0);
    }
    if (canopen_decode_tpdo1(&f, &t1) == PROTO_OK) {
      (void)cia402_master_controlword(&master, t1.statusword, (cia402_request_t)(t1.statusword % 3U));
      (void)cia402_state_name(cia402_state_from_statusword(t1.statusword));
    }
    cia401_bumpers_t bump;
    if (cia401_decode_bumpers(&f, &bump) == PROTO_OK) {
      // Every decoded panel fits its 4 segments, the mask names exactly the pressed ones, and
      // re-encoding gives the same 7 bytes.
      check(kind == CANOPEN_KIND_TPDO1 && f.dlc >= CIA401_BUMP_TPDO1_DLC);
      const uint32_t mask = cia401_bumper_mask(&bump);
      for (unsigned p = 0; p < CIA401_BUMP_PANELS; ++p) {
        check(bump.panels[p] <= CIA401_BUMP_SEGMENTS);
        check(((mask >> p) & 1U) == (bump.panels[p] != 0U ? 1U : 0U));
      }
      check((mask >> CIA401_BUMP_PANELS) == 0U);
      canopen_frame_t g;
      check(cia401_encode_bumpers(&g, bump.node, bump.panels) == PROTO_OK);
      check(g.id == f.id && memcmp(g.data, f.data, CIA401_BUMP_TPDO1_DLC) == 0);
    }
    (void)canopen_decode_tpdo2(&f, &t2);
    (void)canopen_decode_heartbeat(&f, &h);
    (void)canopen_hb_feed(&hb, &f, now);
    now += f.data[0];
    (void)canopen_hb_expired(&hb, now, 0);
    if (f.data[1] == 0xEE) {
      cia402_drive_set_fault(&drive, (uint16_t)(f.data[2] | (f.data[3] << 8)));
    }
    const uint16_t sw = cia402_drive_statusword(&drive, false);
    check(cia402_state_from_statusword(sw) == drive.state);
  }
  return 0;
}
