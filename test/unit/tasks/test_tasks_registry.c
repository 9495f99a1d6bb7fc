// SPDX-License-Identifier: MIT
// The registry of declared tasks: every declaration is complete and consistent (so a new task is
// checked by adding it, not by writing these tests again), lookups by name and id, parameters by
// name with their ranges, evaluation poses of a configuration's own, and a run of every task from
// its own declaration (start, observe, outcome, driver) without allocation.
#include <b21r_test/alloc_counter.h>
#include <tasks/decl.h>
#include <tasks/episode.h>

#include <math.h>
#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include <cmocka.h>

static int count_calls(void* user) {
  ++*(int*)user;
  return 0;
}
static int sink_corridor(void* u, double a, double b, int e) {
  (void)a, (void)b, (void)e;
  return count_calls(u);
}
static int sink_arena(void* u, double a, double b, double c, double d) {
  (void)a, (void)b, (void)c, (void)d;
  return count_calls(u);
}
static int sink_wall(void* u, double a, double b, double c, double d, double t) {
  (void)a, (void)b, (void)c, (void)d, (void)t;
  return count_calls(u);
}
static int sink_cylinder(void* u, double a, double b, double r) {
  (void)a, (void)b, (void)r;
  return count_calls(u);
}
static int sink_goal(void* u, double a, double b, double r) {
  (void)a, (void)b, (void)r;
  return count_calls(u);
}
static int sink_start(void* u, features_pose_t p) {
  (void)p;
  return count_calls(u);
}
static int sink_name(void* u, const char* n) {
  assert_non_null(n);
  assert_true(strlen(n) > 0U);
  return count_calls(u);
}

static void test_registry_declarations_complete(void** state) {
  (void)state;
  assert_true(tasks_count() >= 2U);
  assert_null(tasks_decl_at(tasks_count()));
  for (uint32_t i = 0; i < tasks_count(); ++i) {
    const tasks_decl_t* d = tasks_decl_at(i);
    assert_non_null(d);
    assert_non_null(d->name);
    assert_non_null(d->title);
    assert_non_null(d->env_id);
    assert_true(d->state_dim >= 1U && d->state_dim <= TASKS_MAX_STATE_DIM);
    assert_true(d->spec_size > 0U && d->spec_size <= TASKS_SPEC_BYTES);
    for (uint32_t k = 0; k < d->state_dim; ++k) {
      assert_non_null(d->state_names[k]);
      assert_true(d->state_scale[k] > 0.0 && isfinite(d->state_scale[k]));
    }
    assert_true(d->action_scale > 0.0 && d->greedy_reach >= 0.0);
    assert_true(d->gain_min > 0.0 && d->gain_min <= d->gain_max);
    void (*const fns[])(void) = {(void (*)(void))d->state_range, (void (*)(void))d->spec_default,
                                 (void (*)(void))d->run_init,    (void (*)(void))d->observe,
                                 (void (*)(void))d->observe_pose, (void (*)(void))d->outcome,
                                 (void (*)(void))d->speed_mps,   (void (*)(void))d->training_start_near,
                                 (void (*)(void))d->laser_mount, (void (*)(void))d->state_bounds,
                                 (void (*)(void))d->driver_law,  (void (*)(void))d->driver_action,
                                 (void (*)(void))d->world};  // driver_human is optional
    for (size_t k = 0; k < sizeof fns / sizeof fns[0]; ++k) assert_non_null(fns[k]);
    // Names and ids are unique; lookups find the declaration itself.
    for (uint32_t j = 0; j < i; ++j) {
      assert_string_not_equal(tasks_decl_at(j)->name, d->name);
      assert_string_not_equal(tasks_decl_at(j)->env_id, d->env_id);
      assert_int_not_equal(tasks_decl_at(j)->id, d->id);
    }
    assert_ptr_equal(tasks_find(d->name), d);
    assert_ptr_equal(tasks_by_id(d->id), d);
  }
  assert_null(tasks_find("no-such-task"));
  assert_null(tasks_find(NULL));
  assert_null(tasks_by_id(-1));
  assert_null(tasks_by_id(255));
}

