// SPDX-License-Identifier: MIT
// Safety supervisor: priority of causes, latching, clearing.
#include "fw/safety.h"

#include <stdio.h>
#include <string.h>

static const char* const k_names[FW_STOP_REASON_COUNT] = {
    "", "laser silent", "base silent", "base fault", "bumper", "non-finite value", "deadman released",
    "signal", "operator pause", "device lost", "teleop out of range"};

const char* fw_stop_reason_name(int32_t reason) {
  return (reason >= 0 && reason < FW_STOP_REASON_COUNT) ? k_names[reason] : "";
}

void fw_safety_init(fw_safety_t* s, const fw_safety_config_t* cfg) {
  memset(s, 0, sizeof *s);
  s->cfg = *cfg;
  if (s->cfg.clear_ticks < 1) {
    s->cfg.clear_ticks = 1;
  }
}

// Priority rank: higher wins.
static int rank(int32_t reason) {
  switch (reason) {
    case FW_STOP_SIGNAL:
      return 9;
    case FW_STOP_DEVICE_LOST:
      return 8;
    case FW_STOP_BASE_FAULT:
      return 7;
    case FW_STOP_BUMPER:
      return 6;
    case FW_STOP_NON_FINITE:
      return 5;
    case FW_STOP_LASER_SILENT:
      return 4;
    case FW_STOP_BASE_SILENT:
      return 3;
    case FW_STOP_DEADMAN:
    case FW_STOP_TELEOP_RANGE:
      return 2;
    case FW_STOP_OPERATOR:
      return 1;
    default:
      return 0;
  }
}

static int lowest_panel(uint32_t mask) {
  for (int i = 0; i < 32; ++i) {
    if ((mask >> i) & 1U) {
      return i;
    }
  }
  return -1;
}

// The highest-priority cause present this tick, with its detail text.
static int32_t current_cause(const fw_safety_t* s, const fw_safety_inputs_t* in, char* detail, size_t cap) {
  const fw_safety_config_t* c = &s->cfg;
  if (in->signal_number != 0) {
    snprintf(detail, cap, "signal %d received: zero command, brake set, checkpoint, exit", in->signal_number);
    return FW_STOP_SIGNAL;
  }
  if (in->device_lost) {
    snprintf(detail, cap, "%s", in->device_lost_detail != NULL ? in->device_lost_detail : "a device was lost");
    return FW_STOP_DEVICE_LOST;
  }
  if (in->base_fault) {
    snprintf(detail, cap, "base fault: %s", in->base_fault_detail != NULL ? in->base_fault_detail : "unspecified");
    return FW_STOP_BASE_FAULT;
  }
  if (in->bumper_mask != 0U) {
    snprintf(detail, cap, "bump panel %d pressed (mask 0x%04x)", lowest_panel(in->bumper_mask),
             (unsigned)in->bumper_mask);
    return FW_STOP_BUMPER;
  }
  if (in->non_finite) {
    snprintf(detail, cap, "non-finite value in %s", in->non_finite_where != NULL ? in->non_finite_where : "a tick value");
    return FW_STOP_NON_FINITE;
  }
  if (c->lockstep ? in->laser_silent_ticks >= c->laser_limit_ticks : in->laser_age_us >= c->laser_limit_us) {
    if (in->laser_repeats > 0) {
      // Telegrams arrive, valid, but with the same distances: the measurement is frozen.
      if (c->lockstep) {
        snprintf(detail, cap, "laser stuck: the same scan %d times in a row, no new scan for %d ticks",
                 (int)in->laser_repeats, (int)in->laser_silent_ticks);
      } else {
        snprintf(detail, cap, "laser stuck: the same scan %d times in a row, no new scan for %lld ms (limit %lld ms)",
                 (int)in->laser_repeats, (long long)(in->laser_age_us / 1000), (long long)(c->laser_limit_us / 1000));
      }
    } else if (in->laser_bad_since_scan > 0U && c->lockstep) {
      // Bytes arrive, but nothing in them is a valid telegram: baud rate, cable or noise.
      snprintf(detail, cap, "laser stream corrupt: no valid telegram for %d ticks, %llu bad bytes or telegrams",
               (int)in->laser_silent_ticks, (unsigned long long)in->laser_bad_since_scan);
    } else if (in->laser_bad_since_scan > 0U) {
      snprintf(detail, cap,
               "laser stream corrupt: no valid telegram for %lld ms, %llu bad bytes or telegrams (check the baud "
               "rate and the cable)",
               (long long)(in->laser_age_us / 1000), (unsigned long long)in->laser_bad_since_scan);
    } else if (c->lockstep) {
      snprintf(detail, cap, "laser silent for %d ticks (limit %d)", (int)in->laser_silent_ticks,
               (int)c->laser_limit_ticks);
    } else {
      snprintf(detail, cap, "laser silent for %lld ms (limit %lld ms)", (long long)(in->laser_age_us / 1000),
               (long long)(c->laser_limit_us / 1000));
    }
    return FW_STOP_LASER_SILENT;
  }
  if (c->lockstep ? in->base_silent_ticks >= c->base_limit_ticks : in->base_age_us >= c->base_limit_us) {
    if (c->lockstep) {
      snprintf(detail, cap, "base silent for %d ticks (limit %d)", (int)in->base_silent_ticks,
               (int)c->base_limit_ticks);
    } else {
      snprintf(detail, cap, "base silent for %lld ms (limit %lld ms)", (long long)(in->base_age_us / 1000),
               (long long)(c->base_limit_us / 1000));
    }
    return FW_STOP_BASE_SILENT;
  }
  if (in->deadman_required && !in->deadman_fresh) {
    if (in->teleop_out_of_range) {
      // The operator holds the deadman but asks for more than allowed: say so, not "released".
      snprintf(detail, cap, "%s (refused)",
               in->teleop_range_detail != NULL ? in->teleop_range_detail : "B21R_TELEOP outside the limits");
      return FW_STOP_TELEOP_RANGE;
    }
    snprintf(detail, cap, "no fresh B21R_TELEOP with the deadman held");
    return FW_STOP_DEADMAN;
  }
  if (in->operator_pause) {
    snprintf(detail, cap, "operator PAUSE (send RESUME to continue)");
    return FW_STOP_OPERATOR;
  }
  detail[0] = '\0';
  return FW_STOP_NONE;
}

