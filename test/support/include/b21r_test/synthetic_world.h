// SPDX-License-Identifier: MIT
/// b21r_test/synthetic_world.h — An analytic 2-D world (wall segments, circular obstacles), an
/// exact ray caster producing LMS200-like scans, and a kinematic synchro-drive stepper.
///
/// Purpose: ground truth for tests. Feature tests place a robot at a known pose and compare the
/// features computed from the synthetic scan with the exact geometry; task tests run whole
/// episodes on the kinematic model; the emulator's ODE ray casts are checked against
/// synth_world_raycast, which is exact up to double rounding (closed-form line and circle
/// intersections, no stepping, no tolerance).
///
/// Frames: a world frame (x, y in metres, angles CCW in radians). The robot pose is its centre
/// and heading; the laser sits at a mount pose on the robot (default 0.15 m forward); beam i has
/// bearing angle_min + i * increment in the laser frame (LMS200 180°: -90°..+90°, index 0 on the
/// right, CCW).
///
/// Memory: everything lives in caller-owned structs of fixed size (synth_world_t is about 3 KB);
/// no allocation. Deterministic: randomness only from a caller-owned synth_rng_t (splitmix64).
/// Not thread-safe per instance. Depends on libc and libm only (never on the project's
/// libraries), so any test and the emulator's tests can use it.
#ifndef B21R_TEST_SYNTHETIC_WORLD_H
#define B21R_TEST_SYNTHETIC_WORLD_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SYNTH_MAX_SEGMENTS 64
#define SYNTH_MAX_CIRCLES 16
/// Largest scan (LMS200 100° at 0.25°).
#define SYNTH_MAX_BEAMS 401
/// LMS200 millimetre-mode raw value for "no echo" (8191 mm), used when raw codes are emitted.
#define SYNTH_LMS200_NO_ECHO_M 8.191
/// Returns at or beyond this range come back as "no echo" in millimetre mode (8183 mm is the
/// first saturation code, protocols.md B.5).
#define SYNTH_LMS200_MAX_RANGE_M 8.183

/// A wall: the segment from (x0, y0) to (x1, y1) [m]. Seen from both sides.
typedef struct synth_segment {
  double x0_m, y0_m, x1_m, y1_m;
} synth_segment_t;

/// A vertical cylinder (obstacle, person, bin): centre and radius [m].
typedef struct synth_circle {
  double x_m, y_m, radius_m;
} synth_circle_t;

/// The world. Fill with synth_world_init and the add functions; fields are read-only to users.
typedef struct synth_world {
  synth_segment_t segments[SYNTH_MAX_SEGMENTS];
  uint32_t n_segments;
  synth_circle_t circles[SYNTH_MAX_CIRCLES];
  uint32_t n_circles;
} synth_world_t;

/// What a ray hit.
typedef enum synth_hit_kind {
  SYNTH_HIT_NONE = 0,
  SYNTH_HIT_SEGMENT = 1,
  SYNTH_HIT_CIRCLE = 2,
} synth_hit_kind_t;

typedef struct synth_hit {
  uint8_t kind;    ///< synth_hit_kind_t
  uint32_t index;  ///< segment or circle index
} synth_hit_t;

/// Empties the world.
void synth_world_init(synth_world_t* w);
/// Adds a wall segment; returns 0, or -1 when full or the segment is degenerate/non-finite.
int synth_world_add_segment(synth_world_t* w, double x0_m, double y0_m, double x1_m, double y1_m);
/// Adds a circle; returns 0, or -1 when full or radius <= 0 / non-finite.
int synth_world_add_circle(synth_world_t* w, double x_m, double y_m, double radius_m);
/// Adds the four walls of an axis-aligned box (a room); returns 0 or -1 (nothing added).
int synth_world_add_box(synth_world_t* w, double min_x_m, double min_y_m, double max_x_m,
                        double max_y_m);
/// Adds a closed corridor in the corridor frame of lib/tasks: side walls y = +-width/2 for
/// x in [0, length], a start wall at x = 0 and an end wall at x = length. Returns 0 or -1.
int synth_world_add_corridor(synth_world_t* w, double length_m, double width_m);

/// Exact distance along the ray from (ox, oy) in direction dir_rad to the first wall or circle,
/// or +INFINITY when nothing is hit. A ray starting inside a circle returns 0. hit may be NULL.
/// O(n_segments + n_circles).
double synth_world_raycast(const synth_world_t* w, double ox_m, double oy_m, double dir_rad,
                           synth_hit_t* hit);

/// Distance from the point to the nearest geometry (segments: Euclidean distance; circles:
/// distance to the surface, negative inside). +INFINITY for an empty world.
double synth_world_clearance(const synth_world_t* w, double x_m, double y_m);

/// 1 if a disc of radius_m at (x, y) touches or overlaps any geometry.
int synth_world_collides(const synth_world_t* w, double x_m, double y_m, double radius_m);

