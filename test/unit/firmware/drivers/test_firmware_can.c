// SPDX-License-Identifier: MIT
// CAN driver over SOCK_SEQPACKET socket pairs and a named local socket (the emulated bus), the
// struct can_frame conversion, and the clear failure of SocketCAN on a kernel without CAN.
#define _GNU_SOURCE
#include <drivers/can.h>
#include <proto/canopen.h>

#include <errno.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cmocka.h>

typedef struct fixture {
  int fds[2];
  drv_can_t host;
  drv_can_t drive;
} fixture_t;

static int setup(void** state) {
  static fixture_t fx;
  if (socketpair(AF_UNIX, SOCK_SEQPACKET, 0, fx.fds) != 0) {
    return -1;
  }
  if (drv_can_attach(&fx.host, fx.fds[0], DRV_CAN_SEQPACKET, true) != 0 ||
      drv_can_attach(&fx.drive, fx.fds[1], DRV_CAN_SEQPACKET, true) != 0) {
    return -1;
  }
  *state = &fx;
  return 0;
}

static int teardown(void** state) {
  fixture_t* fx = *state;
  drv_can_close(&fx->host);
  drv_can_close(&fx->drive);
  return 0;
}

// A CANopen exchange crosses the emulated bus intact in both directions.
static void test_can_seqpacket_canopen_exchange(void** state) {
  fixture_t* fx = *state;
  canopen_frame_t f;
  canopen_frame_t g;
  assert_int_equal(drv_can_recv(&fx->drive, &g), 0);  // nothing yet, no blocking
  assert_int_equal(canopen_encode_nmt(&f, CANOPEN_NMT_START, 0), PROTO_OK);
  assert_int_equal(drv_can_send(&fx->host, &f), 0);
  assert_int_equal(canopen_encode_rpdo1(&f, 1, CIA402_CW_ENABLE_OPERATION, -51500), PROTO_OK);
  assert_int_equal(drv_can_send(&fx->host, &f), 0);
  assert_int_equal(canopen_encode_sync(&f), PROTO_OK);
  assert_int_equal(drv_can_send(&fx->host, &f), 0);
  assert_int_equal(drv_can_wait_readable(&fx->drive, 1000), 1);
  assert_int_equal(drv_can_recv(&fx->drive, &g), 1);
  canopen_nmt_t nmt;
  assert_int_equal(canopen_decode_nmt(&g, &nmt), PROTO_OK);
  assert_int_equal(nmt.command, CANOPEN_NMT_START);
  assert_int_equal(drv_can_recv(&fx->drive, &g), 1);
  canopen_rpdo1_t r;
  assert_int_equal(canopen_decode_rpdo1(&g, &r), PROTO_OK);
  assert_int_equal(r.controlword, CIA402_CW_ENABLE_OPERATION);
  assert_int_equal(r.target_velocity, -51500);
  assert_int_equal(drv_can_recv(&fx->drive, &g), 1);
  assert_int_equal(canopen_classify(&g, NULL), CANOPEN_KIND_SYNC);
  assert_int_equal(g.dlc, 0);
  assert_int_equal(canopen_encode_tpdo1(&f, 1, 0x0237, 51499), PROTO_OK);
  assert_int_equal(drv_can_send(&fx->drive, &f), 0);
  assert_int_equal(drv_can_recv(&fx->host, &g), 1);
  canopen_tpdo1_t t;
  assert_int_equal(canopen_decode_tpdo1(&g, &t), PROTO_OK);
  assert_true(cia402_operation_enabled(t.statusword));
  assert_int_equal(t.velocity_actual, 51499);
  assert_int_equal(fx->host.counters.frames_tx, 3);
  assert_int_equal(fx->drive.counters.frames_rx, 3);
}

