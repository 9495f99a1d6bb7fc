// SPDX-License-Identifier: MIT
// Link mode of the serial port: one helper thread per device makes the terminal's calls that can
// wait for the kernel's tty worker (poll, read, tcdrain, tcsetattr, tcflush, open), so that the
// port's owner, the real-time control thread, never does (drivers/serial.h explains why).
//
// Between the owner and the helper:
// - input: a single-producer single-consumer byte ring (the helper appends, the owner takes),
//   lock-free; an input flush of the helper is a marker (sequence number and ring position) that
//   the owner applies when it next takes input;
// - requests (open, close, paced writes, rate changes, input flushes) and the state: a mutex
//   held only for bookkeeping, never across a system call, with priority inheritance, so that
//   the owner waits at most for a few copies;
// - wake-ups: an eventfd wakes the helper; the helper calls the owner's notify callback.
#define _GNU_SOURCE
#include <drivers/serial_link.h>

#include <errno.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/eventfd.h>
#include <termios.h>
#include <unistd.h>

_Static_assert((DRV_SERIAL_LINK_RX_BYTES & (DRV_SERIAL_LINK_RX_BYTES - 1U)) == 0U, "ring size: a power of two");

enum { OP_WRITE = 1, OP_BAUD = 2, OP_FLUSH_INPUT = 3 };

typedef struct link_op {
  int kind;
  uint32_t baud;
  uint32_t chunk_gap_us;
  uint32_t byte_gap_us;
  uint16_t n;
  uint8_t bytes[DRV_SERIAL_LINK_OP_BYTES];
} link_op_t;

struct drv_serial_link {
  // Input ring (lock-free): head and tail count bytes since the start (they wrap together).
  uint8_t* rx;
  _Atomic uint32_t rx_head;     // the helper's
  _Atomic uint32_t rx_tail;     // the owner's
  _Atomic uint32_t flush_seq;   // input flushes done by the helper
  _Atomic uint32_t flush_at;    // rx_head when the last one was done
  _Atomic int error;            // hang-up or I/O error of the open descriptor (negative errno)

  // Under mu.
  pthread_mutex_t mu;
  int state;                    // drv_serial_link_state_t
  int fd;                       // the helper's descriptor (-1: none)
  uint32_t baud;                // rate of the open
  int open_error;
  char open_msg[200];
  bool want_open;
  bool want_close;
  bool stop;
  char path[256];
  uint32_t want_baud;
  link_op_t ops[DRV_SERIAL_LINK_OPS];
  uint32_t op_head;
  uint32_t op_n;
  drv_serial_link_counters_t counters;

  int wake_fd;
  void (*notify)(void* user);
  void* user;
  pthread_t thread;
  bool running;
};

drv_serial_link_t* drv_serial_link_create(void (*notify)(void* user), void* user) {
  drv_serial_link_t* l = (drv_serial_link_t*)calloc(1, sizeof *l);
  if (l == NULL) {
    return NULL;
  }
  l->rx = (uint8_t*)malloc(DRV_SERIAL_LINK_RX_BYTES);
  l->wake_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (l->rx == NULL || l->wake_fd < 0) {
    if (l->wake_fd >= 0) {
      close(l->wake_fd);
    }
    free(l->rx);
    free(l);
    return NULL;
  }
  pthread_mutexattr_t ma;
  pthread_mutexattr_init(&ma);
  // The owner is a real-time thread: whoever holds the lock runs at its priority meanwhile.
  (void)pthread_mutexattr_setprotocol(&ma, PTHREAD_PRIO_INHERIT);
  pthread_mutex_init(&l->mu, &ma);
  pthread_mutexattr_destroy(&ma);
  atomic_init(&l->rx_head, 0U);
  atomic_init(&l->rx_tail, 0U);
  atomic_init(&l->flush_seq, 0U);
  atomic_init(&l->flush_at, 0U);
  atomic_init(&l->error, 0);
  l->fd = -1;
  l->notify = notify;
  l->user = user;
  return l;
}

static void wake(drv_serial_link_t* l) {
  const uint64_t one = 1;
  (void)!write(l->wake_fd, &one, sizeof one);
}

