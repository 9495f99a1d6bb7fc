// SPDX-License-Identifier: MIT
// libFuzzer target: the base input of the loop (rFLEX bytes or CANopen frames) through the
// public API, on the fake robot (a loop per base that lives on across inputs, fuzz_loop.h):
// every base read takes the next input record, op byte first: 0 = bytes (length byte, bytes)
// or one frame (id u16, dlc, 8 data bytes) from the input; 1 = the fake robot's genuine data;
// 2 = nothing (the read ends). Input byte 0 bit 0 picks CANopen. The loop ticks until the input
// is used up (2 ticks at most), then once more on genuine data. The loop evaluates the example
// policy (no learning: the target is about the base's input, and learning made each tick five
// times dearer).
// Properties (fuzz_loop.c): the loop survives anything and commands only finite values within
// the configured limits; its counters stay consistent.
#include "fuzz_loop.h"
#include "fuzz_util.h"

typedef struct source {
  fuzz_in_t in;
  fuzz_loop_t* fl;
} source_t;

static ssize_t fuzzed_base_read(void* user, uint8_t* buf, size_t cap) {
  source_t* s = (source_t*)user;
  if (!fuzz_more(&s->in)) {
    return fuzz_loop_fake_base_read(s->fl, buf, cap);
  }
  switch (fuzz_u8(&s->in) % 3U) {
    case 0: {
      size_t n = fuzz_u8(&s->in);
      n = n < cap ? n : cap;
      return (ssize_t)fuzz_bytes(&s->in, buf, n);
    }
    case 1:
      return fuzz_loop_fake_base_read(s->fl, buf, cap);
    default:
      return 0;
  }
}

static int fuzzed_can_read(void* user, canopen_frame_t* frame) {
  source_t* s = (source_t*)user;
  if (!fuzz_more(&s->in)) {
    return fuzz_loop_fake_can_read(s->fl, frame);
  }
  switch (fuzz_u8(&s->in) % 3U) {
    case 0:
      frame->id = fuzz_u16(&s->in) & 0x7FFU;
      frame->dlc = (uint8_t)(fuzz_u8(&s->in) % 9U);
      (void)fuzz_bytes(&s->in, frame->data, 8);
      return 1;
    case 1:
      return fuzz_loop_fake_can_read(s->fl, frame);
    default:
      return 0;
  }
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) {
    return 0;
  }
  static fuzz_loop_t loops[2];
  static source_t src;
  const bool canopen = (data[0] & 1U) != 0;
  fuzz_loop_t* fl = &loops[canopen ? 1 : 0];
  src.in = (fuzz_in_t){data + 1, size - 1};
  src.fl = fl;
  const fuzz_base_input_t input = {.base_read = canopen ? NULL : fuzzed_base_read,
                                   .can_read = canopen ? fuzzed_can_read : NULL,
                                   .user = &src};
  fw_config_t cfg;
  fuzz_loop_config(&cfg, canopen);
  cfg.mode = FW_MODE_EVALUATE;
  cfg.evaluate_policy = FW_EVAL_EXAMPLE;
  cfg.eval_starts = 16;
  (void)fuzz_loop_ready(fl, &cfg, &input);
  for (int ticks = 0; fuzz_more(&src.in) && ticks < 2 && fuzz_loop_tick(fl); ++ticks) {
  }
  (void)fuzz_loop_tick(fl);
  fw_loop_stats_t st;
  fw_loop_get_stats(fl->loop, &st);
  FUZZ_CHECK(st.runs_finished >= 0 && st.runs_aborted >= 0 && st.training_runs <= st.runs_finished);
  return 0;
}
