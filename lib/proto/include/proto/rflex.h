// SPDX-License-Identifier: MIT
/// proto/rflex.h — iRobot/RWI rFLEX serial codec (B21r base): packets, typed messages, odometry.
///
/// Wire format (protocols.md A.2), multi-byte fields big-endian:
/// `ESC(0x1B) STX(0x02) PORT ID OPCODE DLEN DATA[DLEN] CHK ESC ETX(0x03)`, CHK = XOR of
/// PORT..last DATA byte. The base stuffs a literal 0x1B inside a packet as `ESC NUL` and may
/// insert `ESC SOH` fillers; DLEN and CHK refer to the unstuffed bytes. Hosts do not stuff, so
/// this codec's host encoders never let a raw 0x1B appear between the markers (values are
/// nudged by one count instead, see rflex_make_axis_velocity()).
///
/// Both sides are here: the host (controller) builds commands and parses reports; the device
/// (emulator) parses commands and builds reports. The streaming decoder has a role per side
/// (rflex_role_t): the host role de-stuffs only, since the base always stuffs its output; the
/// device role also accepts DLEN-framed raw packets, since host output is not stuffed.
///
/// Memory: rflex_packet_t is 260 bytes, rflex_decoder_t about 1 KB. No allocation.
#ifndef PROTO_RFLEX_H
#define PROTO_RFLEX_H

#include <proto/common.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// @name Framing
/// @{
#define RFLEX_ESC 0x1BU
#define RFLEX_STX 0x02U
#define RFLEX_ETX 0x03U
#define RFLEX_NUL 0x00U  ///< After ESC inside a packet: one literal 0x1B.
#define RFLEX_SOH 0x01U  ///< After ESC inside a packet: filler, both bytes discarded.
#define RFLEX_MAX_DATA 255U
/// Unstuffed packet size for a given DLEN: DLEN + 9.
#define RFLEX_PACKET_BYTES(dlen) ((size_t)(dlen) + 9U)
/// Largest stuffed packet: every byte of PORT..CHK doubled.
#define RFLEX_MAX_STUFFED_BYTES (4U + 2U * (4U + RFLEX_MAX_DATA + 1U))
/// Raw bytes the decoder holds for one candidate packet (stuffed packet plus some ESC SOH
/// fillers); a candidate that grows beyond this is dropped as too long.
#define RFLEX_DECODER_BUF_BYTES 640U
/// @}

/// @name Ports (modules) and opcodes (protocols.md A.3)
/// @{
#define RFLEX_PORT_SYS 1U
#define RFLEX_PORT_MOT 2U
#define RFLEX_PORT_JSTK 3U
#define RFLEX_PORT_SONAR 4U
#define RFLEX_PORT_DIO 5U
#define RFLEX_PORT_IR 6U

#define RFLEX_OP_SYS_LCD_DUMP 0U
#define RFLEX_OP_SYS_STATUS 1U
#define RFLEX_OP_MOT_AXIS_SET_DIR 7U
#define RFLEX_OP_MOT_AXIS_SET_POS 8U
#define RFLEX_OP_MOT_SET_DEFAULTS 10U
#define RFLEX_OP_MOT_BRAKE_SET 11U
#define RFLEX_OP_MOT_BRAKE_RELEASE 12U
#define RFLEX_OP_MOT_SYSTEM_REPORT 33U
#define RFLEX_OP_MOT_SYSTEM_REPORT_REQ 34U
#define RFLEX_OP_JSTK_GET_STATE 0U
#define RFLEX_OP_SONAR_RUN 0U
#define RFLEX_OP_SONAR_GET_UPDATE 1U
#define RFLEX_OP_SONAR_REPORT 2U
#define RFLEX_OP_DIO_REPORTS_REQ 0U
#define RFLEX_OP_DIO_REPORT 1U
#define RFLEX_OP_IR_RUN 0U
#define RFLEX_OP_IR_REPORT 1U

#define RFLEX_AXIS_TRANS 0U  ///< Translation axis.
#define RFLEX_AXIS_ROT 1U    ///< Rotation (steering) axis.

