// SPDX-License-Identifier: MIT
/// proto/canopen.h — CANopen (CiA 301) frames and the CiA 402 drive state machine, both sides.
///
/// The project's CAN base interface (protocols.md D.1): two CiA 402 drives in profile velocity
/// mode (0x6060 = 3), translation (default node 1) and rotation/steering (default node 2). The
/// controller is NMT master and SYNC producer. The PDO mapping is fixed (no SDO set-up needed):
///
/// | frame  | COB-ID      | DLC | layout (little-endian, CANopen)                                  |
/// |--------|-------------|-----|------------------------------------------------------------------|
/// | NMT    | 0x000       | 2   | [0] command (CANOPEN_NMT_*), [1] node id (0 = all)               |
/// | SYNC   | 0x080       | 0   | —                                                                |
/// | EMCY   | 0x080 + id  | 8   | [0..1] error code 0x603F, [2] error register 0x1001, [3..7] vendor|
/// | TPDO1  | 0x180 + id  | 6   | [0..1] statusword 0x6041 u16, [2..5] velocity actual 0x606C i32  |
/// | RPDO1  | 0x200 + id  | 6   | [0..1] controlword 0x6040 u16, [2..5] target velocity 0x60FF i32 |
/// | TPDO2  | 0x280 + id  | 4   | [0..3] position actual 0x6064 i32                                |
/// | HB     | 0x700 + id  | 1   | [0] NMT state (CANOPEN_NMT_STATE_*)                              |
///
/// Velocities are drive counts/s, positions drive counts; the scale is a per-drive parameter
/// of the caller (canopen_counts_from_si()). TPDO1 and TPDO2 are sent by the drives on SYNC.
///
/// The B21r's 14 bump panels reach the controller through a CiA 401 digital-input node (default
/// node 16, away from the drives' ids so that more drives fit below it), started by the same
/// NMT master:
///
/// | frame  | COB-ID      | DLC | layout                                                           |
/// |--------|-------------|-----|------------------------------------------------------------------|
/// | TPDO1  | 0x180 + id  | 7   | digital inputs 0x6000 sub 1..7 (8 lines each); line 4p + s =     |
/// |        | (0x190)     |     | segment s (0..3) of bump panel p (0..13): byte p/2, low nibble   |
/// |        |             |     | for even p, high nibble for odd p                                |
/// | HB     | 0x700 + id  | 1   | [0] NMT state                                                    |
///
/// Panel numbers are the rFLEX ones (panel p = DIO address 0x40 + p): 0..5 the upper enclosure,
/// 6..13 the base skirt; a panel's nibble is the value its DIO report carries, so one mapping
/// serves both bases. The node sends TPDO1 when any input changes and, without a change, every
/// event timer (0x1800 sub 5, 100 ms), so that its silence can be told from "no contact".
/// `lib/proto/b21r_canopen.dbc` describes exactly these frames for nodes 1, 2 and 16.
///
/// Frames are a plain struct (no Linux headers here); firmware/drivers converts them to and
/// from `struct can_frame`. Only 11-bit identifiers are used; no RTR frames.
#ifndef PROTO_CANOPEN_H
#define PROTO_CANOPEN_H

#include <proto/common.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// A classic CAN frame with an 11-bit identifier.
typedef struct canopen_frame {
  uint32_t id;      ///< 11-bit COB-ID (0..0x7FF).
  uint8_t dlc;      ///< Data length 0..8.
  uint8_t data[8];  ///< data[dlc..7] unspecified (encoders write 0).
} canopen_frame_t;

