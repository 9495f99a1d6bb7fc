// SPDX-License-Identifier: MIT
// Run schedule: training runs, evaluation blocks, phase switch.
#include "learn/schedule.h"

#include <math.h>
#include <stdbool.h>
#include <string.h>

double learn_student_t975(int32_t df) {
  static const double t[31] = {0.0,    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
                               2.201,  2.179,  2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080,
                               2.074,  2.069,  2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042};
  if (df < 1) {
    return 0.0;
  }
  if (df <= 30) {
    return t[df];
  }
  return 1.96 + 2.4 / (double)df;
}

void learn_mean_ci95(const double* values, int32_t n, double* mean, double* half_width) {
  *mean = 0.0;
  *half_width = 0.0;
  if (n <= 0) {
    return;
  }
  double sum = 0.0;
  for (int32_t i = 0; i < n; ++i) {
    sum += values[i];
  }
  const double m = sum / (double)n;
  *mean = m;
  if (n < 2) {
    return;
  }
  double ss = 0.0;
  for (int32_t i = 0; i < n; ++i) {
    ss += (values[i] - m) * (values[i] - m);
  }
  const double sd = sqrt(ss / (double)(n - 1));
  *half_width = learn_student_t975(n - 1) * sd / sqrt((double)n);
}

static void begin_block(learn_schedule_t* s) {
  s->in_eval = true;
  s->eval_index = 0;
  memset(&s->current, 0, sizeof s->current);
  s->current.block = s->p.eval_blocks;
  s->current.training_runs = s->p.training_runs;
  s->current.phase = s->p.phase;
  s->current.n_starts = s->cfg.eval_starts;
}

void learn_schedule_init(learn_schedule_t* s, const learn_schedule_config_t* cfg, const learn_schedule_progress_t* resume) {
  const learn_schedule_config_t c = *cfg;  // cfg may point into *s
  const learn_schedule_progress_t r = resume != NULL ? *resume : (learn_schedule_progress_t){0};
  memset(s, 0, sizeof *s);
  s->cfg = c;
  if (s->cfg.eval_every < 1) {
    s->cfg.eval_every = 1;
  }
  if (s->cfg.eval_starts < 1) {
    s->cfg.eval_starts = 1;
  }
  if (s->cfg.eval_starts > LEARN_SCHEDULE_MAX_STARTS) {
    s->cfg.eval_starts = LEARN_SCHEDULE_MAX_STARTS;
  }
  if (resume != NULL) {
    s->p = r;
  }
  if (s->p.phase != 2) {
    s->p.phase = 1;
  }
  if (s->cfg.evaluate_only) {
    s->final_block = true;
    begin_block(s);
    return;
  }
  if (s->p.phase == 2 && s->p.phase_two_runs >= s->cfg.phase_two_runs) {
    // Resumed after the schedule had ended: one more block documents the final state.
    s->final_block = true;
    begin_block(s);
    return;
  }
  // Saved after the training run that made a block due (progress is saved between training runs,
  // never inside a block): the block comes first, as it would have without the restart, and a
  // phase-one schedule that has used up its runs switches after it.
  const int32_t blocks_due = (s->cfg.eval_at_start ? 1 : 0) + s->p.training_runs / s->cfg.eval_every;
  if (s->p.training_runs > 0 && s->p.training_runs % s->cfg.eval_every == 0 && s->p.eval_blocks < blocks_due) {
    s->switch_pending = s->p.phase == 1 && s->cfg.switch_mode != LEARN_SWITCH_OPERATOR &&
                        s->p.phase_one_runs >= s->cfg.phase_one_runs;
    begin_block(s);
    return;
  }
  // A phase-one schedule that has used up its runs switches on resume (RUNS mode).
  if (s->p.phase == 1 && s->cfg.switch_mode != LEARN_SWITCH_OPERATOR && s->p.phase_one_runs >= s->cfg.phase_one_runs) {
    s->p.phase = 2;
  }
  if (s->cfg.eval_at_start && s->p.training_runs == 0) {
    begin_block(s);
  }
}

