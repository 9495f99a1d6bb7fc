// SPDX-License-Identifier: MIT
#include "fw/errfmt.h"

#include <stdarg.h>
#include <stdio.h>

void fw_errfmt(char* err, size_t cap, const char* format, ...) {
  if (err == NULL || cap == 0) {
    return;
  }
  va_list ap;
  va_start(ap, format);
  (void)vsnprintf(err, cap, format, ap);
  va_end(ap);
}