static void tell_owner(drv_serial_link_t* l) {
  if (l->notify != NULL) {
    l->notify(l->user);
  }
}

// ---- the helper thread ------------------------------------------------------------------------

// Carries out one request on fd (the helper only; no lock held).
static void execute(drv_serial_link_t* l, int fd, const link_op_t* op) {
  drv_serial_t port;  // a plain port on the helper's descriptor: the calls of the non-link mode
  memset(&port, 0, sizeof port);
  port.fd = fd;
  pthread_mutex_lock(&l->mu);
  port.baud = l->baud;
  pthread_mutex_unlock(&l->mu);
  int rc = 0;
  switch (op->kind) {
    case OP_WRITE:
      drv_serial_set_pacing(&port, 0, op->chunk_gap_us, op->byte_gap_us);
      rc = drv_serial_write(&port, op->bytes, op->n, 200);
      break;
    case OP_BAUD:
      rc = drv_serial_set_baud(&port, op->baud);
      if (rc == 0) {
        pthread_mutex_lock(&l->mu);
        l->baud = op->baud;
        pthread_mutex_unlock(&l->mu);
      }
      break;
    case OP_FLUSH_INPUT:
      rc = tcflush(fd, TCIFLUSH) == 0 ? 0 : -errno;
      // Bytes read before the flush are stale too: the owner drops them when it sees the marker.
      atomic_store_explicit(&l->flush_at, atomic_load_explicit(&l->rx_head, memory_order_relaxed),
                            memory_order_relaxed);
      atomic_fetch_add_explicit(&l->flush_seq, 1U, memory_order_release);
      break;
    default:
      break;
  }
  // A write that failed for good (not a timeout) means the line is gone.
  if (rc < 0 && rc != -ETIMEDOUT && rc != -EINVAL && op->kind == OP_WRITE) {
    int none = 0;
    (void)atomic_compare_exchange_strong(&l->error, &none, rc);
  }
}

// Reads what poll() reported into the ring (one read: poll reports again if more is pending).
// Returns true when the owner should be told (input, or a new error).
static bool take_input(drv_serial_link_t* l, int fd, short revents) {
  bool news = false;
  ssize_t n = 0;
  if ((revents & POLLIN) != 0) {
    const uint32_t head = atomic_load_explicit(&l->rx_head, memory_order_relaxed);
    const uint32_t tail = atomic_load_explicit(&l->rx_tail, memory_order_acquire);
    const uint32_t room = DRV_SERIAL_LINK_RX_BYTES - (head - tail);
    const uint32_t at = head & (DRV_SERIAL_LINK_RX_BYTES - 1U);
    const uint32_t contiguous = DRV_SERIAL_LINK_RX_BYTES - at;
    const size_t want = room < contiguous ? room : contiguous;
    n = want > 0U ? read(fd, l->rx + at, want) : 0;
    if (n > 0) {
      atomic_store_explicit(&l->rx_head, head + (uint32_t)n, memory_order_release);
      pthread_mutex_lock(&l->mu);
      l->counters.bytes_in += (uint64_t)n;
      pthread_mutex_unlock(&l->mu);
      news = true;
    } else if (n < 0 && errno != EAGAIN && errno != EINTR) {
      int none = 0;
      news = atomic_compare_exchange_strong(&l->error, &none, -errno);
    }
  }
  if ((revents & (POLLHUP | POLLERR | POLLNVAL)) != 0 && n <= 0) {
    // A hang-up (the other end closed, an adapter unplugged) once the input is read: it stays
    // set on the descriptor, which is not polled again (no spinning on a dead line).
    int none = 0;
    news = atomic_compare_exchange_strong(&l->error, &none, (revents & POLLHUP) != 0 ? -EPIPE : -EIO) || news;
  }
  return news;
}

