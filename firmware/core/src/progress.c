// SPDX-License-Identifier: MIT
// The checkpoint's controller section: encoding and a validating decoder (fw/progress.h).
#include "fw/progress.h"

#include "fw/config.h"
#include "le_bytes.h"
#include "fw/errfmt.h"

#include <hedger/hedger.h>

#include <math.h>
#include <stdbool.h>
#include <stdio.h>
#include <string.h>

#define MAGIC "FWMETA01"

// Bytes 0-95 are all in use (the clearance ends at 96); the hold and the reserved word end at 104.
_Static_assert(FW_PROGRESS_BYTES_BASE == 96U, "fw_progress_encode fills bytes 0-95 in every section");
_Static_assert(FW_PROGRESS_BYTES == 104U, "and bytes 96-103 in one that records the hold");

size_t fw_progress_encode(const fw_progress_t* p, uint8_t out[FW_PROGRESS_BYTES]) {
  const fw_schedule_progress_t* g = &p->schedule;
  memset(out, 0, FW_PROGRESS_BYTES);
  memcpy(out, MAGIC, 8);
  fw_put_u32(out + 8, (uint32_t)p->task);
  fw_put_u32(out + 12, p->state_dim);
  fw_put_u32(out + 16, (uint32_t)g->phase);
  fw_put_u32(out + 20, (uint32_t)g->training_runs);
  fw_put_u32(out + 24, (uint32_t)g->phase_one_runs);
  fw_put_u32(out + 28, (uint32_t)g->phase_two_runs);
  fw_put_u32(out + 32, (uint32_t)g->eval_blocks);
  fw_put_u32(out + 36, (uint32_t)g->example_runs);
  fw_put_f64(out + 40, g->example_steps_sum);
  fw_put_u32(out + 48, (uint32_t)g->best_example_steps);
  fw_put_u32(out + 52, (uint32_t)p->run_id + 1U);
  fw_put_f64(out + 56, p->shift.gain);
  fw_put_f64(out + 64, p->shift.centring);
  fw_put_u32(out + 72, p->shift.pairs);
  fw_put_u32(out + 76, FW_PAIR_TERMS_REVISION);
  fw_put_f64(out + 80, p->shift.imitation);
  fw_put_f64(out + 88, p->obstacle_clearance_m);
  if (!p->pass_hold_recorded) {
    return FW_PROGRESS_BYTES_BASE;
  }
  fw_put_u32(out + 96, (uint32_t)p->obstacle_pass_hold_steps + 1U);
  return FW_PROGRESS_BYTES;
}

// The shift's two terms within ±FW_PAIR_SHIFT_MAX, and the imitation's weight within its bounds
// (each false for NaN too).
static bool terms_valid(double gain, double centring) {
  return fabs(gain) <= FW_PAIR_SHIFT_MAX && fabs(centring) <= FW_PAIR_SHIFT_MAX;
}
static bool imitation_valid(double imitation) {
  return imitation >= FW_PAIR_IMITATION_MIN && imitation <= FW_PAIR_IMITATION_MAX;
}

bool fw_pair_shift_valid(double gain, double centring, double imitation) {
  return terms_valid(gain, centring) && imitation_valid(imitation);
}

static bool is_zero(double x) { return x >= 0.0 && x <= 0.0; }

// An obstacle shift with something learned on its terms (a or b not 0): the only shift whose
// policy depends on the clearance (the imitation's weight does not).
static bool obstacle_terms_learned(const fw_progress_t* p) {
  return p->task == (int32_t)FW_TASK_OBSTACLES && !(is_zero(p->shift.gain) && is_zero(p->shift.centring));
}

void fw_progress_record_clearance(fw_progress_t* p, double clearance_m) {
  p->obstacle_clearance_m = obstacle_terms_learned(p) ? clearance_m : 0.0;
}

// An obstacle shift that moved at all (a, b or w not 0): every step of it was vetted with the
// hold past the obstacle in the rollouts, the imitation's weight's too.
static bool obstacle_shift_moved(const fw_progress_t* p) {
  return p->task == (int32_t)FW_TASK_OBSTACLES &&
         !(is_zero(p->shift.gain) && is_zero(p->shift.centring) && is_zero(p->shift.imitation));
}

void fw_progress_record_pass_hold(fw_progress_t* p, int32_t hold_steps) {
  p->pass_hold_recorded = obstacle_shift_moved(p);
  p->obstacle_pass_hold_steps = p->pass_hold_recorded ? hold_steps : 0;
}

