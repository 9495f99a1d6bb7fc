// SPDX-License-Identifier: MIT
// Doorway state: the wall by a bounded Hough search and a line refit, the gap between its jambs,
// the odometry fallback.
#include "features/doorway.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "scan_points.h"

#define COARSE_STEP_RAD (2.0 * FEAT_PI / 180.0)
#define FINE_STEP_RAD (0.5 * FEAT_PI / 180.0)
#define BIN_M 0.05
#define MAX_BINS 180                  // offsets 0 .. 9 m along the normal
#define MAX_DIRS 91                   // the front half-turn at COARSE_STEP_RAD
#define FREE_CANDIDATES 3             // wall directions tried without odometry
#define REFIT_PASSES 4                // bands: 0.15 m, 0.10 m, then inlier_tolerance_m twice
#define SAME_DIRECTION_RAD (6.0 * FEAT_PI / 180.0)

void features_doorway_config_default(features_doorway_config_t* cfg) {
  features_scan_config_default(&cfg->scan);
  cfg->door_x_m = 0.0;
  cfg->door_y_m = 0.0;
  cfg->normal_rad = 0.0;
  cfg->door_width_m = 1.0;
  cfg->wall_thickness_m = 0.1;
  cfg->width_tolerance_m = 0.2;
  cfg->inlier_tolerance_m = 0.05;
  cfg->split_gap_m = 0.3;
  cfg->min_wall_points = 8U;
  cfg->heading_window_rad = 0.5;
  cfg->min_view_m = 0.3;
  cfg->gate_m = 0.5;
  cfg->gate_rad = 0.3;
}

static int config_ok(const features_doorway_config_t* cfg) {
  return features_scan_config_ok(&cfg->scan) && isfinite(cfg->door_x_m) && isfinite(cfg->door_y_m) &&
         isfinite(cfg->normal_rad) && isfinite(cfg->door_width_m) && cfg->door_width_m > 0.0 &&
         isfinite(cfg->wall_thickness_m) && cfg->wall_thickness_m >= 0.0 && isfinite(cfg->width_tolerance_m) &&
         cfg->width_tolerance_m >= 0.0 && isfinite(cfg->inlier_tolerance_m) && cfg->inlier_tolerance_m > 0.0 &&
         isfinite(cfg->split_gap_m) && cfg->split_gap_m > 0.0 &&
         cfg->split_gap_m < cfg->door_width_m - cfg->width_tolerance_m && isfinite(cfg->heading_window_rad) &&
         isfinite(cfg->min_view_m) && cfg->min_view_m >= 0.0 && isfinite(cfg->gate_m) && cfg->gate_m >= 0.0 &&
         isfinite(cfg->gate_rad) && cfg->gate_rad >= 0.0;
}

static void set_neutral(const features_doorway_config_t* cfg, features_doorway_t* out) {
  const double w =
      (cfg != NULL && isfinite(cfg->door_width_m) && cfg->door_width_m > 0.0) ? cfg->door_width_m : 1.0;
  out->wall_distance_m = 0.0;
  out->offset_m = 0.0;
  out->heading_rad = 0.0;
  out->jamb_distance_m = 0.5 * w;
  out->gap_bearing_rad = 0.0;
  out->gap_distance_m = 0.0;
  out->width_m = w;
  out->valid = 0U;
  out->source = (uint8_t)FEATURES_SOURCE_NONE;
  out->wall_seen = 0U;
  out->jambs_seen = 0U;
  out->n_points = 0U;
  out->wall_points = 0U;
}

