// SPDX-License-Identifier: MIT
// --endpoints: b21r-sim's ready line applied to the config (fw/endpoints.h).
#include "fw/endpoints.h"
#include "fw/errfmt.h"

#include <stdbool.h>
#include <stdio.h>
#include <string.h>

static bool blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; }

int fw_endpoints_apply_line(fw_config_t* cfg, const char* line, char* err, size_t err_cap) {
  static const struct {
    const char* field;
    const char* key;
  } k_map[] = {{"laser", "laser_device"},
               {"base", "base_device"},
               {"can", "can_socket"},
               {"control", "emulator_control"}};
  fw_config_t c = *cfg;  // applied to a copy: an error leaves cfg as it was
  int found = 0;
  const char* p = line;
  while (*p != '\0') {
    while (blank(*p)) {
      ++p;
    }
    const char* tok = p;
    while (*p != '\0' && !blank(*p)) {
      ++p;
    }
    const size_t len = (size_t)(p - tok);
    const char* eq = memchr(tok, '=', len);
    if (eq == NULL) {
      continue;
    }
    const size_t name_len = (size_t)(eq - tok);
    const size_t value_len = len - name_len - 1U;
    for (size_t i = 0; i < sizeof k_map / sizeof k_map[0]; ++i) {
      if (strlen(k_map[i].field) != name_len || memcmp(tok, k_map[i].field, name_len) != 0) {
        continue;
      }
      if (value_len == 0U) {
        fw_errfmt(err, err_cap, "--endpoints: %s= has no value", k_map[i].field);
        return -1;
      }
      if (value_len >= FW_CONFIG_STR_MAX) {
        fw_errfmt(err, err_cap, "--endpoints: the value of %s= is longer than %u characters", k_map[i].field,
            FW_CONFIG_STR_MAX - 1U);
        return -1;
      }
      char value[FW_CONFIG_STR_MAX];
      memcpy(value, eq + 1, value_len);
      value[value_len] = '\0';
      if (fw_config_set(&c, k_map[i].key, value, "--endpoints", err, err_cap) != 0) {
        return -1;
      }
      found++;
      if (i == 1) {
        c.base_protocol = FW_BASE_RFLEX;
      } else if (i == 2) {
        c.base_protocol = FW_BASE_CANOPEN;
      } else if (i == 3) {
        c.reposition = FW_REPOSITION_EMULATOR;
      }
    }
  }
  if (found == 0) {
    fw_errfmt(err, err_cap, "--endpoints: no laser=/base=/can=/control= fields in '%.200s'", line);
    return -1;
  }
  c.base_write_gap_us = 0;
  *cfg = c;
  return 0;
}

int fw_endpoints_apply(fw_config_t* cfg, const char* arg, char* err, size_t err_cap) {
  char line[FW_ENDPOINTS_LINE_MAX + 2U];  // room to see that a line is too long
  FILE* f = fopen(arg, "r");
  if (f != NULL) {
    const bool ok = fgets(line, sizeof line, f) != NULL;
    const bool whole = ok && (strchr(line, '\n') != NULL || feof(f));
    fclose(f);
    if (!ok) {
      fw_errfmt(err, err_cap, "--endpoints %s: empty file", arg);
      return -1;
    }
    if (!whole || strlen(line) > FW_ENDPOINTS_LINE_MAX) {
      fw_errfmt(err, err_cap, "--endpoints %s: first line longer than %u characters", arg, FW_ENDPOINTS_LINE_MAX);
      return -1;
    }
  } else if (strchr(arg, '=') != NULL && strlen(arg) <= FW_ENDPOINTS_LINE_MAX) {
    memcpy(line, arg, strlen(arg) + 1U);
  } else {
    fw_errfmt(err, err_cap, "--endpoints %s: neither a readable file nor a 'laser=... base=...' line", arg);
    return -1;
  }
  return fw_endpoints_apply_line(cfg, line, err, err_cap);
}