// The defaults are inside the declared ranges; common fields are sane; the declared state range
// (the learner's scale and bins) overlaps the bounds of what the features can produce.
static void test_registry_defaults_within_declared_ranges(void** state) {
  (void)state;
  for (uint32_t i = 0; i < tasks_count(); ++i) {
    const tasks_decl_t* d = tasks_decl_at(i);
    tasks_episode_t ep;
    tasks_episode_init(&ep, d, NULL);
    const void* spec = tasks_episode_spec_const(&ep);
    for (uint32_t k = 0; k < d->n_params; ++k) {
      const tasks_param_t* p = &d->params[k];
      assert_true(p->min < p->max);
      assert_non_null(p->help);
      const double v = tasks_spec_get_param(d, spec, p->name);
      assert_true(v >= p->min && v <= p->max);
      assert_ptr_equal(tasks_param_find(d, p->name), p);
      assert_true(p->offset + sizeof(double) <= d->spec_size);
    }
    assert_true(tasks_spec_dt_s(d, spec) > 0.0);
    assert_true(tasks_spec_omega_max(d, spec) > 0.0);
    assert_true(tasks_spec_step_limit(d, spec) > 0U);
    const double g = tasks_spec_gamma(d, spec);
    assert_true(g > 0.0 && g < 1.0);
    assert_true(tasks_spec_robot_radius(d, spec) > 0.0);
    double rlo[TASKS_MAX_STATE_DIM], rhi[TASKS_MAX_STATE_DIM], blo[TASKS_MAX_STATE_DIM], bhi[TASKS_MAX_STATE_DIM];
    tasks_episode_state_range(&ep, rlo, rhi);
    tasks_episode_state_bounds(&ep, blo, bhi);
    for (uint32_t k = 0; k < d->state_dim; ++k) {
      assert_true(rlo[k] < rhi[k] && blo[k] < bhi[k]);
      assert_true(rlo[k] < bhi[k] && blo[k] < rhi[k]);
    }
    int calls = 0;
    const tasks_world_sink_t sink = {&calls,     sink_corridor, sink_arena, sink_wall,
                                     sink_cylinder, sink_goal,  sink_start, sink_name};
    assert_int_equal(d->world(spec, &sink), 0);
    assert_true(calls >= 1 + TASKS_N_EVAL_STARTS);  // a name and the evaluation poses at least
  }
}

static void test_registry_params_by_name(void** state) {
  (void)state;
  for (uint32_t i = 0; i < tasks_count(); ++i) {
    const tasks_decl_t* d = tasks_decl_at(i);
    double spec[TASKS_SPEC_BYTES / sizeof(double)];
    d->spec_default(spec);
    for (uint32_t k = 0; k < d->n_params; ++k) {
      const tasks_param_t* p = &d->params[k];
      const double before = tasks_spec_get_param(d, spec, p->name);
      const double mid = 0.5 * (p->min + p->max);
      assert_int_equal(tasks_spec_set_param(d, spec, p->name, mid), 0);
      assert_true(tasks_spec_get_param(d, spec, p->name) == mid);
      // Outside the range and non-finite values are refused and change nothing.
      assert_int_equal(tasks_spec_set_param(d, spec, p->name, p->max + 1.0), -2);
      assert_int_equal(tasks_spec_set_param(d, spec, p->name, p->min - 1.0), -2);
      assert_int_equal(tasks_spec_set_param(d, spec, p->name, NAN), -2);
      assert_true(tasks_spec_get_param(d, spec, p->name) == mid);
      assert_int_equal(tasks_spec_set_param(d, spec, p->name, before), 0);
    }
    assert_int_equal(tasks_spec_set_param(d, spec, "no_such_parameter", 1.0), -1);
    assert_true(isnan(tasks_spec_get_param(d, spec, "no_such_parameter")));
  }
}

