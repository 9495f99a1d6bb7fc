// SPDX-License-Identifier: MIT
/// loop_harness.h — Runs the loop core against the fake robot in one thread: no publisher
/// thread, the test drains the queue itself (hashing experiences, collecting text and status).
#ifndef B21R_TEST_LOOP_HARNESS_H
#define B21R_TEST_LOOP_HARNESS_H

#include "fake_robot.h"
#include "fw/config.h"
#include "fw/loop.h"
#include "fw/pubq.h"

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct harness {
  fw_config_t cfg;
  fake_robot_t fake;
  fw_pubq_t* q;
  fw_loop_t* loop;
  uint64_t exp_hash;        // FNV-1a over the encoded experiences, in order
  int64_t exp_count;
  int64_t exp_next_seq;     // gap detection
  int64_t exp_gaps;
  int8_t exp_state_dim;     // of the newest experience
  // The executed rotation in the state (cfg.state_rotation): s_next's last entry must be the
  // experience's action (or, after a decision held over several ticks, ramping towards it under the
  // acceleration limit: rotation_ramping), s's last entry the previous experience's s_next's last
  // (0 at a run's first step).
  int64_t rotation_checked;
  int64_t rotation_mismatches;
  int64_t rotation_ramping;
  double exp_prev_rotation;
  int32_t exp_prev_run_id;
  double exp_prev_action;
  // Decisions (cfg.decision_ticks = N): a run's experiences end at its steps N-1, 2N-1, ... (the
  // last may end a window early: the run ended in it).
  int32_t exp_prev_step_id;
  int64_t window_breaks;    // an experience at another step, or not after the previous one
  int64_t window_early;     // an experience ending a window early
  int64_t goals;
  b21r_eval_t last_eval;
  int evals;
  b21r_status_t last_status;
  char last_status_detail[160];
  int8_t max_stop_reason_seen;
  uint32_t stop_reasons_seen;  // bit per STOP_* seen on STATUS
  bool print_text;
  int configs;              // B21R_CONFIG messages seen
  b21r_config_t config;     // the last one (text copied below)
  char config_text[16384];
  int64_t config_before_exp; // experiences seen before the first B21R_CONFIG (must be 0)
  int runs;                 // B21R_RUN messages seen
  b21r_run_t run[64];       // the first 64 (detail points at a static string)
  int64_t run_exp_next_seq[64]; // exp_next_seq when each arrived (its experiences came first)
  // The first experience of runs 0-63 (by run_id): its state's first three entries and action.
  double run_first_s[64][3];
  double run_first_action[64];
} harness_t;

/// Test defaults: lockstep, short corridor schedule, no LCM, fake robot (rFLEX unless canopen).
void harness_config(fw_config_t* cfg);

/// Creates fake + queue + loop and runs fw_loop_start. Returns 0 or fails the test.
int harness_open(harness_t* h, const fw_config_t* cfg, bool canopen, uint64_t fake_seed);

/// harness_open with the fake's CAN frames lagging can_lag_us behind the laser (fake_robot_t.can_lag_us).
int harness_open_can_lag(harness_t* h, const fw_config_t* cfg, uint64_t fake_seed, int64_t can_lag_us);

/// Drains the queue (hash experiences, track EVAL and STATUS).
void harness_drain(harness_t* h);

/// Runs up to max_ticks ticks (draining as it goes); returns the ticks run.
int64_t harness_run(harness_t* h, int64_t max_ticks);

void harness_close(harness_t* h);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TEST_LOOP_HARNESS_H
