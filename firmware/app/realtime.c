// SPDX-License-Identifier: MIT
// Real-time provisions: sched_setaffinity, mlockall, sched_setscheduler, with errors that say
// which privilege is missing and how to grant it.
#define _GNU_SOURCE 1
#include "realtime.h"

#include <errno.h>
#include <sched.h>
#include <stdio.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

// Mask of the CPUs in set that the config syntax can name.
static uint64_t mask_of(const cpu_set_t* set) {
  uint64_t m = 0;
  for (size_t c = 0; c < FW_CONFIG_MAX_CPUS; ++c) {
    if (CPU_ISSET(c, set)) {
      m |= UINT64_C(1) << c;
    }
  }
  return m;
}

static int apply_affinity(uint64_t want, char* err, size_t cap) {
  cpu_set_t allowed;
  CPU_ZERO(&allowed);
  if (sched_getaffinity(0, sizeof allowed, &allowed) != 0) {
    snprintf(err, cap, "rt_cpus: sched_getaffinity: %s", strerror(errno));
    return -1;
  }
  char want_text[4 * FW_CONFIG_MAX_CPUS];
  char allowed_text[4 * FW_CONFIG_MAX_CPUS];
  fw_config_format_cpus(want, want_text, sizeof want_text);
  fw_config_format_cpus(mask_of(&allowed), allowed_text, sizeof allowed_text);
  const uint64_t missing = want & ~mask_of(&allowed);
  if (missing != 0) {
    char missing_text[4 * FW_CONFIG_MAX_CPUS];
    fw_config_format_cpus(missing, missing_text, sizeof missing_text);
    snprintf(err, cap,
             "rt_cpus = \"%s\": CPU %s is not available to this process (this machine has %ld online; allowed "
             "here: %s): choose CPUs from %s",
             want_text, missing_text, sysconf(_SC_NPROCESSORS_ONLN), allowed_text, allowed_text);
    return -1;
  }
  cpu_set_t set;
  CPU_ZERO(&set);
  for (size_t c = 0; c < FW_CONFIG_MAX_CPUS; ++c) {
    if ((want >> c & 1U) != 0U) {
      CPU_SET(c, &set);
    }
  }
  if (sched_setaffinity(0, sizeof set, &set) != 0) {
    snprintf(err, cap, "rt_cpus = \"%s\": sched_setaffinity: %s (allowed here: %s)", want_text, strerror(errno),
             allowed_text);
    return -1;
  }
  return 0;
}

// "unlimited" or the number, for limit messages.
static void limit_text(rlim_t v, const char* unit, char* out, size_t cap) {
  if (v == RLIM_INFINITY) {
    snprintf(out, cap, "unlimited");
  } else {
    snprintf(out, cap, "%llu%s", (unsigned long long)v, unit);
  }
}

static int apply_memory_lock(char* err, size_t cap) {
  if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
    return 0;
  }
  const int e = errno;
  struct rlimit rl = {0, 0};
  (void)getrlimit(RLIMIT_MEMLOCK, &rl);
  char lim[32];
  limit_text(rl.rlim_cur == RLIM_INFINITY ? rl.rlim_cur : rl.rlim_cur / 1024U, " KiB", lim, sizeof lim);
  if (e == ENOMEM || e == EPERM) {
    snprintf(err, cap,
             "rt_lock_memory = true: mlockall: %s: the process's memory exceeds its RLIMIT_MEMLOCK (%s) and it "
             "lacks CAP_IPC_LOCK. Grant one: `ulimit -l unlimited` (as root) before starting, LimitMEMLOCK=infinity "
             "in its systemd unit, '<user> - memlock unlimited' in /etc/security/limits.conf, or `setcap "
             "cap_ipc_lock+ep b21r-controller`; or set rt_lock_memory = false",
             strerror(e), lim);
  } else {
    snprintf(err, cap, "rt_lock_memory = true: mlockall: %s", strerror(e));
  }
  return -1;
}

static const char* policy_name(int policy) {
  switch (policy) {
    case SCHED_FIFO:
      return "fifo";
    case SCHED_RR:
      return "rr";
    case SCHED_OTHER:
      return "other";
    default:
      return "another policy";
  }
}

static int apply_scheduler(int32_t which, int32_t priority, char* err, size_t cap) {
  const int policy = which == FW_RT_FIFO ? SCHED_FIFO : SCHED_RR;
  const struct sched_param sp = {.sched_priority = priority};
  if (sched_setscheduler(0, policy, &sp) == 0) {
    return 0;
  }
  const int e = errno;
  struct rlimit rl = {0, 0};
  (void)getrlimit(RLIMIT_RTPRIO, &rl);
  char lim[32];
  limit_text(rl.rlim_cur, "", lim, sizeof lim);
  if (e == EPERM) {
    snprintf(err, cap,
             "rt_scheduler = %s, rt_priority = %d: sched_setscheduler: %s: the process lacks CAP_SYS_NICE and its "
             "RLIMIT_RTPRIO (%s) is below %d (or its cgroup has no real-time CPU time, cpu.rt_runtime_us = 0). "
             "Grant one: `setcap cap_sys_nice+ep b21r-controller`, LimitRTPRIO=%d in its systemd unit, '<user> - "
             "rtprio %d' in /etc/security/limits.conf, or `prlimit --rtprio=%d` before starting; or set "
             "rt_scheduler = other",
             policy_name(policy), (int)priority, strerror(e), lim, (int)priority, (int)priority, (int)priority,
             (int)priority);
  } else {
    snprintf(err, cap, "rt_scheduler = %s, rt_priority = %d: sched_setscheduler: %s (priorities %d to %d)",
             policy_name(policy), (int)priority, strerror(e), sched_get_priority_min(policy),
             sched_get_priority_max(policy));
  }
  return -1;
}

int rt_apply(const fw_config_t* cfg, char* err, size_t err_cap) {
  if (cfg->rt_cpus != 0 && apply_affinity(cfg->rt_cpus, err, err_cap) != 0) {
    return -1;
  }
  if (cfg->rt_lock_memory && apply_memory_lock(err, err_cap) != 0) {
    return -1;
  }
  if (cfg->rt_scheduler != FW_RT_OTHER && apply_scheduler(cfg->rt_scheduler, cfg->rt_priority, err, err_cap) != 0) {
    return -1;
  }
  return 0;
}

void rt_describe(char* out, size_t cap) {
  const int policy = sched_getscheduler(0);
  struct sched_param sp = {.sched_priority = 0};
  (void)sched_getparam(0, &sp);
  cpu_set_t set;
  CPU_ZERO(&set);
  char cpus[4 * FW_CONFIG_MAX_CPUS] = "?";
  if (sched_getaffinity(0, sizeof set, &set) == 0) {
    fw_config_format_cpus(mask_of(&set), cpus, sizeof cpus);
  }
  snprintf(out, cap, "scheduler %s, priority %d, CPUs %s", policy_name(policy), sp.sched_priority, cpus);
}
