// SPDX-License-Identifier: MIT
// The onboard I/O binding: device drivers over file descriptors, poll(), CLOCK_MONOTONIC.
#define _GNU_SOURCE 1
#include "io_posix.h"

#include <errno.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <time.h>
#include <unistd.h>

int64_t io_posix_now_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000 + ts.tv_nsec / 1000;
}

static int64_t v_now(void* user) {
  (void)user;
  return io_posix_now_us();
}

static int v_wait(void* user, int64_t deadline_us) {
  io_posix_t* io = (io_posix_t*)user;
  struct pollfd fds[2];
  nfds_t n = 0;
  fds[n++] = (struct pollfd){.fd = io->laser_port.fd, .events = POLLIN};
  fds[n++] = (struct pollfd){.fd = io->use_can ? io->can.fd : io->base_port.fd, .events = POLLIN};
  const int64_t left_us = deadline_us - io_posix_now_us();
  if (left_us <= 0) {
    return 0;
  }
  // Round up so that a wait never returns just before its deadline and spins.
  const int timeout_ms = (int)((left_us + 999) / 1000);
  const int r = poll(fds, n, timeout_ms);
  if (r < 0) {
    return errno == EINTR ? 1 : -errno;
  }
  return r > 0 ? 1 : 0;
}

static int v_laser_poll(void* user, int64_t now_us, lms_scan_t* out) {
  io_posix_t* io = (io_posix_t*)user;
  bool got = false;
  (void)drv_lms_step(&io->lms, (uint64_t)now_us, out, &got);
  return got ? 1 : 0;
}

static void v_laser_stats(void* user, fw_laser_stats_t* out) {
  const io_posix_t* io = (const io_posix_t*)user;
  out->bytes_dropped = io->lms.decoder.counters.bytes_dropped;
  out->crc_errors = io->lms.decoder.counters.bad_crc;
  out->restarts = io->lms.counters.restarts;
}

static void v_laser_stop(void* user) {
  io_posix_t* io = (io_posix_t*)user;
  (void)drv_lms_stop_stream(&io->lms);
}

static ssize_t v_base_read(void* user, uint8_t* buf, size_t cap) {
  io_posix_t* io = (io_posix_t*)user;
  const ssize_t n = drv_serial_read(&io->base_port, buf, cap);
  return n;
}

static int v_base_write(void* user, const uint8_t* buf, size_t n) {
  io_posix_t* io = (io_posix_t*)user;
  return drv_serial_write(&io->base_port, buf, n, 100);
}

static int v_can_read(void* user, canopen_frame_t* frame) {
  io_posix_t* io = (io_posix_t*)user;
  return drv_can_recv(&io->can, frame);
}

static int v_can_write(void* user, const canopen_frame_t* frame) {
  io_posix_t* io = (io_posix_t*)user;
  return drv_can_send(&io->can, frame);
}

// Emulator binding of "place the robot": `reset x y theta` on the control socket.
static int v_request_start_pose(void* user, double x_m, double y_m, double theta_rad) {
  io_posix_t* io = (io_posix_t*)user;
  if (io->control_fd < 0) {
    return 0;  // a person places the robot and confirms over B21R_COMMAND
  }
  char line[128];
  // 17 significant digits: the emulator parses back the exact double, so the pty path and the
  // in-process path place the robot at bit-identical poses.
  const int n = snprintf(line, sizeof line, "reset %.17g %.17g %.17g", x_m, y_m, theta_rad);
  if (send(io->control_fd, line, (size_t)n, MSG_NOSIGNAL) != n) {
    return -1;
  }
  struct pollfd pfd = {.fd = io->control_fd, .events = POLLIN};
  if (poll(&pfd, 1, io->reset_timeout_ms) <= 0) {
    return -2;
  }
  char reply[256];
  const ssize_t r = recv(io->control_fd, reply, sizeof reply - 1, 0);
  if (r <= 0) {
    return -3;
  }
  reply[r] = '\0';
  return strncmp(reply, "ok", 2) == 0 ? 1 : -4;
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
    .can_write = v_can_write,
    .request_start_pose = v_request_start_pose,
};