learn_plan_t learn_schedule_next(const learn_schedule_t* s) {
  learn_plan_t plan;
  memset(&plan, 0, sizeof plan);
  plan.phase = s->p.phase;
  if (s->done) {
    plan.kind = LEARN_RUN_NONE;
  } else if (s->in_eval) {
    plan.kind = LEARN_RUN_EVAL;
    plan.eval_index = s->eval_index;
  } else {
    plan.kind = LEARN_RUN_TRAINING;
    plan.training_index = s->p.training_runs;
  }
  return plan;
}

bool learn_schedule_done(const learn_schedule_t* s) { return s->done; }

void learn_schedule_request_phase_two(learn_schedule_t* s) {
  if (s->p.phase == 1) {
    s->operator_request = true;
    if (s->in_eval) {
      s->switch_pending = true;
    }
  }
}

static void switch_to_phase_two(learn_schedule_t* s) {
  s->p.phase = 2;
  s->switch_pending = false;
  s->operator_request = false;
}

static bool ready_for_phase_two(const learn_schedule_t* s, const learn_eval_block_t* b) {
  if (s->p.phase_one_runs < s->cfg.auto_min_runs || b->successes < b->n_starts || s->p.example_runs == 0) {
    return false;
  }
  const double example_mean = s->p.example_steps_sum / (double)s->p.example_runs;
  return b->mean_steps <= s->cfg.auto_ratio * example_mean;
}

static void finish_block(learn_schedule_t* s, learn_eval_block_t* out) {
  learn_eval_block_t* b = &s->current;
  double values[LEARN_SCHEDULE_MAX_STARTS];
  int32_t n = 0;
  for (int32_t i = 0; i < b->n_starts; ++i) {
    if (b->success[i]) {
      values[n++] = (double)b->steps[i];
    }
  }
  b->successes = n;
  learn_mean_ci95(values, n, &b->mean_steps, &b->ci95_halfwidth);
  if (out != NULL) {
    *out = *b;
  }
  s->p.eval_blocks++;
  s->in_eval = false;
  if (s->final_block) {
    s->done = true;
    return;
  }
  if (s->p.phase == 1) {
    const bool auto_ready = s->cfg.switch_mode == LEARN_SWITCH_AUTO && ready_for_phase_two(s, b);
    if (s->switch_pending || s->operator_request || auto_ready) {
      switch_to_phase_two(s);
      // No phase-two runs configured: the block just finished is the last word.
      s->done = s->p.phase_two_runs >= s->cfg.phase_two_runs;
    }
  }
}

bool learn_schedule_finish_run(learn_schedule_t* s, int32_t steps, bool reached_goal, bool aborted, learn_eval_block_t* block) {
  if (s->done) {
    return false;
  }
  if (s->in_eval) {
    if (aborted) {
      return false;  // repeat this start pose
    }
    s->current.steps[s->eval_index] = steps;
    s->current.success[s->eval_index] = reached_goal;
    s->eval_index++;
    if (s->eval_index < s->current.n_starts) {
      return false;
    }
    finish_block(s, block);
    return true;
  }
  if (aborted) {
    return false;
  }
  s->p.training_runs++;
  if (s->p.phase == 1) {
    s->p.phase_one_runs++;
    if (reached_goal) {
      s->p.example_runs++;
      s->p.example_steps_sum += (double)steps;
      if (s->p.best_example_steps == 0 || steps < s->p.best_example_steps) {
        s->p.best_example_steps = steps;
      }
    }
  } else {
    s->p.phase_two_runs++;
  }
  bool switch_now = false;
  if (s->p.phase == 1) {
    const bool by_runs = s->cfg.switch_mode != LEARN_SWITCH_OPERATOR && s->p.phase_one_runs >= s->cfg.phase_one_runs;
    switch_now = by_runs || s->operator_request;
  }
  const bool last = s->p.phase == 2 && s->p.phase_two_runs >= s->cfg.phase_two_runs;
  if (last || s->p.training_runs % s->cfg.eval_every == 0) {
    s->switch_pending = switch_now;
    s->final_block = last;
    begin_block(s);
  } else if (switch_now) {
    switch_to_phase_two(s);
    if (s->p.phase_two_runs >= s->cfg.phase_two_runs) {
      s->final_block = true;
      begin_block(s);
    }
  }
  return false;
}