static void* link_main(void* arg) {
  drv_serial_link_t* l = (drv_serial_link_t*)arg;
  for (;;) {
    bool news = false;
    pthread_mutex_lock(&l->mu);
    if (l->stop) {
      if (l->fd >= 0) {
        close(l->fd);
        l->fd = -1;
      }
      l->state = DRV_SERIAL_LINK_CLOSED;
      pthread_mutex_unlock(&l->mu);
      break;
    }
    if ((l->want_close || l->want_open) && l->fd >= 0) {
      close(l->fd);  // the owner no longer uses it: it asked for this
      l->fd = -1;
      l->state = DRV_SERIAL_LINK_CLOSED;
      l->op_n = 0;  // requests for the old descriptor are void
      news = true;
    }
    l->want_close = false;
    if (l->want_open) {
      l->want_open = false;
      l->state = DRV_SERIAL_LINK_OPENING;
      char path[sizeof l->path];
      memcpy(path, l->path, sizeof path);
      const uint32_t baud = l->want_baud;
      pthread_mutex_unlock(&l->mu);
      drv_serial_t port;
      char msg[sizeof l->open_msg];
      msg[0] = '\0';
      const int rc = drv_serial_open(&port, path, baud, msg, sizeof msg);
      pthread_mutex_lock(&l->mu);
      if (rc == 0 && !l->want_open && !l->want_close) {
        l->fd = port.fd;
        l->baud = baud;
        l->state = DRV_SERIAL_LINK_OPEN;
        atomic_store(&l->error, 0);
        l->counters.opens++;
      } else if (rc == 0) {
        close(port.fd);  // superseded by a newer request meanwhile
        l->state = DRV_SERIAL_LINK_CLOSED;
      } else {
        l->state = DRV_SERIAL_LINK_FAILED;
        l->open_error = rc;
        memcpy(l->open_msg, msg, sizeof msg);
        l->counters.open_failures++;
      }
      news = true;
    }
    // One request at a time, in order; the lock is not held while it runs.
    const int fd = l->fd;
    if (l->op_n > 0U && fd >= 0) {
      const link_op_t op = l->ops[l->op_head];
      pthread_mutex_unlock(&l->mu);
      if (news) {
        tell_owner(l);
      }
      execute(l, fd, &op);
      pthread_mutex_lock(&l->mu);
      if (l->fd == fd && l->op_n > 0U) {
        l->op_head = (l->op_head + 1U) % DRV_SERIAL_LINK_OPS;
        l->op_n--;
        l->counters.requests++;
      }
      pthread_mutex_unlock(&l->mu);
      continue;  // requests first, then input
    }
    pthread_mutex_unlock(&l->mu);
    if (news) {
      tell_owner(l);
      news = false;
    }
    // Wait for input, a request or a full ring's room (polled every 2 ms: the owner takes input
    // every tick, and the kernel keeps what does not fit meanwhile).
    const bool healthy = fd >= 0 && atomic_load(&l->error) == 0;
    const uint32_t used = atomic_load_explicit(&l->rx_head, memory_order_relaxed) -
                          atomic_load_explicit(&l->rx_tail, memory_order_acquire);
    const bool full = used >= DRV_SERIAL_LINK_RX_BYTES;
    struct pollfd p[2] = {{.fd = l->wake_fd, .events = POLLIN, .revents = 0},
                          {.fd = healthy && !full ? fd : -1, .events = POLLIN, .revents = 0}};
    if (healthy && full) {
      pthread_mutex_lock(&l->mu);
      l->counters.rx_full++;
      pthread_mutex_unlock(&l->mu);
    }
    const int r = poll(p, 2, healthy && full ? 2 : -1);
    if (r < 0) {
      continue;  // EINTR
    }
    if ((p[0].revents & POLLIN) != 0) {
      uint64_t v = 0;
      (void)!read(l->wake_fd, &v, sizeof v);
    }
    if (p[1].fd >= 0 && p[1].revents != 0) {
      news = take_input(l, fd, p[1].revents);
    }
    if (news) {
      tell_owner(l);
    }
  }
  return NULL;
}

int drv_serial_link_start(drv_serial_link_t* l) {
  if (l == NULL || l->running) {
    return -EINVAL;
  }
  const int rc = pthread_create(&l->thread, NULL, link_main, l);
  if (rc != 0) {
    return -rc;
  }
  l->running = true;
  return 0;
}

