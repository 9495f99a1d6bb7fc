// SPDX-License-Identifier: MIT
// LCM URLs against lcm_scope (fw/lcm_scope.h). The parsing follows liblcm's own (lcm.c, lcm_udpm.c):
// "provider://network?key=value&...", udpm's network "group:port" with inet_aton and strtol(.., 0).
#define _DEFAULT_SOURCE 1
#include "fw/lcm_scope.h"

#include "fw/errfmt.h"

#include <arpa/inet.h>
#include <errno.h>
#include <stdlib.h>
#include <string.h>

#define SCOPE_HINT "see docs/robot.md, \"Network and security\""

const char* fw_lcm_url_effective(const char* lcm_url, const char* env_default) {
  if (lcm_url != NULL && lcm_url[0] != '\0') {
    return lcm_url;
  }
  if (env_default != NULL && env_default[0] != '\0') {
    return env_default;
  }
  return FW_LCM_DEFAULT_URL;
}

// udpm's "group:port" (or "" for LCM's default group and port).
static int parse_udpm_network(const char* url, const char* net, size_t len, fw_lcm_url_t* out, char* err,
                              size_t err_cap) {
  char text[64];
  if (len == 0) {
    out->group = 0xEFFF4C43U;  // 239.255.76.67, LCM's default
    out->port = 7667;
    return 0;
  }
  if (len >= sizeof text) {
    fw_errfmt(err, err_cap, "lcm_url %s: the address is too long (expected udpm://GROUP:PORT)", url);
    return -1;
  }
  memcpy(text, net, len);
  text[len] = '\0';
  char* colon = strchr(text, ':');
  if (colon == NULL) {
    // liblcm would listen on port 0 (an arbitrary port no other program uses).
    fw_errfmt(err, err_cap, "lcm_url %s: no port (e.g. udpm://239.255.76.67:7667)", url);
    return -1;
  }
  *colon = '\0';
  struct in_addr a;
  if (inet_aton(text, &a) == 0 || (ntohl(a.s_addr) >> 28) != 0xEU) {
    fw_errfmt(err, err_cap, "lcm_url %s: '%s' is not an IPv4 multicast group (224.0.0.0 to 239.255.255.255)", url,
              text);
    return -1;
  }
  char* end = NULL;
  errno = 0;
  const long port = strtol(colon + 1, &end, 0);
  if (end == colon + 1 || *end != '\0' || errno != 0 || port < 1 || port > 65535) {
    fw_errfmt(err, err_cap, "lcm_url %s: port '%s' is not 1..65535", url, colon + 1);
    return -1;
  }
  out->group = ntohl(a.s_addr);
  out->port = (uint16_t)port;
  return 0;
}

int fw_lcm_url_check(const char* url, bool network, fw_lcm_url_t* out, char* err, size_t err_cap) {
  memset(out, 0, sizeof *out);
  const char* sep = strstr(url, "://");
  if (sep == NULL) {
    fw_errfmt(err, err_cap, "lcm_url %s: expected PROVIDER://... (e.g. udpm://239.255.76.67:7667?ttl=0)", url);
    return -1;
  }
  const size_t plen = (size_t)(sep - url);
  const char* net = sep + 3;
  const char* q = strchr(net, '?');
  const size_t nlen = q != NULL ? (size_t)(q - net) : strlen(net);
  const bool is_udpm = plen == 4 && strncmp(url, "udpm", 4) == 0;
  const bool local = (plen == 4 && (strncmp(url, "memq", 4) == 0 || strncmp(url, "file", 4) == 0));
  if (!is_udpm) {
    if (!network && !local) {
      fw_errfmt(err, err_cap,
                "lcm_url %s: with lcm_scope = host the controller takes udpm:// with ttl=0, memq:// or file:// only "
                "(this provider may reach other hosts); set lcm_scope = network to use it (%s)",
                url, SCOPE_HINT);
      return -1;
    }
    return 0;
  }
  out->udpm = true;
  if (parse_udpm_network(url, net, nlen, out, err, err_cap) != 0) {
    return -1;
  }
  // Arguments: key=value pairs joined by '&'; liblcm keeps the last of a repeated key, so every
  // ttl must be 0 (strtol base 0 as liblcm: "0x0" is 0, text without digits is 0 too).
  for (const char* p = q != NULL ? q + 1 : NULL; p != NULL && *p != '\0';) {
    const char* amp = strchr(p, '&');
    const size_t len = amp != NULL ? (size_t)(amp - p) : strlen(p);
    if (len > 4 && strncmp(p, "ttl=", 4) == 0) {
      char v[32];
      const size_t vl = len - 4 < sizeof v - 1 ? len - 4 : sizeof v - 1;
      memcpy(v, p + 4, vl);
      v[vl] = '\0';
      const long ttl = strtol(v, NULL, 0);
      if (ttl != 0) {
        out->ttl = ttl;
      }
    }
    p = amp != NULL ? amp + 1 : NULL;
  }
  if (!network && out->ttl != 0) {
    fw_errfmt(err, err_cap,
              "lcm_url %s: ttl=%ld sends the controller's messages to other hosts, but lcm_scope = host; use ttl=0 "
              "(this host only), or set lcm_scope = network to reach the robot from other machines: everyone on "
              "that network then sees every message and can send to the controller (%s)",
              url, out->ttl, SCOPE_HINT);
    return -1;
  }
  return 0;
}