/// @name COB-ID function codes and limits
/// @{
#define CANOPEN_COB_NMT 0x000U
#define CANOPEN_COB_SYNC 0x080U
#define CANOPEN_COB_EMCY 0x080U   ///< + node id (1..127).
#define CANOPEN_COB_TPDO1 0x180U
#define CANOPEN_COB_RPDO1 0x200U
#define CANOPEN_COB_TPDO2 0x280U
#define CANOPEN_COB_RPDO2 0x300U
#define CANOPEN_COB_SDO_TX 0x580U
#define CANOPEN_COB_SDO_RX 0x600U
#define CANOPEN_COB_HEARTBEAT 0x700U
#define CANOPEN_NODE_MAX 127U
#define CANOPEN_NODE_TRANS_DEFAULT 1U  ///< Translation drive.
#define CANOPEN_NODE_ROT_DEFAULT 2U    ///< Rotation (steering) drive.
#define CANOPEN_NODE_BUMPERS_DEFAULT 16U  ///< CiA 401 bump-panel input node (COB-ID TPDO1 0x190).
/// @}

/// @name CiA 401 bump-panel node
/// @{
#define CIA401_BUMP_PANELS 14U        ///< B21r: 6 upper enclosure panels + 8 base skirt panels.
#define CIA401_BUMP_SEGMENTS 0x0FU    ///< Contact bits of one panel (4 segments).
#define CIA401_BUMP_TPDO1_DLC 7U      ///< 14 panels × 4 lines = 56 inputs = 7 input bytes.
#define CIA401_EVENT_TIMER_MS 100U    ///< TPDO1 period without a change (0x1800 sub 5) [ms].
/// @}

/// @name NMT commands (frame byte 0) and NMT states (heartbeat byte 0)
/// @{
#define CANOPEN_NMT_START 0x01U
#define CANOPEN_NMT_STOP 0x02U
#define CANOPEN_NMT_PREOP 0x80U
#define CANOPEN_NMT_RESET_NODE 0x81U
#define CANOPEN_NMT_RESET_COMM 0x82U
#define CANOPEN_NMT_STATE_BOOTUP 0x00U
#define CANOPEN_NMT_STATE_STOPPED 0x04U
#define CANOPEN_NMT_STATE_OPERATIONAL 0x05U
#define CANOPEN_NMT_STATE_PREOP 0x7FU
/// @}

/// @name CiA 402 objects, controlwords and statusword bits
/// @{
#define CIA402_MODE_PROFILE_VELOCITY 3  ///< Value of 0x6060 the drives run in.
#define CIA402_CW_SHUTDOWN 0x0006U       ///< -> READY_TO_SWITCH_ON.
#define CIA402_CW_SWITCH_ON 0x0007U      ///< -> SWITCHED_ON (also "disable operation").
#define CIA402_CW_ENABLE_OPERATION 0x000FU  ///< -> OPERATION_ENABLED.
#define CIA402_CW_DISABLE_VOLTAGE 0x0000U   ///< -> SWITCH_ON_DISABLED.
#define CIA402_CW_QUICK_STOP 0x0002U     ///< From OPERATION_ENABLED -> QUICK_STOP_ACTIVE.
#define CIA402_CW_FAULT_RESET 0x0080U    ///< Bit 7; acts on its rising edge.
#define CIA402_CW_HALT 0x0100U           ///< Bit 8: halt (decelerate, stay enabled).
#define CIA402_SW_READY_TO_SWITCH_ON 0x0001U
#define CIA402_SW_SWITCHED_ON 0x0002U
#define CIA402_SW_OPERATION_ENABLED 0x0004U
#define CIA402_SW_FAULT 0x0008U
#define CIA402_SW_VOLTAGE_ENABLED 0x0010U
#define CIA402_SW_QUICK_STOP 0x0020U     ///< 1 = NOT in quick stop.
#define CIA402_SW_SWITCH_ON_DISABLED 0x0040U
#define CIA402_SW_WARNING 0x0080U
#define CIA402_SW_REMOTE 0x0200U
#define CIA402_SW_TARGET_REACHED 0x0400U
/// @}

// ---------------------------------------------------------------------------------------------
// Frame encoders. Return PROTO_OK, or PROTO_ERR_INVALID_ARG (NULL frame, node id not 1..127,
// NMT node not 0..127); the frame is fully written (unused data bytes 0) on success. O(1).

