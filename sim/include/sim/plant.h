// SPDX-License-Identifier: MIT
/// sim/plant.h — The B21r body on ODE: a synchro-drive cylinder in a world of walls and
/// cylinders, with contacts, bumper panels and laser ray casts.
///
/// Model:
/// - The base is a rigid cylinder (radius 0.26 m, height 0.30 m: the base skirt) moving on the
///   floor plane. Its two motion axes (translation, rotation) each approach their commanded
///   velocity under an acceleration limit (sim_kin_axis_approach); per substep the heading
///   turns first, then the body translates along the new heading (protocols.md C), so in free
///   space the plant equals sim/kinematic.h to rounding.
/// - ODE (double precision) carries translation and contacts; the heading is integrated by the
///   plant itself (the base cylinder is rotationally symmetric, so its ODE orientation never
///   matters, and the heading stays bit-identical to the kinematic model).
/// - Tick order, per substep of dt_s: set the body velocity from the axes -> collide the base
///   against the static geoms (contact joints, infinite friction) -> dWorldStep(dt_s) -> empty
///   the contact group -> read the pose. Simulation time is substeps * dt_s, never wall time.
/// - A contact stops the body (it cannot move into the obstacle; with infinite friction it does
///   not slide along it either) and clamps the translation axis to what the body actually did,
///   so wheel odometry stops too. `collided` latches until sim_plant_reset; `in_contact` is the
///   current state; `bumper_panel` names the base bump panel (0..7 of the 8 base panels, i.e.
///   DIO addresses 0x46..0x4D) at the contact bearing.
/// - Bump panels of the base skirt: the synchro-drive skirt keeps its orientation while the
///   enclosure steers (protocols.md A.6), so base panel k covers the bearings
///   [k*45 deg - 22.5 deg, k*45 deg + 22.5 deg) CCW from the skirt's front, which is the heading
///   at the last sim_plant_reset.
/// - The laser (LMS200) sits on the steering enclosure at the configured mount, at 0.355 m
///   above the floor; sim_plant_scan casts one ray per beam against walls and cylinders (never
///   the robot itself). Every obstacle is taller than that plane, so the cast is the exact 2-D
///   intersection with the world's geometry (sim_world_raycast), the same solids as the ODE
///   geoms: about 0.05 µs per ray, a quarter of ODE's generic ray-geom collision.
///
/// Memory: sim_plant_create allocates the plant and ODE's world, space, geoms and contact
/// group; steps allocate nothing of their own (ODE reuses its step arena). Not thread-safe: one
/// thread per plant (ODE collision data is allocated for the creating thread).
/// Determinism: dWorldStep (not QuickStep, which reorders constraints with ODE's global RNG),
/// fixed iteration order over geoms: identical inputs give bit-identical trajectories.
#ifndef B21R_SIM_PLANT_H
#define B21R_SIM_PLANT_H

#include <stddef.h>
#include <stdint.h>

#include "sim/kinematic.h"
#include "sim/world.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SIM_ROBOT_RADIUS_M 0.26          ///< base skirt radius (protocols.md C)
#define SIM_ROBOT_HEIGHT_M 0.30          ///< base skirt height
#define SIM_LASER_HEIGHT_M 0.355         ///< LMS200 mirror height above the floor
#define SIM_LASER_X_DEFAULT_M 0.15       ///< forward mount offset (Player's B21r configuration)
#define SIM_BASE_PANELS 8                ///< bump panels on the base skirt (DIO 0x46..0x4D)

/// Configuration of a plant. Defaults: sim_plant_config_default.
typedef struct sim_plant_config {
  double dt_s;                ///< ODE substep [s], default 0.01; (0, 0.1]
  double robot_radius_m;      ///< default SIM_ROBOT_RADIUS_M
  sim_kin_limits_t limits;    ///< axis acceleration limits, default sim_kin_limits_default
  double laser_x_m;           ///< laser mount, robot frame: forward [m], default 0.15
  double laser_y_m;           ///< left [m], default 0
  double laser_yaw_rad;       ///< bearing of the laser's 0 deg beam in the robot frame, default 0
} sim_plant_config_t;

