// SPDX-License-Identifier: MIT
// CAN frame I/O: SocketCAN raw sockets and the emulated bus (AF_UNIX SOCK_SEQPACKET records).
#define _GNU_SOURCE
#include <drivers/can.h>

#include "fd_wait.h"

#include <errno.h>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <stdio.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <unistd.h>

static void msg(char* err, size_t err_len, const char* text, const char* name, int e) {
  if (err != NULL && err_len > 0U) {
    snprintf(err, err_len, "can: %s %s: %s", text, name, strerror(e));
  }
}

static void port_reset(drv_can_t* port) {
  memset(port, 0, sizeof *port);
  port->fd = -1;
}

static int set_nonblocking(int fd) {
  const int flags = fcntl(fd, F_GETFL);
  if (flags < 0 || fcntl(fd, F_SETFL, flags | O_NONBLOCK) != 0) {
    return -errno;
  }
  return 0;
}

int drv_can_open_socketcan(drv_can_t* port, const char* ifname, char* err, size_t err_len) {
  if (port == NULL || ifname == NULL) {
    return -EINVAL;
  }
  port_reset(port);
  if (strlen(ifname) >= IFNAMSIZ) {
    msg(err, err_len, "interface name too long:", ifname, EINVAL);
    return -EINVAL;
  }
  const int fd = socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
  if (fd < 0) {
    const int e = errno;
    if (e == EAFNOSUPPORT || e == EPROTONOSUPPORT) {
      if (err != NULL && err_len > 0U) {
        snprintf(err, err_len,
                 "can: cannot open %s: this kernel has no SocketCAN support (socket(PF_CAN) "
                 "failed: %s); load the can/can_raw modules, or use the emulated bus "
                 "(SOCK_SEQPACKET path)",
                 ifname, strerror(e));
      }
      return -EAFNOSUPPORT;
    }
    msg(err, err_len, "cannot create a CAN socket for", ifname, e);
    return -e;
  }
  struct ifreq ifr;
  memset(&ifr, 0, sizeof ifr);
  memcpy(ifr.ifr_name, ifname, strlen(ifname) + 1U);
  if (ioctl(fd, SIOCGIFINDEX, &ifr) != 0) {
    const int e = errno;
    close(fd);
    if (err != NULL && err_len > 0U) {
      snprintf(err, err_len, "can: no CAN interface named %s (%s); create it (ip link) first",
               ifname, strerror(e));
    }
    return e == ENODEV ? -ENODEV : -e;
  }
  struct sockaddr_can addr;
  memset(&addr, 0, sizeof addr);
  addr.can_family = AF_CAN;
  addr.can_ifindex = ifr.ifr_ifindex;
  if (bind(fd, (const struct sockaddr*)(const void*)&addr, sizeof addr) != 0) {
    const int e = errno;
    close(fd);
    msg(err, err_len, "cannot bind to", ifname, e);
    return -e;
  }
  // Error frames (bus errors, failed CRCs, error-passive and bus-off states) are delivered and
  // counted: they are how a node on a disturbed bus learns that frames had to be sent again.
  // Without the option the port still works; it then counts none.
  const can_err_mask_t err_mask =
      CAN_ERR_PROT | CAN_ERR_CRTL | CAN_ERR_BUSOFF | CAN_ERR_BUSERROR | CAN_ERR_ACK | CAN_ERR_RESTARTED;
  (void)setsockopt(fd, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &err_mask, sizeof err_mask);
  port->fd = fd;
  port->owns_fd = true;
  port->transport = DRV_CAN_SOCKETCAN;
  return 0;
}

static int unix_addr(struct sockaddr_un* addr, const char* path) {
  memset(addr, 0, sizeof *addr);
  addr->sun_family = AF_UNIX;
  const size_t n = strlen(path);
  if (n == 0U || n >= sizeof addr->sun_path) {
    return -ENAMETOOLONG;
  }
  memcpy(addr->sun_path, path, n + 1U);
  return 0;
}

int drv_can_open_seqpacket(drv_can_t* port, const char* path, char* err, size_t err_len) {
  if (port == NULL || path == NULL) {
    return -EINVAL;
  }
  port_reset(port);
  struct sockaddr_un addr;
  if (unix_addr(&addr, path) != 0) {
    msg(err, err_len, "socket path too long:", path, ENAMETOOLONG);
    return -ENAMETOOLONG;
  }
  const int fd = socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    const int e = errno;
    msg(err, err_len, "cannot create a local socket for", path, e);
    return -e;
  }
  // Connect blocking (local, immediate), then switch to non-blocking frame I/O.
  if (connect(fd, (const struct sockaddr*)(const void*)&addr, sizeof addr) != 0) {
    const int e = errno;
    close(fd);
    msg(err, err_len, "cannot connect to the emulated bus at", path, e);
    return -e;
  }
  const int rc = set_nonblocking(fd);
  if (rc != 0) {
    close(fd);
    msg(err, err_len, "cannot make non-blocking:", path, -rc);
    return rc;
  }
  port->fd = fd;
  port->owns_fd = true;
  port->transport = DRV_CAN_SEQPACKET;
  return 0;
}

int drv_can_attach(drv_can_t* port, int fd, drv_can_transport_t transport, bool take_ownership) {
  if (port == NULL || fd < 0 ||
      (transport != DRV_CAN_SOCKETCAN && transport != DRV_CAN_SEQPACKET)) {
    return -EINVAL;
  }
  const int rc = set_nonblocking(fd);
  if (rc != 0) {
    return rc;
  }
  port_reset(port);
  port->fd = fd;
  port->owns_fd = take_ownership;
  port->transport = transport;
  return 0;
}

