// SPDX-License-Identifier: MIT
// liblcm's udpm receive socket kept to this host (lcm_local.h).
#define _GNU_SOURCE 1
#include "lcm_local.h"

#include <arpa/inet.h>
#include <dirent.h>
#include <errno.h>
#include <linux/filter.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <netinet/in.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <unistd.h>

// Keep a datagram when it was looped back by this host or came in on loopback; drop the rest.
static int attach_filter(int fd, unsigned lo_index) {
  struct sock_filter code[] = {
      BPF_STMT(BPF_LD | BPF_W | BPF_ABS, (uint32_t)(SKF_AD_OFF + SKF_AD_PKTTYPE)),
      BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, PACKET_LOOPBACK, 2, 0),
      BPF_STMT(BPF_LD | BPF_W | BPF_ABS, (uint32_t)(SKF_AD_OFF + SKF_AD_IFINDEX)),
      BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, lo_index, 0, 1),
      BPF_STMT(BPF_RET | BPF_K, 0xFFFFFFFFU),  // keep all of it
      BPF_STMT(BPF_RET | BPF_K, 0),            // drop
  };
  const struct sock_fprog prog = {.len = (unsigned short)(sizeof code / sizeof code[0]), .filter = code};
  if (setsockopt(fd, SOL_SOCKET, SO_ATTACH_FILTER, &prog, sizeof prog) != 0) {
    return -1;
  }
  const int one = 1;
  return setsockopt(fd, SOL_SOCKET, SO_LOCK_FILTER, &one, sizeof one);
}

int lcm_local_confine(uint16_t port, uint32_t group, char* err, size_t err_cap) {
  const unsigned lo_index = if_nametoindex("lo");
  if (lo_index == 0) {
    snprintf(err, err_cap, "lcm_scope = host: no loopback interface 'lo' (%s)", strerror(errno));
    return -1;
  }
  DIR* dir = opendir("/proc/self/fd");
  if (dir == NULL) {
    snprintf(err, err_cap, "lcm_scope = host: cannot list /proc/self/fd to find LCM's socket (%s)", strerror(errno));
    return -1;
  }
  int found = 0;
  int failed_errno = 0;
  const int dfd = dirfd(dir);
  for (struct dirent* e = readdir(dir); e != NULL; e = readdir(dir)) {
    char* end = NULL;
    const long fd = strtol(e->d_name, &end, 10);
    if (end == e->d_name || *end != '\0' || fd == dfd) {
      continue;
    }
    int type = 0;
    socklen_t tl = sizeof type;
    struct sockaddr_in a;
    socklen_t al = sizeof a;
    if (getsockopt((int)fd, SOL_SOCKET, SO_TYPE, &type, &tl) != 0 || type != SOCK_DGRAM ||
        getsockname((int)fd, (struct sockaddr*)&a, &al) != 0 || a.sin_family != AF_INET ||
        ntohs(a.sin_port) != port ||
        (a.sin_addr.s_addr != htonl(INADDR_ANY) && a.sin_addr.s_addr != htonl(group))) {
      continue;
    }
    if (attach_filter((int)fd, lo_index) != 0) {
      failed_errno = errno;
      continue;
    }
    ++found;
  }
  closedir(dir);
  if (failed_errno != 0) {
    snprintf(err, err_cap, "lcm_scope = host: cannot filter LCM's receive socket (port %u): %s", (unsigned)port,
             strerror(failed_errno));
    return -1;
  }
  if (found == 0) {
    snprintf(err, err_cap,
             "lcm_scope = host: LCM's receive socket (UDP port %u) not found among this process's descriptors, so "
             "messages from other hosts cannot be kept out; set lcm_scope = network to run without (docs/robot.md, "
             "\"Network and security\")",
             (unsigned)port);
    return -1;
  }
  return found;
}

int lcm_local_route_note(uint32_t group, char* note, size_t note_cap) {
  note[0] = '\0';
  const int fd = socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) {
    return 0;
  }
  // connect() on a datagram socket only picks the route and the source address: nothing is sent.
  struct sockaddr_in to = {.sin_family = AF_INET, .sin_port = htons(9), .sin_addr = {.s_addr = htonl(group)}};
  struct sockaddr_in from;
  socklen_t fl = sizeof from;
  int noted = 0;
  // A route through loopback gives a loopback source, or none at all (0.0.0.0: 127.0.0.1 is of
  // host scope, the multicast route of link scope).
  if (connect(fd, (const struct sockaddr*)&to, sizeof to) == 0 &&
      getsockname(fd, (struct sockaddr*)&from, &fl) == 0 && from.sin_addr.s_addr != htonl(INADDR_ANY) &&
      (ntohl(from.sin_addr.s_addr) >> 24) != 127U) {
    char src[INET_ADDRSTRLEN] = "?";
    char grp[INET_ADDRSTRLEN] = "?";
    (void)inet_ntop(AF_INET, &from.sin_addr, src, sizeof src);
    (void)inet_ntop(AF_INET, &to.sin_addr, grp, sizeof grp);
    snprintf(note, note_cap,
             "note: multicast to %s leaves through the interface of %s, not loopback: this host joins the group on "
             "that network (the controller still takes only what this host sends; other LCM programs here may see "
             "messages from it); `ip route add %s/32 dev lo` keeps LCM off the network (docs/robot.md)",
             grp, src, grp);
    noted = 1;
  }
  (void)close(fd);
  return noted;
}
