// SPDX-License-Identifier: MIT
/// sim/world.h — Worlds of the B21r emulator: a small text format, and analytic 2-D queries.
///
/// A world is a flat floor with vertical walls (line segments with a thickness), vertical
/// cylindrical obstacles, an optional goal disc and a list of start poses. The ODE plant
/// (sim/plant.h) turns it into geoms; the analytic queries here serve the kinematic model
/// (sim/kinematic.h), which must run without ODE.
///
/// ## File format (`*.world`, UTF-8/ASCII text, one directive per line)
/// ```
/// b21r-world 1                       # first directive: magic and format version (must be 1)
/// name corridor10                    # identifier, [A-Za-z0-9_.-], at most 47 characters
/// corridor <length_m> <width_m> [end] # walls of a corridor along +x from x = 0 to x = length,
///                                    # centred on y = 0, closed behind the start (x = 0); end = 1
///                                    # also closes it at x = length (default 0: open end)
/// arena <xmin> <ymin> <xmax> <ymax>  # four walls enclosing the box (faces on its edges)
/// wall <x0> <y0> <x1> <y1> [thick_m] # a wall whose face is the segment p0 -> p1; the solid
///                                    # (default 0.10 m thick) lies to the RIGHT of p0 -> p1
/// cylinder <x> <y> <radius_m>        # a vertical cylindrical obstacle
/// goal <x> <y> <radius_m>            # goal disc (task metadata; not an obstacle)
/// start <x> <y> <theta_rad>          # a start pose; the first one is the default start,
///                                    # all of them are the evaluation start poses, in order
/// bounds <xmin> <ymin> <xmax> <ymax> # drawing area (optional; default: contents + 1 m)
/// ```
/// `#` starts a comment; blank lines are ignored; numbers are C decimal floating point of magnitude
/// at most SIM_WORLD_MAX_ABS (1e6: a world fits in a 2000 km square, and the drawing area and
/// every distance the emulator derives from it stay exact enough to compare).
/// Everything is metres and radians in the world frame (x east, y north, theta CCW from x).
/// Walls and cylinders are 1 m tall (WORLD_OBSTACLE_HEIGHT_M), so the laser (0.355 m) and the
/// base skirt (0-0.30 m) both meet them.
///
/// Memory: sim_world_t is a plain struct with fixed capacities (about 6 KiB), no allocation.
/// Thread-safety: parsing writes only its output; queries are pure.
#ifndef B21R_SIM_WORLD_H
#define B21R_SIM_WORLD_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SIM_WORLD_MAX_WALLS 64        ///< capacity of sim_world_t::walls
#define SIM_WORLD_MAX_CYLINDERS 32    ///< capacity of sim_world_t::cylinders
#define SIM_WORLD_MAX_STARTS 32       ///< capacity of sim_world_t::starts
#define SIM_WORLD_NAME_CAP 48         ///< bytes of sim_world_t::name, including the NUL
#define SIM_WORLD_WALL_THICKNESS_DEFAULT_M 0.10
#define SIM_WORLD_OBSTACLE_HEIGHT_M 1.0
/// Largest magnitude of any number of a world (metres, radians): larger ones are refused.
#define SIM_WORLD_MAX_ABS 1e6

/// Status of the world functions.
typedef enum sim_world_status {
  SIM_WORLD_OK = 0,
  SIM_WORLD_ERR_INVALID_ARG = 2,  ///< NULL pointer or a non-finite / non-positive value
  SIM_WORLD_ERR_CAPACITY,         ///< more walls, cylinders or starts than the capacities
  SIM_WORLD_ERR_SYNTAX,           ///< unknown directive, wrong argument count, bad number (also
                                  ///< one beyond SIM_WORLD_MAX_ABS)
  SIM_WORLD_ERR_IO,               ///< the file could not be opened or read
} sim_world_status_t;

/// A wall: the face is the segment (x0,y0)->(x1,y1); the solid lies to its right.
typedef struct sim_wall {
  double x0_m, y0_m, x1_m, y1_m;
  double thickness_m;  ///< > 0
} sim_wall_t;

/// A vertical cylindrical obstacle.
typedef struct sim_cylinder {
  double x_m, y_m;
  double radius_m;  ///< > 0
} sim_cylinder_t;