proto_status_t canopen_encode_nmt(canopen_frame_t* f, uint8_t command, uint8_t node);
proto_status_t canopen_encode_sync(canopen_frame_t* f);
/// RPDO1 (host -> drive): controlword + target velocity, counts/s.
proto_status_t canopen_encode_rpdo1(canopen_frame_t* f, uint8_t node, uint16_t controlword,
                                    int32_t target_velocity);
/// TPDO1 (drive -> host): statusword + velocity actual, counts/s.
proto_status_t canopen_encode_tpdo1(canopen_frame_t* f, uint8_t node, uint16_t statusword,
                                    int32_t velocity_actual);
/// TPDO2 (drive -> host): position actual, counts.
proto_status_t canopen_encode_tpdo2(canopen_frame_t* f, uint8_t node, int32_t position_actual);
/// Heartbeat (drive -> host): NMT state.
proto_status_t canopen_encode_heartbeat(canopen_frame_t* f, uint8_t node, uint8_t nmt_state);
/// EMCY (drive -> host). @param vendor 5 bytes, or NULL for zeros.
proto_status_t canopen_encode_emcy(canopen_frame_t* f, uint8_t node, uint16_t error_code,
                                   uint8_t error_register, const uint8_t* vendor);

// ---------------------------------------------------------------------------------------------
// Frame classification and decoders

/// What a frame is, by COB-ID.
typedef enum canopen_kind {
  CANOPEN_KIND_UNKNOWN = 0,  ///< Any other COB-ID (SDO, PDO3/4, time stamp, out of range).
  CANOPEN_KIND_NMT,
  CANOPEN_KIND_SYNC,
  CANOPEN_KIND_EMCY,
  CANOPEN_KIND_TPDO1,
  CANOPEN_KIND_RPDO1,
  CANOPEN_KIND_TPDO2,
  CANOPEN_KIND_RPDO2,
  CANOPEN_KIND_HEARTBEAT,
} canopen_kind_t;

/// Classifies by COB-ID and returns the node id (0 for NMT/SYNC/unknown) in *node (may be NULL).
/// Does not check the DLC. O(1).
canopen_kind_t canopen_classify(const canopen_frame_t* f, uint8_t* node);

/// Decoded NMT command.
typedef struct canopen_nmt {
  uint8_t command;  ///< CANOPEN_NMT_START, ...
  uint8_t node;     ///< 0 = all nodes.
} canopen_nmt_t;

/// Decoded EMCY.
typedef struct canopen_emcy {
  uint8_t node;
  uint16_t error_code;     ///< 0x0000 = error reset / no error.
  uint8_t error_register;
  uint8_t vendor[5];
} canopen_emcy_t;

/// Decoded PDOs (fields the fixed mapping carries).
typedef struct canopen_rpdo1 {
  uint8_t node;
  uint16_t controlword;
  int32_t target_velocity;  ///< Counts/s.
} canopen_rpdo1_t;

typedef struct canopen_tpdo1 {
  uint8_t node;
  uint16_t statusword;
  int32_t velocity_actual;  ///< Counts/s.
} canopen_tpdo1_t;

typedef struct canopen_tpdo2 {
  uint8_t node;
  int32_t position_actual;  ///< Counts.
} canopen_tpdo2_t;

typedef struct canopen_heartbeat {
  uint8_t node;
  uint8_t nmt_state;  ///< Low 7 bits of byte 0 (bit 7 is the node-guarding toggle).
} canopen_heartbeat_t;

/// Decoders. Each returns PROTO_OK, PROTO_ERR_FORMAT (wrong COB-ID kind or DLC shorter than the
/// mapping), or PROTO_ERR_INVALID_ARG. Longer DLCs are accepted (extra bytes ignored). O(1).
proto_status_t canopen_decode_nmt(const canopen_frame_t* f, canopen_nmt_t* out);
proto_status_t canopen_decode_emcy(const canopen_frame_t* f, canopen_emcy_t* out);
proto_status_t canopen_decode_rpdo1(const canopen_frame_t* f, canopen_rpdo1_t* out);
proto_status_t canopen_decode_tpdo1(const canopen_frame_t* f, canopen_tpdo1_t* out);
proto_status_t canopen_decode_tpdo2(const canopen_frame_t* f, canopen_tpdo2_t* out);
proto_status_t canopen_decode_heartbeat(const canopen_frame_t* f, canopen_heartbeat_t* out);