/// DIO addresses of the B21r's 14 bump panels: 0x40..0x4D, one panel per address.
#define RFLEX_DIO_BUMPER_FIRST 0x40U
#define RFLEX_DIO_BUMPER_COUNT 14U
/// DIO address of the steering index ("home") pulse.
#define RFLEX_DIO_HEADING_INDEX 0x31U
/// @}

/// One unstuffed packet. `data[dlen..]` is unspecified.
typedef struct rflex_packet {
  uint8_t port;    ///< Module, 1..6 (RFLEX_PORT_*).
  uint8_t id;      ///< Sequence/id byte (hosts send 0; sonar commands 4).
  uint8_t opcode;
  uint8_t dlen;    ///< Number of data bytes.
  uint8_t data[RFLEX_MAX_DATA];
} rflex_packet_t;

/// XOR checksum of PORT, ID, OPCODE, DLEN and data[0..dlen). O(dlen).
uint8_t rflex_checksum(const rflex_packet_t* pkt);

/// True when any byte from PORT through CHK equals 0x1B (a host must not send such a packet
/// unstuffed). O(dlen).
bool rflex_packet_has_esc(const rflex_packet_t* pkt);

/// How rflex_encode() treats 0x1B bytes between the markers.
typedef enum rflex_stuffing {
  RFLEX_HOST_STRICT = 0,  ///< Host output, unstuffed; refuses (returns 0) if any 0x1B would appear.
  RFLEX_HOST_RAW,         ///< Unstuffed, no check (what other host drivers send; for tests).
  RFLEX_DEVICE_STUFFED,   ///< Device output: each 0x1B becomes ESC NUL.
} rflex_stuffing_t;

/// Encodes a packet. @return bytes written (DLEN + 9 unstuffed; up to RFLEX_MAX_STUFFED_BYTES
/// stuffed), or 0 if an argument is NULL, cap is too small, or (HOST_STRICT) a raw 0x1B would be
/// sent. O(dlen).
size_t rflex_encode(uint8_t* buf, size_t cap, const rflex_packet_t* pkt, rflex_stuffing_t mode);

// ---------------------------------------------------------------------------------------------
// B21r conversion parameters

/// Conversion factors and fixed command values. Defaults (rflex_b21r_params_default()) are the
/// Player/ROS B21r values of protocols.md A.4–A.6; calibrate per robot.
typedef struct rflex_b21r_params {
  double trans_counts_per_m;    ///< K_d, odometry counts per metre (default 103000).
  double rot_counts_per_rad;    ///< K_a, odometry counts per radian (default 35000).
  double trans_acc_mps2;        ///< Translational acceleration sent with commands (default 0.7).
  uint32_t trans_torque;        ///< Translational torque limit (default 30000).
  uint32_t rot_acc_counts;      ///< Rotational acceleration, counts/s² (default 100000).
  uint32_t rot_torque;          ///< Rotational torque limit (default 35000).
  double power_offset_v;        ///< Battery volts = raw / 100 + offset (default 1.2).
  double odom_max_step_m;       ///< Odometry: reject a translation step larger than this (default 1.0).
  double odom_max_step_rad;     ///< Odometry: reject a heading step larger than this (default 1.0).
} rflex_b21r_params_t;

/// Fills the B21r defaults above. O(1).
void rflex_b21r_params_default(rflex_b21r_params_t* params);

/// Checks that factors are finite and > 0 and limits finite and > 0. @return PROTO_OK or
/// PROTO_ERR_INVALID_ARG.
proto_status_t rflex_b21r_params_check(const rflex_b21r_params_t* params);

// ---------------------------------------------------------------------------------------------
// Host -> device commands. Builders fill *pkt (never 0x1B anywhere between the markers unless
// the caller's own value forces it; then PROTO_ERR_RANGE and *pkt unspecified).

/// MOT_AXIS_SET_DIR, exact values (no nudge). DLEN 14: axis, |vel| u32, acc u32, torque u32, dir.
/// @param dir 1 for vel >= 0 (forward / CCW), 0 for negative. @return PROTO_OK or INVALID_ARG.
proto_status_t rflex_make_set_dir(rflex_packet_t* pkt, uint8_t axis, uint32_t vel_mag,
                                  uint32_t acc, uint32_t torque, uint8_t dir);

