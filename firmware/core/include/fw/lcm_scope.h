// SPDX-License-Identifier: MIT
/// fw/lcm_scope.h — Which LCM URLs keep the controller's messages on this host (config key
/// lcm_scope; docs/robot.md, "Network and security").
///
/// lcm_scope = host (the default) takes only providers that neither send to nor receive from
/// other machines: memq://, file:// and udpm:// with ttl=0 (LCM's default TTL). For udpm the
/// kernel drops every multicast with TTL 0 after the copy looped back to this host, so nothing is
/// sent; receiving is confined by the controller itself after LCM has opened its socket (a socket
/// filter that keeps only packets that came over loopback or were looped back by this host:
/// firmware/app/lcm_local.c). lcm_scope = network takes any URL and confines nothing: other hosts
/// reach the controller (operator messages are still authenticated, fw/opauth.h).
/// Pure: no I/O, no allocation.
#ifndef FW_LCM_SCOPE_H
#define FW_LCM_SCOPE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// LCM's own default provider, as liblcm resolves an empty URL without $LCM_DEFAULT_URL.
#define FW_LCM_DEFAULT_URL "udpm://239.255.76.67:7667"

/// What a URL names, as far as the scope is concerned.
typedef struct fw_lcm_url {
  bool udpm;           ///< the udpm provider (multicast UDP)
  uint32_t group;      ///< udpm: the multicast group, host byte order (239.255.76.67 = 0xEFFF4C43)
  uint16_t port;       ///< udpm: the UDP port
  long ttl;            ///< udpm: the ttl argument (0 when absent, LCM's default)
} fw_lcm_url_t;

/// The URL the controller opens: lcm_url when set, else env_default ($LCM_DEFAULT_URL, may be
/// NULL or empty), else FW_LCM_DEFAULT_URL. Returns a pointer to one of them.
const char* fw_lcm_url_effective(const char* lcm_url, const char* env_default);

/// Parses url and checks it against the scope (network = lcm_scope network). Returns 0 with *out
/// filled, or -1 with a message in err naming the fix: in host scope, a udpm URL with a ttl other
/// than 0 or a provider that may reach other hosts (tcpq://, unknown ones); in any scope, a udpm
/// URL whose address is not an IPv4 multicast group or whose port is not 1..65535. O(length).
int fw_lcm_url_check(const char* url, bool network, fw_lcm_url_t* out, char* err, size_t err_cap);

#ifdef __cplusplus
}
#endif

#endif  // FW_LCM_SCOPE_H