/// Decoded bump-panel TPDO1 of the CiA 401 node.
typedef struct cia401_bumpers {
  uint8_t node;
  uint8_t panels[CIA401_BUMP_PANELS];  ///< Per panel its segment bits 0..0x0F (0 = released).
} cia401_bumpers_t;

/// Bump-panel TPDO1 (input node -> host) from the panels' segment bits (each 0..0x0F).
/// @return PROTO_OK, or PROTO_ERR_INVALID_ARG (NULL, node not 1..127, a value above 0x0F). O(1).
proto_status_t cia401_encode_bumpers(canopen_frame_t* f, uint8_t node, const uint8_t panels[CIA401_BUMP_PANELS]);
/// Decodes a bump-panel TPDO1: PROTO_OK, PROTO_ERR_FORMAT (not a TPDO1, DLC below 7) or
/// PROTO_ERR_INVALID_ARG. The node id is the frame's; the caller checks it is the input node
/// (a drive's TPDO1 has the same function code). O(1).
proto_status_t cia401_decode_bumpers(const canopen_frame_t* f, cia401_bumpers_t* out);
/// Bit p set when panel p has any segment pressed (the layout of rflex_host_t.bumper_mask).
/// NULL gives 0. O(panels).
uint32_t cia401_bumper_mask(const cia401_bumpers_t* b);

/// Drive counts from an SI value (m/s, rad/s, m, rad) and a counts-per-unit factor:
/// round(value × counts_per_unit), saturated to int32; non-finite input gives 0. O(1).
int32_t canopen_counts_from_si(double value, double counts_per_unit);
/// SI value from counts: counts / counts_per_unit (0 if the factor is 0). O(1).
double canopen_si_from_counts(int32_t counts, double counts_per_unit);

// ---------------------------------------------------------------------------------------------
// CiA 402 power state machine

/// Drive states (CiA 402 figure "state machine").
typedef enum cia402_state {
  CIA402_NOT_READY_TO_SWITCH_ON = 0,
  CIA402_SWITCH_ON_DISABLED,
  CIA402_READY_TO_SWITCH_ON,
  CIA402_SWITCHED_ON,
  CIA402_OPERATION_ENABLED,
  CIA402_QUICK_STOP_ACTIVE,
  CIA402_FAULT_REACTION_ACTIVE,
  CIA402_FAULT,
  CIA402_STATE_UNKNOWN,  ///< Statusword matches no state pattern.
} cia402_state_t;

/// State from a statusword: masks 0x4F / 0x6F per CiA 402 (0x6F == 0x27 -> OPERATION_ENABLED;
/// 0x4F == 0x08 -> FAULT; ...). O(1).
cia402_state_t cia402_state_from_statusword(uint16_t statusword);
/// Short name ("operation_enabled", ...), never NULL.
const char* cia402_state_name(cia402_state_t state);
/// True when the statusword says operation enabled (mask 0x6F == 0x27). O(1).
bool cia402_operation_enabled(uint16_t statusword);
/// True when the fault bit (bit 3) is set. O(1).
bool cia402_fault(uint16_t statusword);

/// What the host wants from a drive.
typedef enum cia402_request {
  CIA402_REQ_DISABLE = 0,   ///< Bring to SWITCH_ON_DISABLED / READY (no torque).
  CIA402_REQ_ENABLE,        ///< Walk to OPERATION_ENABLED, resetting faults on the way.
  CIA402_REQ_QUICK_STOP,    ///< Quick stop (decelerate on the drive's quick-stop ramp).
} cia402_request_t;

/// Host-side controlword sequencer for one drive. Keeps the last controlword so that a fault
/// reset is always a rising edge of bit 7 (it sends 0x00 first if bit 7 was already high).
typedef struct cia402_master {
  uint16_t last_controlword;
  uint64_t fault_resets;  ///< Fault-reset edges sent.
} cia402_master_t;

