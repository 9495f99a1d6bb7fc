// SPDX-License-Identifier: MIT
// The onboard I/O binding: device drivers over file descriptors, poll(), CLOCK_MONOTONIC.
#define _GNU_SOURCE 1
#include "io_posix.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

int64_t io_posix_now_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

// ---- device loss and reopening ---------------------------------------------------------------

// Errors that mean the device itself is gone (unplugged adapter, closed pseudo-terminal, the bus
// server exited), as opposed to a transient failure.
static bool is_loss(int neg_errno) {
  switch (-neg_errno) {
    case EPIPE:
    case EIO:
    case ENODEV:
    case ENXIO:
    case EBADF:
    case ECONNRESET:
    case ENOTCONN:
      return true;
    default:
      return false;
  }
}

static const char* cause_name(int neg_errno) {
  switch (-neg_errno) {
    case EPIPE:
      return "hang-up";
    case EIO:
      return "EIO";
    case ENODEV:
      return "ENODEV";
    case ENXIO:
      return "ENXIO";
    case EBADF:
      return "EBADF";
    case ECONNRESET:
      return "connection reset";
    case ENOTCONN:
      return "not connected";
    default:
      return "error";
  }
}

static int64_t backoff_initial_us(const io_posix_t* io) { return (int64_t)(io->cfg->device_reopen_backoff_s * 1e6); }

// Closes the device's descriptor and schedules the first reopen attempt.
static void lose(io_posix_t* io, io_posix_device_t* d, const char* cause, int64_t now_us) {
  if (d->lost) {
    return;
  }
  if (d == &io->laser) {
    drv_serial_close(&io->laser_port);  // the port lets go; the helper thread closes the line
    drv_serial_link_close(io->laser_link);
  } else if (io->use_can) {
    // Carried over (the reopened port counts from zero) and taken off the closed port at once: a
    // STATUS between now and the reopen must not count them twice.
    io->can_before.error_frames += io->can.counters.rx_error_frames;
    io->can.counters.rx_error_frames = 0;
    drv_can_close(&io->can);
    io->can_out_n = 0;
  } else {
    drv_serial_close(&io->base_port);
    drv_serial_link_close(io->base_link);
  }
  d->lost = true;
  d->opening = false;
  d->losses++;
  snprintf(d->cause, sizeof d->cause, "%s", cause);
  d->backoff_us = backoff_initial_us(io);
  d->retry_at_us = now_us + d->backoff_us;
}

// The laser driver on the laser line, once its helper thread has opened it: a new link, so the
// driver finds the LMS200's rate and starts its stream from the beginning.
static int attach_laser(io_posix_t* io, char* err, size_t err_cap) {
  io->laser_before.bytes_dropped += io->lms.decoder.counters.bytes_dropped;
  io->laser_before.crc_errors += io->lms.decoder.counters.bad_crc;
  io->laser_before.restarts += io->lms.counters.restarts;
  memset(&io->lms.decoder.counters, 0, sizeof io->lms.decoder.counters);
  memset(&io->lms.counters, 0, sizeof io->lms.counters);
  if (drv_serial_use_link(&io->laser_port, io->laser_link) != 0 ||
      drv_lms_init(&io->lms, &io->laser_port, &io->lms_config) != 0) {
    snprintf(err, err_cap, "invalid driver settings (baud %d, %d deg, %d cdeg)", (int)io->cfg->laser_baud,
             (int)io->cfg->laser_fov_deg, (int)io->cfg->laser_resolution_cdeg);
    drv_serial_close(&io->laser_port);
    drv_serial_link_close(io->laser_link);
    return -1;
  }
  return 0;
}

static int attach_base(io_posix_t* io) {
  if (drv_serial_use_link(&io->base_port, io->base_link) != 0) {
    return -1;
  }
  // The rFLEX loses bytes when fed too fast: a pause after each packet (protocols.md A.1).
  drv_serial_set_pacing(&io->base_port, 0, (uint32_t)io->cfg->base_write_gap_us, 0);
  return 0;
}

