// SPDX-License-Identifier: MIT
// Publisher thread: queue → LCM encode → lcm_publish and LCM event logs.
#define _POSIX_C_SOURCE 200809L
#include "fw/publisher.h"
#include "fw/errfmt.h"

#include <errno.h>
#include <lcm/eventlog.h>
#include <pthread.h>
#include <semaphore.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct fw_publisher {
  fw_pubq_t* q;
  lcm_t* lcm;
  lcm_eventlog_t* log;
  lcm_eventlog_t* exp_log;
  sem_t wake;
  atomic_bool stop;
  pthread_mutex_t mu;  // guards the idle flag for flush
  pthread_cond_t cv;
  bool idle;
  pthread_mutex_t log_mu;  // the publisher thread and fw_publisher_record() both write the log
  // Counters: written by one thread each, read from any (relaxed atomics: no lock on the tick).
  atomic_uint_fast64_t published;
  atomic_uint_fast64_t lcm_errors;
  atomic_uint_fast64_t log_errors;
  atomic_uint_fast64_t recorded;
  pthread_t thread;
  uint8_t buf[65536];  // B21R_CONFIG (every key's line) is the largest message
};

int64_t fw_publisher_wall_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_REALTIME, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

static void count(atomic_uint_fast64_t* c, uint64_t n) {
  if (n > 0) {
    atomic_fetch_add_explicit(c, n, memory_order_relaxed);
  }
}

// Encodes m into buf; returns the size or -1.
static int encode(const fw_msg_t* m, uint8_t* buf, int cap, int64_t* utime) {
  switch (m->kind) {
    case FW_MSG_EXPERIENCE:
      *utime = m->u.experience.utime;
      return b21r_experience_t_encode(buf, 0, cap, &m->u.experience);
    case FW_MSG_STATUS: {
      b21r_status_t s = m->u.status.msg;
      s.stop_detail = (char*)(uintptr_t)m->u.status.detail;
      *utime = s.utime;
      return b21r_status_t_encode(buf, 0, cap, &s);
    }
    case FW_MSG_POSE:
      *utime = m->u.pose.utime;
      return b21r_pose_t_encode(buf, 0, cap, &m->u.pose);
    case FW_MSG_EVAL:
      *utime = m->u.eval.utime;
      return b21r_eval_t_encode(buf, 0, cap, &m->u.eval);
    case FW_MSG_SCAN:
      *utime = m->u.scan.utime;
      return b21r_scan_t_encode(buf, 0, cap, &m->u.scan);
    case FW_MSG_CONFIG:
      *utime = m->u.config.utime;
      return b21r_config_t_encode(buf, 0, cap, &m->u.config);
    case FW_MSG_RUN:
      *utime = m->u.run.utime;
      return b21r_run_t_encode(buf, 0, cap, &m->u.run);
    default:
      return -1;
  }
}

static int log_event(lcm_eventlog_t* log, const char* channel, int64_t utime, uint8_t* data, int size) {
  lcm_eventlog_event_t ev;
  memset(&ev, 0, sizeof ev);
  ev.timestamp = utime;
  ev.channellen = (int32_t)strlen(channel);
  ev.datalen = size;
  ev.channel = (char*)(uintptr_t)channel;
  ev.data = data;
  return lcm_eventlog_write_event(log, &ev);
}

static void drain(fw_publisher_t* p) {
  const fw_msg_t* m;
  while ((m = fw_pubq_peek(p->q)) != NULL) {
    if (m->kind == FW_MSG_TEXT) {
      FILE* f = m->u.text.stream == 1 ? stdout : stderr;
      fprintf(f, "%s\n", m->u.text.line);
      fflush(f);
      fw_pubq_pop(p->q);
      count(&p->published, 1);
      continue;
    }
    int64_t utime = 0;
    const int size = encode(m, p->buf, (int)sizeof p->buf, &utime);
    const char* channel = fw_msg_channel(m->kind);
    uint64_t lcm_err = 0;
    uint64_t log_err = 0;
    if (size > 0) {
      if (p->lcm != NULL && lcm_publish(p->lcm, channel, p->buf, (unsigned)size) != 0) {
        lcm_err++;
      }
      if (p->log != NULL || p->exp_log != NULL) {
        pthread_mutex_lock(&p->log_mu);
        // The full log is stamped with the wall clock (the message keeps the controller's time
        // in utime); the experience log with utime, so that identical lockstep runs give
        // byte-identical experience logs.
        if (p->log != NULL && log_event(p->log, channel, fw_publisher_wall_us(), p->buf, size) != 0) {
          log_err++;
        }
        if (p->exp_log != NULL && m->kind == FW_MSG_EXPERIENCE &&
            log_event(p->exp_log, channel, utime, p->buf, size) != 0) {
          log_err++;
        }
        pthread_mutex_unlock(&p->log_mu);
      }
    } else {
      lcm_err++;
    }
    fw_pubq_pop(p->q);
    count(&p->published, 1);
    count(&p->lcm_errors, lcm_err);
    count(&p->log_errors, log_err);
  }
}

void fw_publisher_record(fw_publisher_t* p, const char* channel, const void* data, size_t size) {
  if (p == NULL || p->log == NULL || size > INT32_MAX) {
    return;
  }
  pthread_mutex_lock(&p->log_mu);
  const int rc = log_event(p->log, channel, fw_publisher_wall_us(), (uint8_t*)(uintptr_t)data, (int)size);
  pthread_mutex_unlock(&p->log_mu);
  count(rc == 0 ? &p->recorded : &p->log_errors, 1);
}