/// Initialises (last controlword 0). O(1).
void cia402_master_init(cia402_master_t* m);
/// Next controlword for the drive's current statusword and the request:
/// ENABLE: SWITCH_ON_DISABLED -> 0x06, READY -> 0x07, SWITCHED_ON -> 0x0F, ENABLED -> 0x0F,
/// QUICK_STOP_ACTIVE -> 0x00, FAULT -> 0x80 after a 0x00 (rising edge), other -> 0x00.
/// DISABLE: 0x06 from SWITCHED_ON/ENABLED (-> READY), else 0x00. QUICK_STOP: 0x02.
/// Call once per cycle and send the result in RPDO1. O(1).
uint16_t cia402_master_controlword(cia402_master_t* m, uint16_t statusword, cia402_request_t req);

/// Device-side (emulated drive) state machine.
typedef struct cia402_drive {
  cia402_state_t state;
  uint16_t last_controlword;
  bool fault_active;       ///< Fault condition present (set by cia402_drive_set_fault()).
  uint16_t error_code;     ///< Last fault's EMCY error code.
  uint64_t transitions;    ///< State changes made.
  uint64_t ignored_commands;  ///< Controlwords that are not valid in the current state.
} cia402_drive_t;

/// Starts in SWITCH_ON_DISABLED (NOT_READY passes automatically on power-up). O(1).
void cia402_drive_init(cia402_drive_t* d);
/// Applies a received controlword per the CiA 402 transition table (shutdown, switch on,
/// enable/disable operation, disable voltage, quick stop; fault reset on the rising edge of
/// bit 7, effective only when the fault condition has been cleared). READY + 0x0F goes to
/// OPERATION_ENABLED (transitions 3 + 4). QUICK_STOP_ACTIVE stays until disable voltage or
/// enable operation. O(1).
void cia402_drive_apply_controlword(cia402_drive_t* d, uint16_t controlword);
/// Raises (code != 0) a fault: any state -> FAULT. A code of 0 clears the fault condition so
/// that the next fault-reset edge succeeds (the state stays FAULT until then). O(1).
void cia402_drive_set_fault(cia402_drive_t* d, uint16_t error_code);
/// Statusword for the current state, with voltage-enabled and remote bits as a real drive
/// reports them (e.g. 0x0237 operation enabled, 0x0250 switch on disabled, 0x0218 fault). O(1).
uint16_t cia402_drive_statusword(const cia402_drive_t* d, bool target_reached);
/// True when the drive follows the target velocity (OPERATION_ENABLED). O(1).
bool cia402_drive_enabled(const cia402_drive_t* d);

// ---------------------------------------------------------------------------------------------
// Heartbeat consumer (host side). Time is passed in by the caller; nothing here reads a clock.

typedef struct canopen_hb_consumer {
  uint8_t node;
  uint32_t timeout_us;   ///< Silence longer than this is a fault.
  bool seen;             ///< A heartbeat has arrived.
  uint8_t nmt_state;     ///< Last reported state.
  uint64_t last_us;      ///< Time of the last heartbeat.
  uint64_t count;        ///< Heartbeats received.
  uint64_t bootups;      ///< Boot-up messages (state 0) seen: the drive restarted.
} canopen_hb_consumer_t;

/// @return PROTO_OK or INVALID_ARG (node not 1..127, timeout 0). O(1).
proto_status_t canopen_hb_init(canopen_hb_consumer_t* c, uint8_t node, uint32_t timeout_us);
/// Consumes a frame if it is this node's heartbeat; returns true if it was. O(1).
bool canopen_hb_feed(canopen_hb_consumer_t* c, const canopen_frame_t* f, uint64_t now_us);
/// True when no heartbeat was seen within timeout_us of now_us (measured from since_us until
/// the first heartbeat arrives, e.g. the time the master started). O(1).
bool canopen_hb_expired(const canopen_hb_consumer_t* c, uint64_t now_us, uint64_t since_us);

#ifdef __cplusplus
}
#endif

#endif  // PROTO_CANOPEN_H
