// SPDX-License-Identifier: MIT
// The loop core over the in-process fake robot (test/unit/firmware/core/fake_robot.h) for the
// loop fuzz targets: set-up through fw_loop_start, ticks, and the properties every tick must
// keep whatever the input (commands finite and within the configured limits).
//
// Speed: a loop is created and started once and then lives on across inputs, as the controller
// lives on across the messages and bytes it receives (a fresh loop per input would spend most
// of the time starting up); it is created anew when it ends. A finding may therefore depend on
// the inputs before it: reproduce with the corpus, in order, when the single input does not.
#ifndef B21R_FUZZ_LOOP_H
#define B21R_FUZZ_LOOP_H

#include "fake_robot.h"
#include "fw/config.h"
#include "fw/loop.h"
#include "fw/pubq.h"

#include <stdbool.h>
#include <stdint.h>

/// Replaces the base input of the fake robot (the rest of its binding stays).
typedef struct fuzz_base_input {
  ssize_t (*base_read)(void* user, uint8_t* buf, size_t cap);  ///< rFLEX; NULL = the fake's
  int (*can_read)(void* user, canopen_frame_t* frame);         ///< CANopen; NULL = the fake's
  void* user;
} fuzz_base_input_t;

typedef struct fuzz_loop {
  fw_config_t cfg;
  fake_robot_t fake;
  fw_pubq_t* q;
  fw_loop_t* loop;
  fw_io_vtable_t vt;
  fuzz_base_input_t input;
  bool done;
} fuzz_loop_t;

/// A small, fast configuration: lockstep, the obstacle task with a 100° laser (cheaper features
/// and scans than the corridor's), a schedule that does not end, the cheapest learner (small
/// store and neighbourhoods, 2 greedy actions, no replay), a small queue, no LCM.
void fuzz_loop_config(fw_config_t* cfg, bool canopen);

/// Makes sure a running loop exists: when there is none or the last one ended, creates the
/// fake, the queue and the loop for cfg and starts it on the fake's genuine data. `input` (may
/// be NULL) replaces the base input from then on. Returns true when the loop is new. Aborts on
/// failure.
bool fuzz_loop_ready(fuzz_loop_t* fl, const fw_config_t* cfg, const fuzz_base_input_t* input);

/// The fake's own base input (for a replacement that forwards it).
ssize_t fuzz_loop_fake_base_read(fuzz_loop_t* fl, uint8_t* buf, size_t cap);
int fuzz_loop_fake_can_read(fuzz_loop_t* fl, canopen_frame_t* frame);

/// One wait + tick; drains the queue and checks the command the base received. Returns false
/// once the loop is done.
bool fuzz_loop_tick(fuzz_loop_t* fl);

void fuzz_loop_close(fuzz_loop_t* fl);

#endif  // B21R_FUZZ_LOOP_H