bool fw_progress_pass_hold_fits(const fw_progress_t* p, int32_t hold_steps, int32_t* learned_steps) {
  if (learned_steps != NULL) {
    *learned_steps = p->pass_hold_recorded ? p->obstacle_pass_hold_steps : -1;
  }
  return !obstacle_shift_moved(p) || !p->pass_hold_recorded || p->obstacle_pass_hold_steps == hold_steps;
}

bool fw_progress_pass_hold_unknown(const fw_progress_t* p) {
  return obstacle_shift_moved(p) && !p->pass_hold_recorded;
}

bool fw_progress_clearance_fits(const fw_progress_t* p, double clearance_m, double* learned_m) {
  const double learned = p->obstacle_clearance_m > 0.0 ? p->obstacle_clearance_m : FW_PROGRESS_CLEARANCE_UNRECORDED_M;
  if (learned_m != NULL) {
    *learned_m = learned;
  }
  return !obstacle_terms_learned(p) || (learned >= clearance_m && learned <= clearance_m);
}

// Reads a counter at off into *v; false (with the reason) when it exceeds INT32_MAX.
static bool counter(const uint8_t* b, size_t off, const char* name, int32_t* v, char* why, size_t cap) {
  const uint32_t u = fw_get_u32(b + off);
  if (u > (uint32_t)INT32_MAX) {
    fw_errfmt(why, cap, "%s %u, expected at most %d", name, (unsigned)u, INT32_MAX);
    return false;
  }
  *v = (int32_t)u;
  return true;
}

