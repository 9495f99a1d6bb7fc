// SPDX-License-Identifier: MIT
/// sim/emulator.h — The emulated B21r: ODE plant + LMS200 + base (rFLEX, or two CiA 402 drives
/// and a CiA 401 bump-panel input node), in lockstep or real time, transport-agnostic (bytes and frames in memory). This header is the
/// contract between the emulator (sim/) and the controller (firmware/).
///
/// ## Transport
/// Each device consumes host bytes / CAN frames and produces device bytes / frames in memory
/// (`*_write` / `*_read`). The same object runs behind pseudo-terminals and a SOCK_SEQPACKET CAN
/// socket (the b21r-sim program, sim/endpoints.h) or linked in-process into an experiment runner.
///
/// ## Lockstep (deterministic, faster than real time)
/// - Time advances only in whole control periods (period_s, default 0.1 s = 10 Hz), each made
///   of period_s / dt_s ODE substeps. Simulated time = substeps * dt_s, never wall time.
/// - At sim time t_k the emulator has emitted exactly one LMS200 0xB0 scan telegram and one
///   MOT_SYSTEM_REPORT per axis (rFLEX) - or, on CANopen, the drives' TPDO1 + TPDO2 answering
///   the controller's SYNC - plus a DIO_REPORT for each bump panel whose state changed (rFLEX,
///   when DIO reports are on) or the bump-panel node's TPDO1 (CANopen, node 16, while NMT
///   operational: its event timer equals the period, so one per period, read before the drives'
///   TPDOs). CANopen heartbeats follow simulated time (one per node per heartbeat period), so in
///   lockstep they appear only as time advances.
/// - The controller reads those, runs its tick and sends its command for the cycle: on rFLEX
///   the MOT_AXIS_SET_DIR pair (translation, then rotation); on CANopen RPDO1 of both drives
///   followed by SYNC. Receiving the rotation SET_DIR (rFLEX) or the SYNC (CANopen) advances the
///   emulator by one period under the new command, after which it emits the data for t_{k+1}.
///   Every other host packet (SYS_STATUS, brake, defaults, report requests, NMT, laser
///   commands) is answered at once without advancing time.
/// - Streaming starts when the controller has started the laser stream (LMS `20 24`) and
///   - rFLEX: requested odometry reports (MOT_SYSTEM_REPORT_REQ, period > 0, mask != 0): the
///     emulator then emits the t_0 data at once (after the reply to the completing request);
///   - CANopen: started both drives (NMT start) and enabled them (OPERATION_ENABLED): the
///     emulator then emits the t_0 scan and bump-panel inputs at once (with the answer to the
///     first SYNC after both are enabled, if the laser streamed first); every later SYNC
///     advances one period. Every SYNC gets exactly one TPDO1 and one TPDO2 from each
///     operational drive (before streaming, and for the frame that starts it, at the current
///     time), so the host can match answers to SYNCs; no other TPDO is ever sent.
///   Neither base needs a command to start: the host's first command ends period 0 (a host
///   that sends commands while waiting for the t_0 data gets more than one period's data).
///   Streaming stops (time stands still again) when the laser stream stops, odometry is
///   switched off (rFLEX) or a drive leaves NMT operational (CANopen). A drive fault does not
///   stop it: the controller keeps receiving scans and TPDOs (statusword with the fault bit)
///   while it handles the fault.
/// - In lockstep the controller waits (poll with a generous wall timeout) for one full scan and
///   odometry per tick (CANopen: the answers to every SYNC it has sent).
///
/// ## Real time
/// The caller runs sim_emu_run_until(now) on its own monotonic clock; the laser streams at the
/// rate its baud rate allows, bytes leave at the line rate, odometry follows the requested
/// period, TPDOs answer each SYNC at once, and the base's command watchdog (default 1 s) stops
/// the robot when commands stop.
///
/// ## Control (sim_emu_control; the b21r-sim control socket carries the same text)
/// One command per call, one reply: "ok ..." or "error <reason>".
/// - `reset <x_m> <y_m> <theta_rad>`: place the robot (velocities zero, contacts cleared); used
///   between runs. Time and odometry keep running. Starts a new run in the trace. Each value
///   must lie within +-SIM_WORLD_MAX_ABS (the range of world files), else `error reset: ...`.
/// - `pose`: `ok <t_s> <x_m> <y_m> <theta_rad> <collided 0|1>` (ground truth; collided latches
///   from the first contact until the next reset).
/// - `fault laser_drop <ms>` | `fault laser_stuck <ms>` | `fault corrupt <fraction>` |
///   `fault noise_laser <fraction>` | `fault noise_base <fraction>` |
///   `fault can_errors <fraction>` | `fault can_drop <fraction>` | `fault bus_off <ms>` |
///   `fault base_silent <ms>` | `fault drive_fault <node>` |
///   `fault latency <ms>` | `fault bumper <panel>` | `fault bumper_silent <ms>` |
///   `fault node_stuck <node> <ms>` | `fault babble <node> <ms>` | `fault clear`.
///   Durations are simulated time. laser_stuck: every scan repeats the last measured distances
///   bit for bit (valid telegrams, CRC and scan index fine: a frozen measurement stage).
///   corrupt: each byte read from a serial line is hit with that probability, half the hits line
///   noise (XORed with a random non-zero value), half framing errors (read as NUL, as a Linux tty
///   without IGNPAR delivers them); noise_laser and noise_base: the same on one line only. On the
///   CAN bus (corrupt) each frame's transmission fails its CRC with that
///   probability: the bus signals an error frame (sim_emu_can_take_error_frames) and the frame
///   is sent again, so, as on a real bus, no damaged payload is delivered; can_errors: the same on
///   the bus only. can_drop: each frame
///   is lost with that probability (a receiver overrun). bus_off: the host's CAN controller goes
///   bus-off (after too many failed transmissions a controller switches itself off the bus):
///   for that long it receives and sends nothing, then restarts; the transport signals both as
///   error frames (sim_emu_can_take_bus_event). node_stuck: the node's application hangs:
///   its PDOs keep coming with the values it had (stale), its heartbeat and EMCY stop. babble: a
///   node floods the bus with COB-ID 0x001 frames (4000 per simulated second) and, winning every
///   arbitration, keeps every other node's frame off the bus. latency: stored
///   here, applied by the transport (b21r-sim holds every outgoing byte/frame that long in wall
///   time). bumper: panel 0..13 (or its DIO address 0x40..0x4D) reads pressed (bits 0x0F) until
///   `fault clear`, on either base (rFLEX: DIO_REPORT; CANopen: the bump-panel node's TPDO1).
///   base_silent: the rFLEX, or on CANopen the drives (the bump-panel node keeps sending).
///   drive_fault, can_errors, can_drop, bus_off, node_stuck, babble: CANopen base only. bumper_silent: CANopen only;
///   the bump-panel node sends nothing (no PDO, no heartbeat) for that long.
/// - `status`: `ok t=<s> streaming=<0|1> scans=<n> base_reports=<n> contacts=<n> watchdog_trips=<n>`
///   (watchdog_trips: times the base's command watchdog stopped it: rFLEX trips, CiA 402 RPDO timeouts).
/// - `svg <path>`: writes the trace picture (sim/svg.h).
/// - `quit`: reply `ok bye`; sim_emu_control returns SIM_EMU_CTRL_QUIT (the program exits).
///
/// Memory: sim_emu_create allocates the plant, the devices and the trace (trace_capacity
/// points); nothing per tick except inside ODE's step arena. Not thread-safe: one thread per
/// emulator (ODE collision data is per thread).
/// Determinism: a lockstep run is a function of (world, config, seed, host byte/frame stream):
/// same inputs, same binary -> identical output streams (tested by hashing two runs).
#ifndef B21R_SIM_EMULATOR_H
#define B21R_SIM_EMULATOR_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include <proto/canopen.h>

