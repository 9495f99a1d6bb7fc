// SPDX-License-Identifier: MIT
// b21r-controller: the onboard learning controller of the RWI B21r (command line, wiring, threads).
#define _GNU_SOURCE 1
#include "fw/checkpoint.h"
#include "fw/config.h"
#include "fw/config_task.h"
#include "fw/endpoints.h"
#include "fw/loop.h"
#include "fw/publisher.h"
#include "fw/pubq.h"
#include "io_posix.h"
#include "operator_rx.h"
#include "realtime.h"

#include <drivers/notify.h>

#include <lcm/lcm.h>

#include <errno.h>
#include <pthread.h>
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

enum { EXIT_USAGE = 2, EXIT_CHECKPOINT = 3, EXIT_DEVICE = 4 };

static fw_loop_t* volatile g_loop;  // for the signal handler only
static io_posix_t* volatile g_io;   // likewise: the tick thread's waits it ends

static void on_signal(int sig) {
  const int saved_errno = errno;  // the wake-up is a write(): the interrupted code's errno stays
  fw_loop_t* loop = g_loop;
  if (loop != NULL) {
    fw_loop_signal(loop, sig);
    io_posix_t* io = g_io;
    if (io != NULL) {
      // The handler may run on a helper thread, or on the tick thread just before it blocks: the
      // eventfd ends a lockstep wait for a stalled emulator that would otherwise last lockstep_timeout_s.
      io_posix_wake(io);
    }
  } else {
    _exit(128 + sig);  // before the loop exists there is nothing to stop or save
  }
  errno = saved_errno;
}

static void usage(FILE* f) {
  fprintf(f,
          "usage: b21r-controller [--config FILE]... [--set KEY=VALUE]... [options]\n"
          "The onboard learning controller of the RWI B21r: two-phase Q-learning with HEDGER\n"
          "(Smart & Kaelbling, ICRA 2002) on the real robot or the emulated one (b21r-sim).\n"
          "\n"
          "  --config FILE           settings in 'key = value' lines (reference with every key and\n"
          "                          its documentation: firmware/app/b21r-controller.conf); several\n"
          "                          files apply in order\n"
          "  --set KEY=VALUE         override one setting (applied after the files, in order)\n"
          "  --endpoints FILE|LINE   drive the emulator: b21r-sim's ready line ('laser=... base=...\n"
          "                          can=... control=...') or a file holding it; sets the device\n"
          "                          paths, reposition = emulator and base_write_gap_us = 0\n"
          "  --checkpoint FILE       same as --set checkpoint_file=FILE\n"
          "  --log FILE              same as --set log_file=FILE (LCM event log of every channel, the\n"
          "                          operator's TELEOP/COMMAND and B21R_CONFIG; wall-clock timestamps)\n"
          "  --experience-log FILE   same as --set experience_log_file=FILE\n"
          "  --print-config          print the effective settings and exit\n"
          "  --print-reference-config  print every key, its allowed values and its default\n"
          "  --print-task-params     print every declared task, its state and its parameters\n"
          "                          (task_params = \"name=value,...\") with ranges and defaults\n"
          "  --help                  this text\n"
          "\n"
          "LCM channels: publishes B21R_CONFIG (once), B21R_EXPERIENCE, B21R_RUN (one per run end),\n"
          "B21R_STATUS, B21R_POSE, B21R_EVAL (B21R_SCAN with publish_scan = true), B21R_SESSION; listens\n"
          "to B21R_TELEOP (joystick with deadman) and B21R_COMMAND (START_PHASE_TWO, CONFIRM_START_POSE,\n"
          "PAUSE, RESUME, SHUTDOWN), taken only signed with operator_key_file for this start (B21R_SESSION)\n"
          "and, with lcm_scope = host (the default), only from this host (docs/robot.md).\n"
          "Exit status: 0 schedule done or SHUTDOWN; 2 usage or configuration error (including rt_*\n"
          "settings the process lacks the privilege for); 3 checkpoint\n"
          "refused (before any device is opened); 4 a device did not start; 5 lockstep: a device sent\n"
          "nothing for lockstep_timeout_s; 6 a device was lost (end of file, EIO, ENODEV, hang-up) with\n"
          "device_lost_action = exit, or in lockstep; 128+N after signal N (the base is stopped and\n"
          "braked and the learned state saved first).\n"
          "Under systemd (Type=notify, NOTIFY_SOCKET set) it sends READY=1 once its devices are open and\n"
          "the first tick is done, and WATCHDOG=1 every WATCHDOG_USEC/2 after a tick's command.\n");
}

