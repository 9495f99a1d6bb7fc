// SPDX-License-Identifier: MIT
/// realtime.h — The real-time provisions of the onboard program (config keys rt_*): CPU
/// affinity and scheduling policy of the tick thread, locking the process's memory in RAM.
/// Pre-faulting (rt_prefault) is the loop's own (fw_loop_prefault), called after these.
///
/// Applied once, from the tick thread, after the helper threads (publisher, checkpoint writer,
/// LCM receiver) exist and before the first tick: the policy and the affinity are the tick
/// thread's only, so that helpers never compete with the tick at its priority. Linux only.
#ifndef B21R_APP_REALTIME_H
#define B21R_APP_REALTIME_H

#include "fw/config.h"

#include <stddef.h>

/// Applies rt_cpus, rt_lock_memory, then rt_scheduler / rt_priority to the calling thread.
/// Returns 0, or -1 with a message in err that names the key, the system call's error and, when
/// a privilege or a limit is missing, which one (CAP_SYS_NICE / RLIMIT_RTPRIO, CAP_IPC_LOCK /
/// RLIMIT_MEMLOCK) and how to grant it. Settings applied before the failing one stay applied.
int rt_apply(const fw_config_t* cfg, char* err, size_t err_cap);

/// What is in effect for the calling thread (policy, priority, CPUs), for the start-up message.
void rt_describe(char* out, size_t cap);

#endif  // B21R_APP_REALTIME_H