// ---------------------------------------------------------------------------------------------
// Seeded randomness (splitmix64; independent of the product's generators on purpose)
// ---------------------------------------------------------------------------------------------

typedef struct synth_rng {
  uint64_t state;
} synth_rng_t;

void synth_rng_seed(synth_rng_t* r, uint64_t seed);
uint64_t synth_rng_next(synth_rng_t* r);
/// Uniform in [0, 1).
double synth_rng_uniform(synth_rng_t* r);
/// Standard normal (Box-Muller, one value per call).
double synth_rng_normal(synth_rng_t* r);

// ---------------------------------------------------------------------------------------------
// LMS200-like laser
// ---------------------------------------------------------------------------------------------

/// Reason codes written to no_return[] (0 = valid), mirroring the LMS200 error classes.
typedef enum synth_no_return {
  SYNTH_NR_VALID = 0,
  SYNTH_NR_NO_ECHO = 1,   ///< nothing within max range (8191)
  SYNTH_NR_DAZZLE = 2,    ///< dazzling (8190)
  SYNTH_NR_SNR = 3,       ///< signal-to-noise too small (8187)
  SYNTH_NR_DROPOUT = 4,   ///< a random missing beam (e.g. black or glossy surface)
} synth_no_return_t;

typedef struct synth_lidar_config {
  double angle_min_rad;        ///< bearing of beam 0 in the laser frame
  double angle_increment_rad;  ///< > 0
  uint16_t n_beams;            ///< <= SYNTH_MAX_BEAMS
  double mount_x_m;            ///< laser pose on the robot [m, m, rad]
  double mount_y_m;
  double mount_yaw_rad;
  double max_range_m;          ///< true ranges >= this give NO_ECHO [SYNTH_LMS200_MAX_RANGE_M]
  double noise_sigma_m;        ///< Gaussian range noise, standard deviation [m] [0.01]
  double quantum_m;            ///< output rounded to this (0.001 = mm mode; 0 = no rounding)
  double dropout_prob;         ///< per-beam probability of a DROPOUT [0]
  double error_code_prob;      ///< per-beam probability of DAZZLE or SNR [0]
  /// 0: a beam without return has range 0 and a reason code (as a decoder reports it).
  /// 1: it carries the raw millimetre-mode code as a range (8.191 / 8.190 / 8.187 m) and
  ///    no_return = 0, as if a decoder passed codes through; consumers must reject it by range.
  uint8_t raw_error_codes;
} synth_lidar_config_t;

/// LMS200 geometry: field_deg 180 or 100, resolution_deg 1, 0.5 or 0.25 (0.25 only with 100);
/// mount 0.15 m forward, max range 8.183 m, noise 0.01 m, mm quantum, no dropouts or codes.
/// Returns 0, or -1 for an unsupported combination (cfg unchanged).
int synth_lidar_config_lms200(synth_lidar_config_t* cfg, int field_deg, double resolution_deg);

/// Casts one scan from a robot at (x, y, theta) (world frame). Writes ranges_m[i] and
/// no_return[i] for i < n_beams; returns n_beams, or -1 if capacity < n_beams or cfg is invalid.
/// Draws from rng only when noise, dropouts or codes are enabled (rng may be NULL otherwise).
/// O(n_beams * (n_segments + n_circles)).
int synth_lidar_scan(const synth_world_t* w, const synth_lidar_config_t* cfg, synth_rng_t* rng,
                     double robot_x_m, double robot_y_m, double robot_theta_rad, float* ranges_m,
                     uint8_t* no_return, uint16_t capacity);

// ---------------------------------------------------------------------------------------------
// Kinematic synchro drive
// ---------------------------------------------------------------------------------------------

/// State of the idealised synchro-drive robot (protocols.md C: x' = v cos th, y' = v sin th,
/// th' = omega).
typedef struct synth_robot {
  double x_m, y_m, theta_rad;  ///< pose, world frame
  double v_mps;                ///< current translation velocity
  double omega_radps;          ///< current rotation velocity
} synth_robot_t;

/// Acceleration limits per axis; 0 (or negative) = unlimited (velocity jumps to the command).
typedef struct synth_drive_limits {
  double acc_mps2;
  double acc_radps2;
} synth_drive_limits_t;

/// Advances the robot by dt_s: velocities move towards the commands within the limits (limits
/// may be NULL = unlimited), then the heading is updated first and the robot translates along
/// the new heading (the order the B21r odometry integrates). theta stays in (-pi, pi].
void synth_drive_step(synth_robot_t* r, double v_cmd_mps, double omega_cmd_radps, double dt_s,
                      const synth_drive_limits_t* limits);

#ifdef __cplusplus
}
#endif

#endif  // B21R_TEST_SYNTHETIC_WORLD_H
