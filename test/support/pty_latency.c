// SPDX-License-Identifier: MIT
// b21r_pty_latency: how late bytes written to a pseudo-terminal reach its reader, beside the same
// over a socketpair, both between real-time threads: the reference that tells a late scan's cause
// in the deadline tests. A writer thread (SCHED_FIFO, the emulator's priority) writes a
// 732-byte block (one LMS200 telegram of 361 values) every 100 ms into a pty master and into a
// socketpair; a reader thread per channel (SCHED_FIFO, the laser line's priority) reads it and
// notes the delay from the write to the read of its last byte. A pty passes every block through
// the kernel's tty flip-buffer work, run by a time-shared kernel worker; the socketpair wakes its
// reader directly. Prints one line per channel: blocks, p99 and max delay [ms], blocks later than
// 50 ms.
// usage: b21r_pty_latency SECONDS [WRITER_PRIO READER_PRIO CPU]   (prio 0: time-shared)
#define _GNU_SOURCE
#include <errno.h>
#include <pthread.h>
#include <pty.h>
#include <sched.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#define BLOCK 732
#define PERIOD_NS 100000000LL
#define MAX_BLOCKS 100000

typedef struct channel {
  const char* name;
  int wfd, rfd;
  int64_t sent_ns[MAX_BLOCKS];  // write time of each block, by its index
  int64_t delay_ns[MAX_BLOCKS];
  int blocks_sent, blocks_read;
} channel_t;

static int g_writer_prio, g_reader_prio, g_cpu = -1;
static int64_t g_seconds;

static int64_t now_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (int64_t)t.tv_sec * 1000000000LL + t.tv_nsec;
}

static void set_sched(int prio) {
  if (g_cpu >= 0) {
    cpu_set_t s;
    CPU_ZERO(&s);
    CPU_SET((size_t)g_cpu, &s);
    (void)pthread_setaffinity_np(pthread_self(), sizeof s, &s);
  }
  if (prio > 0) {
    struct sched_param p = {.sched_priority = prio};
    if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &p) != 0) {
      fprintf(stderr, "b21r_pty_latency: SCHED_FIFO %d not permitted\n", prio);
      exit(2);
    }
  }
}

static void* reader(void* arg) {
  channel_t* c = arg;
  set_sched(g_reader_prio);
  uint8_t buf[4096];
  size_t got = 0;  // bytes of the current block
  for (;;) {
    const ssize_t r = read(c->rfd, buf, sizeof buf);
    if (r <= 0) {
      if (r < 0 && errno == EINTR) {
        continue;
      }
      return NULL;  // the writer closed its end
    }
    got += (size_t)r;
    const int64_t t = now_ns();
    while (got >= BLOCK && c->blocks_read < __atomic_load_n(&c->blocks_sent, __ATOMIC_ACQUIRE)) {
      c->delay_ns[c->blocks_read] = t - c->sent_ns[c->blocks_read];
      c->blocks_read++;
      got -= BLOCK;
    }
  }
}

static void* writer(void* arg) {
  channel_t* c = arg;
  set_sched(g_writer_prio);
  uint8_t block[BLOCK];
  memset(block, 0x5a, sizeof block);
  const int64_t start = now_ns();
  int64_t next = start;
  while (next - start < g_seconds * 1000000000LL && c->blocks_sent < MAX_BLOCKS) {
    c->sent_ns[c->blocks_sent] = now_ns();
    __atomic_store_n(&c->blocks_sent, c->blocks_sent + 1, __ATOMIC_RELEASE);
    size_t off = 0;
    while (off < sizeof block) {
      const ssize_t w = write(c->wfd, block + off, sizeof block - off);
      if (w <= 0) {
        if (w < 0 && errno == EINTR) {
          continue;
        }
        return NULL;
      }
      off += (size_t)w;
    }
    next += PERIOD_NS;
    const struct timespec ts = {(time_t)(next / 1000000000LL), (long)(next % 1000000000LL)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {
    }
  }
  usleep(500000);  // the last blocks arrive
  close(c->wfd);
  return NULL;
}

static int cmp_i64(const void* a, const void* b) {
  const int64_t x = *(const int64_t*)a, y = *(const int64_t*)b;
  return (x > y) - (x < y);
}

static void report(channel_t* c) {
  const int n = c->blocks_read;
  int late = 0;
  for (int i = 0; i < n; ++i) {
    late += c->delay_ns[i] > 50000000LL;
  }
  qsort(c->delay_ns, (size_t)n, sizeof c->delay_ns[0], cmp_i64);
  const int k = n > 0 ? (99 * n + 99) / 100 - 1 : 0;
  printf("%s: blocks %d of %d, delay p99 %.2f ms, max %.2f ms, later than 50 ms %d\n", c->name, n, c->blocks_sent,
         n > 0 ? (double)c->delay_ns[k] / 1e6 : 0.0, n > 0 ? (double)c->delay_ns[n - 1] / 1e6 : 0.0, late);
}

int main(int argc, char** argv) {
  if (argc != 2 && argc != 5) {
    fprintf(stderr, "usage: b21r_pty_latency SECONDS [WRITER_PRIO READER_PRIO CPU]\n");
    return 2;
  }
  g_seconds = atoll(argv[1]);
  if (argc == 5) {
    g_writer_prio = atoi(argv[2]);
    g_reader_prio = atoi(argv[3]);
    g_cpu = atoi(argv[4]);
  }
  (void)mlockall(MCL_CURRENT | MCL_FUTURE);
  static channel_t pty = {.name = "pty"}, pair = {.name = "socketpair"};
  int master = -1, slave = -1;
  if (openpty(&master, &slave, NULL, NULL, NULL) != 0) {
    perror("openpty");
    return 1;
  }
  struct termios t;
  tcgetattr(slave, &t);
  cfmakeraw(&t);  // as the laser line is configured: no echo, no line editing
  tcsetattr(slave, TCSANOW, &t);
  pty.wfd = master;
  pty.rfd = slave;
  int sp[2];
  if (socketpair(AF_UNIX, SOCK_STREAM, 0, sp) != 0) {
    perror("socketpair");
    return 1;
  }
  pair.wfd = sp[0];
  pair.rfd = sp[1];
  pthread_t th[4];
  pthread_create(&th[0], NULL, reader, &pty);
  pthread_create(&th[1], NULL, reader, &pair);
  pthread_create(&th[2], NULL, writer, &pty);
  pthread_create(&th[3], NULL, writer, &pair);
  pthread_join(th[2], NULL);
  pthread_join(th[3], NULL);
  pthread_join(th[1], NULL);
  // The pty's reader sees EIO once the master is closed.
  pthread_join(th[0], NULL);
  report(&pty);
  report(&pair);
  return 0;
}
