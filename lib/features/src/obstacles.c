// SPDX-License-Identifier: MIT
// Obstacle-task state: goal from odometry, obstacles segmented from the scan as standing-out clusters.
#include "features/obstacles.h"

#include <math.h>
#include <stddef.h>

#include "scan_points.h"

// Returns within this of the nearest one define an obstacle's bearing [m] (about 3 sigma of
// LMS200 range noise).
#define NEAR_BAND_M 0.03

void features_obstacles_config_default(features_obstacles_config_t* cfg) {
  features_scan_config_default(&cfg->scan);
  cfg->cluster_gap_m = 0.25;
  cfg->max_obstacle_width_m = 1.0;
  cfg->standout_m = 0.3;
  cfg->min_cluster_points = 3U;
  cfg->no_obstacle_distance_m = 8.0;
  cfg->memory_max_age = 30U;
  cfg->memory_margin_m = 0.1;
}

static int config_ok(const features_obstacles_config_t* cfg) {
  return features_scan_config_ok(&cfg->scan) && isfinite(cfg->cluster_gap_m) &&
         cfg->cluster_gap_m > 0.0 && isfinite(cfg->max_obstacle_width_m) &&
         cfg->max_obstacle_width_m > 0.0 && isfinite(cfg->standout_m) && cfg->standout_m >= 0.0 &&
         isfinite(cfg->no_obstacle_distance_m) && cfg->no_obstacle_distance_m > 0.0 &&
         isfinite(cfg->memory_margin_m) && cfg->memory_margin_m >= 0.0;
}

static void slot_empty(double no_obstacle_distance_m, features_obstacle_t* o) {
  o->bearing_rad = FEAT_PI;
  o->distance_m = no_obstacle_distance_m;
  o->width_m = 0.0;
  o->centre_x_m = 0.0;
  o->centre_y_m = 0.0;
  o->n_points = 0U;
  o->visible = 0U;
}

static void set_empty(const features_obstacles_config_t* cfg, features_obstacles_t* out) {
  const double far_m = (cfg != NULL && isfinite(cfg->no_obstacle_distance_m) &&
                        cfg->no_obstacle_distance_m > 0.0)
                           ? cfg->no_obstacle_distance_m : 8.0;
  out->goal_bearing_rad = 0.0;
  out->goal_distance_m = 0.0;
  for (size_t k = 0U; k < FEATURES_MAX_OBSTACLES; ++k) {
    slot_empty(far_m, &out->obstacle[k]);
  }
  out->n_visible = 0U;
  out->valid = 0U;
  out->scan_valid = 0U;
  out->n_points = 0U;
  out->n_clusters = 0U;
  out->n_wall_clusters = 0U;
  out->nearest_any_m = far_m;
  out->nearest_any_bearing_rad = FEAT_PI;
  slot_empty(far_m, &out->known);
  out->known_age = cfg != NULL ? cfg->memory_max_age : 0U;
}

// The known obstacle without memory: the nearest one seen, if any.
static void set_known_seen(const features_obstacles_config_t* cfg, features_obstacles_t* out) {
  if (out->obstacle[0].visible != 0U) {
    out->known = out->obstacle[0];
    out->known_age = 0U;
  } else {
    slot_empty(cfg->no_obstacle_distance_m, &out->known);
    out->known_age = cfg->memory_max_age;
  }
}

// Inserts a candidate into the nearest-first slots (insertion into a sorted array of 2).
static void keep_nearest(features_obstacles_t* out, const features_obstacle_t* cand) {
  for (size_t k = 0U; k < FEATURES_MAX_OBSTACLES; ++k) {
    if (out->obstacle[k].visible == 0U || cand->distance_m < out->obstacle[k].distance_m) {
      for (size_t j = FEATURES_MAX_OBSTACLES - 1U; j > k; --j) {
        out->obstacle[j] = out->obstacle[j - 1U];
      }
      out->obstacle[k] = *cand;
      return;
    }
  }
}

