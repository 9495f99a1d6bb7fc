// SPDX-License-Identifier: MIT
// Outgoing byte queue of an emulated serial device, optionally paced at the line's baud rate.
#include "byteq.h"

#include <string.h>

void sim_byteq_init(sim_byteq_t* q) {
  memset(q, 0, sizeof(*q));
}

void sim_byteq_clear(sim_byteq_t* q) {
  q->head = q->len = 0;
  q->ch_head = q->ch_len = 0;
}

int sim_byteq_push(sim_byteq_t* q, const uint8_t* bytes, size_t n, double ready_t_s, uint32_t baud) {
  if (n == 0) {
    return 1;
  }
  if (n > SIM_BYTEQ_CAP - q->len || q->ch_len == SIM_BYTEQ_CHUNKS) {
    ++q->overflows;
    return 0;
  }
  for (size_t i = 0; i < n; ++i) {
    q->buf[(q->head + q->len + i) % SIM_BYTEQ_CAP] = bytes[i];
  }
  q->len += n;
  sim_byteq_chunk_t* c = &q->chunks[(q->ch_head + q->ch_len) % SIM_BYTEQ_CHUNKS];
  c->remaining = (uint32_t)n;
  c->baud = baud > 0 ? baud : 9600U;
  c->ready_t_s = ready_t_s;
  ++q->ch_len;
  return 1;
}

size_t sim_byteq_drain(sim_byteq_t* q, uint8_t* out, size_t cap, double t_s, int paced) {
  size_t n = 0;
  while (q->len > 0 && n < cap) {
    sim_byteq_chunk_t* c = &q->chunks[q->ch_head];
    if (paced) {
      const double start = c->ready_t_s > q->link_free_t_s ? c->ready_t_s : q->link_free_t_s;
      const double done = start + 10.0 / (double)c->baud;
      if (done > t_s) {
        break;
      }
      q->link_free_t_s = done;
    }
    out[n++] = q->buf[q->head];
    q->head = (q->head + 1U) % SIM_BYTEQ_CAP;
    --q->len;
    if (--c->remaining == 0U) {
      q->ch_head = (q->ch_head + 1U) % SIM_BYTEQ_CHUNKS;
      --q->ch_len;
    }
  }
  return n;
}

int sim_byteq_idle(const sim_byteq_t* q, double t_s) {
  return q->len == 0 && q->link_free_t_s <= t_s;
}
