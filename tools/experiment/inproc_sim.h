// SPDX-License-Identifier: MIT
/// inproc_sim.h — The third binding of the loop's I/O table (fw/io.h, ARCHITECTURE.md "One
/// control tick"): the ODE emulator (sim/emulator.h) linked into the same process, no
/// pseudo-terminals, no sockets. The fast path of experiment sweeps (b21r-experiment) and the
/// harness of the controller's in-process allocation test. It lives in tools/ on purpose: the
/// onboard program (firmware/) never links ODE.
///
/// The LMS200 is started by sending it "start streaming" directly (the host driver's baud and
/// variant negotiation needs a serial line; the emulator powers up at 180°/1°, mm, which is the
/// controller's default laser configuration). Time is the emulator's: lockstep, one control
/// period per command cycle; the clock the loop sees advances 1 µs per reading and jumps to any
/// deadline it waits for, so a run is a function of (world, seeds, config) only.
///
/// Memory: inproc_sim_t holds fixed buffers (about 140 KB: keep it static or on the heap);
/// inproc_sim_open() creates the emulator (ODE allocates in its step arena, see alloc_probe);
/// nothing else allocates. Not thread-safe: one emulator per thread (ODE's rule).
#ifndef B21R_TOOLS_INPROC_SIM_H
#define B21R_TOOLS_INPROC_SIM_H

#include "fw/io.h"

#include <proto/lms200.h>
#include <sim/emulator.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/// How the in-process emulator is set up.
typedef struct inproc_sim_options {
  bool canopen;           ///< base: two CiA 402 drives on CANopen (else the rFLEX base)
  uint64_t seed;          ///< the emulator's root seed (sensor noise), as `b21r-sim --seed`
  size_t trace_capacity;  ///< poses kept for the overhead picture (one per period); ≥ 16
  /// Optional allocation counter (e.g. test/support's alloc_counter_peek): when set, the
  /// allocations made inside emulator calls are summed in sim_allocs, so a test can tell the
  /// controller's allocations from the emulator's. NULL: not counted.
  uint64_t (*alloc_probe)(void);
} inproc_sim_options_t;

typedef struct inproc_sim {
  sim_emu_t* emu;
  inproc_sim_options_t opt;
  lms_decoder_t dec;
  uint8_t laser_buf[65536];
  uint32_t laser_fill;
  uint8_t base_buf[65536];
  uint32_t base_fill;
  canopen_frame_t frames[256];
  uint32_t n_frames;
  uint64_t can_error_frames;  ///< error frames the emulated bus signalled (failed CRCs, frames resent)
  bool can_bus_off;           ///< the emulated host controller is bus-off
  int64_t clock_us;
  uint64_t sim_allocs;  ///< allocations inside emulator calls (only with opt.alloc_probe)
} inproc_sim_t;

/// Creates the emulator for `world` (copied; lockstep) and starts the laser stream. Returns 0,
/// or -1 with a message in err.
int inproc_sim_open(inproc_sim_t* s, const sim_world_t* world, const inproc_sim_options_t* opt, char* err,
                    size_t cap);

/// The binding for fw_loop_create (valid while s is open).
fw_io_t inproc_sim_io(inproc_sim_t* s);

/// Destroys the emulator. Safe on a closed or never-opened (zeroed) binding.
void inproc_sim_close(inproc_sim_t* s);

#endif  // B21R_TOOLS_INPROC_SIM_H
