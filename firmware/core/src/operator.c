// SPDX-License-Identifier: MIT
// Operator input: B21R_TELEOP and B21R_COMMAND arrive on another thread (the LCM receiver, which
// takes only authenticated, fresh ones: fw/opauth.h) into small mailboxes; the tick drains and
// validates them (finite, in range, newer sequence number, fresh; a stop is always obeyed).
#include "operator.h"
#include "outputs.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

// A request over the limits is refused (the tool must clamp), and reported as what it is: a
// counter, one stderr line per burst of refusals, and, while the joystick drives with the deadman
// held, the stop reason STOP_TELEOP_RANGE instead of a released deadman.
static void refuse_range(fw_loop_t* L, const b21r_teleop_t* m) {
  L->teleop_rejected_range++;
  L->teleop_range_newest = m->deadman != 0;
  const bool rot = fabs(m->rotation_radps) > L->cfg.max_rotation_radps;
  (void)snprintf(L->teleop_range_detail, sizeof L->teleop_range_detail,
                 "B21R_TELEOP %s %.3f %s over the limit %.3f (%s)", rot ? "rotation" : "translation",
                 rot ? m->rotation_radps : m->translation_mps, rot ? "rad/s" : "m/s",
                 rot ? L->cfg.max_rotation_radps : L->cfg.max_translation_mps,
                 rot ? "max_rotation_radps" : "max_translation_mps");
  if (!L->teleop_range_logged) {
    L->teleop_range_logged = true;
    fw_loop_log(L, 2, "b21r-controller: %s: refused (the teleop tool must clamp to the limits)",
                L->teleop_range_detail);
  }
}

static void take_teleop(fw_loop_t* L, const b21r_teleop_t* m, int64_t arrival_us, int64_t now_us) {
  L->teleop_range_newest = false;  // the newest message decides (refuse_range sets it again)
  if (!isfinite(m->rotation_radps) || !isfinite(m->translation_mps)) {
    L->teleop_rejected_nan++;
  } else if (fabs(m->rotation_radps) > L->cfg.max_rotation_radps ||
             fabs(m->translation_mps) > L->cfg.max_translation_mps) {
    refuse_range(L, m);
  } else if (L->teleop_have_seq && m->seq <= L->teleop_last_seq) {
    L->teleop_rejected_seq++;
  } else if (now_us - arrival_us > (int64_t)(L->cfg.teleop_timeout_s * 1e6)) {
    L->teleop_rejected_stale++;
  } else {
    L->teleop_accepted++;
    L->teleop_range_logged = false;
    L->teleop_have_seq = true;
    L->teleop_last_seq = m->seq;
    L->teleop_deadman = m->deadman != 0;
    L->teleop_rot_radps = m->rotation_radps;
    L->teleop_last_us = arrival_us;
    return;
  }
  L->teleop_rejected++;
}

static bool is_stop(const b21r_command_t* m) {
  return m->command == B21R_COMMAND_T_PAUSE || m->command == B21R_COMMAND_T_SHUTDOWN;
}

// Commands reach the mailbox authenticated and fresh (fw/opauth.h: their window takes reordered
// ones). A command older than the newest taken was overtaken by the operator's later word and is
// dropped, unless it is a stop: stopping is always safe, so a PAUSE or SHUTDOWN is obeyed whatever
// came before it.
static void take_command(fw_loop_t* L, const b21r_command_t* m) {
  const bool older = L->cmd_have_seq && m->seq <= L->cmd_last_seq;
  if (m->command < B21R_COMMAND_T_START_PHASE_TWO || m->command > B21R_COMMAND_T_SHUTDOWN ||
      (older && !is_stop(m))) {
    L->commands_rejected++;
    return;
  }
  L->commands_accepted++;
  if (!older) {
    L->cmd_have_seq = true;
    L->cmd_last_seq = m->seq;
  }
  switch (m->command) {
    case B21R_COMMAND_T_START_PHASE_TWO:
      learn_request_phase_two(L->agent);
      fw_loop_log(L, 2, "b21r-controller: operator: phase two starts when the current training run ends");
      break;
    case B21R_COMMAND_T_CONFIRM_START_POSE:
      L->confirm_pending = true;
      break;
    case B21R_COMMAND_T_PAUSE:
      L->paused = true;
      break;
    case B21R_COMMAND_T_RESUME:
      L->paused = false;
      L->resume_now = true;
      break;
    default:
      L->shutdown_requested = true;
      break;
  }
}

