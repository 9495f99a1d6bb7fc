// SPDX-License-Identifier: MIT
// firmware.inproc_alloc: the loop core against the ODE emulator linked in-process (rFLEX and
// CANopen, every learner): thousands of lockstep ticks through runs, run ends, evaluation blocks
// and the phase switch perform no heap allocation in the controller (the emulator's own are
// counted apart).
#define _POSIX_C_SOURCE 200809L
#include "fw/loop.h"
#include "fw/pubq.h"
#include "inproc_sim.h"

#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

static const char* g_world;

static void drain(fw_pubq_t* q, int* evals, int* successes) {
  const fw_msg_t* m;
  while ((m = fw_pubq_peek(q)) != NULL) {
    if (m->kind == FW_MSG_EVAL) {
      (*evals)++;
      *successes = m->u.eval.successes;
    }
    fw_pubq_pop(q);
  }
}

static void run_case(bool canopen, fw_learner_kind_t learner) {
  static inproc_sim_t sim;
  static sim_world_t world;
  char err[FW_LOOP_ERR_MAX];
  if (sim_world_load(g_world, &world, err, sizeof err) != SIM_WORLD_OK) {
    fail_msg("world: %s", err);
  }
  const inproc_sim_options_t opt = {.canopen = canopen, .seed = 3, .trace_capacity = 16,
                                    .alloc_probe = alloc_counter_peek};
  assert_int_equal(inproc_sim_open(&sim, &world, &opt, err, sizeof err), 0);
  fw_config_t c;
  fw_config_defaults(&c);
  c.lockstep = true;
  c.lockstep_timeout_s = 1.0;
  c.reposition = FW_REPOSITION_EMULATOR;
  strcpy(c.emulator_control, "in-process");
  c.base_protocol = canopen ? FW_BASE_CANOPEN : FW_BASE_RFLEX;
  c.phase_one_runs = 3;
  c.phase_two_runs = 3;
  c.eval_every_runs = 3;
  c.eval_starts = 3;
  c.progress = true;
  c.learner = learner;
  fw_pubq_t* q = fw_pubq_create(4096);
  assert_non_null(q);
  const fw_io_t io = inproc_sim_io(&sim);
  const fw_loop_outputs_t out = {.queue = q, .notify = NULL, .notify_user = NULL, .checkpoints = NULL};
  fw_loop_t* loop = fw_loop_create(&c, &io, &out, err, sizeof err);
  assert_non_null(loop);
  if (fw_loop_start(loop, err, sizeof err) != 0) {
    fail_msg("start: %s", err);
  }
  int evals = 0;
  int successes = 0;
  sim.sim_allocs = 0;
  alloc_counter_begin();
  int64_t ticks = 0;
  for (bool more = true; more && ticks < 20000; ++ticks) {
    const int64_t t = fw_loop_wait(loop);
    more = fw_loop_tick(loop, t);
    drain(q, &evals, &successes);
  }
  const uint64_t total = alloc_counter_end();
  fw_loop_stats_t st;
  fw_loop_get_stats(loop, &st);
  print_message("%s, learner %d: %lld ticks, %d runs, %d blocks: %llu allocations in the controller, %llu inside the emulator\n",
                canopen ? "canopen" : "rflex", (int)learner, (long long)ticks, st.runs_finished, evals,
                (unsigned long long)(total - sim.sim_allocs), (unsigned long long)sim.sim_allocs);
  assert_true(st.done);
  assert_int_equal(evals, 2);
  assert_true(ticks > 1000);
  assert_int_equal(total - sim.sim_allocs, 0);
  fw_loop_destroy(loop);
  fw_pubq_destroy(q);
  inproc_sim_close(&sim);
}

// rFLEX base: zero allocations in the tick path over a whole short schedule.
static void test_inproc_rflex_tick_allocates_nothing(void** state) {
  (void)state;
  run_case(false, FW_LEARNER_HEDGER);
}

// CANopen base: the same.
static void test_inproc_canopen_tick_allocates_nothing(void** state) {
  (void)state;
  run_case(true, FW_LEARNER_HEDGER);
}

// The other learners of the ablation (HEDGER with LWA only, tabular Q-learning): the same.
static void test_inproc_other_learners_tick_allocates_nothing(void** state) {
  (void)state;
  run_case(false, FW_LEARNER_LWA);
  run_case(false, FW_LEARNER_TABULAR);
}

int main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: test_firmware_inproc WORLD\n");
    return 2;
  }
  g_world = argv[1];
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_inproc_rflex_tick_allocates_nothing),
      cmocka_unit_test(test_inproc_canopen_tick_allocates_nothing),
      cmocka_unit_test(test_inproc_other_learners_tick_allocates_nothing),
  };
  return cmocka_run_group_tests_name("firmware.inproc_alloc", tests, NULL, NULL);
}
