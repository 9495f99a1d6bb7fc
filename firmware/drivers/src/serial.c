// SPDX-License-Identifier: MIT
// termios serial port: raw 8N1, non-blocking reads, paced writes.
#define _GNU_SOURCE  // B500000 and friends, nanosleep, poll
#include <drivers/serial.h>

#include "fd_wait.h"

#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

static speed_t speed_of(uint32_t baud) {
  switch (baud) {
    case 9600U:
      return B9600;
    case 19200U:
      return B19200;
    case 38400U:
      return B38400;
    case 57600U:
      return B57600;
    case 115200U:
      return B115200;
    case 230400U:
      return B230400;
    case 500000U:
      return B500000;
    default:
      return B0;
  }
}

bool drv_serial_baud_supported(uint32_t baud) { return speed_of(baud) != B0; }

// Message "serial: <what>: <cause>" into the caller's buffer.
static void set_err(char* err, size_t err_len, const char* what, int e) {
  if (err != NULL && err_len > 0U) {
    snprintf(err, err_len, "serial: %s: %s", what, strerror(e));
  }
}

static void sleep_us(uint32_t us) {
  if (us == 0U) {
    return;
  }
  struct timespec ts = {.tv_sec = (time_t)(us / 1000000U), .tv_nsec = (long)(us % 1000000U) * 1000L};
  while (nanosleep(&ts, &ts) != 0 && errno == EINTR) {
  }
}

// Raw 8N1, no flow control, reads return what is there (VMIN 0, VTIME 0).
static int configure(int fd, uint32_t baud) {
  struct termios tio;
  if (tcgetattr(fd, &tio) != 0) {
    return -errno;
  }
  cfmakeraw(&tio);
  tio.c_cflag &= ~(tcflag_t)(CSIZE | PARENB | CSTOPB | CRTSCTS);
  tio.c_cflag |= (tcflag_t)(CS8 | CLOCAL | CREAD);
  tio.c_iflag &= ~(tcflag_t)(IXON | IXOFF | IXANY);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  const speed_t sp = speed_of(baud);
  if (cfsetispeed(&tio, sp) != 0 || cfsetospeed(&tio, sp) != 0) {
    return -errno;
  }
  if (tcsetattr(fd, TCSANOW, &tio) != 0) {
    return -errno;
  }
  (void)tcflush(fd, TCIOFLUSH);
  return 0;
}

static void port_reset(drv_serial_t* port) {
  memset(port, 0, sizeof *port);
  port->fd = -1;
}

int drv_serial_attach(drv_serial_t* port, int fd, uint32_t baud, bool take_ownership, char* err,
                      size_t err_len) {
  if (port == NULL || fd < 0) {
    return -EINVAL;
  }
  if (!drv_serial_baud_supported(baud)) {
    set_err(err, err_len, "unsupported baud rate", EINVAL);
    return -EINVAL;
  }
  if (!isatty(fd)) {
    const int e = errno != 0 ? errno : ENOTTY;
    set_err(err, err_len, "descriptor is not a terminal", e);
    return -ENOTTY;
  }
  const int flags = fcntl(fd, F_GETFL);
  if (flags < 0 || fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0) {
    const int e = errno;
    set_err(err, err_len, "cannot make descriptor non-blocking", e);
    return -e;
  }
  const int rc = configure(fd, baud);
  if (rc != 0) {
    set_err(err, err_len, "cannot set raw 8N1 mode", -rc);
    return rc;
  }
  port_reset(port);
  port->fd = fd;
  port->owns_fd = take_ownership;
  port->baud = baud;
  return 0;
}

int drv_serial_open(drv_serial_t* port, const char* path, uint32_t baud, char* err, size_t err_len) {
  if (port == NULL || path == NULL) {
    return -EINVAL;
  }
  port_reset(port);
  if (!drv_serial_baud_supported(baud)) {
    if (err != NULL && err_len > 0U) {
      snprintf(err, err_len, "serial: %s: unsupported baud rate %u", path, (unsigned)baud);
    }
    return -EINVAL;
  }
  const int fd = open(path, O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    const int e = errno;
    if (err != NULL && err_len > 0U) {
      snprintf(err, err_len, "serial: cannot open %s: %s", path, strerror(e));
    }
    return -e;
  }
  char sub[128];
  const int rc = drv_serial_attach(port, fd, baud, true, sub, sizeof sub);
  if (rc != 0) {
    if (err != NULL && err_len > 0U) {
      snprintf(err, err_len, "%s (%s)", sub, path);
    }
    close(fd);
    port_reset(port);
    return rc;
  }
  return 0;
}

