// SPDX-License-Identifier: MIT
// Lock-free SPSC ring: head written by the producer only, tail by the consumer only.
#include "fw/pubq.h"

#include "fw/prefault.h"

#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

struct fw_pubq {
  uint32_t capacity;
  uint32_t mask;
  _Alignas(64) atomic_uint_fast64_t head;  // next slot to commit (producer)
  _Alignas(64) atomic_uint_fast64_t tail;  // next slot to pop (consumer)
  _Alignas(64) atomic_uint_fast64_t drops[FW_MSG_KIND_COUNT];
  fw_msg_t* slots;
};

static const char* const k_channels[FW_MSG_KIND_COUNT] = {"B21R_EXPERIENCE", "B21R_STATUS", "B21R_POSE",
                                                          "B21R_EVAL", "B21R_SCAN", "",
                                                          "B21R_CONFIG", "B21R_RUN"};

const char* fw_msg_channel(int32_t kind) {
  return (kind >= 0 && kind < FW_MSG_KIND_COUNT) ? k_channels[kind] : "";
}

fw_pubq_t* fw_pubq_create(uint32_t capacity) {
  if (capacity < 2U || (capacity & (capacity - 1U)) != 0U) {
    return NULL;
  }
  fw_pubq_t* q = (fw_pubq_t*)aligned_alloc(64, (sizeof(fw_pubq_t) + 63U) & ~(size_t)63U);
  if (q == NULL) {
    return NULL;
  }
  memset(q, 0, sizeof *q);
  q->slots = (fw_msg_t*)calloc(capacity, sizeof(fw_msg_t));
  if (q->slots == NULL) {
    free(q);
    return NULL;
  }
  q->capacity = capacity;
  q->mask = capacity - 1U;
  atomic_init(&q->head, 0);
  atomic_init(&q->tail, 0);
  for (int i = 0; i < FW_MSG_KIND_COUNT; ++i) {
    atomic_init(&q->drops[i], 0);
  }
  return q;
}

void fw_pubq_prefault(fw_pubq_t* q) { fw_prefault(q->slots, (size_t)q->capacity * sizeof(fw_msg_t)); }

void fw_pubq_destroy(fw_pubq_t* q) {
  if (q != NULL) {
    free(q->slots);
    free(q);
  }
}

fw_msg_t* fw_pubq_reserve(fw_pubq_t* q, fw_msg_kind_t kind) {
  const uint64_t head = atomic_load_explicit(&q->head, memory_order_relaxed);
  const uint64_t tail = atomic_load_explicit(&q->tail, memory_order_acquire);
  if (head - tail >= q->capacity) {
    if ((int)kind >= 0 && kind < FW_MSG_KIND_COUNT) {
      atomic_fetch_add_explicit(&q->drops[kind], 1, memory_order_relaxed);
    }
    return NULL;
  }
  fw_msg_t* slot = &q->slots[head & q->mask];
  slot->kind = (int32_t)kind;
  return slot;
}

void fw_pubq_commit(fw_pubq_t* q) {
  const uint64_t head = atomic_load_explicit(&q->head, memory_order_relaxed);
  atomic_store_explicit(&q->head, head + 1U, memory_order_release);
}

const fw_msg_t* fw_pubq_peek(fw_pubq_t* q) {
  const uint64_t tail = atomic_load_explicit(&q->tail, memory_order_relaxed);
  const uint64_t head = atomic_load_explicit(&q->head, memory_order_acquire);
  if (tail == head) {
    return NULL;
  }
  return &q->slots[tail & q->mask];
}

void fw_pubq_pop(fw_pubq_t* q) {
  const uint64_t tail = atomic_load_explicit(&q->tail, memory_order_relaxed);
  atomic_store_explicit(&q->tail, tail + 1U, memory_order_release);
}

uint64_t fw_pubq_drops(const fw_pubq_t* q, int32_t kind) {
  fw_pubq_t* m = (fw_pubq_t*)(uintptr_t)q;  // atomic loads need a non-const object in C11
  if (kind >= 0 && kind < FW_MSG_KIND_COUNT) {
    return atomic_load_explicit(&m->drops[kind], memory_order_relaxed);
  }
  uint64_t total = 0;
  for (int i = 0; i < FW_MSG_KIND_COUNT; ++i) {
    total += atomic_load_explicit(&m->drops[i], memory_order_relaxed);
  }
  return total;
}

uint64_t fw_pubq_committed(const fw_pubq_t* q) {
  fw_pubq_t* m = (fw_pubq_t*)(uintptr_t)q;
  return atomic_load_explicit(&m->head, memory_order_acquire);
}

uint32_t fw_pubq_depth(const fw_pubq_t* q) {
  fw_pubq_t* m = (fw_pubq_t*)(uintptr_t)q;
  const uint64_t head = atomic_load_explicit(&m->head, memory_order_acquire);
  const uint64_t tail = atomic_load_explicit(&m->tail, memory_order_acquire);
  return (uint32_t)(head - tail);
}

uint32_t fw_pubq_capacity(const fw_pubq_t* q) { return q->capacity; }
