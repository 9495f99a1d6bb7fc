// SPDX-License-Identifier: MIT
// libFuzzer target: the operator's TELEOP and COMMAND messages through the loop's public API
// (fw_loop_post_teleop, fw_loop_post_command, fw_loop_tick) with the joystick driving phase one,
// on the fake robot (a loop that lives on across inputs, fuzz_loop.h). The input is a sequence
// of records, op byte first (op % 8): 0-2 = TELEOP (seq i64, deadman, rotation f64, translation
// f64, arrival offset i16 ms from the loop's clock); 3-4 = COMMAND (seq u16, command i8,
// argument i32); 5-6 = 1..4 ticks (4 per input at most); 7 = a signal, then a tick.
// Properties: every message is accepted or rejected (counted) once the loop has seen it; the
// base gets finite commands within the limits (fuzz_loop.c); after a signal the loop ends in
// that tick with a zero command.
#include "fuzz_loop.h"
#include "fuzz_util.h"

#include <signal.h>

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz_loop_t fl;
  static int64_t teleops;   // posted to the current loop
  static int64_t commands;
  fw_config_t cfg;
  fuzz_loop_config(&cfg, false);
  cfg.phase_driver = FW_DRIVER_JOYSTICK;
  cfg.phase_switch = FW_SWITCH_OPERATOR;
  if (fuzz_loop_ready(&fl, &cfg, NULL)) {
    teleops = 0;
    commands = 0;
  }
  fuzz_in_t in = {data, size};
  int ticks = 0;
  while (fuzz_more(&in) && !fl.done) {
    const unsigned op = fuzz_u8(&in) % 8U;
    if (op <= 2) {
      b21r_teleop_t m;
      memset(&m, 0, sizeof m);
      m.seq = (int64_t)fuzz_u64(&in);
      m.deadman = (fuzz_u8(&in) & 1U) != 0;
      m.rotation_radps = fuzz_f64(&in);
      m.translation_mps = fuzz_f64(&in);
      const int64_t arrival = fl.fake.clock_us + (int64_t)(int16_t)fuzz_u16(&in) * 1000;
      fw_loop_post_teleop(fl.loop, &m, arrival);
      ++teleops;
    } else if (op <= 4) {
      b21r_command_t m;
      memset(&m, 0, sizeof m);
      m.seq = fuzz_u16(&in);
      m.command = (int8_t)fuzz_u8(&in);
      m.argument = (int32_t)fuzz_u32(&in);
      fw_loop_post_command(fl.loop, &m, fl.fake.clock_us);
      ++commands;
    } else if (op <= 6) {
      const int n = 1 + fuzz_u8(&in) % 4;
      for (int i = 0; i < n && ticks < 4 && fuzz_loop_tick(&fl); ++i, ++ticks) {
      }
    } else {
      fw_loop_signal(fl.loop, SIGINT);
      FUZZ_CHECK(!fuzz_loop_tick(&fl));
      FUZZ_CHECK(fl.fake.v_cmd == 0.0 && fl.fake.w_cmd == 0.0);
    }
  }
  if (fuzz_loop_tick(&fl)) {  // the last messages are seen
    fw_loop_stats_t st;
    fw_loop_get_stats(fl.loop, &st);
    FUZZ_CHECK(st.teleop_accepted + st.teleop_rejected == teleops);
    FUZZ_CHECK(st.commands_accepted + st.commands_rejected == commands);
  }
  return 0;
}