static drv_serial_link_t* link_of(io_posix_t* io, const io_posix_device_t* d) {
  return d == &io->laser ? io->laser_link : (io->use_can ? NULL : io->base_link);
}

static int open_can(io_posix_t* io, char* err, size_t err_cap) {
  const fw_config_t* cfg = io->cfg;
  return (cfg->can_socket[0] != '\0' ? drv_can_open_seqpacket(&io->can, cfg->can_socket, err, err_cap)
                                      : drv_can_open_socketcan(&io->can, cfg->can_interface, err, err_cap)) == 0
             ? 0
             : -1;
}

static void backoff(io_posix_t* io, io_posix_device_t* d, int64_t now_us) {
  const int64_t max_us = (int64_t)(io->cfg->device_reopen_backoff_max_s * 1e6);
  d->backoff_us = d->backoff_us * 2 < max_us ? d->backoff_us * 2 : max_us;
  d->retry_at_us = now_us + d->backoff_us;
}

static void reopened(io_posix_device_t* d) {
  d->lost = false;
  d->reopened = true;
  d->reopens++;
}

// One reopen attempt when its time has come; the back-off doubles after each failure. A serial
// line is opened by its helper thread: the request goes out in one tick, the result is taken in
// a later one.
static void try_reopen(io_posix_t* io, io_posix_device_t* d, int64_t now_us) {
  if (!d->lost) {
    return;
  }
  drv_serial_link_t* link = link_of(io, d);
  if (d->opening) {
    const drv_serial_link_state_t st = drv_serial_link_state(link, NULL, NULL, NULL, 0);
    if (st == DRV_SERIAL_LINK_OPENING) {
      return;
    }
    d->opening = false;
    char e[256];
    if (st == DRV_SERIAL_LINK_OPEN && (d == &io->laser ? attach_laser(io, e, sizeof e) : attach_base(io)) == 0) {
      reopened(d);
      return;
    }
    backoff(io, d, now_us);
    return;
  }
  if (now_us < d->retry_at_us) {
    return;
  }
  if (link != NULL) {
    drv_serial_link_open(link, d->path, d == &io->laser ? (uint32_t)io->cfg->laser_start_baud
                                                        : (uint32_t)io->cfg->base_baud);
    d->opening = true;
    return;
  }
  char e[256];
  if (open_can(io, e, sizeof e) != 0) {
    backoff(io, d, now_us);
    return;
  }
  reopened(d);
}

static void check_result(io_posix_t* io, io_posix_device_t* d, int rc) {
  if (rc < 0 && is_loss(rc)) {
    lose(io, d, cause_name(rc), io_posix_now_us());
  }
}

static void v_health(void* user, int64_t now_us, bool reopen, fw_io_health_t* out) {
  io_posix_t* io = (io_posix_t*)user;
  memset(out, 0, sizeof *out);
  io_posix_device_t* devs[2] = {&io->laser, &io->base};
  const uint32_t bits[2] = {FW_IO_DEVICE_LASER, FW_IO_DEVICE_BASE};
  for (int i = 0; i < 2; ++i) {
    if (reopen) {
      try_reopen(io, devs[i], now_us);
    }
    if (devs[i]->reopened) {
      devs[i]->reopened = false;
      out->reopened |= bits[i];
    }
    if (devs[i]->lost) {
      if (out->lost == 0U) {
        snprintf(out->detail, sizeof out->detail, "%s %s lost: %s (%s)", devs[i]->what,
                 devs[i] == &io->base && io->use_can ? "bus" : "device", devs[i]->path, devs[i]->cause);
      }
      out->lost |= bits[i];
    }
  }
  out->output_overflows = (uint32_t)(io->overflows - io->overflows_reported);
  io->overflows_reported = io->overflows;
}

// ---- base output queues ------------------------------------------------------------------------

static void can_flush(io_posix_t* io) {
  while (io->can_out_n > 0U && io->can.fd >= 0) {
    const int rc = drv_can_send(&io->can, &io->can_out[io->can_out_head]);
    if (rc == -EAGAIN) {
      return;
    }
    // Sent, or refused for good (an invalid frame cannot become valid): either way it leaves.
    io->can_out_head = (io->can_out_head + 1U) % IO_POSIX_CAN_OUT;
    io->can_out_n--;
    if (rc < 0) {
      check_result(io, &io->base, rc);
    }
  }
}

