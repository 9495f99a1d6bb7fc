// SPDX-License-Identifier: MIT
/// instr.h — Instruction counts of code regions: the benchmarks' budgets that do not depend on
/// the machine's load.
///
/// Wall-clock and CPU time depend on what else the machine runs; the number of instructions a
/// region executes does not (the same binary and inputs give the same count, to the instruction).
/// The counter is valgrind's callgrind: a budget test runs the benchmark under it
/// (b21r_add_instruction_budget in test/bench/CMakeLists.txt), instr_begin() zeroes callgrind's
/// counters and instr_end() has it dump them into a file and reads the total back. The file is
/// named by the environment variable B21R_CALLGRIND_OUT, which must be the --callgrind-out-file
/// given to valgrind (the CMake function sets both). Outside callgrind instr_active() is false,
/// and the other functions do nothing (instr_end() returns 0).
///
/// Counts are x86-64 instructions of the build measured (the Release preset). Instructions of the
/// functions valgrind is told to leave out (--toggle-collect) are not counted.
/// Not thread-safe: one caller thread (the count covers every thread, though).
#ifndef B21R_BENCH_INSTR_H
#define B21R_BENCH_INSTR_H

#include <stdbool.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// True when running under callgrind with B21R_CALLGRIND_OUT set: counts are available.
bool instr_active(void);

/// Turns callgrind's instrumentation on (budget tests start with --instr-atstart=no, so that the
/// set-up before it runs several times faster and uncounted). Idempotent. Costs a flush of
/// valgrind's translations (tens of ms): call it once, before the counted part.
void instr_start(void);

/// Starts a region: zeroes the counters.
void instr_begin(void);

/// Instructions executed since instr_begin(), or 0 when inactive. Writes, reads and deletes one
/// dump file (about a millisecond under callgrind; kept when B21R_CALLGRIND_KEEP is set, for
/// callgrind_annotate's per-function profile); its own instructions are not in the count.
/// Returns UINT64_MAX if the dump cannot be read (a misconfigured run: the caller fails).
uint64_t instr_end(void);

#ifdef __cplusplus
}
#endif

#endif  // B21R_BENCH_INSTR_H