static double clampd(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

double features_doorway_jamb_distance(double x_d_m, double y_d_m, double width_m, double thickness_m) {
  const double h = 0.5 * thickness_m;
  const double dx = x_d_m - clampd(x_d_m, -h, h);
  const double left = hypot(dx, y_d_m - 0.5 * width_m);
  const double right = hypot(dx, y_d_m + 0.5 * width_m);
  return left < right ? left : right;
}

// The values of a robot at (x_d, y_d) with heading psi in the door frame; the gap's centre in the
// robot frame from the same numbers.
static void set_door_frame(double x_d, double y_d, double psi, double width_m, double thickness_m,
                           features_doorway_t* out) {
  out->wall_distance_m = -x_d;
  out->offset_m = y_d;
  out->heading_rad = features_angle_wrap(psi);
  out->width_m = width_m;
  out->jamb_distance_m = features_doorway_jamb_distance(x_d, y_d, width_m, thickness_m);
  // The gap's centre is at (-x_d, -y_d) from the robot in the door frame's axes; turned by -psi
  // into the robot frame.
  const double c = cos(psi);
  const double s = sin(psi);
  const double gx = c * (-x_d) + s * (-y_d);
  const double gy = -s * (-x_d) + c * (-y_d);
  out->gap_distance_m = hypot(gx, gy);
  out->gap_bearing_rad = out->gap_distance_m > 0.0 ? features_angle_wrap(atan2(gy, gx)) : 0.0;
}

// Door-frame coordinates of a task-frame pose.
static void door_frame_of_pose(const features_doorway_config_t* cfg, features_pose_t p, double* x_d, double* y_d,
                               double* psi) {
  const double nx = cos(cfg->normal_rad);
  const double ny = sin(cfg->normal_rad);
  const double dx = p.x_m - cfg->door_x_m;
  const double dy = p.y_m - cfg->door_y_m;
  *x_d = dx * nx + dy * ny;
  *y_d = -dx * ny + dy * nx;
  *psi = features_angle_wrap(p.theta_rad - cfg->normal_rad);
}

static int pose_finite(const features_pose_t* p) {
  return isfinite(p->x_m) && isfinite(p->y_m) && isfinite(p->theta_rad);
}

features_status_t features_doorway_from_pose(const features_doorway_config_t* cfg, features_pose_t pose_in_task,
                                             features_doorway_t* out) {
  if (out == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_neutral(cfg, out);
  if (cfg == NULL || !config_ok(cfg) || !pose_finite(&pose_in_task)) {
    return FEATURES_ERR_INVALID_ARG;
  }
  double x_d, y_d, psi;
  door_frame_of_pose(cfg, pose_in_task, &x_d, &y_d, &psi);
  set_door_frame(x_d, y_d, psi, cfg->door_width_m, cfg->wall_thickness_m, out);
  out->valid = 1U;
  out->source = (uint8_t)FEATURES_SOURCE_ODOMETRY;
  return FEATURES_OK;
}

void features_doorway_state(const features_doorway_t* f, double state[FEATURES_DOORWAY_STATE_DIM]) {
  state[0] = f->wall_distance_m;
  state[1] = f->offset_m;
  state[2] = f->heading_rad;
  state[3] = f->jamb_distance_m;
}

// ---- the wall ---------------------------------------------------------------------------------

// A wall line in the robot frame: points p with p . n = rho, n = (cos phi, sin phi) pointing from
// the robot to the wall.
typedef struct wall_line {
  double phi_rad;
  double rho_m;
  uint32_t support;
} wall_line_t;

// Best near-face peak of direction phi: the 3-bin window with the most points, its offset in
// [lo, hi] (bins outside are not considered). O(points).
static wall_line_t peak_of(const double* px, const double* py, int n, double phi, double lo, double hi) {
  uint16_t hist[MAX_BINS];
  memset(hist, 0, sizeof hist);
  const double nx = cos(phi);
  const double ny = sin(phi);
  for (int i = 0; i < n; ++i) {
    const double d = px[i] * nx + py[i] * ny;
    if (d > 0.0 && d < (double)MAX_BINS * BIN_M) {
      const int b = (int)(d / BIN_M);
      if (hist[b] < UINT16_MAX) ++hist[b];
    }
  }
  wall_line_t best = {phi, 0.0, 0U};
  int b_lo = (int)floor(lo / BIN_M);
  int b_hi = (int)floor(hi / BIN_M);
  b_lo = b_lo < 0 ? 0 : b_lo;
  b_hi = b_hi > MAX_BINS - 1 ? MAX_BINS - 1 : b_hi;
  for (int b = b_lo; b <= b_hi; ++b) {
    uint32_t s = hist[b];
    if (b > 0) s += hist[b - 1];
    if (b + 1 < MAX_BINS) s += hist[b + 1];
    if (s > best.support) {
      best.support = s;
      best.rho_m = ((double)b + 0.5) * BIN_M;
    }
  }
  return best;
}

// The best direction in [phi0, phi0 + (n_dirs - 1) step] (ties: the first). O(n_dirs * points).
static wall_line_t search(const double* px, const double* py, int n, double phi0, double step, int n_dirs,
                          double lo, double hi) {
  wall_line_t best = {phi0, 0.0, 0U};
  for (int k = 0; k < n_dirs; ++k) {
    const wall_line_t c = peak_of(px, py, n, phi0 + step * (double)k, lo, hi);
    if (c.support > best.support) {
      best = c;
    }
  }
  return best;
}

// Coarse-to-fine search around phi_c within +-half_window; then a least-squares refit of the line
// through the inliers (principal axis, shrinking band). Returns the line with its inlier count.
static wall_line_t fit_wall(const features_doorway_config_t* cfg, const double* px, const double* py, int n,
                            wall_line_t coarse) {
  const wall_line_t fine = search(px, py, n, coarse.phi_rad - 4.0 * FINE_STEP_RAD, FINE_STEP_RAD, 9,
                                  coarse.rho_m - 0.1, coarse.rho_m + 0.1);
  wall_line_t line = fine.support > 0U ? fine : coarse;
  static const double k_bands[REFIT_PASSES - 2] = {0.15, 0.10};
  for (int pass = 0; pass < REFIT_PASSES; ++pass) {
    const double band = pass < REFIT_PASSES - 2 ? k_bands[pass] : cfg->inlier_tolerance_m;
    const double nx = cos(line.phi_rad);
    const double ny = sin(line.phi_rad);
    double sx = 0.0, sy = 0.0;
    uint32_t m = 0U;
    for (int i = 0; i < n; ++i) {
      if (fabs(px[i] * nx + py[i] * ny - line.rho_m) <= band) {
        sx += px[i];
        sy += py[i];
        ++m;
      }
    }
    if (m < 2U) {
      line.support = m;
      return line;
    }
    const double mx = sx / (double)m;
    const double my = sy / (double)m;
    double sxx = 0.0, syy = 0.0, sxy = 0.0;
    for (int i = 0; i < n; ++i) {
      if (fabs(px[i] * nx + py[i] * ny - line.rho_m) <= band) {
        const double dx = px[i] - mx;
        const double dy = py[i] - my;
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
      }
    }
    // Direction of least scatter = the line's normal; keep it on the side of the previous one.
    const double axis = 0.5 * atan2(2.0 * sxy, sxx - syy);  // major axis
    double phi = axis + 0.5 * FEAT_PI;
    if (cos(phi - line.phi_rad) < 0.0) {
      phi -= FEAT_PI;
    }
    // A refit that turns far from the searched direction followed something else: keep the search.
    if (fabs(features_angle_wrap(phi - fine.phi_rad)) <= 4.0 * FINE_STEP_RAD || fine.support == 0U) {
      line.phi_rad = features_angle_wrap(phi);
      line.rho_m = mx * cos(line.phi_rad) + my * sin(line.phi_rad);
    }
    line.support = m;
  }
  // The final support: inliers of the final line.
  const double nx = cos(line.phi_rad);
  const double ny = sin(line.phi_rad);
  uint32_t m = 0U;
  for (int i = 0; i < n; ++i) {
    if (fabs(px[i] * nx + py[i] * ny - line.rho_m) <= cfg->inlier_tolerance_m) ++m;
  }
  line.support = m;
  return line;
}

// ---- the gap ----------------------------------------------------------------------------------

enum { BETWEEN_NONE = 0, BETWEEN_FRONT = 1, BETWEEN_BEYOND = 2 };

typedef struct gap {
  double centre_s_m;  // along the wall (u = n turned +90°), robot frame
  double width_m;
  uint8_t jambs;      // 1 or 2
} gap_t;

// Where beam i's ray meets the wall line, along the wall, as a jamb on side `side` sees it
// (-1: the jamb at the gap's lower end along the wall, +1: its upper end): a ray that crosses
// the face at s still has the wall's thickness to traverse at its slant, so the jamb it just
// passes lies t * tan(slant) back from s on the side it slants away from. *ok = 0 when the ray
// does not meet the line.
static double ray_s(const features_doorway_config_t* cfg, const features_scan_t* scan, int i, double nx, double ny,
                    double rho, int side, int* ok) {
  const double a = scan->angle_min_rad + (double)i * scan->angle_increment_rad + cfg->scan.mount.yaw_rad;
  const double dx = cos(a);
  const double dy = sin(a);
  const double mx = cfg->scan.mount.x_m;
  const double my = cfg->scan.mount.y_m;
  const double dn = dx * nx + dy * ny;
  const double t = dn > 1e-9 ? (rho - (mx * nx + my * ny)) / dn : -1.0;
  *ok = t > 0.0;
  if (!*ok) {
    return 0.0;
  }
  const double du = dx * (-ny) + dy * nx;
  const double slant = cfg->wall_thickness_m * du / dn;  // along-wall drift across the thickness
  const double s = (mx + t * dx) * (-ny) + (my + t * dy) * nx;
  return side < 0 ? s - fmax(0.0, -slant) : s + fmax(0.0, slant);
}

// Along-wall position of a jamb whose last wall return is beam `in`, the gap lying towards beam
// `end` (the break's other wall return; side as for ray_s). The neighbour towards the gap is the
// next beam with a return (a missing beam may have been the wall's: the edge lies between the
// last beam known to hit the wall and the first known to pass); when the break has no return at
// all, the next beam. The neighbour's own position when it hits the jamb's end face (which lies
// across the wall at the jamb's position); else halfway between the wall return and where the
// neighbour's ray passes the jamb.
static double jamb_s(const features_doorway_config_t* cfg, const features_scan_t* scan,
                     const features_point_t* pts, int in, int end, double nx, double ny, double rho, int side) {
  const double s_in = pts[in].x_m * (-ny) + pts[in].y_m * nx;
  const int step = end > in ? 1 : -1;
  int nb = in + step;
  while (nb != end && pts[nb].valid == 0U) {
    nb += step;
  }
  if (nb == end) {
    nb = in + step;
  }
  if (nb < 0 || nb >= (int)scan->n_beams) {
    return s_in;
  }
  if (pts[nb].valid != 0U) {
    const double e = pts[nb].x_m * nx + pts[nb].y_m * ny - rho;
    if (e <= cfg->wall_thickness_m + 2.0 * cfg->inlier_tolerance_m) {
      return pts[nb].x_m * (-ny) + pts[nb].y_m * nx;
    }
  }
  int ok = 0;
  const double s_nb = ray_s(cfg, scan, nb, nx, ny, rho, side, &ok);
  return ok ? 0.5 * (s_in + s_nb) : s_in;
}

// Walks the points in beam order along the line and returns the gap nearest to s_pred (when
// have_pred) or the best one (whole before partial, then nearest to straight ahead). 1 if found.
static int find_gap(const features_doorway_config_t* cfg, const features_scan_t* scan,
                    const features_point_t* pts, const wall_line_t* line, int have_pred, double s_pred,
                    gap_t* out) {
  const double nx = cos(line->phi_rad);
  const double ny = sin(line->phi_rad);
  const double tol = cfg->inlier_tolerance_m;
  const double w = cfg->door_width_m;
  int found = 0;
  double best_score = HUGE_VAL;
  int last_in = -1;
  int first_kind = BETWEEN_NONE;
  int last_kind = BETWEEN_NONE;
  for (int i = 0; i < (int)scan->n_beams; ++i) {
    if (pts[i].valid == 0U) continue;
    const double e = pts[i].x_m * nx + pts[i].y_m * ny - line->rho_m;
    if (fabs(e) > tol) {
      const int kind = e < 0.0 ? BETWEEN_FRONT : BETWEEN_BEYOND;
      if (first_kind == BETWEEN_NONE) first_kind = kind;
      last_kind = kind;
      continue;
    }
    if (last_in >= 0) {
      const double s_a = pts[last_in].x_m * (-ny) + pts[last_in].y_m * nx;
      const double s_b = pts[i].x_m * (-ny) + pts[i].y_m * nx;
      if (s_b - s_a > cfg->split_gap_m) {
        const int jamb_a = first_kind != BETWEEN_FRONT;
        const int jamb_b = last_kind != BETWEEN_FRONT;
        const double ea = jamb_a ? jamb_s(cfg, scan, pts, last_in, i, nx, ny, line->rho_m, -1) : s_a;
        const double eb = jamb_b ? jamb_s(cfg, scan, pts, i, last_in, nx, ny, line->rho_m, 1) : s_b;
        gap_t g = {0.0, 0.0, 0U};
        if (jamb_a && jamb_b && fabs((eb - ea) - w) <= cfg->width_tolerance_m) {
          g.centre_s_m = 0.5 * (ea + eb);
          g.width_m = eb - ea;
          g.jambs = 2U;
        } else if (jamb_a && !jamb_b && eb - ea >= w - cfg->width_tolerance_m) {
          g.centre_s_m = ea + 0.5 * w;
          g.width_m = w;
          g.jambs = 1U;
        } else if (!jamb_a && jamb_b && eb - ea >= w - cfg->width_tolerance_m) {
          g.centre_s_m = eb - 0.5 * w;
          g.width_m = w;
          g.jambs = 1U;
        }
        if (g.jambs > 0U) {
          // Lower is better: distance from the prediction, or (without one) partial gaps after
          // whole ones, then the angle off straight ahead.
          const double score = have_pred ? fabs(g.centre_s_m - s_pred)
                                         : (g.jambs == 2U ? 0.0 : 10.0) + fabs(atan2(g.centre_s_m, line->rho_m));
          if (score < best_score) {
            best_score = score;
            *out = g;
            found = 1;
          }
        }
      }
    }
    last_in = i;
    first_kind = BETWEEN_NONE;
    last_kind = BETWEEN_NONE;
  }
  return found;
}

// ---- the whole ---------------------------------------------------------------------------------

// The door frame from the wall line and the gap (robot at the origin).
static void set_from_laser(const features_doorway_config_t* cfg, const wall_line_t* line, const gap_t* g,
                           features_doorway_t* out) {
  const double t = cfg->wall_thickness_m;
  const double x_d = -(line->rho_m + 0.5 * t);
  const double y_d = -g->centre_s_m;
  const double psi = -line->phi_rad;
  set_door_frame(x_d, y_d, psi, g->jambs == 2U ? g->width_m : cfg->door_width_m, t, out);
}

features_status_t features_doorway_compute(const features_doorway_config_t* cfg, const features_scan_t* scan,
                                           const features_pose_t* pose_in_task, features_doorway_t* out) {
  if (out == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_neutral(cfg, out);
  if (cfg == NULL || scan == NULL || !config_ok(cfg) || !features_scan_ok(scan)) {
    return FEATURES_ERR_INVALID_ARG;
  }
  const int have_pose = pose_in_task != NULL && pose_finite(pose_in_task);
  features_doorway_t odo;
  if (have_pose) {
    (void)features_doorway_from_pose(cfg, *pose_in_task, &odo);
  }

  features_point_t pts[FEATURES_MAX_BEAMS];
  out->n_points = features_scan_points(&cfg->scan, scan, pts);
  double px[FEATURES_MAX_BEAMS];
  double py[FEATURES_MAX_BEAMS];
  int n = 0;
  for (int i = 0; i < (int)scan->n_beams; ++i) {
    if (pts[i].valid != 0U) {
      px[n] = pts[i].x_m;
      py[n] = pts[i].y_m;
      ++n;
    }
  }

  // Odometry's prediction: the normal's direction and the near face's offset in the robot frame.
  const double t = cfg->wall_thickness_m;
  const double half_window = clampd(cfg->heading_window_rad, 0.05, 0.5 * FEAT_PI);
  int laser_ok = 0;
  wall_line_t line = {0.0, 0.0, 0U};
  gap_t gap = {0.0, 0.0, 0U};
  if (have_pose) {
    const double rho_pred = odo.wall_distance_m - 0.5 * t;
    if (rho_pred >= cfg->min_view_m && n > 0) {
      const double phi_pred = -odo.heading_rad;
      const double lo = cfg->gate_m > 0.0 ? rho_pred - cfg->gate_m : 0.0;
      const double hi = cfg->gate_m > 0.0 ? rho_pred + cfg->gate_m : (double)MAX_BINS * BIN_M;
      int n_dirs = 2 * (int)ceil(half_window / COARSE_STEP_RAD - 1e-9) + 1;
      n_dirs = n_dirs > MAX_DIRS ? MAX_DIRS : n_dirs;
      const wall_line_t coarse =
          search(px, py, n, phi_pred - COARSE_STEP_RAD * (double)(n_dirs / 2), COARSE_STEP_RAD, n_dirs, lo, hi);
      if (coarse.support >= cfg->min_wall_points) {
        line = fit_wall(cfg, px, py, n, coarse);
        if (line.support >= cfg->min_wall_points) {
          out->wall_seen = 1U;
          out->wall_points = (uint16_t)line.support;
          // The predicted gap centre along the measured wall (u = n turned +90°).
          const double s_pred = -odo.offset_m;
          laser_ok = find_gap(cfg, scan, pts, &line, 1, s_pred, &gap);
        }
      }
    }
  } else if (n > 0) {
    // Without odometry: the strongest lines of the front half-turn, best first, until one has
    // the door in it.
    wall_line_t cand[FREE_CANDIDATES];
    memset(cand, 0, sizeof cand);
    const double phi0 = -0.5 * FEAT_PI;
    for (int k = 0; k < MAX_DIRS; ++k) {
      const wall_line_t c = peak_of(px, py, n, phi0 + COARSE_STEP_RAD * (double)k, 0.0, (double)MAX_BINS * BIN_M);
      // Keep the best FREE_CANDIDATES of clearly different directions (insertion; O(1)).
      int same = -1;
      for (int j = 0; j < FREE_CANDIDATES; ++j) {
        if (cand[j].support > 0U && fabs(cand[j].phi_rad - c.phi_rad) < SAME_DIRECTION_RAD) same = j;
      }
      if (same >= 0) {
        if (c.support > cand[same].support) {
          cand[same] = c;
          // Re-sort the slot upwards.
          for (int j = same; j > 0 && cand[j].support > cand[j - 1].support; --j) {
            const wall_line_t tmp = cand[j];
            cand[j] = cand[j - 1];
            cand[j - 1] = tmp;
          }
        }
        continue;
      }
      for (int j = 0; j < FREE_CANDIDATES; ++j) {
        if (c.support > cand[j].support) {
          for (int m = FREE_CANDIDATES - 1; m > j; --m) cand[m] = cand[m - 1];
          cand[j] = c;
          break;
        }
      }
    }
    for (int j = 0; j < FREE_CANDIDATES && !laser_ok; ++j) {
      if (cand[j].support < cfg->min_wall_points) break;
      const wall_line_t l = fit_wall(cfg, px, py, n, cand[j]);
      if (l.support < cfg->min_wall_points) continue;
      if (out->wall_seen == 0U) {
        out->wall_seen = 1U;
        out->wall_points = (uint16_t)l.support;
      }
      if (find_gap(cfg, scan, pts, &l, 0, 0.0, &gap)) {
        line = l;
        out->wall_points = (uint16_t)l.support;
        laser_ok = 1;
      }
    }
  }

  if (laser_ok) {
    features_doorway_t laser = *out;
    set_from_laser(cfg, &line, &gap, &laser);
    const int agrees = !have_pose || cfg->gate_m <= 0.0 ||
                       (fabs(laser.wall_distance_m - odo.wall_distance_m) <= cfg->gate_m &&
                        fabs(laser.offset_m - odo.offset_m) <= cfg->gate_m &&
                        (cfg->gate_rad <= 0.0 || fabs(features_angle_wrap(laser.heading_rad - odo.heading_rad)) <=
                                                     cfg->gate_rad));
    if (agrees) {
      laser.valid = 1U;
      laser.source = (uint8_t)FEATURES_SOURCE_LASER;
      laser.jambs_seen = gap.jambs;
      *out = laser;
      return FEATURES_OK;
    }
  }
  if (have_pose) {
    const uint8_t wall_seen = out->wall_seen;
    const uint16_t n_points = out->n_points;
    const uint16_t wall_points = out->wall_points;
    *out = odo;
    out->wall_seen = wall_seen;
    out->n_points = n_points;
    out->wall_points = wall_points;
  }
  return FEATURES_OK;
}
