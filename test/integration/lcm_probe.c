// SPDX-License-Identifier: MIT
// lcm_probe publish|subscribe URL CHANNEL: the two halves of the multi-process LCM test.
//   publish:   sends b21r_teleop_t with seq 0..N-1 every 20 ms, then exits 0.
//   subscribe: waits up to 10 s for a teleop_t with the expected payload; exits 0 on success,
//              1 on timeout or a wrong payload.
#define _POSIX_C_SOURCE 200809L
#include <b21r/b21r_teleop_t.h>
#include <lcm/lcm.h>

#include <stdio.h>
#include <string.h>
#include <sys/select.h>
#include <time.h>

static int g_received;
static int g_bad;

static void on_teleop(const lcm_recv_buf_t* rbuf, const char* channel, const b21r_teleop_t* msg,
                      void* user) {
  (void)rbuf;
  (void)user;
  if (msg->deadman == 1 && msg->rotation_radps == 0.25 && msg->translation_mps == 0.5) {
    printf("subscriber: %s seq %lld received\n", channel, (long long)msg->seq);
    g_received++;
  } else {
    g_bad++;
  }
}

static int publish(lcm_t* lcm, const char* channel) {
  for (int i = 0; i < 250; ++i) {
    b21r_teleop_t m = {.utime = i, .seq = i, .deadman = 1, .rotation_radps = 0.25, .translation_mps = 0.5};
    if (b21r_teleop_t_publish(lcm, channel, &m) != 0) {
      fprintf(stderr, "publisher: publish failed\n");
      return 1;
    }
    const struct timespec period = {.tv_sec = 0, .tv_nsec = 20 * 1000 * 1000};
    nanosleep(&period, NULL);
  }
  return 0;
}

static int subscribe(lcm_t* lcm, const char* channel) {
  b21r_teleop_t_subscription_t* sub = b21r_teleop_t_subscribe(lcm, channel, on_teleop, NULL);
  printf("subscriber: ready\n");
  fflush(stdout);
  const int fd = lcm_get_fileno(lcm);
  for (int waited_ms = 0; waited_ms < 10000 && g_received == 0 && g_bad == 0; waited_ms += 100) {
    fd_set fds;
    FD_ZERO(&fds);
    FD_SET(fd, &fds);
    struct timeval tv = {.tv_sec = 0, .tv_usec = 100000};
    if (select(fd + 1, &fds, NULL, NULL, &tv) > 0) {
      lcm_handle(lcm);
    }
  }
  b21r_teleop_t_unsubscribe(lcm, sub);
  if (g_bad != 0) {
    fprintf(stderr, "subscriber: wrong payload\n");
    return 1;
  }
  if (g_received == 0) {
    fprintf(stderr, "subscriber: nothing received within 10 s\n");
    return 1;
  }
  return 0;
}

int main(int argc, char** argv) {
  if (argc != 4 || (strcmp(argv[1], "publish") != 0 && strcmp(argv[1], "subscribe") != 0)) {
    fprintf(stderr, "usage: lcm_probe publish|subscribe URL CHANNEL\n");
    return 2;
  }
  lcm_t* lcm = lcm_create(argv[2]);
  if (lcm == NULL) {
    fprintf(stderr, "lcm_probe: cannot open %s\n", argv[2]);
    return 1;
  }
  const int rc = strcmp(argv[1], "publish") == 0 ? publish(lcm, argv[3]) : subscribe(lcm, argv[3]);
  lcm_destroy(lcm);
  return rc;
}
