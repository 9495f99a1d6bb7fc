// SPDX-License-Identifier: MIT
// Link mode of the serial port: what serial.c needs of serial_link.c (the owner's side).
#ifndef DRIVERS_SERIAL_LINK_H
#define DRIVERS_SERIAL_LINK_H

#include <drivers/serial.h>

/// Takes up to cap input bytes; *flushes: the owner's count of input flushes applied (bytes
/// that arrived before the helper thread's flush are dropped). Returns bytes (> 0), 0 (none),
/// or the link's error (< 0: hang-up, I/O error).
ssize_t drv_serial_link_take(drv_serial_link_t* link, uint32_t* flushes, uint8_t* buf, size_t cap);

/// Drops the input the ring holds now and asks the helper thread to flush the terminal's input.
int drv_serial_link_flush_input(drv_serial_link_t* link, uint32_t* flushes);

/// Requests: n bytes written with the given pacing; a rate change after the output drained.
int drv_serial_link_write(drv_serial_link_t* link, const uint8_t* data, size_t n, uint32_t chunk_gap_us,
                          uint32_t byte_gap_us);
int drv_serial_link_set_baud(drv_serial_link_t* link, uint32_t baud);

#endif  // DRIVERS_SERIAL_LINK_H