void fw_operator_drain(fw_loop_t* L, int64_t now_us) {
  b21r_teleop_t tel[FW_MAILBOX];
  int64_t arr[FW_MAILBOX];
  b21r_command_t cmd[FW_MAILBOX];
  pthread_mutex_lock(&L->mbox_mu);
  const uint32_t nt = L->teleop_n;
  const uint32_t nc = L->cmd_n;
  memcpy(tel, L->teleop_box, nt * sizeof tel[0]);
  memcpy(arr, L->teleop_arrival, nt * sizeof arr[0]);
  memcpy(cmd, L->cmd_box, nc * sizeof cmd[0]);
  L->teleop_n = 0;
  L->cmd_n = 0;
  const uint64_t over_t = L->mbox_overflow_teleop;
  const uint64_t over_c = L->mbox_overflow_cmd;
  L->mbox_overflow_teleop = 0;
  L->mbox_overflow_cmd = 0;
  pthread_mutex_unlock(&L->mbox_mu);
  L->teleop_rejected += (int64_t)over_t;
  L->commands_rejected += (int64_t)over_c;
  for (uint32_t i = 0; i < nt; ++i) {
    take_teleop(L, &tel[i], arr[i], now_us);
  }
  for (uint32_t i = 0; i < nc; ++i) {
    take_command(L, &cmd[i]);
  }
}

void fw_loop_post_teleop(fw_loop_t* L, const b21r_teleop_t* msg, int64_t arrival_us) {
  pthread_mutex_lock(&L->mbox_mu);
  if (L->teleop_n == FW_MAILBOX) {
    // Keep the newest: drop the oldest.
    memmove(&L->teleop_box[0], &L->teleop_box[1], (FW_MAILBOX - 1) * sizeof L->teleop_box[0]);
    memmove(&L->teleop_arrival[0], &L->teleop_arrival[1], (FW_MAILBOX - 1) * sizeof L->teleop_arrival[0]);
    L->teleop_n--;
    L->mbox_overflow_teleop++;
  }
  L->teleop_box[L->teleop_n] = *msg;
  L->teleop_arrival[L->teleop_n] = arrival_us;
  L->teleop_n++;
  pthread_mutex_unlock(&L->mbox_mu);
}

void fw_loop_post_command(fw_loop_t* L, const b21r_command_t* msg, int64_t arrival_us) {
  (void)arrival_us;
  pthread_mutex_lock(&L->mbox_mu);
  if (L->cmd_n == FW_MAILBOX && is_stop(msg)) {
    // A full mailbox makes room for a stop: the oldest command that is not one goes (counted).
    for (uint32_t i = 0; i < L->cmd_n; ++i) {
      if (!is_stop(&L->cmd_box[i])) {
        memmove(&L->cmd_box[i], &L->cmd_box[i + 1], (L->cmd_n - i - 1) * sizeof L->cmd_box[0]);
        L->cmd_n--;
        L->mbox_overflow_cmd++;
        break;
      }
    }
  }
  if (L->cmd_n == FW_MAILBOX) {
    L->mbox_overflow_cmd++;
  } else {
    L->cmd_box[L->cmd_n++] = *msg;
  }
  pthread_mutex_unlock(&L->mbox_mu);
}

void fw_loop_signal(fw_loop_t* L, int signal_number) { atomic_store(&L->signal_number, signal_number); }
