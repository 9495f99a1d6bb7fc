// SPDX-License-Identifier: MIT
// Mutexes the real-time tick thread shares with time-shared threads (the checkpoint writer, the
// LCM receive thread) use priority inheritance: a holder preempted by other work would otherwise
// keep the tick waiting for as long as the machine's load keeps the holder off a CPU.
#ifndef FW_PI_MUTEX_H
#define FW_PI_MUTEX_H

#include <pthread.h>

static inline void fw_pi_mutex_init(pthread_mutex_t* mu) {
  pthread_mutexattr_t a;
  pthread_mutexattr_init(&a);
  (void)pthread_mutexattr_setprotocol(&a, PTHREAD_PRIO_INHERIT);
  pthread_mutex_init(mu, &a);
  pthread_mutexattr_destroy(&a);
}

#endif  // FW_PI_MUTEX_H