fw_io_t io_posix_binding(io_posix_t* io) {
  const fw_io_t b = {io->use_can ? &k_vt_can : &k_vt_rflex, io};
  return b;
}

static int open_control(io_posix_t* io, const char* path, char* err, size_t err_cap) {
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
  io->control_fd = fd;
  return 0;
}

int io_posix_open(io_posix_t* io, const fw_config_t* cfg, char* err, size_t err_cap) {
  memset(io, 0, sizeof *io);
  io->laser_port.fd = -1;
  io->base_port.fd = -1;
  io->can.fd = -1;
  io->control_fd = -1;
  io->reset_timeout_ms = 5000;
  char e[256];
  if (drv_serial_open(&io->laser_port, cfg->laser_device, (uint32_t)cfg->laser_start_baud, e, sizeof e) != 0) {
    snprintf(err, err_cap, "laser: %s", e);
    return -1;
  }
  drv_lms_config_t lc;
  drv_lms_config_default(&lc);
  lc.target_baud = (uint32_t)cfg->laser_baud;
  lc.width_deg = (uint16_t)cfg->laser_fov_deg;
  lc.res_cdeg = (uint16_t)cfg->laser_resolution_cdeg;
  lc.unit = LMS_UNIT_MM;
  if (cfg->lockstep) {
    // In lockstep a quiet stream means the emulator has not been scheduled (a loaded machine can
    // stall it for seconds), not a lost scanner: restarting the stream mid-period desynchronises
    // the lockstep. The loop decides silence there (lockstep_timeout_s ends it, naming the
    // device), so the driver's own stream timeout waits a second longer.
    const double s_us = (cfg->lockstep_timeout_s + 1.0) * 1e6;
    lc.stream_timeout_us = s_us < 4.0e9 ? (uint32_t)s_us : 4000000000U;
  }
  if (drv_lms_init(&io->lms, &io->laser_port, &lc) != 0) {
    snprintf(err, err_cap, "laser: invalid driver settings (baud %d, %d deg, %d cdeg)", (int)cfg->laser_baud,
             (int)cfg->laser_fov_deg, (int)cfg->laser_resolution_cdeg);
    io_posix_close(io);
    return -1;
  }
  if (cfg->base_protocol == FW_BASE_RFLEX) {
    if (drv_serial_open(&io->base_port, cfg->base_device, (uint32_t)cfg->base_baud, e, sizeof e) != 0) {
      snprintf(err, err_cap, "base: %s", e);
      io_posix_close(io);
      return -1;
    }
    // The rFLEX loses bytes when fed too fast: a pause after each packet (protocols.md A.1).
    drv_serial_set_pacing(&io->base_port, 0, (uint32_t)cfg->base_write_gap_us, 0);
  } else {
    io->use_can = true;
    const int r = cfg->can_socket[0] != '\0' ? drv_can_open_seqpacket(&io->can, cfg->can_socket, e, sizeof e)
                                             : drv_can_open_socketcan(&io->can, cfg->can_interface, e, sizeof e);
    if (r != 0) {
      snprintf(err, err_cap, "CAN: %s", e);
      io_posix_close(io);
      return -1;
    }
  }
  if (cfg->reposition == FW_REPOSITION_EMULATOR && open_control(io, cfg->emulator_control, err, err_cap) != 0) {
    io_posix_close(io);
    return -1;
  }
  return 0;
}

void io_posix_close(io_posix_t* io) {
  drv_serial_close(&io->laser_port);
  drv_serial_close(&io->base_port);
  drv_can_close(&io->can);
  if (io->control_fd >= 0) {
    close(io->control_fd);
    io->control_fd = -1;
  }
}
