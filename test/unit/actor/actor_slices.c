// SPDX-License-Identifier: MIT
// The actor's costs as the controller pays them, for test_actor_instructions.py under callgrind:
// a ring of about 20,000 transitions of a corridor-like task (the state's shape and scales of the
// corridor with the executed rotation, runs of about 150 steps) in the default configuration,
// then one more run: 1,000 actions, the run's records, and its between-run work in slices of the
// budget given (work units). Each measured part ends with a callgrind dump named after it (no-ops
// outside valgrind): "act x1000", "record run", "slice" (one per slice). Prints the slices and the
// actor's counters.
//
// The ring is filled under cheap settings (one query, one Adam step: the same saved shape) and
// loaded into the measured actor, so that the filling costs little under valgrind (started with
// --instr-atstart=no; instrumentation starts after it).
//
// usage: actor_slices [BUDGET]
#include <actor/actor.h>
#include <rng/rng.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <valgrind/callgrind.h>

static actor_config_t corridor_like(void) {
  actor_config_t c = actor_config_default();
  c.state_dim = 4;
  const double lo[4] = {0.0, 0.0, -1.5707963267948966, -1.0};
  const double hi[4] = {10.0, 1.0, 1.5707963267948966, 1.0};
  const double scale[4] = {1.0, 0.5, 0.125, 1.0};
  for (int i = 0; i < 4; ++i) {
    c.state_min[i] = lo[i];
    c.state_max[i] = hi[i];
    c.state_scale[i] = scale[i];
  }
  c.action_min = -1.0;
  c.action_max = 1.0;
  c.action_scale = 0.25;
  c.gamma = 0.99;
  c.seed = 9;
  return c;
}

static double clampd(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

// One run of a kinematic corridor (10 m, 1.5 m wide, 0.6 m/s, 10 Hz): a proportional teacher with
// dither, or the actor with exploration. Returns the steps.
static int corridor_run(actor_t* a, int teacher, rng_t* rng) {
  double x = 0.5 + 0.5 * rng_uniform(rng);
  double y = 0.3 + 0.4 * rng_uniform(rng);  // fraction of the width
  double heading = rng_uniform_range(rng, -0.8, 0.8);
  double w = 0.0;
  for (int t = 0; t < 400; ++t) {
    const double angle = clampd(atan2(0.5 - y, 2.0 / 1.5) - heading, -1.5, 1.5);
    const double s[4] = {10.0 - x, y, angle, w};
    double act = 0.0;
    if (teacher) {
      act = 0.3 * angle;
    } else {
      (void)actor_act(a, s, &act);
    }
    if (rng_uniform(rng) < 0.2) {
      act += (teacher ? 0.3 : 0.1) * rng_normal(rng);
    }
    act = clampd(act, w - 0.29, w + 0.29);  // the acceleration limit
    act = clampd(act, -1.0, 1.0);
    heading += 0.1 * act;
    x += 0.06 * cos(heading);
    y += 0.06 * sin(heading) / 1.5;
    w = act;
    const int goal = x >= 9.5;
    const int wall = y <= 0.0 || y >= 1.0;
    const double sn[4] = {10.0 - x, y, clampd(atan2(0.5 - y, 2.0 / 1.5) - heading, -1.5, 1.5), w};
    (void)actor_record(a, s, act, goal ? 10.0 : 0.0, sn, goal || wall);
    if (goal || wall) {
      return t + 1;
    }
  }
  return 400;
}

static actor_t* make(const actor_config_t* c) {
  const size_t n = actor_storage_size(c);
  void* mem = aligned_alloc(ACTOR_STORAGE_ALIGN, n);
  actor_t* a = NULL;
  if (mem == NULL || actor_init(&a, mem, n, c) != ACTOR_OK) {
    fprintf(stderr, "actor_slices: cannot set up the actor\n");
    exit(1);
  }
  return a;
}

static void end_run_at_once(actor_t* a) {
  int more = 0;
  (void)actor_end_run_begin(a, &more);
  while (more) {
    (void)actor_end_run_step(a, UINT32_MAX, &more);
  }
}

int main(int argc, char** argv) {
  const uint32_t budget = argc > 1 ? (uint32_t)strtoul(argv[1], NULL, 10) : 1500U;
  const actor_config_t cfg = corridor_like();
  actor_config_t cheap = cfg;
  cheap.max_queries = 1;
  cheap.fit_steps = 1;
  cheap.clone_steps = 1;
  actor_t* fill = make(&cheap);
  rng_t rng;
  rng_seed(&rng, 17);
  int runs = 0;
  while (actor_counters(fill)->fill < cfg.capacity || runs < 140) {
    (void)corridor_run(fill, runs < 30, &rng);
    end_run_at_once(fill);
    ++runs;
  }
  const size_t n = actor_serialized_size(fill);
  uint8_t* bytes = malloc(n);
  actor_t* a = make(&cfg);
  if (bytes == NULL || actor_save(fill, bytes, n, NULL) != ACTOR_OK || actor_load(a, bytes, n) != ACTOR_OK) {
    fprintf(stderr, "actor_slices: cannot carry the ring over\n");
    return 1;
  }
  CALLGRIND_START_INSTRUMENTATION;
  const double s[4] = {5.0, 0.4, 0.2, 0.1};
  double sum = 0.0;
  CALLGRIND_ZERO_STATS;
  for (int i = 0; i < 1000; ++i) {
    double act = 0.0;
    (void)actor_act(a, s, &act);
    sum += act;
  }
  CALLGRIND_DUMP_STATS_AT("act x1000");
  const int steps = corridor_run(a, 0, &rng);
  CALLGRIND_DUMP_STATS_AT("record run");
  int more = 0;
  (void)actor_end_run_begin(a, &more);
  uint64_t slices = 0;
  while (more) {
    CALLGRIND_ZERO_STATS;
    (void)actor_end_run_step(a, budget, &more);
    CALLGRIND_DUMP_STATS_AT("slice");
    ++slices;
  }
  const actor_counters_t* c = actor_counters(a);
  printf("actor_slices: storage %zu bytes; ring %u transitions of %d runs; the measured run %d steps (its actions and records include "
         "the run); %llu slices of budget %u, largest %u units; %llu queries (%llu with a slope); check %.3f\n",
         actor_storage_size(&cfg), c->fill, runs + 1, steps, (unsigned long long)slices, budget, c->max_slice_work,
         (unsigned long long)c->queries, (unsigned long long)c->queries_with_slope, sum);
  return 0;
}
