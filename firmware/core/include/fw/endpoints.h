// SPDX-License-Identifier: MIT
/// fw/endpoints.h — `--endpoints`: the emulator's ready line applied to the controller's config.
///
/// b21r-sim prints (and writes to its --endpoints file) one line naming its devices
/// (sim/endpoints.h): `laser=/dev/pts/N base=/dev/pts/M can=PATH control=PATH`, with the fields
/// that apply. Applying it sets
/// - laser= → laser_device; base= → base_device and base_protocol = rflex;
/// - can= → can_socket and base_protocol = canopen; control= → emulator_control and
///   reposition = emulator;
/// - base_write_gap_us = 0 (the emulator paces its own line).
/// Fields are separated by blanks (space, tab, CR, LF); other `name=value` fields and words
/// without `=` are ignored, so the emulator may print more; when a field repeats, the last one
/// wins. A field with an empty value, a value longer than a config string, or a line without any
/// of the four fields is an error.
///
/// Errors name the argument and the problem; on error the config is unchanged. No allocation;
/// start-up only.
#ifndef FW_ENDPOINTS_H
#define FW_ENDPOINTS_H

#include "fw/config.h"

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Longest ready line (and first line of an endpoints file) accepted, in bytes without the NUL.
#define FW_ENDPOINTS_LINE_MAX 1023U

/// Applies one ready line (see above). Returns 0, or -1 with a message in err (capacity err_cap,
/// e.g. FW_CONFIG_ERR_MAX) and cfg unchanged. O(strlen(line)).
int fw_endpoints_apply_line(fw_config_t* cfg, const char* line, char* err, size_t err_cap);

/// The argument of --endpoints: a readable file whose first line is the ready line, or else the
/// ready line itself (it must contain '='). Returns 0, or -1 with a message (an empty file, a
/// first line longer than FW_ENDPOINTS_LINE_MAX, neither a file nor a line, or a bad line) and
/// cfg unchanged.
int fw_endpoints_apply(fw_config_t* cfg, const char* arg, char* err, size_t err_cap);

#ifdef __cplusplus
}
#endif

#endif  // FW_ENDPOINTS_H