static void flush_output(io_posix_t* io, int64_t now_us) {
  if (io->use_can) {
    can_flush(io);
  } else if (drv_serial_out_pending(&io->base_port)) {
    check_result(io, &io->base, drv_serial_flush(&io->base_port, (uint64_t)now_us));
  }
}

// ---- the binding -------------------------------------------------------------------------------

static int64_t v_now(void* user) {
  (void)user;
  return io_posix_now_us();
}

// The tick's wait: the helper threads' eventfd (input arrived, a line hung up), the CAN socket
// (a socket's poll does not involve the tty worker), and timers: the deadline, the rFLEX pause
// between packets, and a 1 ms retry when the line did not take a packet (never a poll() on a
// terminal: see drivers/serial.h).
static int v_wait(void* user, int64_t deadline_us) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->tick_note_taken) {
    io->tick_note_taken = false;  // a helper's news came during a start-pose wait: read it now
    return 1;
  }
  int64_t now = io_posix_now_us();
  flush_output(io, now);
  int64_t wake_us = deadline_us;
  short can_events = POLLIN;
  if (io->use_can ? io->can_out_n > 0U : drv_serial_out_pending(&io->base_port)) {
    if (io->use_can) {
      can_events |= POLLOUT;
    } else {
      // Still pending after the pause between packets: the line was full; try again in 1 ms.
      const int64_t quiet = (int64_t)io->base_port.out.quiet_until_us;
      const int64_t ready = quiet > now ? quiet : now + 1000;
      wake_us = ready < wake_us ? ready : wake_us;
    }
  }
  // A lost CAN bus has fd -1, which poll() ignores: nothing spins on a closed socket.
  struct pollfd fds[2] = {{.fd = io->tick_fd, .events = POLLIN},
                          {.fd = io->use_can ? io->can.fd : -1, .events = can_events}};
  const int64_t left_us = wake_us - now;
  if (left_us <= 0) {
    return 0;
  }
  const struct timespec timeout = {.tv_sec = (time_t)(left_us / 1000000), .tv_nsec = (long)(left_us % 1000000) * 1000L};
  const int r = ppoll(fds, 2, &timeout, NULL);
  if (r < 0) {
    return errno == EINTR ? 1 : -errno;
  }
  now = io_posix_now_us();
  if ((fds[0].revents & POLLIN) != 0) {
    uint64_t v = 0;
    (void)!read(io->tick_fd, &v, sizeof v);
  }
  // A hang-up or error stays set on the socket: close it now, or every later poll() returns at once.
  if (fds[1].fd >= 0 && (fds[1].revents & (POLLHUP | POLLERR | POLLNVAL)) != 0) {
    lose(io, &io->base, (fds[1].revents & POLLHUP) != 0 ? "hang-up" : "poll error", now);
  } else if ((fds[1].revents & POLLOUT) != 0) {
    flush_output(io, now);
  }
  return r > 0 ? 1 : 0;
}

// In lockstep, once scans flow, a quiet stream means the emulator has not been scheduled (a
// loaded machine can stall it for seconds), not a lost scanner: restarting the stream mid-period
// desynchronises the lockstep. The loop decides silence there (lockstep_timeout_s ends it, naming
// the device), so from the first scan on the driver's own stream timeout waits a second longer.
// Before it, the driver's short timeout stays: a restart is how a start-up recovers.
static void lockstep_stream_patience(io_posix_t* io) {
  const double s_us = (io->cfg->lockstep_timeout_s + 1.0) * 1e6;
  io->lms.config.stream_timeout_us = s_us < 4.0e9 ? (uint32_t)s_us : 4000000000U;
}

static int v_laser_poll(void* user, int64_t now_us, lms_scan_t* out) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->laser.lost) {
    return 0;
  }
  bool got = false;
  io->laser_port.last_error = 0;
  (void)drv_lms_step(&io->lms, (uint64_t)now_us, out, &got);
  check_result(io, &io->laser, io->laser_port.last_error);
  if (got && io->cfg->lockstep && io->lms.config.stream_timeout_us == io->lms_config.stream_timeout_us) {
    lockstep_stream_patience(io);
  }
  return got ? 1 : 0;
}

