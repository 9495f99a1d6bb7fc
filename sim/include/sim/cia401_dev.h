// SPDX-License-Identifier: MIT
/// sim/cia401_dev.h — The emulated bump-panel input node of a CANopen B21r: a CiA 401 digital
/// input module (default node 16) wired to the 14 bump panels, on the same bus as the drives
/// (sim/cia402_dev.h). Host frames in, node frames out, in memory (transport-agnostic).
///
/// Every frame goes through lib/proto (proto/canopen.h): NMT is decoded with canopen_decode_nmt,
/// TPDO1 is built with cia401_encode_bumpers (inputs 0x6000 sub 1..7; line 4p + s = segment s
/// of panel p, panels numbered as on the rFLEX base: 0..5 upper enclosure, 6..13 base skirt).
///
/// Behaviour:
/// - Power-up / NMT reset (node or communication): boot-up heartbeat (state 0), then
///   pre-operational. NMT start / stop / pre-operational for the node or for all nodes (node 0).
/// - TPDO1 only in NMT operational: at once when the node enters it, whenever an input changes
///   (sim_cia401_poll sees new panel bits), and otherwise every event_timer_s, so that a host can
///   tell a silent node from one whose panels are released.
/// - Heartbeat: every heartbeat_s of simulated time the node sends its NMT state.
/// - Silence (fault injection): until the given time the node sends nothing and ignores frames;
///   afterwards it sends its inputs at the next poll.
///
/// Time is whatever the caller passes (simulated seconds): in lockstep the emulator polls the
/// node once per control period with the period's data, so its frames are a function of the
/// period sequence only.
///
/// Memory: sim_cia401_create allocates one object (under 1 KiB). Not thread-safe.
#ifndef B21R_SIM_CIA401_DEV_H
#define B21R_SIM_CIA401_DEV_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include <proto/canopen.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Configuration. Defaults: sim_cia401_config_default.
typedef struct sim_cia401_config {
  uint8_t node;           ///< node id [CANOPEN_NODE_BUMPERS_DEFAULT = 16]
  double event_timer_s;   ///< TPDO1 period without an input change [0.1]; 0 = on change only
  double heartbeat_s;     ///< heartbeat producer time [0.1]; 0 = none
} sim_cia401_config_t;

/// Counters (never decrease).
typedef struct sim_cia401_counters {
  uint64_t frames_in;        ///< frames received
  uint64_t frames_out;       ///< frames queued
  uint64_t pdos;             ///< TPDO1 frames queued
  uint64_t pdos_on_change;   ///< of those, sent because an input changed (or on entering operational)
  uint64_t ignored;          ///< frames not for this node (only NMT is for it)
  uint64_t ignored_silent;   ///< frames ignored while silent
  uint64_t queue_overflows;  ///< frames dropped because the output queue was full
} sim_cia401_counters_t;

typedef struct sim_cia401 sim_cia401_t;

/// Fills the defaults documented above. O(1).
void sim_cia401_config_default(sim_cia401_config_t* cfg);

/// Creates the node at time 0 (panels released) and queues its boot-up heartbeat. NULL on an
/// invalid config (node not 1..127, negative or non-finite times) or without memory.
sim_cia401_t* sim_cia401_create(const sim_cia401_config_t* cfg);
void sim_cia401_destroy(sim_cia401_t* d);

/// One host frame received at t_s (NMT acts; everything else is counted as ignored). O(1).
void sim_cia401_feed(sim_cia401_t* d, const canopen_frame_t* f, double t_s);

/// The inputs at t_s (segment bits 0..0x0F per panel; higher bits are ignored): queues TPDO1
/// when they changed since the last one sent, when the event timer has run out, or when the node
/// has just entered NMT operational; and the heartbeats due. O(panels).
void sim_cia401_poll(sim_cia401_t* d, const uint8_t panels[CIA401_BUMP_PANELS], double t_s);

/// Next node frame, if any (returns 1 and fills *f, else 0). O(1).
int sim_cia401_drain(sim_cia401_t* d, canopen_frame_t* f);

/// True when the node is NMT operational (it then sends its inputs).
bool sim_cia401_operational(const sim_cia401_t* d);

/// The node sends nothing and ignores frames until t_s; 0 ends it.
void sim_cia401_set_silent_until(sim_cia401_t* d, double t_s);

const sim_cia401_counters_t* sim_cia401_get_counters(const sim_cia401_t* d);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_CIA401_DEV_H