// rt_* settings, then pre-faulting (after mlockall, so that the touched pages stay locked).
static int apply_realtime(const fw_config_t* cfg, fw_loop_t* loop, io_posix_t* io, char* err, size_t err_cap) {
  if (rt_apply(cfg, err, err_cap) != 0) {
    return -1;
  }
  // The serial lines' helper threads (they make the terminal calls the tick must not) run just
  // below the tick thread, so that input reaches it as soon as the kernel has it.
  if (cfg->rt_scheduler != FW_RT_OTHER &&
      io_posix_realtime(io, cfg->rt_scheduler == FW_RT_FIFO ? SCHED_FIFO : SCHED_RR, (int)cfg->rt_priority, err,
                        err_cap) != 0) {
    return -1;
  }
  if (cfg->rt_prefault) {
    fw_loop_prefault(loop);
  }
  if (cfg->rt_scheduler != FW_RT_OTHER || cfg->rt_cpus != 0 || cfg->rt_lock_memory || cfg->rt_prefault) {
    char rt[160];
    rt_describe(rt, sizeof rt);
    fprintf(stderr, "b21r-controller: real time: %s%s%s\n", rt, cfg->rt_lock_memory ? ", memory locked" : "",
            cfg->rt_prefault ? ", buffers pre-faulted" : "");
  }
  return 0;
}

static void publisher_notify(void* user) { fw_publisher_notify((fw_publisher_t*)user); }

// ---- the tick loop and the service manager ---------------------------------------------------

// Test fault B21R_TEST_HANG_AFTER_TICKS=N (docs/robot.md): the tick thread blocks for good after
// tick N's command, as a tick stuck in a driver or a bug would; signals are taken and ignored. It
// shows that the watchdog pings stop and that the base's own command timeout stops the robot.
static int64_t test_hang_after_ticks(char* err, size_t err_cap) {
  const char* v = getenv("B21R_TEST_HANG_AFTER_TICKS");
  if (v == NULL || *v == '\0') {
    return 0;
  }
  char* end = NULL;
  errno = 0;
  const long long n = strtoll(v, &end, 10);
  if (errno != 0 || end == v || *end != '\0' || n < 1) {
    snprintf(err, err_cap, "B21R_TEST_HANG_AFTER_TICKS='%s' is not a positive tick count (a test setting: unset it)", v);
    return -1;
  }
  return (int64_t)n;
}

static void test_hang(int64_t tick) {
  fprintf(stderr, "b21r-controller: test fault: the tick thread hangs after tick %lld (B21R_TEST_HANG_AFTER_TICKS)\n",
          (long long)tick);
  for (;;) {
    pause();
  }
}

// fw_loop_run's loop, with the service manager told of it (drivers/notify.h): READY=1 once the
// devices are open and the first tick is done, WATCHDOG=1 at half the manager's interval. Both go
// after fw_loop_tick has sent the tick's command, and never wait. Returns the exit status.
static int run_ticks(fw_loop_t* loop, const fw_config_t* cfg, drv_notify_t* notify, int64_t hang_after) {
  for (int64_t ticks = 1;; ++ticks) {
    const bool more = fw_loop_tick(loop, fw_loop_wait(loop));
    if (ticks == hang_after) {
      test_hang(ticks);
    }
    if (ticks == 1) {
      char status[600];
      snprintf(status, sizeof status, "running: laser %s, base %s", cfg->laser_device,
               cfg->base_protocol == FW_BASE_RFLEX ? cfg->base_device
                                                   : (cfg->can_socket[0] != '\0' ? cfg->can_socket : cfg->can_interface));
      (void)drv_notify_ready(notify, io_posix_now_us(), status);
    } else {
      (void)drv_notify_tick(notify, io_posix_now_us());
    }
    if (!more) {
      break;
    }
  }
  fw_loop_stats_t st;
  fw_loop_get_stats(loop, &st);
  return st.exit_status;
}