/// MOT_AXIS_SET_DIR for a signed velocity in counts/s, with the 0x1B workaround (protocols.md
/// A.2 recommendation): no byte from PORT to CHK may be 0x1B. Each of |velocity|, acceleration
/// and torque is first moved to the nearest value without a 0x1B byte (a byte 0x1B becomes 0x1A
/// with all lower bytes 0xFF, or 0x1C with lower bytes 0x00: at most 128 counts when bits 8-15
/// are 0x1B, i.e. |v| in 6912..7167, a few counts otherwise); then, if the checksum is 0x1B,
/// the velocity magnitude is moved by ±1, ±2, ... counts (smaller first; never crossing zero,
/// never changing sign). A zero velocity stays exactly zero and the acceleration moves instead.
/// @param nudge_counts if not NULL, receives (sent - requested) of the velocity magnitude, or of
///        the acceleration when the velocity is 0.
/// @return PROTO_OK, PROTO_ERR_INVALID_ARG (axis > 1, NULL pkt), PROTO_ERR_RANGE (no clean
///         value within 64 counts of the cleaned value; not reachable in practice).
proto_status_t rflex_make_axis_velocity(rflex_packet_t* pkt, uint8_t axis, int32_t vel_counts,
                                        uint32_t acc_counts, uint32_t torque, int32_t* nudge_counts);

/// The pair of MOT_AXIS_SET_DIR packets for (v, ω): out[0] translation, out[1] rotation, sent
/// in that order. Counts = round(value × factor), saturated to ±(2^31 - 1).
/// @param trans_acc_mps2 acceleration for this command (e.g. a deceleration when stopping);
///        <= 0 or not finite means params->trans_acc_mps2.
/// @return PROTO_OK, PROTO_ERR_INVALID_ARG (NULL, bad params, v or ω not finite).
proto_status_t rflex_make_velocity(rflex_packet_t out[2], const rflex_b21r_params_t* params,
                                   double v_mps, double omega_radps, double trans_acc_mps2);

/// MOT_BRAKE_SET (no data): engage brake / amplifier inhibit.
void rflex_make_brake_set(rflex_packet_t* pkt);
/// MOT_BRAKE_RELEASE (no data): motors enabled.
void rflex_make_brake_release(rflex_packet_t* pkt);
/// MOT_SET_DEFAULTS (no data).
void rflex_make_set_defaults(rflex_packet_t* pkt);
/// SYS_STATUS request (no data).
void rflex_make_sys_status_request(rflex_packet_t* pkt);
/// MOT_SYSTEM_REPORT_REQ: period u32 (µs as far as known; 100000 = 10 Hz), axis mask u32
/// (3 = both). Period 0 / mask 0 switches reports off. @return PROTO_OK or PROTO_ERR_RANGE when
/// the period contains a 0x1B byte (choose another period).
proto_status_t rflex_make_odometry_request(rflex_packet_t* pkt, uint32_t period, uint32_t axis_mask);
/// DIO_REPORTS_REQ on port DIO, id 0: period u32 (0 = off). @return as above.
proto_status_t rflex_make_dio_request(rflex_packet_t* pkt, uint32_t period);
/// SONAR_RUN, id 4: echo, ping and set delays (µs) u32 and mode u8 (2 = on, 0 = off). DLEN 13.
proto_status_t rflex_make_sonar_run(rflex_packet_t* pkt, uint32_t echo_delay, uint32_t ping_delay,
                                    uint32_t set_delay, uint8_t mode);
/// Sonar off: SONAR_RUN with all zeros, id 4.
void rflex_make_sonar_off(rflex_packet_t* pkt);
/// IR_RUN: five u32 values and a run flag (2 = on). DLEN 21.
proto_status_t rflex_make_ir_run(rflex_packet_t* pkt, const uint32_t values[5], uint8_t run);
/// IR off: IR_RUN with all zeros.
void rflex_make_ir_off(rflex_packet_t* pkt);