#include "sim/cia401_dev.h"
#include "sim/cia402_dev.h"
#include "sim/lms200_dev.h"
#include "sim/plant.h"
#include "sim/rflex_dev.h"
#include "sim/svg.h"
#include "sim/world.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum sim_mode {
  SIM_MODE_LOCKSTEP = 0,
  SIM_MODE_REALTIME = 1,
} sim_mode_t;

typedef enum sim_base_kind {
  SIM_BASE_RFLEX = 0,    ///< rFLEX serial base (the B21r's own)
  SIM_BASE_CANOPEN = 1,  ///< two CiA 402 drives (protocols.md D.1)
} sim_base_kind_t;

/// Configuration. Defaults: sim_emu_config_default. The devices' `paced` flags and seeds are
/// set by sim_emu_create from mode and seed.
typedef struct sim_emu_config {
  sim_mode_t mode;              ///< [SIM_MODE_LOCKSTEP]
  sim_base_kind_t base;         ///< [SIM_BASE_RFLEX]
  double period_s;              ///< control period; a whole multiple of plant.dt_s [0.1]
  uint64_t seed;                ///< every random stream (noise, corruption) derives from it [1]
  sim_plant_config_t plant;     ///< [sim_plant_config_default]
  sim_lms_config_t laser;       ///< [sim_lms_config_default]
  sim_rflex_config_t rflex;     ///< [sim_rflex_config_default]
  sim_cia402_config_t cia402;   ///< [sim_cia402_config_default]
  sim_cia401_config_t cia401;   ///< CANopen bump-panel node [sim_cia401_config_default]
  size_t trace_capacity;        ///< poses kept for the picture (one per period) [200000]
} sim_emu_config_t;

/// Result of sim_emu_control.
typedef enum sim_emu_ctrl {
  SIM_EMU_CTRL_OK = 0,     ///< reply starts with "ok"
  SIM_EMU_CTRL_ERROR = 1,  ///< reply starts with "error"
  SIM_EMU_CTRL_QUIT = 2,   ///< "quit" received: reply "ok bye"; the caller should stop
} sim_emu_ctrl_t;