int drv_serial_link_set_scheduler(drv_serial_link_t* l, int policy, int priority) {
  if (l == NULL || !l->running) {
    return -EINVAL;
  }
  const struct sched_param sp = {.sched_priority = priority};
  const int rc = pthread_setschedparam(l->thread, policy, &sp);
  return rc == 0 ? 0 : -rc;
}

void drv_serial_link_stop(drv_serial_link_t* l) {
  if (l == NULL || !l->running) {
    return;
  }
  pthread_mutex_lock(&l->mu);
  l->stop = true;
  pthread_mutex_unlock(&l->mu);
  wake(l);
  pthread_join(l->thread, NULL);
  l->running = false;
}

void drv_serial_link_destroy(drv_serial_link_t* l) {
  if (l == NULL) {
    return;
  }
  drv_serial_link_stop(l);
  if (l->fd >= 0) {
    close(l->fd);
  }
  pthread_mutex_destroy(&l->mu);
  close(l->wake_fd);
  free(l->rx);
  free(l);
}

// ---- the owner --------------------------------------------------------------------------------

void drv_serial_link_open(drv_serial_link_t* l, const char* path, uint32_t baud) {
  pthread_mutex_lock(&l->mu);
  snprintf(l->path, sizeof l->path, "%s", path);
  l->want_baud = baud;
  l->want_open = true;
  l->want_close = false;
  l->state = DRV_SERIAL_LINK_OPENING;
  pthread_mutex_unlock(&l->mu);
  wake(l);
}

void drv_serial_link_close(drv_serial_link_t* l) {
  pthread_mutex_lock(&l->mu);
  l->want_close = true;
  l->want_open = false;
  l->op_n = 0;
  l->state = DRV_SERIAL_LINK_CLOSED;
  pthread_mutex_unlock(&l->mu);
  wake(l);
}

drv_serial_link_state_t drv_serial_link_state(drv_serial_link_t* l, int* fd, int* error, char* msg, size_t msg_cap) {
  pthread_mutex_lock(&l->mu);
  // A close or open asked for and not yet carried out shows as closed / opening.
  const drv_serial_link_state_t s = (drv_serial_link_state_t)l->state;
  if (fd != NULL) {
    *fd = s == DRV_SERIAL_LINK_OPEN ? l->fd : -1;
  }
  if (error != NULL) {
    *error = s == DRV_SERIAL_LINK_FAILED ? l->open_error : 0;
  }
  if (msg != NULL && msg_cap > 0U) {
    snprintf(msg, msg_cap, "%s", s == DRV_SERIAL_LINK_FAILED ? l->open_msg : "");
  }
  pthread_mutex_unlock(&l->mu);
  return s;
}

// Applies a flush marker of the helper that the owner has not seen yet.
static void apply_flush(drv_serial_link_t* l, uint32_t* flushes) {
  const uint32_t seq = atomic_load_explicit(&l->flush_seq, memory_order_acquire);
  if (seq == *flushes) {
    return;
  }
  *flushes = seq;
  const uint32_t at = atomic_load_explicit(&l->flush_at, memory_order_relaxed);
  const uint32_t tail = atomic_load_explicit(&l->rx_tail, memory_order_relaxed);
  if ((int32_t)(at - tail) > 0) {
    atomic_store_explicit(&l->rx_tail, at, memory_order_release);
  }
}

static ssize_t link_take(drv_serial_link_t* l, uint32_t* flushes, uint8_t* buf, size_t cap) {
  apply_flush(l, flushes);
  const uint32_t tail = atomic_load_explicit(&l->rx_tail, memory_order_relaxed);
  const uint32_t head = atomic_load_explicit(&l->rx_head, memory_order_acquire);
  uint32_t n = head - tail;
  if (n == 0U) {
    const int e = atomic_load(&l->error);
    return e < 0 ? (ssize_t)e : 0;
  }
  if ((size_t)n > cap) {
    n = (uint32_t)cap;
  }
  const uint32_t at = tail & (DRV_SERIAL_LINK_RX_BYTES - 1U);
  const uint32_t first = DRV_SERIAL_LINK_RX_BYTES - at < n ? DRV_SERIAL_LINK_RX_BYTES - at : n;
  memcpy(buf, l->rx + at, first);
  memcpy(buf + first, l->rx, n - first);
  atomic_store_explicit(&l->rx_tail, tail + n, memory_order_release);
  return (ssize_t)n;
}