/// A planar pose in the world frame.
typedef struct sim_pose {
  double x_m, y_m;
  double theta_rad;
} sim_pose_t;

/// A parsed world. Fields are read-only for users; build one with sim_world_parse/_load, or
/// fill it by hand (then call nothing else: every function accepts any consistent content).
typedef struct sim_world {
  char name[SIM_WORLD_NAME_CAP];
  int has_corridor;              ///< 1 when a `corridor` directive was given
  double corridor_length_m;      ///< corridor metadata (0 without a corridor)
  double corridor_width_m;
  int has_goal;                  ///< 1 when a `goal` directive was given
  sim_cylinder_t goal;           ///< goal disc (centre, radius)
  double bounds_min_x_m, bounds_min_y_m, bounds_max_x_m, bounds_max_y_m;
  size_t n_walls;
  sim_wall_t walls[SIM_WORLD_MAX_WALLS];
  size_t n_cylinders;
  sim_cylinder_t cylinders[SIM_WORLD_MAX_CYLINDERS];
  size_t n_starts;
  sim_pose_t starts[SIM_WORLD_MAX_STARTS];
} sim_world_t;

/// Parses `len` bytes of world text into *out (overwritten; on failure it holds an empty world).
/// On failure writes a one-line message "line N: <problem>" into err (if err_cap > 0). O(len).
sim_world_status_t sim_world_parse(const char* text, size_t len, sim_world_t* out, char* err,
                                   size_t err_cap);

/// Reads and parses a world file (at most 64 KiB). Errors as sim_world_parse, plus
/// SIM_WORLD_ERR_IO with the path and the reason in err. Allocates one temporary buffer of the
/// file's size, freed before returning. O(file size).
sim_world_status_t sim_world_load(const char* path, sim_world_t* out, char* err, size_t err_cap);

/// Empties *w (no walls, no starts, name "empty"). O(1).
void sim_world_clear(sim_world_t* w);

/// Adds a wall / cylinder / start (used by the parser; exposed for worlds built in code).
/// SIM_WORLD_ERR_CAPACITY when full, SIM_WORLD_ERR_INVALID_ARG for bad numbers; w unchanged then.
sim_world_status_t sim_world_add_wall(sim_world_t* w, double x0_m, double y0_m, double x1_m,
                                      double y1_m, double thickness_m);
sim_world_status_t sim_world_add_cylinder(sim_world_t* w, double x_m, double y_m, double radius_m);
sim_world_status_t sim_world_add_start(sim_world_t* w, double x_m, double y_m, double theta_rad);
/// Adds the walls of a corridor (see the file format) and records its metadata.
sim_world_status_t sim_world_add_corridor(sim_world_t* w, double length_m, double width_m,
                                          int closed_end);
/// Adds four walls whose faces are the edges of the box, solids outside (see the file format).
sim_world_status_t sim_world_add_arena(sim_world_t* w, double min_x_m, double min_y_m,
                                       double max_x_m, double max_y_m);
/// Recomputes the default bounds (contents + 1 m margin, at least a 2 m square). O(n).
void sim_world_compute_bounds(sim_world_t* w);

/// Does a disc of radius r at (x, y) overlap (distance < r) any wall solid or cylinder? Walls
/// count as their full thick rectangle. The kinematic model's collision test.
/// O(walls + cylinders).
int sim_world_disc_collides(const sim_world_t* w, double x_m, double y_m, double radius_m);

/// Distance along the ray from (x, y) in direction dir_rad (floor plane) to the first wall solid
/// or cylinder, or INFINITY when nothing lies within max_range_m. Walls count as their full thick
/// rectangle (as in the ODE plant, whose boxes they are); a ray starting inside a solid returns 0.
/// Exact closed-form intersections (no stepping). The LMS200 emulation's ray cast. O(walls +
/// cylinders), pure.
double sim_world_raycast(const sim_world_t* w, double x_m, double y_m, double dir_rad, double max_range_m);

/// Is (x, y) inside the goal disc? 0 when the world has no goal. O(1).
int sim_world_in_goal(const sim_world_t* w, double x_m, double y_m);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_WORLD_H
