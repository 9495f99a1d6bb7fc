// SPDX-License-Identifier: MIT
// The error-text helper of the firmware and its tools (config, endpoints, checkpoints, progress,
// publisher, b21r-experiment, b21r-train).
#ifndef FW_ERRFMT_H
#define FW_ERRFMT_H

#include <stddef.h>

/// printf-style text into err[cap] (always NUL-terminated, truncated to fit); does nothing when
/// err is NULL or cap is 0, so every caller may pass an optional error buffer straight through.
void fw_errfmt(char* err, size_t cap, const char* format, ...) __attribute__((format(printf, 3, 4)));

#endif  // FW_ERRFMT_H
