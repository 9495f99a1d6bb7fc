// SPDX-License-Identifier: MIT
/// sim/endpoints.h — The transports of the b21r-sim program: pseudo-terminals for the serial
/// devices, SOCK_SEQPACKET unix sockets for the CAN bus and the control channel.
///
/// - Serial: sim_pty_open creates a pty pair in raw mode (8N1, no echo, no translation). The
///   controller opens the slave path (e.g. /dev/pts/3) exactly like a serial port; b21r-sim
///   reads and writes the master. The emulator keeps its own slave descriptor open so that the
///   master never reports a hang-up while the controller reopens the port. Baud settings on a
///   pty have no effect; the emulator paces bytes itself (real-time mode).
/// - CAN: a SOCK_SEQPACKET socket carrying one `struct can_frame` (16 bytes, <linux/can.h>) per
///   datagram, 11-bit ids only. Every connected client is a node on one bus: a frame from one
///   client goes to the emulated drives and to every other client; drive frames go to all.
/// - Control: a SOCK_SEQPACKET socket, one text command per datagram, one reply per datagram
///   (sim/emulator.h, sim_emu_control).
/// - Ready line: `laser=/dev/pts/N base=/dev/pts/M can=PATH control=PATH` (the fields that
///   apply), printed on stdout and, with --endpoints FILE, written to FILE atomically
///   (temporary file, fsync, rename) so that a waiting test harness never reads half a line.
///
/// All functions return -1 with errno set on failure and leave nothing open then.
#ifndef B21R_SIM_ENDPOINTS_H
#define B21R_SIM_ENDPOINTS_H

#include <stddef.h>

#include <linux/can.h>
#include <proto/canopen.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Opens a pty pair in raw mode. *master_fd is non-blocking and close-on-exec; *slave_fd stays
/// open in the emulator (see above). Writes the slave's path into path (cap >= 32). Returns 0.
int sim_pty_open(int* master_fd, int* slave_fd, char* path, size_t cap);

/// Creates a listening non-blocking SOCK_SEQPACKET unix socket at path (a stale socket file is
/// removed first). Returns the descriptor. path must fit sockaddr_un (107 bytes).
int sim_seqpacket_listen(const char* path);

/// Connects to a SOCK_SEQPACKET unix socket (blocking descriptor). Returns the descriptor.
int sim_seqpacket_connect(const char* path);

/// Converts between the socket record and lib/proto's frame (flags dropped, dlc clamped to 8).
void sim_can_from_linux(const struct can_frame* in, canopen_frame_t* out);
void sim_can_to_linux(const canopen_frame_t* in, struct can_frame* out);

/// Writes text to path atomically (temporary file in the same directory, fsync, rename).
int sim_write_file_atomic(const char* path, const char* text);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_ENDPOINTS_H
