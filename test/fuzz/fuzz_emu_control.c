// SPDX-License-Identifier: MIT
// libFuzzer target: the emulator's control commands (sim/emulator.h, sim_emu_control), as the
// b21r-sim control socket receives them, on the rFLEX and the CANopen emulator in real-time
// mode with the laser and the base reports running. Input byte 0 picks the emulator (bit 0) and
// the reply capacity (bits 1..7: 1..127 bytes, or 1024 when 0); the rest is command lines. After
// each command the emulator advances 5 ms and its output is read. Properties: the reply is one
// NUL-terminated line within the capacity, "ok..." exactly when the result is OK or QUIT and
// "error ..." for ERROR; the robot's ground truth stays finite and within the coordinates a world
// may use (SIM_WORLD_MAX_ABS, plus what the robot can drive in the meantime).
// `svg` commands are skipped (they write files).
#include <proto/lms200.h>
#include <proto/rflex.h>

#include "sim/emulator.h"
#include "sim/world.h"
#include "fuzz_util.h"

#include <math.h>

static sim_world_t g_world;
static sim_emu_t* g_emu[2];

static void start_streams(sim_emu_t* e, bool rflex) {
  uint8_t buf[64];
  sim_emu_laser_write(e, buf, lms_encode_start_stream(buf, sizeof buf));
  if (rflex) {
    rflex_packet_t p;
    FUZZ_CHECK(rflex_make_odometry_request(&p, 100000, 3) == PROTO_OK);
    sim_emu_base_write(e, buf, rflex_encode(buf, sizeof buf, &p, RFLEX_HOST_STRICT));
    FUZZ_CHECK(rflex_make_dio_request(&p, 100000) == PROTO_OK);
    sim_emu_base_write(e, buf, rflex_encode(buf, sizeof buf, &p, RFLEX_HOST_STRICT));
  }
}

static void setup(void) {
  char err[256];
  if (sim_world_load(SIM_WORLDS_DIR "/corridor10.world", &g_world, err, sizeof err) != SIM_WORLD_OK) {
    fprintf(stderr, "fuzz_emu_control: %s\n", err);
    abort();
  }
  for (int i = 0; i < 2; ++i) {
    sim_emu_config_t cfg;
    sim_emu_config_default(&cfg);
    cfg.mode = SIM_MODE_REALTIME;
    cfg.base = i == 0 ? SIM_BASE_RFLEX : SIM_BASE_CANOPEN;
    cfg.trace_capacity = 1000;
    g_emu[i] = sim_emu_create(&g_world, &cfg);
    FUZZ_CHECK(g_emu[i] != NULL);
    start_streams(g_emu[i], i == 0);
  }
}

static void advance_and_read(sim_emu_t* e) {
  sim_emu_run_until(e, sim_emu_time(e) + 0.005);
  static uint8_t buf[65536];
  (void)sim_emu_laser_read(e, buf, sizeof buf);
  (void)sim_emu_base_read(e, buf, sizeof buf);
  canopen_frame_t f;
  for (int i = 0; i < 64 && sim_emu_can_read(e, &f) == 1; ++i) {
  }
  sim_plant_state_t s;
  sim_emu_state(e, &s);
  FUZZ_CHECK(isfinite(s.x_m) && isfinite(s.y_m) && isfinite(s.theta_rad) && isfinite(s.v_mps) &&
             isfinite(s.omega_radps));
  FUZZ_CHECK(fabs(s.x_m) <= SIM_WORLD_MAX_ABS + 10.0 && fabs(s.y_m) <= SIM_WORLD_MAX_ABS + 10.0);
  FUZZ_CHECK(isfinite(sim_emu_latency_s(e)) && sim_emu_latency_s(e) >= 0.0);
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (g_emu[0] == NULL) {
    setup();
  }
  if (size == 0) {
    return 0;
  }
  sim_emu_t* e = g_emu[data[0] & 1U];
  const size_t cap = (data[0] >> 1) != 0 ? (size_t)(data[0] >> 1) : 1024U;
  char reply[1024];
  // Every input starts from the same conditions: no fault, the robot at the first start pose.
  FUZZ_CHECK(sim_emu_control(e, "fault clear", reply, sizeof reply) == SIM_EMU_CTRL_OK);
  sim_emu_reset(e, g_world.starts[0].x_m, g_world.starts[0].y_m, g_world.starts[0].theta_rad);
  size_t pos = 1;
  while (pos < size) {
    const uint8_t* nl = memchr(data + pos, '\n', size - pos);
    const size_t len = nl != NULL ? (size_t)(nl - (data + pos)) : size - pos;
    char line[1100];
    const size_t k = len < sizeof line - 1U ? len : sizeof line - 1U;
    memcpy(line, data + pos, k);
    line[k] = '\0';
    pos += len + 1U;
    const char* p = line;
    while (*p == ' ' || *p == '\t' || *p == '\r') {
      ++p;
    }
    if (strncmp(p, "svg", 3) == 0) {
      continue;
    }
    memset(reply, 0x55, sizeof reply);
    const sim_emu_ctrl_t rc = sim_emu_control(e, line, reply, cap);
    FUZZ_CHECK(memchr(reply, '\0', cap) != NULL);
    for (size_t i = cap; i < sizeof reply; ++i) {
      FUZZ_CHECK(reply[i] == 0x55);
    }
    FUZZ_CHECK(strchr(reply, '\n') == NULL);
    if (rc == SIM_EMU_CTRL_ERROR) {
      FUZZ_CHECK(strncmp(reply, "error", cap - 1U < 5U ? cap - 1U : 5U) == 0);
    } else {
      FUZZ_CHECK(rc == SIM_EMU_CTRL_OK || rc == SIM_EMU_CTRL_QUIT);
      FUZZ_CHECK(strncmp(reply, "ok", cap - 1U < 2U ? cap - 1U : 2U) == 0);
    }
    advance_and_read(e);
  }
  return 0;
}
