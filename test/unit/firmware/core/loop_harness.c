// SPDX-License-Identifier: MIT
// Single-threaded driver of the loop core over the fake robot (see loop_harness.h).
#include "loop_harness.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

void harness_config(fw_config_t* cfg) {
  fw_config_defaults(cfg);
  cfg->lockstep = true;
  cfg->lockstep_timeout_s = 1.0;
  cfg->reposition = FW_REPOSITION_EMULATOR;
  strcpy(cfg->emulator_control, "fake");
  strcpy(cfg->lcm_url, "none");
  cfg->queue_capacity = 4096;
  cfg->status_period_ticks = 10;
}

static int open_fake(harness_t* h, const fw_config_t* cfg, bool canopen, uint64_t fake_seed, int64_t can_lag_us) {
  memset(h, 0, sizeof *h);
  h->cfg = *cfg;
  if (canopen) {
    h->cfg.base_protocol = FW_BASE_CANOPEN;
  }
  fake_robot_init(&h->fake, canopen, 1.0 / h->cfg.tick_rate_hz, fake_seed);
  h->fake.paced = !h->cfg.lockstep;  // real time: the fake's periods follow its clock
  h->fake.can_lag_us = can_lag_us;
  h->q = fw_pubq_create((uint32_t)h->cfg.queue_capacity);
  if (h->q == NULL) {
    return -1;
  }
  const fw_io_t io = fake_robot_io(&h->fake);
  const fw_loop_outputs_t out = {.queue = h->q, .notify = NULL, .notify_user = NULL, .checkpoints = NULL};
  char err[FW_LOOP_ERR_MAX];
  h->loop = fw_loop_create(&h->cfg, &io, &out, err, sizeof err);
  if (h->loop == NULL) {
    fprintf(stderr, "harness: %s\n", err);
    return -1;
  }
  if (fw_loop_start(h->loop, err, sizeof err) != 0) {
    fprintf(stderr, "harness: %s\n", err);
    return -1;
  }
  h->max_stop_reason_seen = 0;
  return 0;
}

int harness_open(harness_t* h, const fw_config_t* cfg, bool canopen, uint64_t fake_seed) {
  return open_fake(h, cfg, canopen, fake_seed, 0);
}

int harness_open_can_lag(harness_t* h, const fw_config_t* cfg, uint64_t fake_seed, int64_t can_lag_us) {
  return open_fake(h, cfg, true, fake_seed, can_lag_us);
}

static uint64_t fnv1a(uint64_t h, const uint8_t* p, int n) {
  for (int i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 1099511628211ULL;
  }
  return h;
}

// Bit for bit: the state carries the very value the loop commanded, not an approximation.
static bool same_bits(double a, double b) { return memcmp(&a, &b, sizeof a) == 0; }

void harness_drain(harness_t* h) {
  const fw_msg_t* m;
  while ((m = fw_pubq_peek(h->q)) != NULL) {
    switch (m->kind) {
      case FW_MSG_EXPERIENCE: {
        uint8_t buf[1024];
        const int n = b21r_experience_t_encode(buf, 0, (int)sizeof buf, &m->u.experience);
        if (h->exp_count == 0) {
          h->exp_hash = 14695981039346656037ULL;
        }
        h->exp_hash = fnv1a(h->exp_hash, buf, n);
        if (m->u.experience.seq != h->exp_next_seq) {
          h->exp_gaps++;
        }
        h->exp_next_seq = m->u.experience.seq + 1;
        h->exp_count++;
        const b21r_experience_t* e = &m->u.experience;
        h->exp_state_dim = e->state_dim;
        const bool same_run = h->exp_count > 1 && e->run_id == h->exp_prev_run_id;
        if (h->cfg.state_rotation && e->state_dim >= 1) {
          const int last = e->state_dim - 1;
          // The rotation in force before the step: the previous step's at its end (0 at a run's start).
          const double before = same_run ? h->exp_prev_rotation : 0.0;
          const double r0 = e->s[last], r1 = e->s_next[last], d = e->action_radps;
          // After a held decision (decision_ticks > 1) the acceleration limit may still be ramping
          // towards it: strictly between the rotation before and the decision.
          const bool ramping = !same_bits(r1, d) && ((r0 < r1 && r1 < d) || (d < r1 && r1 < r0));
          h->rotation_checked++;
          if ((!same_bits(r1, d) && !ramping) || !same_bits(r0, before)) {
            h->rotation_mismatches++;
          } else if (ramping) {
            h->rotation_ramping++;
          }
          h->exp_prev_rotation = r1;
        }
        {
          const int32_t ticks = h->cfg.decision_ticks > 1 ? h->cfg.decision_ticks : 1;
          const int32_t expected = same_run ? h->exp_prev_step_id + ticks : ticks - 1;
          if (e->step_id > expected || (same_run && e->step_id <= h->exp_prev_step_id) || e->step_id < 0) {
            h->window_breaks++;
          } else if (e->step_id < expected) {
            h->window_early++;
          }
          h->exp_prev_step_id = e->step_id;
        }
        if (e->step_id == 0 && e->run_id >= 0 && e->run_id < 64 && e->state_dim >= 3) {
          memcpy(h->run_first_s[e->run_id], e->s, sizeof h->run_first_s[0]);
          h->run_first_action[e->run_id] = e->action_radps;
        }
        h->exp_prev_run_id = e->run_id;
        h->exp_prev_action = e->action_radps;
        if (m->u.experience.terminal && m->u.experience.reward > 0.0) {
          h->goals++;
        }
        break;
      }
      case FW_MSG_EVAL:
        h->last_eval = m->u.eval;
        h->evals++;
        break;
      case FW_MSG_STATUS:
        h->last_status = m->u.status.msg;
        memcpy(h->last_status_detail, m->u.status.detail, sizeof h->last_status_detail);
        if (m->u.status.msg.stop_reason > 0 && m->u.status.msg.stop_reason < 32) {
          h->stop_reasons_seen |= 1U << m->u.status.msg.stop_reason;
        }
        break;
      case FW_MSG_CONFIG:
        if (h->configs++ == 0) {
          h->config_before_exp = h->exp_count;
        }
        h->config = m->u.config;
        (void)snprintf(h->config_text, sizeof h->config_text, "%s", m->u.config.text);
        h->config.text = h->config_text;
        break;
      case FW_MSG_RUN:
        if (h->runs < 64) {
          h->run[h->runs] = m->u.run;
          h->run_exp_next_seq[h->runs] = h->exp_next_seq;
        }
        h->runs++;
        break;
      case FW_MSG_TEXT:
        if (h->print_text) {
          printf("%s\n", m->u.text.line);
        }
        break;
      default:
        break;
    }
    fw_pubq_pop(h->q);
  }
}

int64_t harness_run(harness_t* h, int64_t max_ticks) {
  int64_t n = 0;
  while (n < max_ticks) {
    const int64_t t = fw_loop_wait(h->loop);
    const bool more = fw_loop_tick(h->loop, t);
    n++;
    harness_drain(h);
    if (!more) {
      break;
    }
  }
  return n;
}

void harness_close(harness_t* h) {
  fw_loop_destroy(h->loop);
  fw_pubq_destroy(h->q);
  h->loop = NULL;
  h->q = NULL;
}