// Judges the cluster pts[first..last] (valid points only, beam order) and reports it if it is an
// obstacle. prev/next: index of the nearest valid beam outside the cluster, or -1 if none.
static void judge_cluster(const features_obstacles_config_t* cfg, const features_point_t* pts,
                          int first, int last, int prev, int next, features_obstacles_t* out) {
  uint16_t n = 0U;
  double sx = 0.0, sy = 0.0;
  double best_d = HUGE_VAL;
  for (int i = first; i <= last; ++i) {
    if (pts[i].valid == 0U) continue;
    ++n;
    sx += pts[i].x_m;
    sy += pts[i].y_m;
    best_d = fmin(best_d, hypot(pts[i].x_m, pts[i].y_m));
  }
  // Bearing of the nearest part: the mean direction of the returns within NEAR_BAND_M of the
  // nearest one. Around its nearest point a surface is flat in range, so the single nearest
  // return wanders over several beams with range noise; the mean does not.
  double ux = 0.0, uy = 0.0;
  for (int i = first; i <= last; ++i) {
    if (pts[i].valid == 0U) continue;
    const double d = hypot(pts[i].x_m, pts[i].y_m);
    if (d <= best_d + NEAR_BAND_M && d > 0.0) {
      ux += pts[i].x_m / d;
      uy += pts[i].y_m / d;
    }
  }
  const double best_b = atan2(uy, ux);
  if (out->n_clusters < UINT16_MAX) ++out->n_clusters;
  const double width = hypot(pts[last].x_m - pts[first].x_m, pts[last].y_m - pts[first].y_m);
  const int stands_out_prev = prev < 0 || pts[prev].range_m - pts[first].range_m >= cfg->standout_m;
  const int stands_out_next = next < 0 || pts[next].range_m - pts[last].range_m >= cfg->standout_m;
  if (n < cfg->min_cluster_points) {
    return;  // noise: neither wall nor obstacle
  }
  if (width > cfg->max_obstacle_width_m || !stands_out_prev || !stands_out_next) {
    if (out->n_wall_clusters < UINT16_MAX) ++out->n_wall_clusters;
    return;
  }
  features_obstacle_t o;
  o.bearing_rad = features_angle_wrap(best_b);
  o.distance_m = best_d;
  o.width_m = width;
  o.centre_x_m = sx / (double)n;
  o.centre_y_m = sy / (double)n;
  o.n_points = n;
  o.visible = 1U;
  if (out->n_visible < UINT8_MAX) ++out->n_visible;
  keep_nearest(out, &o);
}

// The goal part of the state: from the pose, when it and the goal are finite.
static void set_goal(const features_pose_t* pose, double goal_x_m, double goal_y_m,
                     features_obstacles_t* out) {
  if (pose != NULL && isfinite(pose->x_m) && isfinite(pose->y_m) && isfinite(pose->theta_rad) &&
      isfinite(goal_x_m) && isfinite(goal_y_m)) {
    const double dx = goal_x_m - pose->x_m;
    const double dy = goal_y_m - pose->y_m;
    out->goal_distance_m = hypot(dx, dy);
    out->goal_bearing_rad = features_angle_wrap(atan2(dy, dx) - pose->theta_rad);
    out->valid = 1U;
  }
}

