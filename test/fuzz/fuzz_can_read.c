// SPDX-License-Identifier: MIT
// libFuzzer target: the SocketCAN read path (drivers/can.h, drv_can_recv) over a SOCK_SEQPACKET
// socket pair (the kernel here has no CAN; the pair carries the same struct can_frame records),
// attached as the emulated bus or, when input byte 0 is odd, as a SocketCAN socket. The rest of
// the input is a sequence of records, each a length byte (0..31) and that many bytes, sent as one
// datagram each: well-formed struct can_frame
// records, short and long ones, empty ones, extended/RTR/error ids and DLCs above 8. Properties:
// every frame passed up is a standard data frame (id <= 0x7FF, dlc <= 8);
// every record is either passed up or counted (dropped, or an error frame; bus-off reports among
// the error frames); the peer is never taken for closed while it is open.
#include <drivers/can.h>

#include "fuzz_util.h"

#include <errno.h>
#include <linux/can.h>
#include <sys/socket.h>

static int g_fd[2] = {-1, -1};

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (g_fd[0] < 0) {
    FUZZ_CHECK(socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, g_fd) == 0);
  }
  fuzz_in_t in = {data, size};
  const drv_can_transport_t transport = (fuzz_u8(&in) & 1U) != 0 ? DRV_CAN_SOCKETCAN : DRV_CAN_SEQPACKET;
  drv_can_t port;
  FUZZ_CHECK(drv_can_attach(&port, g_fd[1], transport, false) == 0);
  uint64_t records = 0;
  uint64_t frames = 0;
  while (fuzz_more(&in)) {
    // A burst of up to 8 records, then read until the socket is empty (keeps the queue short).
    for (int b = 0; b < 8 && fuzz_more(&in); ++b) {
      uint8_t rec[32];
      const size_t len = fuzz_u8(&in) % 32U;
      (void)fuzz_bytes(&in, rec, len);
      FUZZ_CHECK(send(g_fd[0], rec, len, MSG_NOSIGNAL) == (ssize_t)len);
      ++records;
    }
    for (;;) {
      canopen_frame_t f;
      memset(&f, 0xEE, sizeof f);
      const int r = drv_can_recv(&port, &f);
      FUZZ_CHECK(r == 0 || r == 1);  // the peer is open: never -EPIPE or another error
      if (r == 0) {
        break;
      }
      ++frames;
      FUZZ_CHECK(f.id <= 0x7FFU && f.dlc <= 8U);
    }
  }
  const drv_can_counters_t* c = &port.counters;
  FUZZ_CHECK(c->frames_rx == frames);
  FUZZ_CHECK(c->frames_rx + c->rx_bad_size + c->rx_dropped_kind + c->rx_error_frames == records);
  FUZZ_CHECK(c->bus_off_events <= c->rx_error_frames);
  FUZZ_CHECK(c->errors == 0);
  drv_can_close(&port);  // does not own the descriptor
  return 0;
}