// A configuration's own evaluation poses replace the declaration's for evaluation; n = 0 restores.
static void test_registry_eval_poses_override(void** state) {
  (void)state;
  for (uint32_t i = 0; i < tasks_count(); ++i) {
    const tasks_decl_t* d = tasks_decl_at(i);
    tasks_episode_t ep;
    tasks_episode_init(&ep, d, NULL);
    assert_int_equal(tasks_episode_n_eval_starts(&ep), TASKS_N_EVAL_STARTS);
    const features_pose_t first = tasks_episode_eval_start(&ep, 0);
    features_pose_t mine[TASKS_MAX_EVAL_STARTS];
    for (uint32_t k = 0; k < TASKS_MAX_EVAL_STARTS; ++k) mine[k] = (features_pose_t){0.5 + 0.01 * k, 0.1, -0.2};
    tasks_episode_set_eval_starts(&ep, mine, TASKS_MAX_EVAL_STARTS);
    assert_int_equal(tasks_episode_n_eval_starts(&ep), TASKS_MAX_EVAL_STARTS);
    for (uint32_t k = 0; k < TASKS_MAX_EVAL_STARTS; ++k) {
      const features_pose_t p = tasks_episode_eval_start(&ep, k);
      assert_true(p.x_m == mine[k].x_m && p.y_m == mine[k].y_m && p.theta_rad == mine[k].theta_rad);
    }
    tasks_episode_set_eval_starts(&ep, NULL, 0);
    const features_pose_t again = tasks_episode_eval_start(&ep, 0);
    assert_true(again.x_m == first.x_m && again.y_m == first.y_m && again.theta_rad == first.theta_rad);
  }
}

// Every task runs from its declaration alone: training start, exact observation, speed, the
// example driver's command within the bound, an outcome; no allocation.
static void test_registry_every_task_runs(void** state) {
  (void)state;
  for (uint32_t i = 0; i < tasks_count(); ++i) {
    const tasks_decl_t* d = tasks_decl_at(i);
    tasks_episode_t ep;
    tasks_episode_init(&ep, d, NULL);
    rng_t rng;
    rng_seed(&rng, 7U + i);
    tasks_driver_t drv;
    alloc_counter_begin();
    for (int run = 0; run < 3; ++run) {
      const features_pose_t start = tasks_episode_training_start(&ep, &rng);
      tasks_episode_begin(&ep, start, (features_pose_t){0.0, 0.0, 0.0});
      double s[TASKS_MAX_STATE_DIM];
      assert_int_equal(tasks_episode_observe_pose(&ep, start, s), 1);
      double lo[TASKS_MAX_STATE_DIM], hi[TASKS_MAX_STATE_DIM];
      tasks_episode_state_bounds(&ep, lo, hi);
      for (uint32_t k = 0; k < d->state_dim; ++k) assert_true(isfinite(s[k]) && s[k] >= lo[k] && s[k] <= hi[k]);
      tasks_episode_driver_begin(&ep, &drv, TASKS_DRIVER_PROPORTIONAL, tasks_episode_omega_max(&ep), (uint64_t)run + 1U);
      const double w = tasks_episode_driver_action(&ep, &drv);
      assert_true(isfinite(w) && fabs(w) <= tasks_episode_omega_max(&ep) + 1e-12);
      const double v = tasks_episode_speed_mps(&ep);
      assert_true(isfinite(v) && v >= 0.0);
      const tasks_outcome_t o = tasks_episode_outcome(&ep, 0U, 1U);
      assert_true(isfinite(o.reward));
    }
    assert_int_equal(alloc_counter_end(), 0);
  }
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_registry_declarations_complete),
      cmocka_unit_test(test_registry_defaults_within_declared_ranges),
      cmocka_unit_test(test_registry_params_by_name),
      cmocka_unit_test(test_registry_eval_poses_override),
      cmocka_unit_test(test_registry_every_task_runs),
  };
  return cmocka_run_group_tests(tests, NULL, NULL);
}