static void v_laser_stats(void* user, fw_laser_stats_t* out) {
  const io_posix_t* io = (const io_posix_t*)user;
  out->bytes_dropped = io->laser_before.bytes_dropped + io->lms.decoder.counters.bytes_dropped;
  out->crc_errors = io->laser_before.crc_errors + io->lms.decoder.counters.bad_crc;
  out->restarts = io->laser_before.restarts + io->lms.counters.restarts;
}

static void v_laser_stop(void* user) {
  io_posix_t* io = (io_posix_t*)user;
  if (!io->laser.lost) {
    (void)drv_lms_stop_stream(&io->lms);
  }
}

static ssize_t v_base_read(void* user, uint8_t* buf, size_t cap) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->base.lost) {
    return 0;
  }
  const ssize_t n = drv_serial_read(&io->base_port, buf, cap);
  check_result(io, &io->base, (int)n);
  return n;
}

static int v_base_write(void* user, const uint8_t* buf, size_t n) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->base.lost) {
    return -ENODEV;
  }
  const int rc = drv_serial_queue(&io->base_port, buf, n, (uint64_t)io_posix_now_us());
  if (rc == -ENOBUFS) {
    io->overflows++;
  }
  check_result(io, &io->base, rc);
  return rc;
}

static int v_can_read(void* user, canopen_frame_t* frame) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->base.lost) {
    return 0;
  }
  const int rc = drv_can_recv(&io->can, frame);
  check_result(io, &io->base, rc);
  return rc;
}

static void v_can_stats(void* user, fw_can_stats_t* out) {
  const io_posix_t* io = (const io_posix_t*)user;
  out->error_frames = io->can_before.error_frames + io->can.counters.rx_error_frames;
  out->bus_off = io->can.bus_off;
}

static int v_can_write(void* user, const canopen_frame_t* frame) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->base.lost) {
    return -ENODEV;
  }
  can_flush(io);  // order: older frames first
  if (io->can_out_n == 0U) {
    const int rc = drv_can_send(&io->can, frame);
    if (rc != -EAGAIN) {
      check_result(io, &io->base, rc);
      return rc;
    }
  }
  if (io->can_out_n == IO_POSIX_CAN_OUT) {
    io->overflows++;
    return -ENOBUFS;
  }
  io->can_out[(io->can_out_head + io->can_out_n) % IO_POSIX_CAN_OUT] = *frame;
  io->can_out_n++;
  return 0;
}

// ---- the emulator's control socket -----------------------------------------------------------

static int connect_control(const char* path, char* err, size_t err_cap) {
  const int fd = socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    snprintf(err, err_cap, "emulator_control %s: socket: %s", path, strerror(errno));
    return -1;
  }
  struct sockaddr_un addr;
  memset(&addr, 0, sizeof addr);
  addr.sun_family = AF_UNIX;
  if (strlen(path) >= sizeof addr.sun_path) {
    snprintf(err, err_cap, "emulator_control %s: path too long for a unix socket", path);
    close(fd);
    return -1;
  }
  strcpy(addr.sun_path, path);
  if (connect(fd, (const struct sockaddr*)&addr, sizeof addr) != 0) {
    snprintf(err, err_cap, "emulator_control %s: cannot connect: %s (is b21r-sim running with --control %s?)", path,
             strerror(errno), path);
    close(fd);
    return -1;
  }
  return fd;
}

static void drop_control(io_posix_t* io) {
  if (io->control_fd >= 0) {
    close(io->control_fd);
  }
  io->control_fd = -1;
  io->request_pending = false;
  io->stale_replies = 0;
}

enum { REPLY_WOKEN = 2 };  // read_reply: a stop signal ended the wait (io_posix_wake)

