// SPDX-License-Identifier: MIT
// Instruction counts of code regions under callgrind (see instr.h).
#define _POSIX_C_SOURCE 200809L
#include "instr.h"

#include <valgrind/callgrind.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int g_dumps;  // callgrind numbers its dumps 1, 2, ... in the order they are requested

bool instr_active(void) { return RUNNING_ON_VALGRIND && getenv("B21R_CALLGRIND_OUT") != NULL; }

void instr_start(void) {
  if (instr_active()) {
    CALLGRIND_START_INSTRUMENTATION;
  }
}

void instr_begin(void) {
  if (instr_active()) {
    CALLGRIND_ZERO_STATS;
  }
}

uint64_t instr_end(void) {
  if (!instr_active()) {
    return 0;
  }
  CALLGRIND_DUMP_STATS_AT("b21r region");
  char path[1024];
  snprintf(path, sizeof path, "%s.%d", getenv("B21R_CALLGRIND_OUT"), ++g_dumps);
  FILE* f = fopen(path, "r");
  if (f == NULL) {
    fprintf(stderr, "instr: no callgrind dump %s (is B21R_CALLGRIND_OUT valgrind's --callgrind-out-file?)\n", path);
    return UINT64_MAX;
  }
  // The dump's "summary:" line (or, in older formats, "totals:") holds the event counts; with
  // the default events the first one is Ir, the instructions executed.
  char line[4096];
  uint64_t ir = UINT64_MAX;
  while (fgets(line, sizeof line, f) != NULL) {
    if (strncmp(line, "summary:", 8) == 0) {
      ir = strtoull(line + 8, NULL, 10);
    } else if (strncmp(line, "totals:", 7) == 0 && ir == UINT64_MAX) {
      ir = strtoull(line + 7, NULL, 10);
    }
  }
  fclose(f);
  if (getenv("B21R_CALLGRIND_KEEP") == NULL) {
    remove(path);
  }
  return ir;
}
