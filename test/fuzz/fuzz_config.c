// SPDX-License-Identifier: MIT
// libFuzzer target: the controller's config parser (fw/config.h): whole files and `--set`
// arguments. Input byte 0 picks the form (bit 0: the rest is --set arguments, one per line;
// else a config file). Properties: a refused --set leaves the config unchanged and says why
// (naming the source); every config the parser accepts prints (fw_config_print) as a file that
// parses back to the identical config.
#include "fw/config.h"
#include "fuzz_util.h"

static fuzz_file_t g_file;
static char g_print[1 << 16];
static fw_config_t g_defaults;  // fw_config_defaults() once: it parses every key's default

static void check_message(const char* err, const char* source) {
  FUZZ_CHECK(memchr(err, '\0', FW_CONFIG_ERR_MAX) != NULL);
  FUZZ_CHECK(strstr(err, source) != NULL);
}

// fw_config_print's output must load back to the same bytes.
static void check_print_round_trip(const fw_config_t* c) {
  FILE* out = fmemopen(g_print, sizeof g_print, "w");
  FUZZ_CHECK(out != NULL);
  fw_config_print(c, out);
  const long n = ftell(out);
  FUZZ_CHECK(fclose(out) == 0);
  FUZZ_CHECK(n > 0 && (size_t)n < sizeof g_print);
  fw_config_t back = g_defaults;
  char err[FW_CONFIG_ERR_MAX];
  if (fw_config_load_file(&back, fuzz_file_set(&g_file, g_print, (size_t)n), err, sizeof err) != 0) {
    fprintf(stderr, "fuzz: printed config does not load: %s\n", err);
    abort();
  }
  // The settings byte for byte; where each key came from (origins) names the printed file now.
  FUZZ_CHECK(memcmp(&back, c, offsetof(fw_config_t, origins)) == 0);
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (g_file.path[0] == '\0') {
    FUZZ_CHECK(fuzz_file_open(&g_file, "config") == 0);
    fw_config_defaults(&g_defaults);
  }
  if (size == 0) {
    return 0;
  }
  const bool set_args = (data[0] & 1U) != 0;
  ++data;
  --size;
  fw_config_t c = g_defaults;
  char err[FW_CONFIG_ERR_MAX];
  if (set_args) {
    // A command line carries a handful of --set arguments: at most 16 per input keeps the
    // executions fast (each unknown key is compared with every known one for a suggestion).
    size_t pos = 0;
    int args = 0;
    while (pos < size && args++ < 16) {
      const uint8_t* nl = memchr(data + pos, '\n', size - pos);
      const size_t len = nl != NULL ? (size_t)(nl - (data + pos)) : size - pos;
      char arg[2048];
      const size_t k = len < sizeof arg - 1U ? len : sizeof arg - 1U;
      memcpy(arg, data + pos, k);
      arg[k] = '\0';
      const fw_config_t before = c;
      err[0] = '\0';
      if (fw_config_set_arg(&c, arg, err, sizeof err) != 0) {
        FUZZ_CHECK(memcmp(&before, &c, sizeof c) == 0);
        check_message(err, "--set");
      }
      pos += len + 1U;
    }
  } else {
    const char* path = fuzz_file_set(&g_file, data, size);
    err[0] = '\0';
    if (fw_config_load_file(&c, path, err, sizeof err) != 0) {
      check_message(err, path);
      return 0;
    }
  }
  check_print_round_trip(&c);
  if (fw_config_validate(&c, err, sizeof err) == 0) {
    FUZZ_CHECK(fw_config_period_us(&c) >= 10000 && fw_config_period_us(&c) <= 1000000);
    FUZZ_CHECK(fw_config_ticks(&c, c.laser_timeout_s) >= 1);
  } else {
    FUZZ_CHECK(err[0] != '\0');
  }
  return 0;
}