int drv_serial_set_baud(drv_serial_t* port, uint32_t baud) {
  if (port == NULL || port->fd < 0 || !drv_serial_baud_supported(baud)) {
    return -EINVAL;
  }
  if (port->link != NULL) {
    // The helper thread drains the output and changes the rate, after the requests before it.
    const int rc = port->link_ops->set_baud(port->link, baud);
    if (rc == 0) {
      port->baud = baud;
      port->counters.baud_changes++;
    }
    return rc;
  }
  struct termios tio;
  (void)tcdrain(port->fd);
  if (tcgetattr(port->fd, &tio) != 0) {
    return -errno;
  }
  const speed_t sp = speed_of(baud);
  if (cfsetispeed(&tio, sp) != 0 || cfsetospeed(&tio, sp) != 0 ||
      tcsetattr(port->fd, TCSANOW, &tio) != 0) {
    return -errno;
  }
  port->baud = baud;
  port->counters.baud_changes++;
  return 0;
}

void drv_serial_set_pacing(drv_serial_t* port, uint32_t chunk_bytes, uint32_t chunk_gap_us,
                           uint32_t byte_gap_us) {
  if (port != NULL) {
    port->chunk_bytes = chunk_bytes;
    port->chunk_gap_us = chunk_gap_us;
    port->byte_gap_us = byte_gap_us;
  }
}

ssize_t drv_serial_read(drv_serial_t* port, uint8_t* buf, size_t cap) {
  if (port == NULL || port->fd < 0 || buf == NULL) {
    return -EINVAL;
  }
  if (port->link != NULL) {
    const ssize_t n = port->link_ops->take(port->link, &port->link_flushes, buf, cap);
    if (n > 0) {
      port->counters.bytes_read += (uint64_t)n;
    } else if (n < 0) {
      if (port->last_error == 0) {
        port->counters.read_errors++;
      }
      port->last_error = (int)n;
    }
    return n;
  }
  for (;;) {
    const ssize_t n = read(port->fd, buf, cap);
    if (n > 0) {
      port->counters.bytes_read += (uint64_t)n;
      return n;
    }
    if (n == 0) {
      // A terminal in raw mode with VMIN = VTIME = 0 returns 0 when nothing is there; only a
      // hang-up (e.g. the emulator closed its pseudo-terminal end) tells the two apart.
      struct pollfd pfd = {.fd = port->fd, .events = POLLIN, .revents = 0};
      if (poll(&pfd, 1, 0) > 0 && (pfd.revents & POLLHUP) != 0) {
        port->counters.read_errors++;
        port->last_error = -EPIPE;
        return -EPIPE;
      }
      return 0;
    }
    if (errno == EINTR) {
      continue;
    }
    if (errno == EAGAIN || errno == EWOULDBLOCK) {
      return 0;
    }
    const int e = errno;
    port->counters.read_errors++;
    port->last_error = -e;
    return -e;
  }
}

// Writes n bytes, waiting for room until `end`; 0 or a negative errno.
static int write_some(drv_serial_t* port, const uint8_t* data, size_t n, const struct timespec* end) {
  size_t done = 0;
  while (done < n) {
    const ssize_t w = write(port->fd, data + done, n - done);
    if (w > 0) {
      done += (size_t)w;
      port->counters.bytes_written += (uint64_t)w;
      continue;
    }
    if (w < 0 && errno == EINTR) {
      continue;
    }
    if (w < 0 && errno != EAGAIN && errno != EWOULDBLOCK) {
      const int e = errno;
      port->counters.write_errors++;
      port->last_error = -e;
      return -e;
    }
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    const long long left_ms = (long long)(end->tv_sec - now.tv_sec) * 1000LL +
                              (long long)(end->tv_nsec - now.tv_nsec) / 1000000LL;
    if (left_ms <= 0) {
      port->counters.write_errors++;
      return -ETIMEDOUT;
    }
    struct pollfd pfd = {.fd = port->fd, .events = POLLOUT, .revents = 0};
    (void)poll(&pfd, 1, (int)(left_ms > 1000 ? 1000 : left_ms));
  }
  return 0;
}

int drv_serial_write(drv_serial_t* port, const uint8_t* data, size_t n, int timeout_ms) {
  if (port == NULL || port->fd < 0 || (data == NULL && n > 0U)) {
    return -EINVAL;
  }
  if (port->link != NULL) {
    // Written by the helper thread, with this port's pacing, after the requests before it.
    const int rc = port->link_ops->write(port->link, data, n, port->chunk_gap_us, port->byte_gap_us);
    if (rc == 0) {
      port->counters.bytes_written += (uint64_t)n;
    } else {
      port->counters.write_errors++;
    }
    return rc;
  }
  struct timespec end;
  clock_gettime(CLOCK_MONOTONIC, &end);
  const int t = timeout_ms < 0 ? 0 : timeout_ms;
  end.tv_sec += t / 1000;
  end.tv_nsec += (long)(t % 1000) * 1000000L;
  if (end.tv_nsec >= 1000000000L) {
    end.tv_sec += 1;
    end.tv_nsec -= 1000000000L;
  }
  if (port->byte_gap_us > 0U) {
    // Byte-by-byte spacing: drain each byte so the gap is on the wire, not in the queue.
    for (size_t i = 0; i < n; ++i) {
      const int rc = write_some(port, data + i, 1, &end);
      if (rc != 0) {
        return rc;
      }
      (void)tcdrain(port->fd);
      sleep_us(port->byte_gap_us);
    }
    sleep_us(port->chunk_gap_us);
    return 0;
  }
  const size_t chunk = port->chunk_bytes == 0U ? (n == 0U ? 1U : n) : port->chunk_bytes;
  for (size_t off = 0; off < n; off += chunk) {
    const size_t k = (n - off) < chunk ? (n - off) : chunk;
    const int rc = write_some(port, data + off, k, &end);
    if (rc != 0) {
      return rc;
    }
    sleep_us(port->chunk_gap_us);
  }
  return 0;
}

