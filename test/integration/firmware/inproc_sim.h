// SPDX-License-Identifier: MIT
/// inproc_sim.h — The in-process binding of the loop's I/O table to the ODE emulator
/// (sim/emulator.h, linked into the same process: no pseudo-terminals, no sockets). The fast path
/// for experiment sweeps and the harness of the allocation test. Lives outside firmware/ on
/// purpose: the onboard program never links ODE.
///
/// The LMS200 is started by sending it "start streaming" directly (the host driver's baud and
/// variant negotiation needs a serial line; the emulator powers up at 180°/1°, mm). Time is the
/// emulator's: lockstep, one period per command cycle. Allocations made inside the emulator's
/// calls (ODE's step arena) are measured separately so a test can exclude them.
#ifndef B21R_TEST_INPROC_SIM_H
#define B21R_TEST_INPROC_SIM_H

#include "fw/io.h"

#include <proto/lms200.h>
#include <sim/emulator.h>

#include <stdbool.h>
#include <stdint.h>

typedef struct inproc_sim {
  sim_emu_t* emu;
  bool canopen;
  lms_decoder_t dec;
  uint8_t laser_buf[65536];
  uint32_t laser_fill;
  uint8_t base_buf[65536];
  uint32_t base_fill;
  canopen_frame_t frames[256];
  uint32_t n_frames;
  int64_t clock_us;
  uint64_t sim_allocs;  ///< allocations counted (alloc_counter) inside emulator calls
} inproc_sim_t;

/// Creates the emulator for world_path (lockstep, seed) and starts the laser stream.
int inproc_sim_open(inproc_sim_t* s, const char* world_path, bool canopen, uint64_t seed, char* err, size_t cap);
fw_io_t inproc_sim_io(inproc_sim_t* s);
void inproc_sim_close(inproc_sim_t* s);

#endif  // B21R_TEST_INPROC_SIM_H