static int request(drv_serial_link_t* l, const link_op_t* op) {
  pthread_mutex_lock(&l->mu);
  if (l->state != DRV_SERIAL_LINK_OPEN || l->op_n == DRV_SERIAL_LINK_OPS) {
    const int rc = l->state != DRV_SERIAL_LINK_OPEN ? -ENOTCONN : -ENOBUFS;
    l->counters.requests_refused++;
    pthread_mutex_unlock(&l->mu);
    return rc;
  }
  l->ops[(l->op_head + l->op_n) % DRV_SERIAL_LINK_OPS] = *op;
  l->op_n++;
  pthread_mutex_unlock(&l->mu);
  wake(l);
  return 0;
}

static int link_write(drv_serial_link_t* l, const uint8_t* data, size_t n, uint32_t chunk_gap_us,
                      uint32_t byte_gap_us) {
  if (n > DRV_SERIAL_LINK_OP_BYTES) {
    pthread_mutex_lock(&l->mu);
    l->counters.requests_refused++;
    pthread_mutex_unlock(&l->mu);
    return -EMSGSIZE;
  }
  link_op_t op;
  memset(&op, 0, sizeof op);
  op.kind = OP_WRITE;
  op.chunk_gap_us = chunk_gap_us;
  op.byte_gap_us = byte_gap_us;
  op.n = (uint16_t)n;
  memcpy(op.bytes, data, n);
  return request(l, &op);
}

static int link_set_baud(drv_serial_link_t* l, uint32_t baud) {
  link_op_t op;
  memset(&op, 0, sizeof op);
  op.kind = OP_BAUD;
  op.baud = baud;
  return request(l, &op);
}

static int link_flush_input(drv_serial_link_t* l, uint32_t* flushes) {
  apply_flush(l, flushes);
  atomic_store_explicit(&l->rx_tail, atomic_load_explicit(&l->rx_head, memory_order_acquire), memory_order_release);
  link_op_t op;
  memset(&op, 0, sizeof op);
  op.kind = OP_FLUSH_INPUT;
  return request(l, &op);
}

// What a port in link mode calls (drivers/serial.h): the owner's side of the ring and requests.
static const drv_serial_link_ops_t k_link_ops = {
    .take = link_take, .write = link_write, .flush_input = link_flush_input, .set_baud = link_set_baud};

int drv_serial_use_link(drv_serial_t* port, drv_serial_link_t* l) {
  if (port == NULL || l == NULL) {
    return -EINVAL;
  }
  int fd = -1;
  pthread_mutex_lock(&l->mu);
  const bool open = l->state == DRV_SERIAL_LINK_OPEN;
  fd = l->fd;
  const uint32_t baud = l->baud;
  pthread_mutex_unlock(&l->mu);
  if (!open) {
    return -ENOTCONN;
  }
  memset(port, 0, sizeof *port);
  port->fd = fd;
  port->owns_fd = false;
  port->baud = baud;
  port->link = l;
  port->link_ops = &k_link_ops;
  port->link_flushes = atomic_load_explicit(&l->flush_seq, memory_order_acquire);
  // Input that arrived before is not the new owner's.
  atomic_store_explicit(&l->rx_tail, atomic_load_explicit(&l->rx_head, memory_order_acquire), memory_order_release);
  return 0;
}

bool drv_serial_link_busy(drv_serial_link_t* l) {
  pthread_mutex_lock(&l->mu);
  const bool busy = l->op_n > 0U;
  pthread_mutex_unlock(&l->mu);
  return busy;
}

drv_serial_link_counters_t drv_serial_link_counters(drv_serial_link_t* l) {
  pthread_mutex_lock(&l->mu);
  const drv_serial_link_counters_t c = l->counters;
  pthread_mutex_unlock(&l->mu);
  return c;
}