// ---------------------------------------------------------------------------------------------
// Device -> host reports (the emulator builds them; the host parses them)

/// MOT_SYSTEM_REPORT contents (one packet per axis, DLEN 25).
typedef struct rflex_motor_report {
  uint32_t rv;          ///< Return value (meaning unknown; 0 from the emulator).
  uint32_t timestamp;   ///< Base timestamp (units undocumented, probably 4 ms ticks).
  uint8_t axis;         ///< RFLEX_AXIS_TRANS or RFLEX_AXIS_ROT.
  int32_t position;     ///< Translation: cumulative distance counts. Rotation: bearing counts.
  int32_t velocity;     ///< Counts/s.
  uint32_t acceleration;
  uint32_t torque;
} rflex_motor_report_t;

/// SYS_STATUS reply contents (DLEN 9).
typedef struct rflex_sys_status {
  uint32_t timestamp;
  uint32_t voltage_raw;  ///< Battery volts = raw / 100 + power offset (rflex_battery_volts()).
  uint8_t brake;         ///< Nonzero = brake engaged.
} rflex_sys_status_t;

/// DIO_REPORT contents (DLEN 7): timestamp, address (net id), value u16.
typedef struct rflex_dio_report {
  uint32_t timestamp;
  uint8_t address;  ///< 0x40..0x4D bump panels, 0x31 heading index.
  uint16_t value;   ///< For bump panels the low 4 bits say which segments are pressed.
} rflex_dio_report_t;

/// Builds a MOT_SYSTEM_REPORT. id is the device's running packet id. @return PROTO_OK or INVALID_ARG.
proto_status_t rflex_make_motor_report(rflex_packet_t* pkt, uint8_t id, const rflex_motor_report_t* r);
/// Builds a SYS_STATUS reply.
proto_status_t rflex_make_sys_status(rflex_packet_t* pkt, uint8_t id, const rflex_sys_status_t* s);
/// Builds a DIO_REPORT.
proto_status_t rflex_make_dio_report(rflex_packet_t* pkt, uint8_t id, const rflex_dio_report_t* d);

/// Parses a MOT_SYSTEM_REPORT (port MOT, opcode 33, DLEN >= 25). @return PROTO_OK, FORMAT.
proto_status_t rflex_parse_motor_report(const rflex_packet_t* pkt, rflex_motor_report_t* out);
/// Parses a SYS_STATUS reply (port SYS, opcode 1, DLEN >= 9). @return PROTO_OK, FORMAT.
proto_status_t rflex_parse_sys_status(const rflex_packet_t* pkt, rflex_sys_status_t* out);
/// Parses a DIO_REPORT (port DIO, opcode 1, DLEN >= 7). @return PROTO_OK, FORMAT.
proto_status_t rflex_parse_dio_report(const rflex_packet_t* pkt, rflex_dio_report_t* out);

/// Battery volts from the raw SYS_STATUS value: raw / 100 + offset_v. O(1).
double rflex_battery_volts(uint32_t voltage_raw, double offset_v);
/// Bump panel index 0..13 for a DIO address, or -1 if the address is not a bump panel. O(1).
int rflex_dio_bumper_panel(uint8_t address);

// ---------------------------------------------------------------------------------------------
// Host commands as the device sees them

/// What a received packet is, for dispatch.
typedef enum rflex_msg_kind {
  RFLEX_MSG_UNKNOWN = 0,       ///< Well-framed packet of a port/opcode not modelled here.
  RFLEX_MSG_SET_DIR,           ///< MOT 7.
  RFLEX_MSG_SET_POS,           ///< MOT 8.
  RFLEX_MSG_SET_DEFAULTS,      ///< MOT 10.
  RFLEX_MSG_BRAKE_SET,         ///< MOT 11.
  RFLEX_MSG_BRAKE_RELEASE,     ///< MOT 12.
  RFLEX_MSG_MOTOR_REPORT,      ///< MOT 33 (device -> host).
  RFLEX_MSG_ODOMETRY_REQUEST,  ///< MOT 34.
  RFLEX_MSG_SYS_STATUS,        ///< SYS 1: a request when DLEN 0, a reply otherwise.
  RFLEX_MSG_SYS_LCD_DUMP,      ///< SYS 0.
  RFLEX_MSG_JSTK,              ///< JSTK 0.
  RFLEX_MSG_SONAR_RUN,         ///< SONAR 0 with DLEN 13, or the short "DIO off" variant (ignore).
  RFLEX_MSG_SONAR_REPORT,      ///< SONAR 2.
  RFLEX_MSG_DIO_REQUEST,       ///< DIO 0.
  RFLEX_MSG_DIO_REPORT,        ///< DIO 1.
  RFLEX_MSG_IR_RUN,            ///< IR 0.
  RFLEX_MSG_IR_REPORT,         ///< IR 1.
} rflex_msg_kind_t;