int drv_can_seqpacket_listen(const char* path, int backlog, char* err, size_t err_len) {
  if (path == NULL) {
    return -EINVAL;
  }
  struct sockaddr_un addr;
  if (unix_addr(&addr, path) != 0) {
    msg(err, err_len, "socket path too long:", path, ENAMETOOLONG);
    return -ENAMETOOLONG;
  }
  const int fd = socket(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    const int e = errno;
    msg(err, err_len, "cannot create a local socket for", path, e);
    return -e;
  }
  (void)unlink(path);  // a stale socket file from an earlier run
  if (bind(fd, (const struct sockaddr*)(const void*)&addr, sizeof addr) != 0 ||
      listen(fd, backlog > 0 ? backlog : 4) != 0) {
    const int e = errno;
    close(fd);
    msg(err, err_len, "cannot listen at", path, e);
    return -e;
  }
  return fd;
}

int drv_can_to_linux(const canopen_frame_t* in, struct can_frame* out) {
  if (in == NULL || out == NULL || in->id > CAN_SFF_MASK || in->dlc > 8U) {
    return -EINVAL;
  }
  memset(out, 0, sizeof *out);
  out->can_id = in->id;
  out->can_dlc = in->dlc;
  memcpy(out->data, in->data, in->dlc);
  return 0;
}

int drv_can_from_linux(const struct can_frame* in, canopen_frame_t* out) {
  if (in == NULL || out == NULL) {
    return -EINVAL;
  }
  if ((in->can_id & (CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG)) != 0U || in->can_dlc > 8U) {
    return -EINVAL;
  }
  memset(out, 0, sizeof *out);
  out->id = in->can_id & CAN_SFF_MASK;
  out->dlc = in->can_dlc;
  memcpy(out->data, in->data, in->can_dlc);
  return 0;
}

int drv_can_send(drv_can_t* port, const canopen_frame_t* frame) {
  if (port == NULL || port->fd < 0) {
    return -EINVAL;
  }
  struct can_frame cf;
  if (drv_can_to_linux(frame, &cf) != 0) {
    return -EINVAL;
  }
  for (;;) {
    const ssize_t n = send(port->fd, &cf, sizeof cf, MSG_NOSIGNAL);
    if (n == (ssize_t)sizeof cf) {
      port->counters.frames_tx++;
      return 0;
    }
    if (n < 0 && errno == EINTR) {
      continue;
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK || errno == ENOBUFS)) {
      port->counters.tx_would_block++;
      return -EAGAIN;
    }
    port->counters.errors++;
    return n < 0 ? -errno : -EIO;
  }
}

// recv() returns 0 both at the end of the stream and for an empty record: only the socket's
// hang-up state tells them apart.
static bool peer_closed(int fd) {
  struct pollfd pfd = {.fd = fd, .events = POLLIN | POLLRDHUP, .revents = 0};
  return poll(&pfd, 1, 0) > 0 && (pfd.revents & (POLLHUP | POLLRDHUP)) != 0;
}

int drv_can_recv(drv_can_t* port, canopen_frame_t* frame) {
  if (port == NULL || port->fd < 0 || frame == NULL) {
    return -EINVAL;
  }
  for (;;) {
    struct can_frame cf;
    // MSG_TRUNC makes recv report a record's real length, so oversize records are detected.
    const ssize_t n = recv(port->fd, &cf, sizeof cf, MSG_TRUNC);
    if (n < 0) {
      if (errno == EINTR) {
        continue;
      }
      if (errno == EAGAIN || errno == EWOULDBLOCK) {
        return 0;
      }
      port->counters.errors++;
      return -errno;
    }
    if (n == 0 && port->transport == DRV_CAN_SEQPACKET && peer_closed(port->fd)) {
      return -EPIPE;  // the bus server closed its end
    }
    // Otherwise an empty record (SOCK_SEQPACKET keeps zero-length records): malformed below.
    // SocketCAN may deliver CAN FD sized records only when enabled (it is not): any size other
    // than one classic frame is malformed on either transport.
    if (n != (ssize_t)sizeof cf) {
      port->counters.rx_bad_size++;
      continue;
    }
    if (cf.can_dlc > 8U) {
      port->counters.rx_bad_size++;
      continue;
    }
    if ((cf.can_id & CAN_ERR_FLAG) != 0U) {
      port->counters.rx_error_frames++;
      if ((cf.can_id & CAN_ERR_BUSOFF) != 0U) {
        port->bus_off = true;
        port->counters.bus_off_events++;
      } else if ((cf.can_id & CAN_ERR_RESTARTED) != 0U) {
        port->bus_off = false;
      }
      continue;
    }
    if (drv_can_from_linux(&cf, frame) != 0) {
      port->counters.rx_dropped_kind++;
      continue;
    }
    port->counters.frames_rx++;
    port->bus_off = false;  // a frame arrived: the controller is on the bus (its restart report may be lost)
    return 1;
  }
}

int drv_can_wait_readable(drv_can_t* port, int timeout_ms) {
  if (port == NULL || port->fd < 0) {
    return -EINVAL;
  }
  return drv_fd_wait_readable(port->fd, timeout_ms);
}

void drv_can_close(drv_can_t* port) {
  if (port == NULL) {
    return;
  }
  if (port->fd >= 0 && port->owns_fd) {
    close(port->fd);
  }
  port->fd = -1;
  port->owns_fd = false;
}