static void* publisher_main(void* arg) {
  fw_publisher_t* p = (fw_publisher_t*)arg;
  for (;;) {
    // Wait for a notification, but never sleep forever: a missed notify costs at most 20 ms.
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    ts.tv_nsec += 20 * 1000 * 1000;
    if (ts.tv_nsec >= 1000000000L) {
      ts.tv_sec += 1;
      ts.tv_nsec -= 1000000000L;
    }
    while (sem_timedwait(&p->wake, &ts) != 0 && errno == EINTR) {
    }
    pthread_mutex_lock(&p->mu);
    p->idle = false;
    pthread_mutex_unlock(&p->mu);
    drain(p);
    pthread_mutex_lock(&p->log_mu);
    if (p->log != NULL) {
      fflush(p->log->f);
    }
    if (p->exp_log != NULL) {
      fflush(p->exp_log->f);
    }
    pthread_mutex_unlock(&p->log_mu);
    pthread_mutex_lock(&p->mu);
    p->idle = fw_pubq_peek(p->q) == NULL;
    pthread_cond_broadcast(&p->cv);
    pthread_mutex_unlock(&p->mu);
    if (atomic_load(&p->stop) && fw_pubq_peek(p->q) == NULL) {
      break;
    }
  }
  return NULL;
}

fw_publisher_t* fw_publisher_create(fw_pubq_t* q, const fw_publisher_config_t* cfg, char* err, size_t err_cap) {
  fw_publisher_t* p = (fw_publisher_t*)calloc(1, sizeof *p);
  if (p == NULL) {
    fw_errfmt(err, err_cap, "publisher: out of memory");
    return NULL;
  }
  p->q = q;
  p->lcm = cfg->lcm;
  if (cfg->log_file != NULL && cfg->log_file[0] != '\0') {
    p->log = lcm_eventlog_create(cfg->log_file, "w");
    if (p->log == NULL) {
      fw_errfmt(err, err_cap, "log_file %s: cannot create: %s", cfg->log_file, strerror(errno));
      free(p);
      return NULL;
    }
  }
  if (cfg->experience_log_file != NULL && cfg->experience_log_file[0] != '\0') {
    p->exp_log = lcm_eventlog_create(cfg->experience_log_file, "w");
    if (p->exp_log == NULL) {
      fw_errfmt(err, err_cap, "experience_log_file %s: cannot create: %s", cfg->experience_log_file, strerror(errno));
      if (p->log != NULL) {
        lcm_eventlog_destroy(p->log);
      }
      free(p);
      return NULL;
    }
  }
  sem_init(&p->wake, 0, 0);
  atomic_init(&p->stop, false);
  pthread_mutex_init(&p->mu, NULL);
  pthread_mutex_init(&p->log_mu, NULL);
  pthread_cond_init(&p->cv, NULL);
  atomic_init(&p->published, 0);
  atomic_init(&p->lcm_errors, 0);
  atomic_init(&p->log_errors, 0);
  atomic_init(&p->recorded, 0);
  p->idle = true;
  if (pthread_create(&p->thread, NULL, publisher_main, p) != 0) {
    fw_errfmt(err, err_cap, "publisher: cannot start thread");
    if (p->log != NULL) {
      lcm_eventlog_destroy(p->log);
    }
    if (p->exp_log != NULL) {
      lcm_eventlog_destroy(p->exp_log);
    }
    free(p);
    return NULL;
  }
  return p;
}

void fw_publisher_notify(fw_publisher_t* p) {
  int v = 0;
  // Posting only when the count is 0 keeps the semaphore from overflowing at high rates.
  if (sem_getvalue(&p->wake, &v) == 0 && v > 0) {
    return;
  }
  sem_post(&p->wake);
}

void fw_publisher_flush(fw_publisher_t* p) {
  for (;;) {
    sem_post(&p->wake);
    pthread_mutex_lock(&p->mu);
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    ts.tv_sec += 1;
    if (!(p->idle && fw_pubq_peek(p->q) == NULL)) {
      pthread_cond_timedwait(&p->cv, &p->mu, &ts);
    }
    const bool done = p->idle && fw_pubq_peek(p->q) == NULL;
    pthread_mutex_unlock(&p->mu);
    if (done) {
      return;
    }
  }
}

fw_publisher_counters_t fw_publisher_counters(const fw_publisher_t* p) {
  fw_publisher_counters_t c;
  memset(&c, 0, sizeof c);
  if (p != NULL) {
    c.published = atomic_load_explicit(&p->published, memory_order_relaxed);
    c.lcm_errors = atomic_load_explicit(&p->lcm_errors, memory_order_relaxed);
    c.log_errors = atomic_load_explicit(&p->log_errors, memory_order_relaxed);
    c.recorded = atomic_load_explicit(&p->recorded, memory_order_relaxed);
  }
  return c;
}

void fw_publisher_destroy(fw_publisher_t* p) {
  if (p == NULL) {
    return;
  }
  atomic_store(&p->stop, true);
  sem_post(&p->wake);
  pthread_join(p->thread, NULL);
  if (p->log != NULL) {
    lcm_eventlog_destroy(p->log);
  }
  if (p->exp_log != NULL) {
    lcm_eventlog_destroy(p->exp_log);
  }
  sem_destroy(&p->wake);
  pthread_mutex_destroy(&p->mu);
  pthread_mutex_destroy(&p->log_mu);
  pthread_cond_destroy(&p->cv);
  free(p);
}