/// Classifies by port and opcode only (does not check DLEN). O(1).
rflex_msg_kind_t rflex_classify(const rflex_packet_t* pkt);

/// MOT_AXIS_SET_DIR contents.
typedef struct rflex_set_dir {
  uint8_t axis;
  uint32_t vel_mag;   ///< |velocity| counts/s.
  uint32_t acc;       ///< Counts/s².
  uint32_t torque;
  uint8_t dir;        ///< 1 = positive, 0 = negative.
  int32_t vel_counts; ///< Signed velocity (saturated to ±(2^31 - 1)).
} rflex_set_dir_t;

/// Parses MOT_AXIS_SET_DIR (DLEN >= 14). @return PROTO_OK, FORMAT, RANGE (axis > 1).
proto_status_t rflex_parse_set_dir(const rflex_packet_t* pkt, rflex_set_dir_t* out);
/// Parses MOT_SYSTEM_REPORT_REQ (DLEN >= 8). @return PROTO_OK or FORMAT.
proto_status_t rflex_parse_odometry_request(const rflex_packet_t* pkt, uint32_t* period,
                                            uint32_t* axis_mask);
/// Parses DIO_REPORTS_REQ (DLEN >= 4) on port DIO, or the short SONAR-port variant older
/// drivers send (port SONAR, opcode 0, DLEN 4). @return PROTO_OK or FORMAT.
proto_status_t rflex_parse_dio_request(const rflex_packet_t* pkt, uint32_t* period);
/// Parses SONAR_RUN (DLEN >= 13). Short SONAR opcode-0 packets give PROTO_ERR_FORMAT: ignore.
proto_status_t rflex_parse_sonar_run(const rflex_packet_t* pkt, uint32_t* echo_delay,
                                     uint32_t* ping_delay, uint32_t* set_delay, uint8_t* mode);

// ---------------------------------------------------------------------------------------------
// Streaming decoder

/// Counters of an rflex_decoder_t. Never decrease.
typedef struct rflex_decoder_counters {
  uint64_t bytes_in;          ///< Every byte consumed.
  uint64_t packets_ok;        ///< Valid packets emitted.
  uint64_t packets_stuffed;   ///< ... of which contained ESC NUL or ESC SOH.
  uint64_t packets_raw_esc;   ///< ... of which carried a raw 0x1B, accepted by DLEN framing (device role).
  uint64_t bytes_garbage;     ///< Bytes skipped while hunting for ESC STX.
  uint64_t bad_port;          ///< Candidates dropped: PORT not 1..6.
  uint64_t bad_checksum;      ///< Candidates dropped: framing fine but CHK wrong.
  uint64_t bad_framing;       ///< Candidates dropped: no ESC ETX where DLEN says, bad escape.
  uint64_t too_long;          ///< Candidates dropped: more than RFLEX_DECODER_BUF_BYTES raw bytes.
  uint64_t bytes_dropped;     ///< Bytes discarded in total (garbage + dropped candidates).
} rflex_decoder_counters_t;