// Reads one answer if there is one, waiting up to timeout_ms for it (0: never waits). 1 "ok",
// 0 none yet, REPLY_WOKEN a stop signal came first, < 0 error. The wait also watches the tick's
// eventfd, so that a signal handler on any thread ends it; a helper's news read there meanwhile
// is handed on to the next v_wait (tick_note_taken).
static int read_reply(io_posix_t* io, int timeout_ms) {
  const int64_t end_us = io_posix_now_us() + (int64_t)timeout_ms * 1000;
  for (;;) {
    if (timeout_ms > 0 && io->woken) {
      return REPLY_WOKEN;
    }
    const int64_t left_us = end_us - io_posix_now_us();
    struct pollfd pfd[2] = {{.fd = io->control_fd, .events = POLLIN},
                            {.fd = timeout_ms > 0 ? io->tick_fd : -1, .events = POLLIN}};
    const int pr = poll(pfd, 2, left_us > 0 ? (int)((left_us + 999) / 1000) : 0);
    if (pr < 0 && errno == EINTR) {
      continue;  // a signal: io->woken says whether it was a stop
    }
    if ((pfd[1].revents & POLLIN) != 0) {
      uint64_t v = 0;
      (void)!read(io->tick_fd, &v, sizeof v);
      io->tick_note_taken = true;
    }
    if (pr > 0 && (pfd[0].revents & (POLLIN | POLLHUP | POLLERR)) == 0) {
      continue;  // only the eventfd: wait on for the answer (or see the stop above)
    }
    if (pr == 0) {
      return 0;
    }
    char reply[256];
    const ssize_t r = pr < 0 ? -1 : recv(io->control_fd, reply, sizeof reply - 1, MSG_DONTWAIT);
    if (r < 0 && (errno == EAGAIN || errno == EINTR)) {
      return 0;
    }
    if (r <= 0) {
      drop_control(io);  // the emulator went away: reconnect with the next request
      return -3;
    }
    if (io->stale_replies > 0U) {
      io->stale_replies--;  // the answer to a request that already timed out
      continue;
    }
    reply[r] = '\0';
    return strncmp(reply, "ok", 2) == 0 ? 1 : -4;
  }
}

// Emulator binding of "place the robot": `reset x y theta` on the control socket. Real time: the
// request is sent in one tick and its answer read in a later one (2 meanwhile). Lockstep: the
// answer is awaited at once and as long as the period's data are (lockstep_timeout_s): a stalled
// emulator must not turn the request into a retry that starts the run at another tick. A stop
// signal ends that wait (2: under way; the tick then stops).
static int v_request_start_pose(void* user, double x_m, double y_m, double theta_rad, uint64_t run) {
  io_posix_t* io = (io_posix_t*)user;
  const fw_config_t* cfg = io->cfg;
  if (cfg->reposition != FW_REPOSITION_EMULATOR) {
    return 0;  // a person places the robot and confirms over B21R_COMMAND
  }
  const int64_t now = io_posix_now_us();
  const int64_t timeout_us =
      (int64_t)((cfg->lockstep ? cfg->lockstep_timeout_s : cfg->emulator_reply_timeout_s) * 1e6);
  if (io->control_fd < 0) {
    char e[256];
    io->control_fd = connect_control(cfg->emulator_control, e, sizeof e);
    if (io->control_fd < 0) {
      return -5;
    }
  }
  const double pose[3] = {x_m, y_m, theta_rad};
  if (io->request_pending && memcmp(pose, io->request_pose, sizeof pose) != 0) {
    io->stale_replies++;  // a different pose is wanted now: forget the old request
    io->request_pending = false;
  }
  if (!io->request_pending) {
    char line[128];
    // 17 significant digits: the emulator parses back the exact double, so the pty path and the
    // in-process path place the robot at bit-identical poses.
    const int n = snprintf(line, sizeof line, "reset %.17g %.17g %.17g %llu", x_m, y_m, theta_rad,
                           (unsigned long long)run);
    if (send(io->control_fd, line, (size_t)n, MSG_NOSIGNAL | MSG_DONTWAIT) != n) {
      drop_control(io);
      return -1;
    }
    io->request_pending = true;
    memcpy(io->request_pose, pose, sizeof pose);
    io->request_sent_us = now;
  }
  const int r = read_reply(io, cfg->lockstep ? (int)((timeout_us + 999) / 1000) : 0);
  if (r == REPLY_WOKEN) {
    return 2;  // still under way: the tick that comes stops for the signal, no retry is logged
  }
  if (r != 0) {
    io->request_pending = false;
    return r;
  }
  if (now - io->request_sent_us >= timeout_us || cfg->lockstep) {
    io->request_pending = false;
    io->stale_replies++;
    return -2;
  }
  return 2;
}

