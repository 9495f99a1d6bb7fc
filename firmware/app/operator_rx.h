// SPDX-License-Identifier: MIT
/// operator_rx.h — The controller's LCM receive thread: B21R_TELEOP and B21R_COMMAND checked by
/// fw/opauth.h (key, mac, session, seq window) before they reach the loop's mailboxes, the session
/// announced on B21R_SESSION twice a second, and (lcm_scope = host) LCM's receive socket kept to
/// this host (lcm_local.h). docs/robot.md, "Network and security".
///
/// Messages that are taken go to the loop (fw_loop_post_*) and into the --log file (each carries
/// its session nonce); refused ones only count (B21R_STATUS operator_refused_*), and the first
/// refusal of each kind and channel is explained on stderr. Nothing here runs in the tick.
#ifndef B21R_APP_OPERATOR_RX_H
#define B21R_APP_OPERATOR_RX_H

#include "fw/config.h"
#include "fw/lcm_scope.h"
#include "fw/loop.h"
#include "fw/opauth.h"
#include "fw/publisher.h"

#include <lcm/lcm.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stddef.h>

/// Period of the B21R_SESSION announcement [µs].
#define OPERATOR_RX_SESSION_PERIOD_US 500000

typedef struct operator_rx {
  fw_opauth_t auth;          ///< the session; its counters go on STATUS (fw_loop_outputs_t)
  fw_lcm_url_t url;          ///< the effective LCM URL, parsed
  bool host_only;            ///< lcm_scope = host
  lcm_t* lcm;
  fw_loop_t* loop;
  fw_publisher_t* pub;
  lcm_subscription_t* teleop_sub;
  lcm_subscription_t* command_sub;
  atomic_bool stop;
  bool running;
  pthread_t thread;
  int64_t next_session_us;   ///< monotonic time of the next announcement
  bool explained[FW_OPAUTH_CHANNEL_COUNT][FW_OPAUTH_VERDICT_COUNT];
} operator_rx_t;

/// Before LCM is created: checks the effective URL (lcm_url, $LCM_DEFAULT_URL, LCM's default)
/// against lcm_scope, loads operator_key_file (when set) and starts a session with a fresh nonce.
/// Writes the URL to open into *url_out (points into cfg or the environment). Returns 0, or -1
/// with a message in err (a configuration error: the program exits with status 2).
int operator_rx_prepare(operator_rx_t* rx, const fw_config_t* cfg, const char** url_out, char* err, size_t err_cap);

/// After the loop and the devices: subscribes to the two channels on lcm, keeps LCM's socket to
/// this host (lcm_scope = host, udpm), and starts the thread. Returns 0, or -1 with a message.
int operator_rx_start(operator_rx_t* rx, lcm_t* lcm, fw_loop_t* loop, fw_publisher_t* pub, char* err,
                      size_t err_cap);

/// Stops the thread (when started) and unsubscribes. Safe after a failed or no start.
void operator_rx_stop(operator_rx_t* rx);

#endif  // B21R_APP_OPERATOR_RX_H