features_status_t features_obstacles_compute(const features_obstacles_config_t* cfg,
                                             const features_scan_t* scan,
                                             const features_pose_t* pose, double goal_x_m,
                                             double goal_y_m, features_obstacles_t* out) {
  if (out == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_empty(cfg, out);
  if (cfg == NULL || scan == NULL || !config_ok(cfg) || !features_scan_ok(scan)) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_goal(pose, goal_x_m, goal_y_m, out);

  features_point_t pts[FEATURES_MAX_BEAMS];
  out->n_points = features_scan_points(&cfg->scan, scan, pts);
  out->scan_valid = (uint8_t)(out->n_points > 0U ? 1U : 0U);
  if (out->n_points == 0U) {
    set_known_seen(cfg, out);
    return FEATURES_OK;
  }
  const int n = (int)scan->n_beams;
  for (int i = 0; i < n; ++i) {
    if (pts[i].valid == 0U) continue;
    const double d = hypot(pts[i].x_m, pts[i].y_m);
    if (d < out->nearest_any_m) {
      out->nearest_any_m = d;
      out->nearest_any_bearing_rad = features_angle_wrap(atan2(pts[i].y_m, pts[i].x_m));
    }
  }
  // Clusters in beam order. Missing beams are skipped: they neither split nor join clusters.
  int first = -1;    // first valid beam of the open cluster
  int last = -1;     // last valid beam of the open cluster
  int before = -1;   // last valid beam before the open cluster
  for (int i = 0; i < n; ++i) {
    if (pts[i].valid == 0U) continue;
    if (first < 0) {
      first = i;
      last = i;
      continue;
    }
    const double gap = hypot(pts[i].x_m - pts[last].x_m, pts[i].y_m - pts[last].y_m);
    if (gap > cfg->cluster_gap_m) {
      judge_cluster(cfg, pts, first, last, before, i, out);
      before = last;
      first = i;
    }
    last = i;
  }
  judge_cluster(cfg, pts, first, last, before, -1, out);
  set_known_seen(cfg, out);
  return FEATURES_OK;
}

features_status_t features_obstacles_from_pose(const features_obstacles_config_t* cfg,
                                               features_pose_t pose, double goal_x_m,
                                               double goal_y_m, const features_disc_t* obstacles,
                                               uint32_t n_obstacles, double field_of_view_rad,
                                               features_obstacles_t* out) {
  if (out == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_empty(cfg, out);
  if (cfg == NULL || !config_ok(cfg) || (obstacles == NULL && n_obstacles > 0U) ||
      !isfinite(pose.x_m) || !isfinite(pose.y_m) || !isfinite(pose.theta_rad) ||
      !isfinite(goal_x_m) || !isfinite(goal_y_m) || !(field_of_view_rad > 0.0) ||
      field_of_view_rad > 2.0 * FEAT_PI) {
    return FEATURES_ERR_INVALID_ARG;
  }
  for (uint32_t k = 0U; k < n_obstacles; ++k) {
    const features_disc_t* d = &obstacles[k];
    if (!isfinite(d->x_m) || !isfinite(d->y_m) || !isfinite(d->radius_m) || !(d->radius_m > 0.0)) {
      return FEATURES_ERR_INVALID_ARG;
    }
  }
  set_goal(&pose, goal_x_m, goal_y_m, out);
  out->scan_valid = 1U;
  const double c = cos(pose.theta_rad);
  const double s = sin(pose.theta_rad);
  // The laser's origin and heading in the task frame.
  const features_laser_mount_t* m = &cfg->scan.mount;
  const double lx = pose.x_m + c * m->x_m - s * m->y_m;
  const double ly = pose.y_m + s * m->x_m + c * m->y_m;
  const double l_theta = pose.theta_rad + m->yaw_rad;
  for (uint32_t k = 0U; k < n_obstacles; ++k) {
    const features_disc_t* d = &obstacles[k];
    const double dx = d->x_m - pose.x_m;
    const double dy = d->y_m - pose.y_m;
    const double centre_dist = hypot(dx, dy);
    const double surface = centre_dist > d->radius_m ? centre_dist - d->radius_m : 0.0;
    // The surface point nearest to the robot centre, and how the laser sees it.
    const double ux = centre_dist > 0.0 ? dx / centre_dist : 1.0;
    const double uy = centre_dist > 0.0 ? dy / centre_dist : 0.0;
    const double px = pose.x_m + surface * ux - lx;
    const double py = pose.y_m + surface * uy - ly;
    const double range = hypot(px, py);
    const double laser_bearing = features_angle_wrap(atan2(py, px) - l_theta);
    if (fabs(laser_bearing) > 0.5 * field_of_view_rad || range < cfg->scan.min_range_m ||
        range > cfg->scan.max_range_m) {
      continue;
    }
    features_obstacle_t o;
    o.bearing_rad = features_angle_wrap(atan2(uy, ux) - pose.theta_rad);
    o.distance_m = surface;
    o.width_m = 2.0 * d->radius_m;
    o.centre_x_m = c * dx + s * dy;
    o.centre_y_m = -s * dx + c * dy;
    o.n_points = 0U;
    o.visible = 1U;
    if (out->n_visible < UINT8_MAX) ++out->n_visible;
    if (surface < out->nearest_any_m) {
      out->nearest_any_m = surface;
      out->nearest_any_bearing_rad = o.bearing_rad;
    }
    keep_nearest(out, &o);
  }
  set_known_seen(cfg, out);
  return FEATURES_OK;
}

void features_obstacle_memory_reset(features_obstacle_memory_t* mem) {
  mem->x_m = 0.0;
  mem->y_m = 0.0;
  mem->radius_m = 0.0;
  mem->age = 0U;
  mem->n_points = 0U;
  mem->held = 0U;
}

features_status_t features_obstacles_remember(const features_obstacles_config_t* cfg,
                                              features_obstacle_memory_t* mem, features_pose_t pose,
                                              features_obstacles_t* f) {
  if (cfg == NULL || mem == NULL || f == NULL || !config_ok(cfg) || !isfinite(pose.x_m) ||
      !isfinite(pose.y_m) || !isfinite(pose.theta_rad)) {
    return FEATURES_ERR_INVALID_ARG;
  }
  const double c = cos(pose.theta_rad);
  const double s = sin(pose.theta_rad);
  // 1. The remembered obstacle one observation older, seen from the current pose.
  double dx = 0.0, dy = 0.0, dist = 0.0;
  if (mem->held != 0U) {
    mem->age = mem->age < UINT32_MAX ? mem->age + 1U : UINT32_MAX;
    dx = mem->x_m - pose.x_m;
    dy = mem->y_m - pose.y_m;
    dist = fmax(hypot(dx, dy) - mem->radius_m, 0.0);
    if (mem->age > cfg->memory_max_age || !(dist < cfg->no_obstacle_distance_m) || !isfinite(mem->x_m) ||
        !isfinite(mem->y_m)) {
      mem->held = 0U;
    }
  }
  // 2. The obstacle seen now: the remembered one seen again, or another one, which replaces it
  //    unless the remembered one is clearly nearer.
  const features_obstacle_t* seen = &f->obstacle[0];
  const double a = pose.theta_rad + seen->bearing_rad;
  const double ux = cos(a), uy = sin(a);
  const double px = pose.x_m + seen->distance_m * ux;  // its nearest return
  const double py = pose.y_m + seen->distance_m * uy;
  const int same = seen->visible != 0U && mem->held != 0U &&
                   hypot(px - mem->x_m, py - mem->y_m) <= mem->radius_m + cfg->cluster_gap_m;
  if (seen->visible != 0U && (mem->held == 0U || same || seen->distance_m <= dist + cfg->memory_margin_m)) {
    if (!same || seen->n_points >= mem->n_points) {
      const double r = fmin(fmax(0.5 * seen->width_m, 0.0), 0.5 * cfg->max_obstacle_width_m);
      mem->x_m = px + r * ux;
      mem->y_m = py + r * uy;
      mem->radius_m = r;
      mem->n_points = seen->n_points;
    }  // else: the same obstacle, seen less well than before: its disc stays
    mem->age = 0U;
    mem->held = 1U;
    f->known = *seen;
    f->known_age = 0U;
    return FEATURES_OK;
  }
  // 3. The remembered one, or none.
  if (mem->held == 0U) {
    slot_empty(cfg->no_obstacle_distance_m, &f->known);
    f->known_age = cfg->memory_max_age;
    return FEATURES_OK;
  }
  f->known.bearing_rad = features_angle_wrap(atan2(dy, dx) - pose.theta_rad);
  f->known.distance_m = dist;
  f->known.width_m = 2.0 * mem->radius_m;
  f->known.centre_x_m = c * dx + s * dy;
  f->known.centre_y_m = -s * dx + c * dy;
  f->known.n_points = 0U;
  f->known.visible = 0U;
  f->known_age = mem->age;
  return FEATURES_OK;
}

size_t features_obstacles_memory_state(const features_obstacles_t* f, double period_s, double* state,
                                       size_t capacity) {
  if (f == NULL || state == NULL || capacity < FEATURES_OBSTACLES_MEMORY_STATE_DIM || !isfinite(period_s) ||
      !(period_s > 0.0)) {
    return 0U;
  }
  state[0] = f->goal_bearing_rad;
  state[1] = f->goal_distance_m;
  state[2] = f->known.bearing_rad;
  state[3] = f->known.distance_m;
  state[4] = (double)f->known_age * period_s;
  return FEATURES_OBSTACLES_MEMORY_STATE_DIM;
}

size_t features_obstacles_state(const features_obstacles_t* f, uint32_t n_obstacles, double* state,
                                size_t capacity) {
  if (f == NULL || state == NULL || n_obstacles == 0U || n_obstacles > FEATURES_MAX_OBSTACLES) {
    return 0U;
  }
  const size_t n = 2U + 2U * (size_t)n_obstacles;
  if (capacity < n) {
    return 0U;
  }
  state[0] = f->goal_bearing_rad;
  state[1] = f->goal_distance_m;
  for (uint32_t k = 0U; k < n_obstacles; ++k) {
    state[2U + 2U * k] = f->obstacle[k].bearing_rad;
    state[3U + 2U * k] = f->obstacle[k].distance_m;
  }
  return n;
}
