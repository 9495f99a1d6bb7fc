// SPDX-License-Identifier: MIT
// The LCM receive thread: authenticated operator messages and the session announcement (operator_rx.h).
#define _GNU_SOURCE 1
#include "operator_rx.h"

#include "io_posix.h"
#include "lcm_local.h"

#include <b21r/b21r_session_t.h>

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char* const k_channel[FW_OPAUTH_CHANNEL_COUNT] = {"B21R_TELEOP", "B21R_COMMAND"};

static void hex(const uint8_t* b, size_t n, char* out) {
  static const char digits[] = "0123456789abcdef";
  for (size_t i = 0; i < n; ++i) {
    out[2 * i] = digits[b[i] >> 4];
    out[2 * i + 1] = digits[b[i] & 0x0F];
  }
  out[2 * n] = '\0';
}

int operator_rx_prepare(operator_rx_t* rx, const fw_config_t* cfg, const char** url_out, char* err, size_t err_cap) {
  memset(rx, 0, sizeof *rx);
  atomic_init(&rx->stop, false);
  rx->host_only = cfg->lcm_scope == FW_LCM_SCOPE_HOST;
  const char* url = fw_lcm_url_effective(cfg->lcm_url, getenv("LCM_DEFAULT_URL"));
  if (fw_lcm_url_check(url, !rx->host_only, &rx->url, err, err_cap) != 0) {
    return -1;
  }
  uint8_t key[FW_OPAUTH_KEY_BYTES];
  const bool have_key = cfg->operator_key_file[0] != '\0';
  if (have_key && fw_opauth_load_key(cfg->operator_key_file, key, err, err_cap) != 0) {
    return -1;
  }
  uint8_t nonce[FW_OPAUTH_NONCE_BYTES];
  if (fw_opauth_new_nonce(nonce) != 0) {
    snprintf(err, err_cap, "no session nonce: OpenSSL's random generator failed");
    return -1;
  }
  fw_opauth_init(&rx->auth, have_key ? key : NULL, nonce, fw_publisher_wall_us());
  memset(key, 0, sizeof key);
  *url_out = url;
  return 0;
}

// The first refusal of each kind and channel, explained; the rest are counted on STATUS.
static void explain(operator_rx_t* rx, fw_opauth_channel_t ch, fw_opauth_verdict_t v) {
  if (rx->explained[ch][v]) {
    return;
  }
  rx->explained[ch][v] = true;
  char mine[2 * FW_OPAUTH_KEY_ID_BYTES + 1];
  hex(rx->auth.key_id, FW_OPAUTH_KEY_ID_BYTES, mine);
  char why[200];
  switch (v) {
    case FW_OPAUTH_MALFORMED:
      snprintf(why, sizeof why, "not a message of this controller's type");
      break;
    case FW_OPAUTH_UNAUTHENTICATED:
      snprintf(why, sizeof why, "unauthenticated: an older operator tool? update it");
      break;
    case FW_OPAUTH_KEY:
      if (rx->auth.have_key) {
        snprintf(why, sizeof why, "signed with another key (this controller's key id is %s)", mine);
      } else {
        snprintf(why, sizeof why, "this controller has no operator key (operator_key_file)");
      }
      break;
    case FW_OPAUTH_MAC:
      snprintf(why, sizeof why, "its mac is wrong: forged or altered");
      break;
    case FW_OPAUTH_SESSION:
      snprintf(why, sizeof why, "signed for another start of the controller: a replay, or a tool that has not yet "
                                "seen this session");
      break;
    case FW_OPAUTH_REPLAY:
      snprintf(why, sizeof why, "its seq was taken already: a replay");
      break;
    default:
      snprintf(why, sizeof why, "its seq is more than %u below the newest taken: delayed or replayed",
               FW_OPAUTH_WINDOW - 1U);
      break;
  }
  fprintf(stderr,
          "b21r-controller: refused %s (%s); it changes nothing; further refusals are counted on B21R_STATUS "
          "(operator_refused_*)\n",
          k_channel[ch], why);
}

