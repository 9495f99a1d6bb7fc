// SPDX-License-Identifier: MIT
/// lcm_local.h — Keeps liblcm's udpm receive socket to this host (lcm_scope = host; docs/robot.md,
/// "Network and security").
///
/// liblcm (Debian 12: 1.3.1) binds its receive socket to the wildcard address and joins the group
/// on whatever interface routes it, and its URL has no option to narrow that: a unicast datagram
/// to the robot's address and port, or multicast arriving on its network interface, reaches the
/// controller. After LCM has opened the socket (on the first subscription), the controller finds
/// it among its own descriptors (a UDP socket bound to the URL's port) and attaches a socket
/// filter (classic BPF, SO_ATTACH_FILTER, then locked with SO_LOCK_FILTER) that keeps only
/// datagrams that arrived on the loopback interface or were looped back by this host's own
/// multicast (packet type PACKET_LOOPBACK): what programs on this host send, over any route. The
/// kernel applies the filter before a datagram is queued, so what comes from other hosts never
/// reaches liblcm. Needs no privilege.
#ifndef B21R_APP_LCM_LOCAL_H
#define B21R_APP_LCM_LOCAL_H

#include <stddef.h>
#include <stdint.h>

/// Filters every UDP socket of this process bound to port (host order) on the wildcard address
/// or on group (host order). Returns how many (at least 1), or -1 with a message in err.
int lcm_local_confine(uint16_t port, uint32_t group, char* err, size_t err_cap);

/// When multicast to group does not leave through the loopback interface (this host then joins
/// the group on a network interface, and other programs here may see messages from that network),
/// writes a note naming the route to add into note and returns 1; else 0 (note empty).
int lcm_local_route_note(uint32_t group, char* note, size_t note_cap);

#endif  // B21R_APP_LCM_LOCAL_H