fw_safety_event_t fw_safety_update(fw_safety_t* s, const fw_safety_inputs_t* in) {
  char detail[FW_SAFETY_DETAIL_MAX];
  const int32_t cause = current_cause(s, in, detail, sizeof detail);
  if (!s->stopped) {
    if (cause == FW_STOP_NONE) {
      return FW_SAFETY_OK;
    }
    s->stopped = true;
    s->reason = cause;
    memcpy(s->detail, detail, sizeof detail);
    s->clear_count = 0;
    s->resume_requested = false;
    s->stops++;
    s->stops_by_reason[cause]++;
    return FW_SAFETY_STOP_BEGAN;
  }
  if (in->operator_resume) {
    s->resume_requested = true;
  }
  if (cause != FW_STOP_NONE) {
    s->clear_count = 0;
    if (rank(cause) > rank(s->reason)) {
      // A more serious cause appeared during the stop: report it (it is a new stop reason).
      s->reason = cause;
      memcpy(s->detail, detail, sizeof detail);
      s->stops_by_reason[cause]++;
      return FW_SAFETY_STOP_BEGAN;
    }
    return FW_SAFETY_STOPPED;
  }
  if (s->reason == FW_STOP_SIGNAL) {
    return FW_SAFETY_STOPPED;
  }
  if (s->clear_count < s->cfg.clear_ticks) {
    s->clear_count++;
  }
  const bool needs_operator = s->reason == FW_STOP_OPERATOR || !s->cfg.auto_resume;
  if (s->clear_count >= s->cfg.clear_ticks && (!needs_operator || s->resume_requested)) {
    s->stopped = false;
    s->resume_requested = false;
    s->reason = FW_STOP_NONE;
    s->detail[0] = '\0';
    s->clear_count = 0;
    return FW_SAFETY_RESUMED;
  }
  return FW_SAFETY_STOPPED;
}