static const fw_io_vtable_t k_vt_rflex = {
    .now_us = v_now,
    .wait = v_wait,
    .laser_poll = v_laser_poll,
    .laser_stats = v_laser_stats,
    .laser_stop = v_laser_stop,
    .base_read = v_base_read,
    .base_write = v_base_write,
    .can_read = NULL,
    .can_write = NULL,
    .request_start_pose = v_request_start_pose,
    .health = v_health,
};

static const fw_io_vtable_t k_vt_can = {
    .now_us = v_now,
    .wait = v_wait,
    .laser_poll = v_laser_poll,
    .laser_stats = v_laser_stats,
    .laser_stop = v_laser_stop,
    .base_read = NULL,
    .base_write = NULL,
    .can_read = v_can_read,
    .can_stats = v_can_stats,
    .can_write = v_can_write,
    .request_start_pose = v_request_start_pose,
    .health = v_health,
};

fw_io_t io_posix_binding(io_posix_t* io) {
  const fw_io_t b = {io->use_can ? &k_vt_can : &k_vt_rflex, io};
  return b;
}

void io_posix_init(io_posix_t* io, const fw_config_t* cfg) {
  memset(io, 0, sizeof *io);
  io->cfg = cfg;
  io->laser_port.fd = -1;
  io->base_port.fd = -1;
  io->can.fd = -1;
  io->control_fd = -1;
  io->tick_fd = -1;
  io->use_can = cfg->base_protocol != FW_BASE_RFLEX;
  io->laser = (io_posix_device_t){.what = "laser", .path = cfg->laser_device};
  io->base = (io_posix_device_t){.what = io->use_can ? "CAN" : "base",
                                 .path = io->use_can ? (cfg->can_socket[0] != '\0' ? cfg->can_socket : cfg->can_interface)
                                                     : cfg->base_device};
  drv_lms_config_default(&io->lms_config);
  io->lms_config.target_baud = (uint32_t)cfg->laser_baud;
  io->lms_config.width_deg = (uint16_t)cfg->laser_fov_deg;
  io->lms_config.res_cdeg = (uint16_t)cfg->laser_resolution_cdeg;
  io->lms_config.unit = LMS_UNIT_MM;
}


// The helper threads tell the tick thread of news (from their threads: never blocks).
static void notify_tick(void* user) {
  io_posix_t* io = (io_posix_t*)user;
  const uint64_t one = 1;
  (void)!write(io->tick_fd, &one, sizeof one);
}

void io_posix_wake(io_posix_t* io) {
  io->woken = 1;
  if (io->tick_fd >= 0) {
    notify_tick(io);
  }
}

// Start-up (not a tick): a serial line opened by its helper thread, waited for.
static int open_line(drv_serial_link_t* link, const char* path, uint32_t baud, char* err, size_t err_cap) {
  drv_serial_link_open(link, path, baud);
  const int64_t end = io_posix_now_us() + 10000000;
  for (;;) {
    int e = 0;
    const drv_serial_link_state_t st = drv_serial_link_state(link, NULL, &e, err, err_cap);
    if (st == DRV_SERIAL_LINK_OPEN) {
      return 0;
    }
    if (st == DRV_SERIAL_LINK_FAILED) {
      return -1;
    }
    if (io_posix_now_us() > end) {
      snprintf(err, err_cap, "serial: opening %s did not finish within 10 s", path);
      return -1;
    }
    struct pollfd p = {.fd = -1, .events = 0};
    (void)poll(&p, 0, 2);
  }
}