int main(int argc, char** argv) {
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  char err[FW_LOOP_ERR_MAX];
  bool print_config = false;

  // Pass 1: config files, in order; pass 2: everything else, in order.
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--help") == 0 || strcmp(argv[i], "-h") == 0) {
      usage(stdout);
      return 0;
    }
    if (strcmp(argv[i], "--print-reference-config") == 0) {
      fw_config_print_reference(stdout);
      return 0;
    }
    if (strcmp(argv[i], "--print-task-params") == 0) {
      fw_config_print_task_params(stdout);
      return 0;
    }
    if (strcmp(argv[i], "--config") == 0) {
      if (i + 1 >= argc) {
        fprintf(stderr, "b21r-controller: --config needs a file\n");
        return EXIT_USAGE;
      }
      if (fw_config_load_file(&cfg, argv[++i], err, sizeof err) != 0) {
        fprintf(stderr, "b21r-controller: %s\n", err);
        return EXIT_USAGE;
      }
    }
  }
  for (int i = 1; i < argc; ++i) {
    const char* a = argv[i];
    const char* v = i + 1 < argc ? argv[i + 1] : NULL;
    int rc = 0;
    if (strcmp(a, "--config") == 0) {
      ++i;
    } else if (strcmp(a, "--print-config") == 0) {
      print_config = true;
    } else if (v == NULL && (strcmp(a, "--set") == 0 || strcmp(a, "--endpoints") == 0 ||
                             strcmp(a, "--checkpoint") == 0 || strcmp(a, "--log") == 0 ||
                             strcmp(a, "--experience-log") == 0)) {
      fprintf(stderr, "b21r-controller: %s needs an argument (see --help)\n", a);
      return EXIT_USAGE;
    } else if (strcmp(a, "--set") == 0) {
      rc = fw_config_set_arg(&cfg, v, err, sizeof err);
      ++i;
    } else if (strcmp(a, "--endpoints") == 0) {
      rc = fw_endpoints_apply(&cfg, v, err, sizeof err);
      ++i;
    } else if (strcmp(a, "--checkpoint") == 0) {
      rc = fw_config_set(&cfg, "checkpoint_file", v, a, err, sizeof err);
      ++i;
    } else if (strcmp(a, "--log") == 0) {
      rc = fw_config_set(&cfg, "log_file", v, a, err, sizeof err);
      ++i;
    } else if (strcmp(a, "--experience-log") == 0) {
      rc = fw_config_set(&cfg, "experience_log_file", v, a, err, sizeof err);
      ++i;
    } else {
      fprintf(stderr, "b21r-controller: unknown argument '%s' (see --help)\n", a);
      return EXIT_USAGE;
    }
    if (rc != 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
      return EXIT_USAGE;
    }
  }
  if (fw_config_validate_program(&cfg, err, sizeof err) != 0) {
    fprintf(stderr, "b21r-controller: %s\n", err);
    return EXIT_USAGE;
  }
  if (print_config) {
    fw_config_print(&cfg, stdout);
    return 0;
  }
  // The service manager (systemd, Type=notify) and the test fault, before anything is opened.
  drv_notify_t notify;
  const int64_t hang_after = test_hang_after_ticks(err, sizeof err);
  if (hang_after < 0 || drv_notify_open(&notify, getenv("NOTIFY_SOCKET"), getenv("WATCHDOG_USEC"),
                                        getenv("WATCHDOG_PID"), getpid(), err, sizeof err) != 0) {
    fprintf(stderr, "b21r-controller: %s\n", err);
    return EXIT_USAGE;
  }
  if (hang_after > 0) {
    fprintf(stderr, "b21r-controller: warning: B21R_TEST_HANG_AFTER_TICKS=%lld: a test fault is armed\n",
            (long long)hang_after);
  }
  if (notify.watchdog_us > 0) {
    fprintf(stderr, "b21r-controller: service watchdog %.3f s: pinged every %.3f s after the tick's command\n",
            (double)notify.watchdog_us / 1e6, (double)notify.watchdog_us / 2e6);
  }

  // Signals: stop the base, brake, checkpoint, exit (handled by the tick).
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  signal(SIGPIPE, SIG_IGN);

  // LCM: the URL against lcm_scope, the operator key and the session (operator_rx.h), then LCM.
  lcm_t* lcm = NULL;
  static operator_rx_t rx;  // static: the loop reads its counters until the very end
  if (strcmp(cfg.lcm_url, "none") != 0) {
    const char* url = NULL;
    if (operator_rx_prepare(&rx, &cfg, &url, err, sizeof err) != 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
      return EXIT_USAGE;
    }
    lcm = lcm_create(url);
    if (lcm == NULL) {
      fprintf(stderr,
              "b21r-controller: cannot open LCM at '%s' (multicast needs a route: e.g. ip route add 224.0.0.0/4 dev "
              "lo; or set lcm_url = none)\n",
              url);
      return EXIT_DEVICE;
    }
  }
  fw_pubq_t* q = fw_pubq_create((uint32_t)cfg.queue_capacity);
  const fw_publisher_config_t pc = {.lcm = lcm, .log_file = cfg.log_file, .experience_log_file = cfg.experience_log_file};
  fw_publisher_t* pub = q != NULL ? fw_publisher_create(q, &pc, err, sizeof err) : NULL;
  if (pub == NULL) {
    fprintf(stderr, "b21r-controller: %s\n", q == NULL ? "out of memory" : err);
    return EXIT_DEVICE;
  }

  // The loop and the checkpoint first: a bad checkpoint is refused before any device is touched.
  io_posix_t io;
  io_posix_init(&io, &cfg);
  const fw_io_t binding = io_posix_binding(&io);
  const fw_loop_outputs_t out = {
      .queue = q, .notify = publisher_notify, .notify_user = pub, .checkpoints = NULL, .publisher = pub,
      .operator_auth = lcm != NULL ? &rx.auth : NULL};
  fw_loop_t* loop = fw_loop_create(&cfg, &binding, &out, err, sizeof err);
  if (loop == NULL) {
    fprintf(stderr, "b21r-controller: %s\n", err);
    fw_publisher_destroy(pub);
    return EXIT_USAGE;
  }
  fw_ckpt_writer_t* ckpt = NULL;
  int status = 0;
  if (cfg.checkpoint_file[0] != '\0') {
    const int r = fw_loop_load_checkpoint(loop, err, sizeof err);
    if (r < 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
      status = EXIT_CHECKPOINT;
    } else {
      fw_loop_stats_t st;
      fw_loop_get_stats(loop, &st);
      fprintf(stderr, "b21r-controller: %s %s (phase %d, %d training runs, %d evaluation blocks, %u samples)\n",
              r == 1 ? "resumed from" : "no checkpoint yet at", cfg.checkpoint_file, st.phase, st.training_runs,
              st.eval_blocks, st.store_fill);
      if (r == 1 && err[0] != '\0') {
        fprintf(stderr, "b21r-controller: %s\n", err);
      }
      size_t meta_cap = 0;
      size_t payload_cap = 0;
      fw_loop_checkpoint_capacity(loop, &meta_cap, &payload_cap);
      ckpt = fw_ckpt_writer_create(cfg.checkpoint_file, meta_cap, payload_cap, err, sizeof err);
      if (ckpt == NULL) {
        fprintf(stderr, "b21r-controller: %s\n", err);
        status = EXIT_CHECKPOINT;
      }
      fw_loop_attach_checkpoints(loop, ckpt);
    }
  } else {
    fprintf(stderr, "b21r-controller: warning: checkpoint_file is not set: learned data is lost at exit\n");
  }
  if (status == 0 && io_posix_open(&io, err, sizeof err) != 0) {
    fprintf(stderr, "b21r-controller: %s\n", err);
    status = EXIT_DEVICE;
  }

  if (status == 0 && lcm != NULL && operator_rx_start(&rx, lcm, loop, pub, err, sizeof err) != 0) {
    fprintf(stderr, "b21r-controller: %s\n", err);
    status = EXIT_DEVICE;
  }

  if (status == 0) {
    g_io = &io;
    g_loop = loop;
    fprintf(stderr, "b21r-controller: starting devices (laser %s, base %s %s)%s\n", cfg.laser_device,
            cfg.base_protocol == FW_BASE_RFLEX ? "rflex" : "canopen",
            cfg.base_protocol == FW_BASE_RFLEX ? cfg.base_device
                                                : (cfg.can_socket[0] != '\0' ? cfg.can_socket : cfg.can_interface),
            cfg.lockstep ? ", lockstep" : "");
    // Real-time provisions of the tick thread (this one), after the helper threads exist.
    int start_rc = 0;
    if (apply_realtime(&cfg, loop, &io, err, sizeof err) != 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
      status = EXIT_USAGE;
    } else if ((start_rc = fw_loop_start(loop, err, sizeof err)) != 0) {
      fprintf(stderr, "b21r-controller: %s\n", err);
      fw_loop_stats_t st;
      fw_loop_get_stats(loop, &st);
      status = start_rc == FW_LOOP_START_SIGNALLED ? st.exit_status : EXIT_DEVICE;
    } else {
      status = run_ticks(loop, &cfg, &notify, hang_after);
    }
    char stopping[64];
    snprintf(stopping, sizeof stopping, status > 128 ? "stopping: signal %d" : "stopping: exit status %d",
             status > 128 ? status - 128 : status);
    (void)drv_notify_stopping(&notify, stopping);
    if (fw_loop_shutdown(loop) != 0 && status == 0) {
      fprintf(stderr, "b21r-controller: the final checkpoint could not be written\n");
      status = EXIT_CHECKPOINT;
    }
  }

  if (lcm != NULL) {
    operator_rx_stop(&rx);
  }
  g_loop = NULL;
  g_io = NULL;
  fw_publisher_flush(pub);
  fw_publisher_destroy(pub);
  fw_ckpt_writer_destroy(ckpt);
  fw_loop_destroy(loop);
  fw_pubq_destroy(q);
  io_posix_close(&io);
  if (lcm != NULL) {
    lcm_destroy(lcm);
  }
  drv_notify_close(&notify);
  return status;
}