int drv_serial_queue(drv_serial_t* port, const uint8_t* data, size_t n, uint64_t now_us) {
  if (port == NULL || port->fd < 0 || (data == NULL && n > 0U) || n > UINT16_MAX) {
    return -EINVAL;
  }
  drv_serial_out_t* q = &port->out;
  if (n == 0U) {
    return 0;
  }
  if (n > DRV_SERIAL_OUT_BYTES - q->len || q->packets == DRV_SERIAL_OUT_PACKETS) {
    port->counters.out_overflows++;
    return -ENOBUFS;
  }
  const uint32_t tail = (q->head + q->len) % DRV_SERIAL_OUT_BYTES;
  const size_t first = n < (size_t)(DRV_SERIAL_OUT_BYTES - tail) ? n : (size_t)(DRV_SERIAL_OUT_BYTES - tail);
  memcpy(q->bytes + tail, data, first);
  memcpy(q->bytes, data + first, n - first);
  q->len += (uint32_t)n;
  q->packet_len[(q->packet_head + q->packets) % DRV_SERIAL_OUT_PACKETS] = (uint16_t)n;
  q->packets++;
  return drv_serial_flush(port, now_us);
}

int drv_serial_flush(drv_serial_t* port, uint64_t now_us) {
  if (port == NULL || port->fd < 0) {
    return -EINVAL;
  }
  drv_serial_out_t* q = &port->out;
  while (q->packets > 0U && now_us >= q->quiet_until_us) {
    const uint32_t left = (uint32_t)q->packet_len[q->packet_head] - q->first_done;
    const uint32_t contiguous = DRV_SERIAL_OUT_BYTES - q->head;
    const size_t k = left < contiguous ? left : contiguous;
    const ssize_t w = write(port->fd, q->bytes + q->head, k);
    if (w < 0) {
      if (errno == EINTR) {
        continue;
      }
      if (errno == EAGAIN || errno == EWOULDBLOCK) {
        return 0;  // the line is busy: the rest goes when the descriptor polls writable
      }
      const int e = errno;
      port->counters.write_errors++;
      port->last_error = -e;
      return -e;
    }
    port->counters.bytes_written += (uint64_t)w;
    q->head = (q->head + (uint32_t)w) % DRV_SERIAL_OUT_BYTES;
    q->len -= (uint32_t)w;
    q->first_done += (uint32_t)w;
    if (q->first_done == q->packet_len[q->packet_head]) {
      q->packet_head = (q->packet_head + 1U) % DRV_SERIAL_OUT_PACKETS;
      q->packets--;
      q->first_done = 0;
      // The device's pause after each packet: the next one goes once the gap has passed.
      q->quiet_until_us = now_us + port->chunk_gap_us;
      if (port->chunk_gap_us > 0U) {
        return 0;
      }
    }
  }
  return 0;
}

bool drv_serial_out_pending(const drv_serial_t* port) { return port != NULL && port->out.packets > 0U; }

int drv_serial_wait_readable(drv_serial_t* port, int timeout_ms) {
  if (port == NULL || port->fd < 0 || port->link != NULL) {
    return -EINVAL;  // link mode: the owner is notified of input instead
  }
  return drv_fd_wait_readable(port->fd, timeout_ms);
}

int drv_serial_flush_input(drv_serial_t* port) {
  if (port == NULL || port->fd < 0) {
    return -EINVAL;
  }
  if (port->link != NULL) {
    return port->link_ops->flush_input(port->link, &port->link_flushes);
  }
  return tcflush(port->fd, TCIFLUSH) == 0 ? 0 : -errno;
}

void drv_serial_close(drv_serial_t* port) {
  if (port == NULL) {
    return;
  }
  if (port->fd >= 0 && port->owns_fd && port->link == NULL) {
    close(port->fd);
  }
  port->fd = -1;
  port->owns_fd = false;
  port->link_ops = NULL;
  port->link = NULL;  // link mode: the owner asks the helper thread to close (drv_serial_link_close)
  memset(&port->out, 0, sizeof port->out);
}