/// Which side's output a decoder reads (protocols.md A.2).
typedef enum rflex_role {
  /// The controller reads the base's output, which is always stuffed: ESC NUL for a literal
  /// 0x1B, ESC SOH fillers, ESC ETX at the end. Only that form is accepted, so a byte lost on
  /// the line (UART overrun) can never turn a stuffed packet into a "valid" raw one with shifted
  /// fields, and a false raw frame cannot swallow the genuine packets after it.
  RFLEX_ROLE_HOST = 0,
  /// The emulator reads a host's output, which is not stuffed and may carry a raw 0x1B (other
  /// drivers send them): a packet is accepted in its de-stuffed form or in its raw form framed
  /// by DLEN (DLEN + 9 bytes ending in ESC ETX).
  RFLEX_ROLE_DEVICE = 1,
} rflex_role_t;

/// Private: how far the stuffed form of the candidate at the front of the buffer has been read.
typedef struct rflex_stuffed_scan {
  uint16_t pos;       ///< Next raw byte to read (0 = not started).
  uint16_t n;         ///< De-stuffed bytes so far.
  uint8_t stuffed;    ///< An ESC NUL or ESC SOH was seen.
  uint8_t verdict;    ///< 0 while undecided, else the final verdict for this candidate.
  uint8_t body[4U + RFLEX_MAX_DATA + 1U];  ///< PORT ID OPCODE DLEN DATA CHK, de-stuffed.
} rflex_stuffed_scan_t;

/// Decoder state (fixed size). Read `counters` directly; other fields are private.
typedef struct rflex_decoder {
  uint16_t fill;      ///< Raw bytes held.
  uint16_t pending;   ///< Bytes of the emitted packet to discard on the next push.
  uint8_t role;       ///< rflex_role_t.
  uint8_t buf[RFLEX_DECODER_BUF_BYTES];
  rflex_stuffed_scan_t scan;
  rflex_decoder_counters_t counters;
} rflex_decoder_t;

/// Initialises a decoder for the host role (RFLEX_ROLE_HOST: the controller reading the base),
/// zeroing counters. O(1).
void rflex_decoder_init(rflex_decoder_t* dec);

/// Initialises a decoder for the given role (an unknown value means RFLEX_ROLE_HOST), zeroing
/// counters. O(1).
void rflex_decoder_init_role(rflex_decoder_t* dec, rflex_role_t role);

/// Drops any partial packet (counted in bytes_dropped). O(1).
void rflex_decoder_reset(rflex_decoder_t* dec);

/// Feeds bytes; consumes until one packet completes or all bytes are used and returns the
/// number consumed (> 0 when len > 0). Accepts a packet when (a) its ESC-de-stuffed form
/// (ESC NUL -> 0x1B, ESC SOH dropped, ended by ESC ETX) has a valid PORT, a DLEN equal to the
/// de-stuffed length and a valid checksum, or, in the device role only, (b) its raw form framed
/// by DLEN (DLEN + 9 bytes ending in ESC ETX) does. While hunting, ESC ESC restarts the hunt.
/// After a failed candidate the bytes already held are rescanned from the next ESC STX, so no
/// packet that starts inside a corrupt one is lost. Cost: O(1) per byte, plus O(packet length)
/// where a candidate ends or is dropped (the bytes after a dropped ESC are read again, so a
/// stream of false starts costs at most RFLEX_DECODER_BUF_BYTES per byte); no allocation.
/// @param out written only when *got_packet is set. @param got_packet always written.
size_t rflex_decoder_push(rflex_decoder_t* dec, const uint8_t* bytes, size_t len,
                          rflex_packet_t* out, bool* got_packet);

// ---------------------------------------------------------------------------------------------
// Odometry integration (Player's update rule, protocols.md A.5)

/// Odometry state. Pose in the odometry frame: x forward at start, y left, theta CCW.
typedef struct rflex_odometry {
  rflex_b21r_params_t params;
  bool have_trans;          ///< A translation report has been seen.
  bool have_rot;            ///< A rotation report has been seen.
  bool baseline;            ///< Both seen and integrated once (the first update only sets it).
  int32_t trans_latest;     ///< Latest translation position counts.
  int32_t rot_latest;       ///< Latest bearing counts.
  int32_t trans_used;       ///< Translation counts at the last update.
  int32_t rot_used;         ///< Bearing counts at the last update.
  double x_m;
  double y_m;
  double theta_rad;         ///< Normalised to (-pi, pi].
  double v_mps;             ///< Latest reported translational velocity.
  double omega_radps;       ///< Latest reported rotational velocity.
  uint64_t updates;         ///< Integration steps applied.
  uint64_t rejected_trans;  ///< Translation steps rejected as implausible (|Δd| > max step).
  uint64_t rejected_rot;    ///< Heading steps rejected as implausible (|Δθ| > max step).
} rflex_odometry_t;

