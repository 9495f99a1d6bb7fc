// SPDX-License-Identifier: MIT
// The base adapters of the loop (base.c): rFLEX bytes, CANopen frames.
#ifndef FW_BASE_H
#define FW_BASE_H

#include "loop_state.h"

/// 0, -1 (err names the device), or FW_LOOP_START_SIGNALLED (fw_base_start_signalled).
int fw_base_start(fw_loop_t* L, char* err, size_t err_cap);
/// True when fw_loop_signal() came during the start: err then says which signal ended it and in
/// which step (`during` ends "... during <during>"), and the loop's exit status is 128 + its
/// number. Read at every wake-up of a start's wait.
bool fw_base_start_signalled(fw_loop_t* L, const char* during, char* err, size_t err_cap);
void fw_base_poll(fw_loop_t* L, int64_t now_us);
bool fw_base_all_reports(const fw_loop_t* L);
bool fw_base_any_report(const fw_loop_t* L);
void fw_base_clear_flags(fw_loop_t* L);
void fw_base_evaluate_faults(fw_loop_t* L, int64_t now_us);
void fw_base_command(fw_loop_t* L, double v_mps, double w_radps, bool stopping);
void fw_base_shutdown(fw_loop_t* L);
/// The base's device came back (reopened after a loss): repeat its start-up without waiting
/// (rFLEX start packets; CANopen NMT start, the drives are enabled again tick by tick) and take
/// the next odometry as a new baseline.
void fw_base_restart(fw_loop_t* L);
uint64_t fw_base_bytes_dropped(const fw_loop_t* L);
uint64_t fw_base_checksum_errors(const fw_loop_t* L);

#endif  // FW_BASE_H