// Extended and RTR frames and wrong-size records are dropped and counted, error frames counted
// apart; the next valid frame is still delivered.
static void test_can_recv_drops_foreign_records(void** state) {
  fixture_t* fx = *state;
  struct can_frame cf;
  memset(&cf, 0, sizeof cf);
  cf.can_id = 0x12345678U | CAN_EFF_FLAG;
  cf.can_dlc = 8;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  cf.can_id = 0x201U | CAN_RTR_FLAG;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  cf.can_id = CAN_ERR_FLAG;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  const uint8_t junk[5] = {1, 2, 3, 4, 5};
  assert_int_equal(send(fx->fds[1], junk, sizeof junk, 0), 5);
  uint8_t big[40];
  memset(big, 0, sizeof big);
  assert_int_equal(send(fx->fds[1], big, sizeof big, 0), 40);
  // An empty record is malformed, not the end of the bus (found by fuzz_can_read: recv() returns
  // 0 for it, which was taken for the peer's hang-up).
  assert_int_equal(send(fx->fds[1], big, 0, 0), 0);
  cf.can_id = 0x181;
  cf.can_dlc = 9;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  canopen_frame_t f;
  assert_int_equal(canopen_encode_heartbeat(&f, 2, CANOPEN_NMT_STATE_OPERATIONAL), PROTO_OK);
  assert_int_equal(drv_can_send(&fx->drive, &f), 0);
  canopen_frame_t g;
  assert_int_equal(drv_can_recv(&fx->host, &g), 1);
  assert_int_equal(g.id, 0x702);
  assert_int_equal(g.dlc, 1);
  assert_int_equal(g.data[0], CANOPEN_NMT_STATE_OPERATIONAL);
  assert_int_equal(fx->host.counters.rx_dropped_kind, 2);  // extended, RTR
  assert_int_equal(fx->host.counters.rx_error_frames, 1);  // counted apart: the bus resent a frame
  assert_int_equal(fx->host.counters.rx_bad_size, 4);
  assert_int_equal(fx->host.counters.frames_rx, 1);
}

// The controller's bus-off report sets the port's bus_off state (counted), its restart report
// clears it; so does any frame received after a restart report was lost.
static void test_can_bus_off_and_restart(void** state) {
  fixture_t* fx = *state;
  struct can_frame cf;
  memset(&cf, 0, sizeof cf);
  cf.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
  cf.can_dlc = CAN_ERR_DLC;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  canopen_frame_t g;
  assert_int_equal(drv_can_recv(&fx->host, &g), 0);
  assert_true(fx->host.bus_off);
  assert_int_equal(fx->host.counters.bus_off_events, 1);
  cf.can_id = CAN_ERR_FLAG | CAN_ERR_RESTARTED;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  assert_int_equal(drv_can_recv(&fx->host, &g), 0);
  assert_false(fx->host.bus_off);
  cf.can_id = CAN_ERR_FLAG | CAN_ERR_BUSOFF;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  memset(&cf, 0, sizeof cf);
  cf.can_id = 0x701;
  cf.can_dlc = 1;
  cf.data[0] = CANOPEN_NMT_STATE_OPERATIONAL;
  assert_int_equal(send(fx->fds[1], &cf, sizeof cf, 0), (ssize_t)sizeof cf);
  assert_int_equal(drv_can_recv(&fx->host, &g), 1);
  assert_false(fx->host.bus_off);
  assert_int_equal(fx->host.counters.bus_off_events, 2);
  assert_int_equal(fx->host.counters.rx_error_frames, 3);
}

// Invalid frames are refused before they reach the bus; a closed peer is reported as -EPIPE.
static void test_can_invalid_send_and_peer_closed(void** state) {
  fixture_t* fx = *state;
  canopen_frame_t f = {.id = 0x800, .dlc = 1};
  assert_int_equal(drv_can_send(&fx->host, &f), -EINVAL);
  f.id = 0x100;
  f.dlc = 9;
  assert_int_equal(drv_can_send(&fx->host, &f), -EINVAL);
  drv_can_close(&fx->drive);
  canopen_frame_t g;
  assert_int_equal(drv_can_recv(&fx->host, &g), -EPIPE);
  f.dlc = 1;
  assert_true(drv_can_send(&fx->host, &f) < 0);
}