/// Initialises at pose (0, 0, 0) with the given parameters. @return PROTO_OK or INVALID_ARG.
proto_status_t rflex_odom_init(rflex_odometry_t* odo, const rflex_b21r_params_t* params);
/// Stores a MOT_SYSTEM_REPORT's position and velocity for its axis. O(1).
/// @return PROTO_OK or PROTO_ERR_RANGE (axis > 1, nothing stored).
proto_status_t rflex_odom_feed(rflex_odometry_t* odo, const rflex_motor_report_t* report);
/// Integrates the latest reports: Δ = latest - used with int32 wrap-around; heading first
/// (θ += Δbearing / K_a, normalised), then translation along the new heading
/// (d = Δpos / K_d; x += d cos θ; y += d sin θ). A step larger than the configured maximum is
/// not applied and counted; the baseline still moves on, so one corrupt value costs at most two
/// steps. Before both axes have been seen this does nothing. O(1).
/// @return true when the pose changed or the baseline was set.
bool rflex_odom_update(rflex_odometry_t* odo);
/// Sets the pose (e.g. heading from the index pulse); keeps the baseline. O(1).
void rflex_odom_set_pose(rflex_odometry_t* odo, double x_m, double y_m, double theta_rad);
/// A second integrator of the same encoders (e.g. one restarted at (0, 0, 0) per run): takes the
/// latest counts `source` has been fed and integrates them like rflex_odom_update. O(1).
/// @return rflex_odom_update's result.
bool rflex_odom_follow(rflex_odometry_t* odo, const rflex_odometry_t* source);

// ---------------------------------------------------------------------------------------------
// Host view of the base: what a controller learns from the base's reports

/// Everything a host keeps from the base's byte stream: framing, odometry, bump panels, brake,
/// battery. The controller and the Python environment (sim/env.h) read the base through it.
typedef struct rflex_host {
  rflex_decoder_t decoder;    ///< framing of the base's bytes (its counters: dropped bytes, ...)
  rflex_odometry_t odometry;  ///< fed by every MOT_SYSTEM_REPORT; the caller runs rflex_odom_update()
  bool report_new[2];         ///< per axis: a MOT_SYSTEM_REPORT arrived since the caller cleared it
  uint32_t bumper_mask;       ///< bit p set while bump panel p (DIO 0x40 + p) reads pressed
  int8_t brake;               ///< from SYS_STATUS: -1 unknown, 0 released, 1 engaged
  double battery_v;           ///< from SYS_STATUS [V]; 0 before the first one
  uint64_t packets;           ///< valid packets handled
} rflex_host_t;

/// Initialises the host view (odometry at the origin with params). O(1).
/// @return PROTO_OK, or PROTO_ERR_INVALID_ARG (NULL, bad params; *host unusable).
proto_status_t rflex_host_init(rflex_host_t* host, const rflex_b21r_params_t* params);

/// Takes one packet from the base: a MOT_SYSTEM_REPORT feeds the odometry and sets
/// report_new[axis]; a DIO_REPORT of a bump panel sets or clears its bit (pressed = any of the
/// low 4 value bits); a SYS_STATUS reply (DLEN >= 9) sets brake and battery_v. Other packets
/// only count. @return the packet's kind. O(1).
rflex_msg_kind_t rflex_host_handle(rflex_host_t* host, const rflex_packet_t* pkt);

/// Frames n bytes from the base with the host's decoder and handles every complete packet.
/// @return packets handled. O(n).
size_t rflex_host_feed(rflex_host_t* host, const uint8_t* bytes, size_t n);

#ifdef __cplusplus
}
#endif

#endif  // PROTO_RFLEX_H
