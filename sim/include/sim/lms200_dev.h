// SPDX-License-Identifier: MIT
/// sim/lms200_dev.h — An emulated SICK LMS200: host telegrams in, ACKs, replies and 0xB0 scan
/// telegrams out, as bytes in memory (transport-agnostic).
///
/// Every byte goes through lib/proto (proto/lms200.h): the device decodes requests with an
/// lms_decoder_t in the device role and encodes every reply with the lms_encode_* functions.
///
/// Behaviour (protocols.md B):
/// - Power-up: 9600 Bd, not streaming, variant and unit from the config (default 180°/1°, mm).
/// - Each accepted request is answered by an ACK byte (0x06) and the reply telegram
///   (reply code = request + 0x80): mode 0x20 -> 0xA0 (stream `24`, stop `25`, installation
///   `00`+password, baud `40/41/42/48`; other stream modes are answered "not possible"),
///   values 0x30 -> 0xB0 (one scan), status 0x31 -> 0xB1, type 0x3A -> 0xBA ("LMS200;30106"),
///   variant 0x3B -> 0xBB (accepted for the five LMS200 variants, else rejected with the current
///   one), config read 0x74 -> 0xF4, config write 0x77 -> 0xF7 (one byte: 1 accepted, 0 refused
///   outside installation mode; unit and availability are applied), reset 0x10 -> 0x91 (back to
///   power-up settings). Unknown or malformed requests get a NAK byte (0x15).
/// - A baud change is acknowledged at the old rate; later bytes leave at the new rate.
/// - Scans: ranges come from the scan provider (the plant's ray casts), get Gaussian range
///   noise (seeded), and become raw values in the unit in force: no hit within max_range_m ->
///   8191 (no echo); a hit farther than the unit's largest value (8.182 m in mm mode) -> 8183
///   (measured value > maximum); optional random dazzle/SNR codes (8190/8187).
/// - Pacing (paced = 1, real-time mode): bytes leave at the baud rate (10 bits per byte), and
///   in streaming mode a new scan is sent as soon as the line is idle and the mirror has
///   finished a sweep (75 Hz at 1°, 37.5 Hz at 0.5°, 18.75 Hz at 0.25°), i.e. at the rate the
///   baud allows: about 2.6 Hz at 9600 Bd and 10.3 Hz at 38400 Bd for 181 values.
///   Unpaced (lockstep): bytes are available at once; scans are sent only when the emulator
///   calls sim_lms_emit_scan (one per control period).
/// - Silence (fault injection): until the given time the device sends nothing and ignores
///   requests (they are still consumed and counted).
///
/// Memory: sim_lms_create allocates one object (about 40 KiB); nothing after. Not thread-safe.
#ifndef B21R_SIM_LMS200_DEV_H
#define B21R_SIM_LMS200_DEV_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// Takes one scan for the device: writes n distances [m] (INFINITY = nothing hit) for beams at
/// bearings angle_min_rad + i * increment_rad in the laser frame.
typedef void (*sim_lms_scan_fn)(void* user, double angle_min_rad, double increment_rad, size_t n,
                                double* out_m);

/// Configuration. Defaults: sim_lms_config_default.
typedef struct sim_lms_config {
  uint16_t width_deg;        ///< power-up variant: 180 or 100 [180]
  uint16_t res_cdeg;         ///< power-up resolution, 0.01° (100, 50, 25) [100]
  uint8_t unit_mm;           ///< power-up unit: 1 = mm, 0 = cm [1]
  uint32_t power_up_baud;    ///< [9600]
  double noise_sigma_m;      ///< Gaussian range noise, standard deviation [0.005]
  double max_range_m;        ///< nothing beyond this gives an echo [30.0]
  double error_code_prob;    ///< per-beam probability of a dazzle or SNR code [0]
  bool paced;                ///< real-time pacing (see above) [false]
  uint64_t seed;             ///< noise seed [1]
} sim_lms_config_t;

/// Counters (never decrease).
typedef struct sim_lms_counters {
  uint64_t requests;          ///< valid telegrams received
  uint64_t naks;              ///< NAK bytes sent
  uint64_t scans;             ///< 0xB0 telegrams queued
  uint64_t ignored_silent;    ///< requests ignored while silent
  uint64_t queue_overflows;   ///< telegrams dropped because the output queue was full
  uint64_t repeated_scans;    ///< scans that repeated the previous distances (stuck fault)
} sim_lms_counters_t;

typedef struct sim_lms sim_lms_t;

/// Fills the defaults documented above. O(1).
void sim_lms_config_default(sim_lms_config_t* cfg);

/// Creates a device. scan_fn is called (with user) whenever a scan is needed. Returns NULL on
/// invalid config (bad variant, baud, non-finite numbers) or out of memory.
sim_lms_t* sim_lms_create(const sim_lms_config_t* cfg, sim_lms_scan_fn scan_fn, void* user);
void sim_lms_destroy(sim_lms_t* d);

/// Host -> device bytes received at time t_s; answers are queued. Consumes all n. O(n).
void sim_lms_feed(sim_lms_t* d, const uint8_t* bytes, size_t n, double t_s);

/// Device -> host bytes available by t_s (all queued bytes when unpaced). O(bytes).
size_t sim_lms_drain(sim_lms_t* d, uint8_t* out, size_t cap, double t_s);

/// Real-time service: in streaming mode queues a scan when one is due at t_s (paced only).
/// Call at least every millisecond or so of simulated time. O(1) or one scan.
void sim_lms_poll(sim_lms_t* d, double t_s);

/// Queues one 0xB0 scan telegram taken now (lockstep: once per control period). Does nothing
/// while silent. O(beams).
void sim_lms_emit_scan(sim_lms_t* d, double t_s);

/// True while the host has the device streaming (mode 0x24).
bool sim_lms_streaming(const sim_lms_t* d);
/// Current baud rate, variant and unit.
uint32_t sim_lms_baud(const sim_lms_t* d);
void sim_lms_variant(const sim_lms_t* d, uint16_t* width_deg, uint16_t* res_cdeg);
/// Beam geometry of the current variant: count, bearing of beam 0, increment [rad].
size_t sim_lms_beams(const sim_lms_t* d, double* angle_min_rad, double* increment_rad);

/// The device sends nothing and ignores requests until t_s (fault injection). 0 ends it.
void sim_lms_set_silent_until(sim_lms_t* d, double t_s);

/// Until t_s every scan repeats the distances of the last measured scan bit for bit (a frozen
/// measurement stage: the telegrams, their CRC and scan index are fine, the values never change).
/// 0 ends it. The first scan of a variant is always measured. O(1).
void sim_lms_set_stuck_until(sim_lms_t* d, double t_s);

/// Restarts the noise stream (range noise and error codes) from seed: every scan after it
/// depends only on the seed and the scene, not on how many scans came before. O(1).
void sim_lms_reseed(sim_lms_t* d, uint64_t seed);

/// Counters.
const sim_lms_counters_t* sim_lms_get_counters(const sim_lms_t* d);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_LMS200_DEV_H
