// SPDX-License-Identifier: MIT
/// sim/svg.h — An overhead picture of runs (trajectories over the world) as an SVG file,
/// written by plain C so that no plotting dependency is needed.
///
/// The picture shows the world's walls (their solid rectangles), cylinders, the goal disc and
/// the start poses (small arrows), then each run's trajectory as a polyline (a new run starts
/// at every point with `run` different from the previous point's) coloured in run order on the
/// viridis scale (as tools/b21r_trajectories.py), a dot at each run's start, the robot's outline
/// at each run's last pose, and a red cross where a run first touched an obstacle; a legend to
/// the right names the runs (a colour bar from the first to the last when there are more than
/// 12) and the symbols. 1 m = 60 px by default, y up (the SVG is flipped so that the world's CCW
/// angles look CCW).
///
/// Memory: no allocation (streams to the file). Not thread-safe per file.
#ifndef B21R_SIM_SVG_H
#define B21R_SIM_SVG_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "sim/world.h"

#ifdef __cplusplus
extern "C" {
#endif

/// One recorded pose.
typedef struct sim_trace_point {
  double t_s;
  double x_m, y_m, theta_rad;
  uint32_t run;      ///< run index (incremented by every reset)
  uint8_t collided;  ///< collision latch at this point
} sim_trace_point_t;

/// Writes the picture to an open stream. Returns 0, or -1 on a write error. O(walls + points).
/// `title` (may be NULL) is written as the picture's caption.
int sim_svg_write_stream(FILE* f, const sim_world_t* world, const sim_trace_point_t* points,
                         size_t n_points, double robot_radius_m, const char* title);

/// Writes the picture to `path` atomically (a temporary file renamed over the target).
/// Returns 0, or -1 (errno set) when the file cannot be written.
int sim_svg_write(const char* path, const sim_world_t* world, const sim_trace_point_t* points,
                  size_t n_points, double robot_radius_m, const char* title);

#ifdef __cplusplus
}
#endif

#endif  // B21R_SIM_SVG_H