static drv_serial_link_t* start_link(io_posix_t* io, char* err, size_t err_cap) {
  drv_serial_link_t* link = drv_serial_link_create(notify_tick, io);
  if (link == NULL) {
    snprintf(err, err_cap, "out of memory (serial line buffers)");
    return NULL;
  }
  const int rc = drv_serial_link_start(link);
  if (rc != 0) {
    snprintf(err, err_cap, "cannot start a serial line thread: %s", strerror(-rc));
    drv_serial_link_destroy(link);
    return NULL;
  }
  return link;
}

int io_posix_open(io_posix_t* io, char* err, size_t err_cap) {
  const fw_config_t* cfg = io->cfg;
  char e[256];
  io->tick_fd = eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (io->tick_fd < 0) {
    snprintf(err, err_cap, "eventfd: %s", strerror(errno));
    return -1;
  }
  io->laser_link = start_link(io, err, err_cap);
  if (io->laser_link == NULL) {
    io_posix_close(io);
    return -1;
  }
  if (open_line(io->laser_link, cfg->laser_device, (uint32_t)cfg->laser_start_baud, e, sizeof e) != 0 ||
      attach_laser(io, e, sizeof e) != 0) {
    snprintf(err, err_cap, "laser: %s", e);
    io_posix_close(io);
    return -1;
  }
  if (io->use_can) {
    if (open_can(io, e, sizeof e) != 0) {
      snprintf(err, err_cap, "CAN: %s", e);
      io_posix_close(io);
      return -1;
    }
  } else {
    io->base_link = start_link(io, err, err_cap);
    if (io->base_link == NULL) {
      io_posix_close(io);
      return -1;
    }
    if (open_line(io->base_link, cfg->base_device, (uint32_t)cfg->base_baud, e, sizeof e) != 0 ||
        attach_base(io) != 0) {
      snprintf(err, err_cap, "base: %s", e);
      io_posix_close(io);
      return -1;
    }
  }
  if (cfg->reposition == FW_REPOSITION_EMULATOR) {
    io->control_fd = connect_control(cfg->emulator_control, err, err_cap);
    if (io->control_fd < 0) {
      io_posix_close(io);
      return -1;
    }
  }
  return 0;
}

int io_posix_realtime(io_posix_t* io, int policy, int priority, char* err, size_t err_cap) {
  const int below = priority > 1 ? priority - 1 : 1;
  drv_serial_link_t* links[2] = {io->laser_link, io->base_link};
  for (int i = 0; i < 2; ++i) {
    if (links[i] == NULL) {
      continue;
    }
    const int rc = drv_serial_link_set_scheduler(links[i], policy, below);
    if (rc != 0) {
      snprintf(err, err_cap, "serial line thread: real-time priority %d: %s", below, strerror(-rc));
      return -1;
    }
  }
  return 0;
}

// Shutdown only (not a tick): the last commands (zero velocity, brake; the laser's stop request)
// leave before the lines close.
static void drain_output(io_posix_t* io, int timeout_ms) {
  const int64_t end = io_posix_now_us() + (int64_t)timeout_ms * 1000;
  while ((!io->base.lost && (io->use_can ? io->can_out_n > 0U : drv_serial_out_pending(&io->base_port))) ||
         (!io->laser.lost && io->laser_link != NULL && drv_serial_link_busy(io->laser_link))) {
    const int64_t now = io_posix_now_us();
    if (now >= end || v_wait(io, now + 1000 < end ? now + 1000 : end) < 0) {
      return;
    }
    flush_output(io, io_posix_now_us());
  }
}

void io_posix_close(io_posix_t* io) {
  if (io->tick_fd >= 0) {
    drain_output(io, 500);
  }
  drv_serial_close(&io->laser_port);
  drv_serial_close(&io->base_port);
  drv_serial_link_destroy(io->laser_link);  // stops its thread, which closes the line
  drv_serial_link_destroy(io->base_link);
  io->laser_link = NULL;
  io->base_link = NULL;
  drv_can_close(&io->can);
  drop_control(io);
  if (io->tick_fd >= 0) {
    close(io->tick_fd);
    io->tick_fd = -1;
  }
}