// Frame conversion to and from struct can_frame keeps id, DLC and data, and rejects the rest.
static void test_can_linux_conversion(void** state) {
  (void)state;
  canopen_frame_t f;
  assert_int_equal(canopen_encode_emcy(&f, 1, 0x1234, 0x56, NULL), PROTO_OK);
  struct can_frame cf;
  assert_int_equal(drv_can_to_linux(&f, &cf), 0);
  assert_int_equal(cf.can_id, 0x081);
  assert_int_equal(cf.can_dlc, 8);
  assert_int_equal(cf.data[0], 0x34);
  canopen_frame_t g;
  assert_int_equal(drv_can_from_linux(&cf, &g), 0);
  assert_memory_equal(&f, &g, sizeof f);
  cf.can_id |= CAN_EFF_FLAG;
  assert_int_equal(drv_can_from_linux(&cf, &g), -EINVAL);
  f.id = 0x1000;
  assert_int_equal(drv_can_to_linux(&f, &cf), -EINVAL);
}

// A named bus socket: the server listens, the driver connects by path, frames flow.
static void test_can_named_seqpacket_connects(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r_can_XXXXXX";
  assert_non_null(mkdtemp(dir));
  char path[128];
  snprintf(path, sizeof path, "%s/bus.sock", dir);
  char err[256] = "";
  const int lfd = drv_can_seqpacket_listen(path, 2, err, sizeof err);
  assert_true(lfd >= 0);
  drv_can_t host;
  assert_int_equal(drv_can_open_seqpacket(&host, path, err, sizeof err), 0);
  const int sfd = accept(lfd, NULL, NULL);
  assert_true(sfd >= 0);
  drv_can_t server;
  assert_int_equal(drv_can_attach(&server, sfd, DRV_CAN_SEQPACKET, true), 0);
  canopen_frame_t f;
  assert_int_equal(canopen_encode_tpdo2(&f, 2, -123456789), PROTO_OK);
  assert_int_equal(drv_can_send(&server, &f), 0);
  assert_int_equal(drv_can_wait_readable(&host, 1000), 1);
  canopen_frame_t g;
  assert_int_equal(drv_can_recv(&host, &g), 1);
  canopen_tpdo2_t t;
  assert_int_equal(canopen_decode_tpdo2(&g, &t), PROTO_OK);
  assert_int_equal(t.position_actual, -123456789);
  drv_can_close(&host);
  drv_can_close(&server);
  close(lfd);
  // A missing bus is a clear error naming the path.
  assert_true(drv_can_open_seqpacket(&host, path, err, sizeof err) < 0);
  unlink(path);
  assert_true(drv_can_open_seqpacket(&host, path, err, sizeof err) < 0);
  assert_non_null(strstr(err, path));
  rmdir(dir);
}

// Opening can0 fails here with a message that says why (no CAN in this kernel, or no such
// interface); it never succeeds silently on a machine without the interface.
static void test_can_socketcan_missing_reports_reason(void** state) {
  (void)state;
  drv_can_t port;
  char err[512] = "";
  const int rc = drv_can_open_socketcan(&port, "b21r_nocan0", err, sizeof err);
  assert_true(rc < 0);
  assert_true(strlen(err) > 0U);
  if (rc == -EAFNOSUPPORT) {
    assert_non_null(strstr(err, "no SocketCAN support"));
  } else {
    assert_non_null(strstr(err, "b21r_nocan0"));
  }
  const int rc0 = drv_can_open_socketcan(&port, "can0", err, sizeof err);
  if (rc0 == 0) {
    drv_can_close(&port);  // a machine with a real can0: nothing more to check here
  } else {
    assert_non_null(strstr(err, "can0"));
  }
  assert_int_equal(drv_can_open_socketcan(&port, "a_very_long_interface_name", err, sizeof err),
                   -EINVAL);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test_setup_teardown(test_can_seqpacket_canopen_exchange, setup, teardown),
      cmocka_unit_test_setup_teardown(test_can_recv_drops_foreign_records, setup, teardown),
      cmocka_unit_test_setup_teardown(test_can_bus_off_and_restart, setup, teardown),
      cmocka_unit_test_setup_teardown(test_can_invalid_send_and_peer_closed, setup, teardown),
      cmocka_unit_test(test_can_linux_conversion),
      cmocka_unit_test(test_can_named_seqpacket_connects),
      cmocka_unit_test(test_can_socketcan_missing_reports_reason),
  };
  return cmocka_run_group_tests_name("firmware.can", tests, NULL, NULL);
}
