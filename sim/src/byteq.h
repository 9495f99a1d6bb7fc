// SPDX-License-Identifier: MIT
// Outgoing byte queue of an emulated serial device, optionally paced at the line's baud rate.
#ifndef B21R_SIM_BYTEQ_H
#define B21R_SIM_BYTEQ_H

#include <stddef.h>
#include <stdint.h>

#define SIM_BYTEQ_CAP 16384U   // bytes: ten full 361-beam scans, or hundreds of rFLEX packets
#define SIM_BYTEQ_CHUNKS 512U  // telegrams/packets queued at once

// One queued telegram: its bytes leave no earlier than ready_t_s, at `baud` (8N1: 10 bits/byte).
typedef struct sim_byteq_chunk {
  uint32_t remaining;
  uint32_t baud;
  double ready_t_s;
} sim_byteq_chunk_t;

typedef struct sim_byteq {
  uint8_t buf[SIM_BYTEQ_CAP];
  size_t head;  // index of the oldest byte
  size_t len;   // bytes queued
  sim_byteq_chunk_t chunks[SIM_BYTEQ_CHUNKS];
  size_t ch_head;
  size_t ch_len;
  double link_free_t_s;  // when the last byte released so far has left the line
  uint64_t overflows;    // chunks dropped because the queue was full (never decreases)
} sim_byteq_t;

void sim_byteq_init(sim_byteq_t* q);
// Queues n bytes as one chunk; drops the whole chunk (counted) if it does not fit. Returns 1 if
// queued. O(n).
int sim_byteq_push(sim_byteq_t* q, const uint8_t* bytes, size_t n, double ready_t_s, uint32_t baud);
// Releases bytes into out: all of them when paced == 0, else those whose last bit has left the
// line by t_s. O(bytes released).
size_t sim_byteq_drain(sim_byteq_t* q, uint8_t* out, size_t cap, double t_s, int paced);
// 1 when nothing is queued and the line is idle at t_s (paced view).
int sim_byteq_idle(const sim_byteq_t* q, double t_s);
// Drops everything queued (e.g. on a reset).
void sim_byteq_clear(sim_byteq_t* q);

#endif  // B21R_SIM_BYTEQ_H
