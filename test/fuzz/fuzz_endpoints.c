// SPDX-License-Identifier: MIT
// libFuzzer target: the --endpoints parser (fw/endpoints.h), as a line and as a file. An
// accepted line changes only the settings the ready line may set, and the result is the same
// either way; a refused one changes nothing and says why.
#include "fw/config.h"
#include "fw/endpoints.h"
#include "fuzz_util.h"

static fuzz_file_t g_file;

// The config with the fields --endpoints may set reset to the defaults' values.
static void mask(fw_config_t* c, const fw_config_t* defaults) {
  memcpy(c->laser_device, defaults->laser_device, sizeof c->laser_device);
  memcpy(c->base_device, defaults->base_device, sizeof c->base_device);
  memcpy(c->can_socket, defaults->can_socket, sizeof c->can_socket);
  memcpy(c->emulator_control, defaults->emulator_control, sizeof c->emulator_control);
  c->base_protocol = defaults->base_protocol;
  c->reposition = defaults->reposition;
  c->base_write_gap_us = defaults->base_write_gap_us;
  c->origins = defaults->origins;  // where a key came from is not a setting
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (g_file.path[0] == '\0') {
    FUZZ_CHECK(fuzz_file_open(&g_file, "endpoints") == 0);
  }
  static fw_config_t defaults;
  fw_config_defaults(&defaults);
  char line[4096];
  const size_t n = size < sizeof line - 1U ? size : sizeof line - 1U;
  memcpy(line, data, n);
  line[n] = '\0';
  char err[FW_CONFIG_ERR_MAX];
  fw_config_t a = defaults;
  const int ra = fw_endpoints_apply_line(&a, line, err, sizeof err);
  if (ra != 0) {
    FUZZ_CHECK(memcmp(&a, &defaults, sizeof a) == 0);
    FUZZ_CHECK(err[0] != '\0' && memchr(err, '\0', sizeof err) != NULL);
  } else {
    FUZZ_CHECK(a.base_write_gap_us == 0);
    FUZZ_CHECK(memchr(a.laser_device, '\0', sizeof a.laser_device) != NULL);
    FUZZ_CHECK(memchr(a.emulator_control, '\0', sizeof a.emulator_control) != NULL);
    fw_config_t m = a;
    mask(&m, &defaults);
    FUZZ_CHECK(memcmp(&m, &defaults, sizeof m) == 0);
  }
  // The same bytes as a file: same verdict and result when the first line is the whole input.
  fw_config_t b = defaults;
  const int rb = fw_endpoints_apply(&b, fuzz_file_set(&g_file, data, size), err, sizeof err);
  if (rb != 0) {
    FUZZ_CHECK(memcmp(&b, &defaults, sizeof b) == 0);
  }
  if (memchr(data, '\n', size) == NULL && memchr(data, '\0', size) == NULL && size > 0 && size <= FW_ENDPOINTS_LINE_MAX) {
    FUZZ_CHECK(ra == rb);
    FUZZ_CHECK(memcmp(&a, &b, offsetof(fw_config_t, origins)) == 0);  // settings; origins name the source
  }
  return 0;
}