typedef struct sim_emu sim_emu_t;

/// Fills the defaults documented above. O(1).
void sim_emu_config_default(sim_emu_config_t* cfg);

/// Creates the emulator; the robot starts at the world's first start pose. Returns NULL on an
/// invalid configuration (period not a positive multiple of dt, invalid device configs) or
/// when memory or ODE cannot be set up.
sim_emu_t* sim_emu_create(const sim_world_t* world, const sim_emu_config_t* cfg);
void sim_emu_destroy(sim_emu_t* e);

/// Laser serial line: host -> LMS200 bytes, and LMS200 -> host bytes. O(bytes).
void sim_emu_laser_write(sim_emu_t* e, const uint8_t* bytes, size_t n);
size_t sim_emu_laser_read(sim_emu_t* e, uint8_t* out, size_t cap);

/// rFLEX serial line (base SIM_BASE_RFLEX; ignored otherwise). In lockstep a rotation SET_DIR
/// advances one period inside this call (O(substeps + beams)).
void sim_emu_base_write(sim_emu_t* e, const uint8_t* bytes, size_t n);
size_t sim_emu_base_read(sim_emu_t* e, uint8_t* out, size_t cap);

/// CAN bus (base SIM_BASE_CANOPEN; ignored otherwise). In lockstep a SYNC advances one period
/// inside this call. can_read returns 1 with the next frame of a node (the bump-panel node's
/// first, then the drives'), or 0.
void sim_emu_can_write(sim_emu_t* e, const canopen_frame_t* f);
int sim_emu_can_read(sim_emu_t* e, canopen_frame_t* f);
/// Error frames the bus signalled (failed CRCs under `fault corrupt`) since the last call; the
/// transport sends them to the host as error frames. O(1).
uint32_t sim_emu_can_take_error_frames(sim_emu_t* e);

/// A change of the host's CAN controller state under `fault bus_off`, for the transport to signal
/// as an error frame (SocketCAN: CAN_ERR_BUSOFF, then CAN_ERR_RESTARTED).
typedef enum sim_emu_bus_event {
  SIM_EMU_BUS_NONE = 0,
  SIM_EMU_BUS_OFF = 1,        ///< the controller went bus-off
  SIM_EMU_BUS_RESTARTED = 2,  ///< it is back on the bus
} sim_emu_bus_event_t;
/// The next pending state change, bus-off before its restart; SIM_EMU_BUS_NONE when there is
/// none. Call it after sim_emu_can_read (a restart is noticed there). O(1).
sim_emu_bus_event_t sim_emu_can_take_bus_event(sim_emu_t* e);

/// Real-time mode: advances physics and device timing to t_s (no effect in lockstep or for
/// t_s in the past). O(substeps).
void sim_emu_run_until(sim_emu_t* e, double t_s);

/// Current simulated time [s].
double sim_emu_time(const sim_emu_t* e);

/// True while lockstep streaming is running (see above); in real time: the laser streams.
bool sim_emu_streaming(const sim_emu_t* e);

/// Ground truth. O(1).
void sim_emu_state(const sim_emu_t* e, sim_plant_state_t* out);

/// Places the robot (see `reset`); sensor noise goes on from where it was. O(1).
void sim_emu_reset(sim_emu_t* e, double x_m, double y_m, double theta_rad);

/// Places the robot for the run identified by run_stream (see `reset` with a fourth number): the
/// sensor-noise stream restarts from (emulator seed, run_stream), so the run's scans do not depend
/// on what earlier runs did or how long they took. The controller passes the id of the run about
/// to start: variants of an experiment (other learners, settings) then see the same noise in the
/// same run, and a paired comparison measures the variant, not the noise. O(1).
void sim_emu_reset_run(sim_emu_t* e, double x_m, double y_m, double theta_rad, uint64_t run_stream);

/// Executes one control command (see above); writes a NUL-terminated reply. O(1) except `svg`.
sim_emu_ctrl_t sim_emu_control(sim_emu_t* e, const char* line, char* reply, size_t cap);

/// The latency fault in force [s] (applied by the transport).
double sim_emu_latency_s(const sim_emu_t* e);

/// The devices and plant, for inspection in tests (owned by the emulator; NULL when absent).
sim_lms_t* sim_emu_laser(sim_emu_t* e);
sim_rflex_t* sim_emu_rflex(sim_emu_t* e);
sim_cia402_t* sim_emu_cia402(sim_emu_t* e);
sim_cia401_t* sim_emu_cia401(sim_emu_t* e);
sim_plant_t* sim_emu_plant(sim_emu_t* e);

/// The recorded trace (one point per control period, runs separated by resets).
const sim_trace_point_t* sim_emu_trace(const sim_emu_t* e, size_t* n_points);

/// Writes the trace picture (sim_svg_write). Returns 0 or -1 (errno set).
int sim_emu_write_svg(const sim_emu_t* e, const char* path);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_EMULATOR_H
