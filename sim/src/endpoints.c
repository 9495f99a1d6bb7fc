// SPDX-License-Identifier: MIT
// Transports of b21r-sim: raw pseudo-terminals, SOCK_SEQPACKET unix sockets, atomic files.
#define _GNU_SOURCE  // openpty, accept4 flags
#include "sim/endpoints.h"

#include <errno.h>
#include <fcntl.h>
#include <pty.h>
#include <stdio.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <termios.h>
#include <unistd.h>

int sim_pty_open(int* master_fd, int* slave_fd, char* path, size_t cap) {
  int m = -1, s = -1;
  struct termios tio;
  memset(&tio, 0, sizeof(tio));
  cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  if (openpty(&m, &s, NULL, &tio, NULL) != 0) {
    return -1;
  }
  const char* name = ttyname(s);
  if (name == NULL || strlen(name) + 1 > cap) {
    const int e = name == NULL ? errno : ENAMETOOLONG;
    close(m);
    close(s);
    errno = e;
    return -1;
  }
  (void)snprintf(path, cap, "%s", name);
  const int flags = fcntl(m, F_GETFL);
  if (flags < 0 || fcntl(m, F_SETFL, flags | O_NONBLOCK) != 0 || fcntl(m, F_SETFD, FD_CLOEXEC) != 0 ||
      fcntl(s, F_SETFD, FD_CLOEXEC) != 0) {
    const int e = errno;
    close(m);
    close(s);
    errno = e;
    return -1;
  }
  *master_fd = m;
  *slave_fd = s;
  return 0;
}

static int fill_addr(struct sockaddr_un* addr, const char* path) {
  memset(addr, 0, sizeof(*addr));
  addr->sun_family = AF_UNIX;
  if (strlen(path) >= sizeof(addr->sun_path)) {
    errno = ENAMETOOLONG;
    return -1;
  }
  memcpy(addr->sun_path, path, strlen(path) + 1);
  return 0;
}

int sim_seqpacket_listen(const char* path) {
  struct sockaddr_un addr;
  if (fill_addr(&addr, path) != 0) {
    return -1;
  }
  const int fd = socket(AF_UNIX, SOCK_SEQPACKET | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return -1;
  }
  (void)unlink(path);  // a stale socket of an earlier run
  if (bind(fd, (const struct sockaddr*)&addr, sizeof(addr)) != 0 || listen(fd, 8) != 0) {
    const int e = errno;
    close(fd);
    errno = e;
    return -1;
  }
  return fd;
}

int sim_seqpacket_connect(const char* path) {
  struct sockaddr_un addr;
  if (fill_addr(&addr, path) != 0) {
    return -1;
  }
  const int fd = socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return -1;
  }
  if (connect(fd, (const struct sockaddr*)&addr, sizeof(addr)) != 0) {
    const int e = errno;
    close(fd);
    errno = e;
    return -1;
  }
  return fd;
}

void sim_can_from_linux(const struct can_frame* in, canopen_frame_t* out) {
  memset(out, 0, sizeof(*out));
  out->id = in->can_id & CAN_SFF_MASK;
  out->dlc = in->len > 8U ? 8U : in->len;
  memcpy(out->data, in->data, out->dlc);
}

void sim_can_to_linux(const canopen_frame_t* in, struct can_frame* out) {
  memset(out, 0, sizeof(*out));
  out->can_id = in->id & CAN_SFF_MASK;
  out->len = in->dlc > 8U ? 8U : in->dlc;
  memcpy(out->data, in->data, out->len);
}

int sim_write_file_atomic(const char* path, const char* text) {
  char tmp[4096];
  if (snprintf(tmp, sizeof(tmp), "%s.tmp.%ld", path, (long)getpid()) >= (int)sizeof(tmp)) {
    errno = ENAMETOOLONG;
    return -1;
  }
  const int fd = open(tmp, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) {
    return -1;
  }
  const size_t len = strlen(text);
  size_t done = 0;
  while (done < len) {
    const ssize_t k = write(fd, text + done, len - done);
    if (k < 0) {
      if (errno == EINTR) {
        continue;
      }
      const int e = errno;
      close(fd);
      unlink(tmp);
      errno = e;
      return -1;
    }
    done += (size_t)k;
  }
  int rc = fsync(fd);
  int e = errno;
  if (close(fd) != 0 && rc == 0) {
    rc = -1;
    e = errno;
  }
  if (rc == 0 && rename(tmp, path) != 0) {
    rc = -1;
    e = errno;
  }
  if (rc != 0) {
    unlink(tmp);
    errno = e;
  }
  return rc;
}