/// Snapshot of the plant (ground truth and wheel odometry).
typedef struct sim_plant_state {
  uint64_t substeps;          ///< substeps since creation (sim time = substeps * dt_s)
  double t_s;                 ///< simulation time [s]
  double x_m, y_m, theta_rad; ///< ground-truth pose
  double v_mps;               ///< translation axis velocity (wheel speed) [m/s]
  double omega_radps;         ///< rotation axis velocity [rad/s]
  // Axis positions (wheel odometry) in two parts: the position at the last reset plus the motion
  // since (summed in counts by sim_plant_axis_counts). Each run's encoder steps then depend only
  // on the run's motion, not on the rounding of a position that grew over earlier runs.
  double odo_trans_m;         ///< translation axis: signed distance rolled since the last reset [m]
  double odo_rot_rad;         ///< rotation axis: heading change accumulated since the last reset [rad]
  double odo_trans_at_reset_m;  ///< translation axis position at the last reset [m]
  double odo_rot_at_reset_rad;  ///< rotation axis position at the last reset [rad]
  int in_contact;             ///< 1 while the base touches an obstacle
  int collided;               ///< 1 once the base touched anything since the last reset
  int bumper_panel;           ///< base panel 0..7 at the contact bearing, -1 without contact
  uint8_t bumper_bits;        ///< which quarter of that panel (bit 0..3, CCW), 0 without contact
  uint64_t contacts_total;    ///< substeps that had a contact (never decreases)
} sim_plant_state_t;

typedef struct sim_plant sim_plant_t;

/// Fills cfg with the defaults documented on each field. O(1).
void sim_plant_config_default(sim_plant_config_t* cfg);

/// Builds the ODE world from `world` (copied: the caller may free it afterwards) and places the
/// robot at the world's first start pose (or the origin). Returns NULL on invalid cfg or when
/// ODE cannot be initialised. Calls dInitODE2 (reference-counted by ODE) and allocates ODE's
/// per-thread collision data for the calling thread. O(walls + cylinders).
sim_plant_t* sim_plant_create(const sim_world_t* world, const sim_plant_config_t* cfg);

/// Destroys the plant and releases its ODE objects; NULL is ignored.
void sim_plant_destroy(sim_plant_t* p);

/// The world the plant was built from (owned by the plant).
const sim_world_t* sim_plant_world(const sim_plant_t* p);

/// The configuration in use.
const sim_plant_config_t* sim_plant_get_config(const sim_plant_t* p);

/// Places the robot at (x, y, theta) at rest, clears contacts, the collided latch and the
/// commands; odometry accumulators keep running (like real encoders). Time is not reset. O(1).
void sim_plant_reset(sim_plant_t* p, double x_m, double y_m, double theta_rad);

/// Sets the axis commands [m/s], [rad/s]; non-finite values count as 0. Held until changed.
void sim_plant_set_command(sim_plant_t* p, double v_mps, double omega_radps);

/// Sets the acceleration limits used from the next substep on (<= 0 = unlimited).
void sim_plant_set_limits(sim_plant_t* p, const sim_kin_limits_t* limits);

/// Advances n substeps (collide -> step -> clear contacts each). O(n * (walls + cylinders)).
void sim_plant_step(sim_plant_t* p, uint32_t n);

/// Copies the current state into *out. O(1).
/// An axis encoder's count: round(at_reset · k) + round(since · k), wrapping at 32 bits like a
/// real encoder (two's complement). k: counts per metre or per radian. O(1).
int32_t sim_plant_axis_counts(double at_reset, double since, double counts_per_unit);

void sim_plant_get_state(const sim_plant_t* p, sim_plant_state_t* out);

/// Casts one ray in the floor plane at the laser height from (x, y) in direction dir_rad and
/// returns the distance to the first wall or cylinder face, or INFINITY if nothing lies within
/// max_range_m. O(walls + cylinders).
double sim_plant_ray(sim_plant_t* p, double x_m, double y_m, double dir_rad, double max_range_m);

/// Casts n beams from the laser mount at the current pose: beam i has bearing
/// angle_min_rad + i * increment_rad in the laser frame. Writes distances (INFINITY = no hit
/// within max_range_m) to out_m[0..n). O(n * (walls + cylinders)).
void sim_plant_scan(sim_plant_t* p, double angle_min_rad, double increment_rad, size_t n,
                    double max_range_m, double* out_m);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_PLANT_H