int fw_progress_decode(const uint8_t* b, size_t n, fw_progress_t* out, char* why, size_t cap) {
  if ((n != FW_PROGRESS_BYTES_BASE && n != FW_PROGRESS_BYTES) || memcmp(b, MAGIC, 8) != 0) {
    fw_errfmt(why, cap, "unknown format (%zu bytes%s, expected %u or %u starting with " MAGIC ")", n,
        n >= 8 && memcmp(b, MAGIC, 8) != 0 ? ", other magic" : "", FW_PROGRESS_BYTES_BASE, FW_PROGRESS_BYTES);
    return -1;
  }
  fw_progress_t p;
  memset(&p, 0, sizeof p);
  fw_schedule_progress_t* g = &p.schedule;
  const uint32_t task = fw_get_u32(b + 8);
  if (task != (uint32_t)FW_TASK_CORRIDOR && task != (uint32_t)FW_TASK_OBSTACLES) {
    fw_errfmt(why, cap, "task %u, expected %d (corridor) or %d (obstacles)", (unsigned)task, FW_TASK_CORRIDOR,
        FW_TASK_OBSTACLES);
    return -1;
  }
  p.task = (int32_t)task;
  p.state_dim = fw_get_u32(b + 12);
  if (p.state_dim < 1U || p.state_dim > HEDGER_MAX_STATE_DIM) {
    fw_errfmt(why, cap, "state dimension %u, expected 1..%u", (unsigned)p.state_dim, HEDGER_MAX_STATE_DIM);
    return -1;
  }
  const uint32_t phase = fw_get_u32(b + 16);
  if (phase != 1U && phase != 2U) {
    fw_errfmt(why, cap, "phase %u, expected 1 or 2", (unsigned)phase);
    return -1;
  }
  g->phase = (int32_t)phase;
  int32_t run_id_plus_1 = 0;
  int32_t shift_pairs = 0;
  if (!counter(b, 20, "training runs", &g->training_runs, why, cap) ||
      !counter(b, 24, "phase-one runs", &g->phase_one_runs, why, cap) ||
      !counter(b, 28, "phase-two runs", &g->phase_two_runs, why, cap) ||
      !counter(b, 32, "evaluation blocks", &g->eval_blocks, why, cap) ||
      !counter(b, 36, "successful phase-one runs", &g->example_runs, why, cap) ||
      !counter(b, 48, "shortest phase-one run", &g->best_example_steps, why, cap) ||
      !counter(b, 52, "run id + 1", &run_id_plus_1, why, cap) ||
      !counter(b, 72, "pairs that moved the shift", &shift_pairs, why, cap)) {
    return -1;
  }
  g->example_steps_sum = fw_get_f64(b + 40);
  if ((int64_t)g->phase_one_runs + g->phase_two_runs != g->training_runs) {
    fw_errfmt(why, cap, "training runs %d != phase-one runs %d + phase-two runs %d", (int)g->training_runs,
        (int)g->phase_one_runs, (int)g->phase_two_runs);
    return -1;
  }
  if (g->phase == 1 && g->phase_two_runs != 0) {
    fw_errfmt(why, cap, "phase 1 with %d phase-two runs", (int)g->phase_two_runs);
    return -1;
  }
  if (g->example_runs > g->phase_one_runs) {
    fw_errfmt(why, cap, "successful phase-one runs %d > phase-one runs %d", (int)g->example_runs, (int)g->phase_one_runs);
    return -1;
  }
  const double sum = g->example_steps_sum;
  const double runs = (double)g->example_runs;
  // A sum of whole step counts, each at least the shortest one.
  const bool stats_ok = g->example_runs == 0 ? is_zero(sum) && g->best_example_steps == 0
                                             : isfinite(sum) && !(sum > floor(sum)) &&
                                                   sum >= (double)g->best_example_steps * runs &&
                                                   sum <= runs * (double)INT32_MAX;
  if (!stats_ok) {
    fw_errfmt(why, cap, "phase-one statistics inconsistent (%d successful runs, %.17g steps in total, shortest %d)",
        (int)g->example_runs, sum, (int)g->best_example_steps);
    return -1;
  }
  if (run_id_plus_1 < g->training_runs) {
    fw_errfmt(why, cap, "run id %d below the %d training runs", (int)run_id_plus_1 - 1, (int)g->training_runs);
    return -1;
  }
  p.run_id = run_id_plus_1 - 1;
  p.shift.gain = fw_get_f64(b + 56);
  p.shift.centring = fw_get_f64(b + 64);
  p.shift.pairs = (uint32_t)shift_pairs;
  p.shift.imitation = fw_get_f64(b + 80);  // 0 in files written before it: the greedy action counts once
  const uint32_t terms = fw_get_u32(b + 76);
  if (terms > FW_PAIR_TERMS_REVISION) {
    fw_errfmt(why, cap, "shift terms revision %u, expected at most %u (written by a newer controller)", (unsigned)terms,
        (unsigned)FW_PAIR_TERMS_REVISION);
    return -1;
  }
  if (terms == 0U && p.task == (int32_t)FW_TASK_OBSTACLES) {
    // Revision 0's obstacle terms were the goal bearing g and its bend: a g + b bend is
    // a (g + bend) + (b - a) bend in today's terms, the same policy.
    p.shift.centring -= p.shift.gain;
  }
  if (!terms_valid(p.shift.gain, p.shift.centring)) {
    fw_errfmt(why, cap, "learned policy shift (%.17g, %.17g), expected finite values within +-%g", p.shift.gain,
        p.shift.centring, FW_PAIR_SHIFT_MAX);
    return -1;
  }
  if (!imitation_valid(p.shift.imitation)) {
    fw_errfmt(why, cap, "learned imitation weight %.17g, expected a finite value in [%g, %g]", p.shift.imitation,
        FW_PAIR_IMITATION_MIN, FW_PAIR_IMITATION_MAX);
    return -1;
  }
  p.obstacle_clearance_m = fw_get_f64(b + 88);
  const bool clearance_ok =
      is_zero(p.obstacle_clearance_m) ||
      (p.task == (int32_t)FW_TASK_OBSTACLES && p.obstacle_clearance_m >= FW_PAIR_OBSTACLE_CLEARANCE_MIN_M &&
       p.obstacle_clearance_m <= FW_PAIR_OBSTACLE_CLEARANCE_MAX_M);
  if (!clearance_ok) {
    fw_errfmt(why, cap, "obstacle pair clearance %.17g m, expected 0 or (obstacle task) within [%g, %g]",
        p.obstacle_clearance_m, FW_PAIR_OBSTACLE_CLEARANCE_MIN_M, FW_PAIR_OBSTACLE_CLEARANCE_MAX_M);
    return -1;
  }
  if (n == FW_PROGRESS_BYTES) {
    const uint32_t hold_plus_1 = fw_get_u32(b + 96);
    const uint32_t reserved = fw_get_u32(b + 100);
    if (p.task != (int32_t)FW_TASK_OBSTACLES || hold_plus_1 < 1U ||
        hold_plus_1 > (uint32_t)FW_PROGRESS_PASS_HOLD_STEPS_MAX + 1U) {
      fw_errfmt(why, cap, "obstacle pass hold + 1 = %u, expected (obstacle task) 1..%d", (unsigned)hold_plus_1,
          FW_PROGRESS_PASS_HOLD_STEPS_MAX + 1);
      return -1;
    }
    if (reserved != 0U) {
      fw_errfmt(why, cap, "reserved bytes 100-103 not 0 (written by a newer controller)");
      return -1;
    }
    p.pass_hold_recorded = true;
    p.obstacle_pass_hold_steps = (int32_t)(hold_plus_1 - 1U);
  }
  *out = p;
  return 0;
}
