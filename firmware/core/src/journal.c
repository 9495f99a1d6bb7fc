// SPDX-License-Identifier: MIT
// The journal of finished runs: record encoding and decoding (fw/journal.h).
#include "fw/journal.h"

#include "fw/checkpoint.h"
#include "le_bytes.h"

#include <string.h>

static const uint8_t k_magic[4] = {'B', '2', '1', 'J'};

size_t fw_journal_transition_bytes(uint32_t state_dim) { return 8U * (2U * (size_t)state_dim + 2U) + 8U; }

size_t fw_journal_record_bytes(uint32_t state_dim, uint32_t n) {
  return FW_JOURNAL_HEADER_BYTES + FW_JOURNAL_RUN_BYTES + (size_t)n * fw_journal_transition_bytes(state_dim);
}

bool fw_journal_put_transition(uint8_t* rec, size_t cap, uint32_t state_dim, uint32_t i,
                               const fw_journal_transition_t* t) {
  if (state_dim == 0U || state_dim > FW_JOURNAL_MAX_DIM || fw_journal_record_bytes(state_dim, i + 1U) > cap) {
    return false;
  }
  uint8_t* p = rec + fw_journal_record_bytes(state_dim, i);
  for (uint32_t k = 0; k < state_dim; ++k, p += 8) {
    fw_put_f64(p, t->s[k]);
  }
  fw_put_f64(p, t->a);
  fw_put_f64(p + 8, t->r);
  p += 16;
  for (uint32_t k = 0; k < state_dim; ++k, p += 8) {
    fw_put_f64(p, t->s_next[k]);
  }
  fw_put_u64(p, t->terminal ? 1U : 0U);
  return true;
}

static void put_i32(uint8_t* p, int32_t v) { fw_put_u32(p, (uint32_t)v); }
static int32_t get_i32(const uint8_t* p) { return (int32_t)fw_get_u32(p); }

size_t fw_journal_finish(uint8_t* rec, size_t cap, const fw_journal_run_t* run) {
  if (run->state_dim == 0U || run->state_dim > FW_JOURNAL_MAX_DIM || (run->n > 0U && !run->learned)) {
    return 0;
  }
  const size_t size = fw_journal_record_bytes(run->state_dim, run->n);
  if (size > cap || size - FW_JOURNAL_HEADER_BYTES > UINT32_MAX) {
    return 0;
  }
  uint8_t* b = rec + FW_JOURNAL_HEADER_BYTES;
  put_i32(b + 0, run->run_id);
  put_i32(b + 4, run->kind);
  put_i32(b + 8, run->phase);
  put_i32(b + 12, run->training_index);
  put_i32(b + 16, run->eval_index);
  put_i32(b + 20, run->steps);
  b[24] = run->goal ? 1U : 0U;
  b[25] = run->aborted ? 1U : 0U;
  b[26] = run->learned ? 1U : 0U;
  b[27] = 0U;
  fw_put_u32(b + 28, run->state_dim);
  fw_put_u32(b + 32, run->n);
  const size_t body = size - FW_JOURNAL_HEADER_BYTES;
  memcpy(rec, k_magic, sizeof k_magic);
  fw_put_u32(rec + 4, FW_JOURNAL_VERSION);
  fw_put_u32(rec + 8, (uint32_t)body);
  fw_put_u32(rec + 12, fw_crc32(0, b, body));
  return size;
}

int fw_journal_next(const uint8_t* p, size_t len, fw_journal_run_t* run, const uint8_t** transitions, size_t* size) {
  if (len == 0U) {
    return 0;
  }
  if (len < FW_JOURNAL_HEADER_BYTES) {
    return memcmp(p, k_magic, len < sizeof k_magic ? len : sizeof k_magic) == 0 ? 0 : -1;
  }
  if (memcmp(p, k_magic, sizeof k_magic) != 0 || fw_get_u32(p + 4) != FW_JOURNAL_VERSION) {
    return -1;
  }
  const uint32_t body = fw_get_u32(p + 8);
  if (body < FW_JOURNAL_RUN_BYTES) {
    return -1;
  }
  if ((size_t)body > len - FW_JOURNAL_HEADER_BYTES) {
    return 0;  // cut short: written when the process died
  }
  const uint8_t* b = p + FW_JOURNAL_HEADER_BYTES;
  if (fw_crc32(0, b, body) != fw_get_u32(p + 12)) {
    return -1;
  }
  fw_journal_run_t r;
  memset(&r, 0, sizeof r);
  r.run_id = get_i32(b + 0);
  r.kind = get_i32(b + 4);
  r.phase = get_i32(b + 8);
  r.training_index = get_i32(b + 12);
  r.eval_index = get_i32(b + 16);
  r.steps = get_i32(b + 20);
  r.goal = b[24] != 0U;
  r.aborted = b[25] != 0U;
  r.learned = b[26] != 0U;
  r.state_dim = fw_get_u32(b + 28);
  r.n = fw_get_u32(b + 32);
  if (b[24] > 1U || b[25] > 1U || b[26] > 1U || b[27] != 0U || r.state_dim == 0U || r.state_dim > FW_JOURNAL_MAX_DIM ||
      r.run_id < 0 || r.steps < 0 || (r.n > 0U && !r.learned) ||
      (uint64_t)r.n * fw_journal_transition_bytes(r.state_dim) != (uint64_t)body - FW_JOURNAL_RUN_BYTES) {
    return -1;
  }
  *run = r;
  *transitions = b + FW_JOURNAL_RUN_BYTES;
  *size = FW_JOURNAL_HEADER_BYTES + (size_t)body;
  return 1;
}

void fw_journal_get_transition(const uint8_t* transitions, uint32_t state_dim, uint32_t i,
                               fw_journal_transition_t* out) {
  memset(out, 0, sizeof *out);
  const uint8_t* p = transitions + (size_t)i * fw_journal_transition_bytes(state_dim);
  for (uint32_t k = 0; k < state_dim; ++k, p += 8) {
    out->s[k] = fw_get_f64(p);
  }
  out->a = fw_get_f64(p);
  out->r = fw_get_f64(p + 8);
  p += 16;
  for (uint32_t k = 0; k < state_dim; ++k, p += 8) {
    out->s_next[k] = fw_get_f64(p);
  }
  out->terminal = fw_get_u64(p) != 0U;
}