// B21R_TELEOP and B21R_COMMAND: taken ones go to the loop and the --log file, refused ones only count.
static void on_operator(const lcm_recv_buf_t* rbuf, const char* channel, void* user) {
  operator_rx_t* rx = (operator_rx_t*)user;
  const bool teleop = strcmp(channel, k_channel[FW_OPAUTH_TELEOP]) == 0;
  b21r_teleop_t t;
  b21r_command_t c;
  const fw_opauth_verdict_t v = teleop ? fw_opauth_take_teleop(&rx->auth, rbuf->data, rbuf->data_size, &t)
                                       : fw_opauth_take_command(&rx->auth, rbuf->data, rbuf->data_size, &c);
  if (v != FW_OPAUTH_TAKEN) {
    explain(rx, teleop ? FW_OPAUTH_TELEOP : FW_OPAUTH_COMMAND, v);
    return;
  }
  if (teleop) {
    fw_loop_post_teleop(rx->loop, &t, io_posix_now_us());
  } else {
    fw_loop_post_command(rx->loop, &c, io_posix_now_us());
  }
  fw_publisher_record(rx->pub, channel, rbuf->data, rbuf->data_size);
}

static void announce(operator_rx_t* rx) {
  b21r_session_t s;
  fw_opauth_session(&rx->auth, fw_publisher_wall_us(), &s);
  (void)b21r_session_t_publish(rx->lcm, "B21R_SESSION", &s);
}

static void* receiver_main(void* arg) {
  operator_rx_t* rx = (operator_rx_t*)arg;
  while (!atomic_load(&rx->stop)) {
    if (rx->auth.have_key) {
      const int64_t now = io_posix_now_us();
      if (now >= rx->next_session_us) {
        announce(rx);
        rx->next_session_us = now + OPERATOR_RX_SESSION_PERIOD_US;
      }
    }
    (void)lcm_handle_timeout(rx->lcm, 100);
  }
  return NULL;
}

int operator_rx_start(operator_rx_t* rx, lcm_t* lcm, fw_loop_t* loop, fw_publisher_t* pub, char* err,
                      size_t err_cap) {
  rx->lcm = lcm;
  rx->loop = loop;
  rx->pub = pub;
  // Raw subscriptions: the generated handlers would print every undecodable message on stderr;
  // opauth decodes, counts and explains once instead.
  rx->teleop_sub = lcm_subscribe(lcm, k_channel[FW_OPAUTH_TELEOP], on_operator, rx);
  rx->command_sub = lcm_subscribe(lcm, k_channel[FW_OPAUTH_COMMAND], on_operator, rx);
  if (rx->teleop_sub == NULL || rx->command_sub == NULL) {
    snprintf(err, err_cap, "cannot subscribe to B21R_TELEOP / B21R_COMMAND on LCM");
    return -1;
  }
  char line[400];
  if (rx->host_only && rx->url.udpm) {
    // liblcm opened its receive socket on the first subscription: keep it to this host before
    // the thread takes anything from it.
    if (lcm_local_confine(rx->url.port, rx->url.group, err, err_cap) < 0) {
      return -1;
    }
    if (lcm_local_route_note(rx->url.group, line, sizeof line)) {
      fprintf(stderr, "b21r-controller: %s\n", line);
    }
  }
  if (rx->auth.have_key) {
    char id[2 * FW_OPAUTH_KEY_ID_BYTES + 1];
    char nonce[2 * FW_OPAUTH_NONCE_BYTES + 1];
    hex(rx->auth.key_id, FW_OPAUTH_KEY_ID_BYTES, id);
    hex(rx->auth.nonce, FW_OPAUTH_NONCE_BYTES, nonce);
    fprintf(stderr, "b21r-controller: operator messages: key id %s, session %s (B21R_SESSION); LCM %s\n", id, nonce,
            rx->host_only ? "this host only (lcm_scope = host)" : "open to other hosts (lcm_scope = network)");
  } else {
    fprintf(stderr,
            "b21r-controller: no operator key (operator_key_file): every B21R_TELEOP and B21R_COMMAND is refused; "
            "LCM %s\n",
            rx->host_only ? "this host only (lcm_scope = host)" : "open to other hosts (lcm_scope = network)");
  }
  rx->next_session_us = io_posix_now_us();
  rx->running = pthread_create(&rx->thread, NULL, receiver_main, rx) == 0;
  if (!rx->running) {
    snprintf(err, err_cap, "cannot start the LCM receive thread");
    return -1;
  }
  return 0;
}

void operator_rx_stop(operator_rx_t* rx) {
  if (rx->running) {
    atomic_store(&rx->stop, true);
    pthread_join(rx->thread, NULL);
    rx->running = false;
  }
  if (rx->teleop_sub != NULL) {
    lcm_unsubscribe(rx->lcm, rx->teleop_sub);
    rx->teleop_sub = NULL;
  }
  if (rx->command_sub != NULL) {
    lcm_unsubscribe(rx->lcm, rx->command_sub);
    rx->command_sub = NULL;
  }
}
