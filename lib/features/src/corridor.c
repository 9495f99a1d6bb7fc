// SPDX-License-Identifier: MIT
// Corridor state: wall pair by a bounded Hough search plus joint least squares, end wall, fusion.
#include "features/corridor.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "scan_points.h"

void features_corridor_config_default(features_corridor_config_t* cfg) {
  features_scan_config_default(&cfg->scan);
  cfg->width_m = 2.0;
  cfg->length_m = 10.0;
  cfg->lookahead_m = 2.0;
  cfg->width_tolerance_m = 0.4;
  cfg->inlier_tolerance_m = 0.08;
  cfg->min_wall_points = 6U;
  cfg->min_end_points = 5U;
  cfg->min_wall_length_m = 0.4;
  cfg->heading_window_rad = 0.6;
  cfg->end_gate_m = 1.5;
}

static int config_ok(const features_corridor_config_t* cfg) {
  return features_scan_config_ok(&cfg->scan) && isfinite(cfg->width_m) && cfg->width_m > 0.0 &&
         isfinite(cfg->length_m) && cfg->length_m > 0.0 && isfinite(cfg->lookahead_m) &&
         cfg->lookahead_m > 0.0 && isfinite(cfg->width_tolerance_m) &&
         cfg->width_tolerance_m >= 0.0 && isfinite(cfg->inlier_tolerance_m) &&
         cfg->inlier_tolerance_m > 0.0 && isfinite(cfg->heading_window_rad) &&
         isfinite(cfg->min_wall_length_m) && cfg->min_wall_length_m >= 0.0 &&
         isfinite(cfg->end_gate_m) && cfg->end_gate_m >= 0.0;
}

static void set_neutral(const features_corridor_config_t* cfg, features_corridor_t* out) {
  out->end_distance_m = (cfg != NULL && isfinite(cfg->length_m) && cfg->length_m > 0.0)
                            ? cfg->length_m : 0.0;
  out->lateral_frac = 0.5;
  out->target_angle_rad = 0.0;
  out->offset_m = 0.0;
  out->heading_rad = 0.0;
  out->width_m = (cfg != NULL && isfinite(cfg->width_m) && cfg->width_m > 0.0) ? cfg->width_m : 0.0;
  out->valid = 0U;
  out->walls_seen = 0U;
  out->left_wall_seen = 0U;
  out->right_wall_seen = 0U;
  out->end_wall_seen = 0U;
  out->lateral_source = (uint8_t)FEATURES_SOURCE_NONE;
  out->end_source = (uint8_t)FEATURES_SOURCE_NONE;
  out->n_points = 0U;
  out->left_points = 0U;
  out->right_points = 0U;
  out->end_points = 0U;
  out->fit_rms_m = 0.0;
}

static double clamp01(double v) { return v < 0.0 ? 0.0 : (v > 1.0 ? 1.0 : v); }

// Lateral quantities from the robot's offset d (+ left of centre) and heading psi (relative to
// the corridor axis): the paper's target angle, written with atan2 (see the header).
static void set_lateral(const features_corridor_config_t* cfg, double offset_m, double heading_rad,
                        double width_m, features_corridor_t* out) {
  out->offset_m = offset_m;
  out->heading_rad = features_angle_wrap(heading_rad);
  out->width_m = width_m;
  out->lateral_frac = clamp01((0.5 * width_m - offset_m) / width_m);
  const double phi = -out->heading_rad;
  out->target_angle_rad = features_angle_wrap(phi - atan2(offset_m, cfg->lookahead_m));
}

features_status_t features_corridor_from_pose(const features_corridor_config_t* cfg,
                                              features_pose_t pose_in_corridor,
                                              features_corridor_t* out) {
  if (out == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_neutral(cfg, out);
  if (cfg == NULL || !config_ok(cfg) || !isfinite(pose_in_corridor.x_m) ||
      !isfinite(pose_in_corridor.y_m) || !isfinite(pose_in_corridor.theta_rad)) {
    return FEATURES_ERR_INVALID_ARG;
  }
  const double d_end = cfg->length_m - pose_in_corridor.x_m;
  out->end_distance_m = d_end > 0.0 ? d_end : 0.0;
  set_lateral(cfg, pose_in_corridor.y_m, pose_in_corridor.theta_rad, cfg->width_m, out);
  out->valid = 1U;
  out->lateral_source = (uint8_t)FEATURES_SOURCE_ODOMETRY;
  out->end_source = (uint8_t)FEATURES_SOURCE_ODOMETRY;
  return FEATURES_OK;
}

// Internal sizes of the bounded searches.
#define DIR_STEP_RAD (FEAT_PI / 180.0)  // 1° between candidate wall directions
#define MAX_DIRS 181                    // covers the full half-turn
#define COARSE_STEPS 3                  // coarse search step, in fine steps
#define BIN_M 0.05                      // histogram bin of lateral and along-axis offsets
#define MAX_LAT_BINS 256                // lateral histogram (|rho| <= width + tolerance)
#define MAX_END_BINS 200                // along-axis histogram (0 .. 10 m)
#define REFIT_PASSES 4                  // first two with a wide band, then the configured one
#define MAX_ASPECT 0.02                 // accepted minor/major scatter of the refit lines
#define MAX_REFIT_TURN_RAD (10.0 * DIR_STEP_RAD)

typedef struct wall_pair {
  double phi_rad;  // corridor axis direction in the robot frame
  double rho_l_m;  // left wall offset along the left normal (> 0)
  double rho_r_m;  // right wall offset (< 0)
  int left_ok;
  int right_ok;
  uint16_t n_left;
  uint16_t n_right;
  double rms_m;
  int has_end;     // a cross wall supported the direction
  double end_s_m;  // its along-axis offset (Hough resolution)
} wall_pair_t;

static double min_d(double a, double b) { return a < b ? a : b; }
static double max_d(double a, double b) { return a > b ? a : b; }

// Extent [lo, hi] of the values recorded in the non-empty bins among b-1, b, b+1.
static void span3(const uint16_t* h, const double* lo_v, const double* hi_v, int nb, int b,
                  double* lo, double* hi) {
  *lo = HUGE_VAL;
  *hi = -HUGE_VAL;
  for (int j = b - 1; j <= b + 1; ++j) {
    if (j >= 0 && j < nb && h[j] > 0U) {
      *lo = min_d(*lo, lo_v[j]);
      *hi = max_d(*hi, hi_v[j]);
    }
  }
}

static double normal_offset(double phi, double x, double y) { return -sin(phi) * x + cos(phi) * y; }

// floor(x) as an int for |x| well inside the int range: the same value as (int)floor(x), without
// the library call (hot: once per point and candidate direction).
static int floor_int(double x) {
  const int t = (int)x;
  return (double)t > x ? t - 1 : t;
}

// Sum of three neighbouring bins: the support of a wall within about +-1.5 bins.
static uint32_t h3(const uint16_t* h, int nb, int b) {
  uint32_t s = h[b];
  if (b > 0) s += h[b - 1];
  if (b + 1 < nb) s += h[b + 1];
  return s;
}

// Hough stage: for each candidate direction, histogram the lateral offsets and score the best
// pair of side walls about one width apart on either side of the robot (or the best single
// wall), plus the best cross wall (end wall) perpendicular to the direction. Counting the cross
// wall makes the direction sharp near the end of the corridor, where only one side wall and the
// end wall are in view and the corner would otherwise pull a tilted band.
static int hough_walls(const features_corridor_config_t* cfg, const features_point_t* pts,
                       uint16_t n_beams, double phi_centre, double half_window, double step,
                       int cross_only_ok, wall_pair_t* best) {
  const double lat_max = cfg->width_m + cfg->width_tolerance_m;
  int nb = (int)ceil(2.0 * lat_max / BIN_M);
  if (nb > MAX_LAT_BINS) nb = MAX_LAT_BINS;
  const double bin = 2.0 * lat_max / (double)nb;
  int n_dirs = 2 * (int)ceil(half_window / step - 1e-9) + 1;
  if (n_dirs > MAX_DIRS) n_dirs = MAX_DIRS;
  const double phi0 = phi_centre - step * (double)(n_dirs / 2);
  const int wmin = (int)floor((cfg->width_m - cfg->width_tolerance_m) / bin);
  const int wmax = (int)ceil((cfg->width_m + cfg->width_tolerance_m) / bin);
  const uint32_t min_pts = cfg->min_wall_points;
  const double min_len = cfg->min_wall_length_m;
  const double s_max = (double)MAX_END_BINS * BIN_M;

  uint32_t best_score = 0U;
  wall_pair_t best_sol = {0};
  uint16_t hist[MAX_LAT_BINS];
  double s_lo[MAX_LAT_BINS];
  double s_hi[MAX_LAT_BINS];
  uint32_t sup[MAX_LAT_BINS];  // support of a side wall centred on the bin (0 if too short)
  uint32_t beyond[MAX_LAT_BINS];
  uint16_t hist_s[MAX_END_BINS];
  double r_lo[MAX_END_BINS];
  double r_hi[MAX_END_BINS];
  // The valid points once, packed; per direction their lateral and along-axis offsets once.
  double px[FEATURES_MAX_BEAMS];
  double py[FEATURES_MAX_BEAMS];
  double rho_of[FEATURES_MAX_BEAMS];
  double along_of[FEATURES_MAX_BEAMS];
  double e_of[FEATURES_MAX_BEAMS];  // along-axis bin coordinate (before truncation)
  double b_of[FEATURES_MAX_BEAMS];  // lateral bin coordinate (before floor)
  int n_valid = 0;
  for (uint16_t i = 0U; i < n_beams; ++i) {
    if (pts[i].valid != 0U) {
      px[n_valid] = pts[i].x_m;
      py[n_valid] = pts[i].y_m;
      ++n_valid;
    }
  }
  for (int k = 0; k < n_dirs; ++k) {
    const double phi = phi0 + step * (double)k;
    const double sn = sin(phi);
    const double cs = cos(phi);
    memset(hist, 0, sizeof hist);
    uint32_t over_pos = 0U;
    uint32_t over_neg = 0U;
    memset(hist_s, 0, sizeof hist_s);
    // Extents start empty (+inf, -inf): the first point of a bin sets both, without a branch.
    for (int e = 0; e < MAX_END_BINS; ++e) {
      r_lo[e] = (double)INFINITY;
      r_hi[e] = -(double)INFINITY;
    }
    for (int b = 0; b < nb; ++b) {
      s_lo[b] = (double)INFINITY;
      s_hi[b] = -(double)INFINITY;
    }
    int e_first = MAX_END_BINS;  // range of the along-axis bins that received points
    int e_last = -1;
    // Pass 1: cross walls (along-axis histogram). Pass 2: side walls (lateral histogram) without
    // the points of the cross wall, whose corners would otherwise join up with clutter.
    // The offsets first, in a loop the compiler vectorises (element-wise: same results).
    for (int i = 0; i < n_valid; ++i) {
      rho_of[i] = -sn * px[i] + cs * py[i];
      along_of[i] = cs * px[i] + sn * py[i];
      e_of[i] = along_of[i] / BIN_M;
      b_of[i] = (rho_of[i] + lat_max) / bin;
    }
    for (int i = 0; i < n_valid; ++i) {
      const double rho = rho_of[i];
      const double along = along_of[i];
      if (along > 0.0 && along < s_max && fabs(rho) < lat_max) {
        const int e = (int)e_of[i];
        e_first = e < e_first ? e : e_first;
        e_last = e > e_last ? e : e_last;
        r_lo[e] = min_d(r_lo[e], rho);
        r_hi[e] = max_d(r_hi[e], rho);
        if (hist_s[e] < UINT16_MAX) ++hist_s[e];
      }
    }
    uint32_t end_sup = 0U;
    double end_s = 0.0;
    // Only bins next to a filled one can reach min_end_points (empty ones are skipped anyway).
    const int e_lo = e_first > 0 ? e_first - 1 : 0;
    const int e_hi = e_last + 1 < MAX_END_BINS ? e_last + 1 : MAX_END_BINS - 1;
    for (int e = e_lo; e <= e_hi; ++e) {
      const uint32_t n3 = h3(hist_s, MAX_END_BINS, e);
      if (n3 < cfg->min_end_points || n3 <= end_sup) continue;
      double lo, hi;
      span3(hist_s, r_lo, r_hi, MAX_END_BINS, e, &lo, &hi);
      if (hi - lo >= 0.5 * cfg->width_m) {
        end_sup = n3;
        end_s = ((double)e + 0.5) * BIN_M;
      }
    }
    const double end_excl = 2.0 * BIN_M + cfg->inlier_tolerance_m;
    int b_first = nb;  // range of the lateral bins that received points
    int b_last = -1;
    for (int i = 0; i < n_valid; ++i) {
      const double along = along_of[i];
      if (end_sup > 0U && fabs(along - end_s) <= end_excl) continue;
      const int b = floor_int(b_of[i]);
      if (b < 0) {
        ++over_neg;
      } else if (b >= nb) {
        ++over_pos;
      } else {
        b_first = b < b_first ? b : b_first;
        b_last = b > b_last ? b : b_last;
        s_lo[b] = min_d(s_lo[b], along);
        s_hi[b] = max_d(s_hi[b], along);
        if (hist[b] < UINT16_MAX) ++hist[b];
      }
    }
    // A wall is many points on a line that extends along it: a person or a door frame also
    // fills one lateral bin, but over a short length. And a wall bounds the corridor: points
    // beyond it (laterally outside) count against it, which keeps a person standing near a
    // wall, plus whatever lines up with them, from posing as the wall.
    // Only bins next to a filled one can have support: the others stay 0 and are not visited
    // below (every loop over them would skip them anyway).
    const int b_lo = b_first > 0 ? b_first - 1 : 0;
    const int b_hi = b_last + 1 < nb ? b_last + 1 : nb - 1;
    uint32_t outside = over_neg;  // points laterally beyond bin b on the right side
    for (int b = b_lo; b <= b_hi; ++b) {
      if (b >= 3) outside += hist[b - 3];
      beyond[b] = outside;
    }
    outside = over_pos;
    for (int b = b_hi; b >= b_lo; --b) {
      if (b + 3 < nb) outside += hist[b + 3];
      if (b >= nb / 2) beyond[b] = outside;
    }
    memset(sup, 0, sizeof sup[0] * (size_t)nb);
    for (int b = b_lo; b <= b_hi; ++b) {
      const uint32_t n3 = h3(hist, nb, b);
      const uint32_t net = n3 > beyond[b] ? n3 - beyond[b] : 0U;
      if (net >= min_pts) {
        double lo, hi;
        span3(hist, s_lo, s_hi, nb, b, &lo, &hi);
        sup[b] = hi - lo >= min_len ? net : 0U;
      }
    }
    const int mid = nb / 2;  // bins >= mid have rho >= 0 (left)
    uint32_t pair_here = 0U;
    uint32_t single_here = 0U;
    wall_pair_t pair_cand = {0};
    wall_pair_t single_cand = {0};
    for (int bl = mid > b_lo ? mid : b_lo; bl <= b_hi; ++bl) {
      const uint32_t sl = sup[bl];
      if (sl == 0U) continue;
      if (sl > single_here) {
        single_here = sl;
        single_cand.left_ok = 1;
        single_cand.right_ok = 0;
        single_cand.rho_l_m = ((double)bl + 0.5) * bin - lat_max;
      }
      const int lo = bl - wmax < 0 ? 0 : bl - wmax;
      const int hi = bl - wmin >= mid ? mid - 1 : bl - wmin;
      for (int br = lo; br <= hi; ++br) {
        const uint32_t sr = sup[br];
        if (sr > 0U && sl + sr > pair_here) {
          pair_here = sl + sr;
          pair_cand.left_ok = 1;
          pair_cand.right_ok = 1;
          pair_cand.rho_l_m = ((double)bl + 0.5) * bin - lat_max;
          pair_cand.rho_r_m = ((double)br + 0.5) * bin - lat_max;
        }
      }
    }
    for (int br = b_lo; br < mid && br <= b_hi; ++br) {
      const uint32_t sr = sup[br];
      if (sr > single_here) {
        single_here = sr;
        single_cand.left_ok = 0;
        single_cand.right_ok = 1;
        single_cand.rho_r_m = ((double)br + 0.5) * bin - lat_max;
      }
    }
    // One score for pairs and single walls: a pair wins at its own direction (it adds the
    // second wall), but a weak pair at a tilted direction does not beat a clean single wall.
    if (pair_here > 0U && pair_here >= single_here && pair_here + end_sup > best_score) {
      best_score = pair_here + end_sup;
      best_sol = pair_cand;
      best_sol.phi_rad = phi;
      best_sol.has_end = end_sup > 0U;
      best_sol.end_s_m = end_s;
    } else if (single_here > pair_here && single_here + end_sup > best_score) {
      best_score = single_here + end_sup;
      best_sol = single_cand;
      best_sol.phi_rad = phi;
      best_sol.has_end = end_sup > 0U;
      best_sol.end_s_m = end_s;
    } else if (cross_only_ok && pair_here == 0U && single_here == 0U && end_sup > best_score) {
      // Only a cross wall (next to the end wall, the side walls out of view): it must still
      // compete, or a tilted direction that joins wall stubs into a bogus side wall would win.
      // Only inside an odometry window: in a full search a side wall seen head-on would pass
      // for a cross wall 90° away.
      best_score = end_sup;
      memset(&best_sol, 0, sizeof best_sol);
      best_sol.phi_rad = phi;
      best_sol.rho_l_m = lat_max;
      best_sol.rho_r_m = -lat_max;
      best_sol.has_end = 1;
      best_sol.end_s_m = end_s;
    }
  }
  if (best_score == 0U) {
    return 0;
  }
  *best = best_sol;
  if (best->left_ok && !best->right_ok) {
    best->rho_r_m = best->rho_l_m - cfg->width_m;
  } else if (best->right_ok && !best->left_ok) {
    best->rho_l_m = best->rho_r_m + cfg->width_m;
  }
  return 1;
}

// Least-squares stage: both walls share one direction. The direction is the principal axis of
// the pooled scatter of each wall's inliers about its own centroid; the offsets are the
// projections of the centroids. Falls back to the Hough direction if the refit turns by more
// than a few candidate steps (too few or too short inliers to trust).
static void refit_walls(const features_corridor_config_t* cfg, const features_point_t* pts,
                        uint16_t n_beams, double tol, wall_pair_t* w) {
  // Groups: 0 left wall, 1 right wall, 2 cross (end) wall. Points near the cross wall are kept
  // out of the side walls: at the corners they lie inside a side wall's band but tilt its fit.
  const double end_excl = 2.0 * BIN_M + cfg->inlier_tolerance_m;
  const double margin = cfg->inlier_tolerance_m + 0.05;
  const double c0 = cos(w->phi_rad);
  const double s0 = sin(w->phi_rad);
  double sx[3] = {0.0, 0.0, 0.0}, sy[3] = {0.0, 0.0, 0.0};
  uint32_t cnt[3] = {0U, 0U, 0U};
  const int use[3] = {w->left_ok, w->right_ok, w->has_end};
  uint8_t group[FEATURES_MAX_BEAMS];
  double lo[3] = {HUGE_VAL, HUGE_VAL, HUGE_VAL};  // extent along each line
  double hi[3] = {-HUGE_VAL, -HUGE_VAL, -HUGE_VAL};
  for (uint16_t i = 0U; i < n_beams; ++i) {
    group[i] = 3U;  // none
    if (pts[i].valid == 0U) continue;
    const double r = -s0 * pts[i].x_m + c0 * pts[i].y_m;
    const double along = c0 * pts[i].x_m + s0 * pts[i].y_m;
    const double de = fabs(along - w->end_s_m);
    int g = 3;
    if (use[2] && de <= tol && r < w->rho_l_m - margin && r > w->rho_r_m + margin) {
      g = 2;
    } else if (use[2] && de <= end_excl) {
      g = 3;
    } else if (use[0] && fabs(r - w->rho_l_m) <= tol) {
      g = 0;
    } else if (use[1] && fabs(r - w->rho_r_m) <= tol) {
      g = 1;
    }
    if (g < 3) {
      group[i] = (uint8_t)g;
      sx[g] += pts[i].x_m;
      sy[g] += pts[i].y_m;
      ++cnt[g];
      lo[g] = fmin(lo[g], g == 2 ? r : along);
      hi[g] = fmax(hi[g], g == 2 ? r : along);
    }
  }
  double cx[3] = {0.0, 0.0, 0.0}, cy[3] = {0.0, 0.0, 0.0};
  int ok[3] = {0, 0, 0};
  for (int g = 0; g < 3; ++g) {
    ok[g] = use[g] && cnt[g] >= (g == 2 ? cfg->min_end_points : cfg->min_wall_points) &&
            hi[g] - lo[g] >= (g == 2 ? 0.5 * cfg->width_m : cfg->min_wall_length_m);
    if (cnt[g] > 0U) {
      cx[g] = sx[g] / (double)cnt[g];
      cy[g] = sy[g] / (double)cnt[g];
    }
  }
  // Pooled scatter about each group's centroid; the cross wall enters rotated by 90° so that
  // all three lines vote for one axis direction.
  double sxx = 0.0, syy = 0.0, sxy = 0.0;
  for (uint16_t i = 0U; i < n_beams; ++i) {
    const int g = group[i];
    if (g >= 3 || !ok[g]) continue;
    const double dx = pts[i].x_m - cx[g];
    const double dy = pts[i].y_m - cy[g];
    if (g == 2) {
      sxx += dy * dy;
      syy += dx * dx;
      sxy -= dx * dy;
    } else {
      sxx += dx * dx;
      syy += dy * dy;
      sxy += dx * dy;
    }
  }
  double phi = w->phi_rad;
  if (ok[0] || ok[1]) {
    const double fit = 0.5 * atan2(2.0 * sxy, sxx - syy);  // line direction, mod pi
    const double turn = features_angle_wrap(2.0 * (fit - w->phi_rad)) * 0.5;  // mod pi
    // Accept the refit only when the inliers really are lines (the spread across them is small
    // against the spread along them) and it stays near the Hough direction; otherwise (a short
    // wall stub, a few points) the Hough direction is the better estimate.
    const double half_sum = 0.5 * (sxx + syy);
    const double root = sqrt(0.25 * (sxx - syy) * (sxx - syy) + sxy * sxy);
    const double minor = half_sum - root;
    const double major = half_sum + root;
    if (major > 0.0 && minor <= MAX_ASPECT * major && fabs(turn) <= MAX_REFIT_TURN_RAD) {
      phi = w->phi_rad + turn;
    }
  }
  w->phi_rad = phi;
  w->left_ok = ok[0];
  w->right_ok = ok[1];
  w->has_end = ok[2];
  w->n_left = (uint16_t)(ok[0] ? cnt[0] : 0U);
  w->n_right = (uint16_t)(ok[1] ? cnt[1] : 0U);
  if (ok[0]) w->rho_l_m = normal_offset(phi, cx[0], cy[0]);
  if (ok[1]) w->rho_r_m = normal_offset(phi, cx[1], cy[1]);
  if (ok[0] && !ok[1]) w->rho_r_m = w->rho_l_m - cfg->width_m;
  if (ok[1] && !ok[0]) w->rho_l_m = w->rho_r_m + cfg->width_m;
  if (ok[2]) w->end_s_m = cos(phi) * cx[2] + sin(phi) * cy[2];
  // Residuals of the side-wall inliers about the final lines.
  double ss = 0.0;
  uint32_t nr = 0U;
  for (uint16_t i = 0U; i < n_beams; ++i) {
    const int g = group[i];
    if (g >= 2 || !ok[g]) continue;
    const double r = normal_offset(phi, pts[i].x_m, pts[i].y_m) - (g == 0 ? w->rho_l_m : w->rho_r_m);
    ss += r * r;
    ++nr;
  }
  w->rms_m = nr > 0U ? sqrt(ss / (double)nr) : 0.0;
}

// End wall: among points between the side walls and ahead along the axis, the farthest
// along-axis peak whose points span at least half the corridor width. Returns its support.
static uint16_t find_end_wall(const features_corridor_config_t* cfg, const features_point_t* pts,
                              uint16_t n_beams, const wall_pair_t* w, double* s_end) {
  uint16_t hist[MAX_END_BINS];
  double lat_lo[MAX_END_BINS];
  double lat_hi[MAX_END_BINS];
  const double s_max = (double)MAX_END_BINS * BIN_M;
  for (int b = 0; b < MAX_END_BINS; ++b) {
    hist[b] = 0U;
    lat_lo[b] = HUGE_VAL;
    lat_hi[b] = -HUGE_VAL;
  }
  const double cs = cos(w->phi_rad);
  const double sn = sin(w->phi_rad);
  const double margin = cfg->inlier_tolerance_m + 0.05;
  for (uint16_t i = 0U; i < n_beams; ++i) {
    if (pts[i].valid == 0U) continue;
    const double s = cs * pts[i].x_m + sn * pts[i].y_m;
    const double r = -sn * pts[i].x_m + cs * pts[i].y_m;
    if (s <= 0.0 || s >= s_max || r >= w->rho_l_m - margin || r <= w->rho_r_m + margin) continue;
    const int b = (int)(s / BIN_M);
    if (hist[b] < UINT16_MAX) ++hist[b];
    lat_lo[b] = fmin(lat_lo[b], r);
    lat_hi[b] = fmax(lat_hi[b], r);
  }
  const double width = w->rho_l_m - w->rho_r_m;
  for (int b = MAX_END_BINS - 1; b >= 0; --b) {
    if (h3(hist, MAX_END_BINS, b) < cfg->min_end_points) continue;
    double lo = lat_lo[b], hi = lat_hi[b];
    if (b > 0) { lo = fmin(lo, lat_lo[b - 1]); hi = fmax(hi, lat_hi[b - 1]); }
    if (b + 1 < MAX_END_BINS) { lo = fmin(lo, lat_lo[b + 1]); hi = fmax(hi, lat_hi[b + 1]); }
    if (hi - lo < 0.5 * width) continue;
    // Refine: mean along-axis offset of the points near this peak.
    const double s_peak = ((double)b + 0.5) * BIN_M;
    double sum = 0.0;
    uint32_t n = 0U;
    for (uint16_t i = 0U; i < n_beams; ++i) {
      if (pts[i].valid == 0U) continue;
      const double s = cs * pts[i].x_m + sn * pts[i].y_m;
      const double r = -sn * pts[i].x_m + cs * pts[i].y_m;
      if (fabs(s - s_peak) <= 1.5 * BIN_M + cfg->inlier_tolerance_m && r < w->rho_l_m - margin &&
          r > w->rho_r_m + margin) {
        sum += s;
        ++n;
      }
    }
    if (n < cfg->min_end_points) continue;
    *s_end = sum / (double)n;
    return (uint16_t)n;
  }
  return 0U;
}

features_status_t features_corridor_compute(const features_corridor_config_t* cfg,
                                            const features_scan_t* scan,
                                            const features_pose_t* pose_in_corridor,
                                            features_corridor_t* out) {
  if (out == NULL) {
    return FEATURES_ERR_INVALID_ARG;
  }
  set_neutral(cfg, out);
  if (cfg == NULL || scan == NULL || !config_ok(cfg) || !features_scan_ok(scan)) {
    return FEATURES_ERR_INVALID_ARG;
  }
  const int have_odom = pose_in_corridor != NULL && isfinite(pose_in_corridor->x_m) &&
                        isfinite(pose_in_corridor->y_m) && isfinite(pose_in_corridor->theta_rad);
  features_corridor_t odom;
  if (have_odom) {
    (void)features_corridor_from_pose(cfg, *pose_in_corridor, &odom);
    *out = odom;
  }

  features_point_t pts[FEATURES_MAX_BEAMS];
  out->n_points = features_scan_points(&cfg->scan, scan, pts);

  // Direction search window: around the odometry prediction, or the full half-turn.
  double window = cfg->heading_window_rad;
  if (window < 0.05) window = 0.05;
  const int full = !have_odom || window >= 0.5 * FEAT_PI;
  const double phi_pred = have_odom ? -features_angle_wrap(pose_in_corridor->theta_rad) : 0.0;
  const double centre = full ? 0.0 : phi_pred;
  const double half = full ? 0.5 * FEAT_PI : window;

  // Coarse to fine: 3° steps over the window, then 1° steps around the best coarse direction.
  // A 1.5° error spreads a wall 8 m away over 0.2 m, still inside the peak windows, and the
  // near walls that dominate the score hardly move.
  wall_pair_t w;
  if (out->n_points > 0U &&
      hough_walls(cfg, pts, scan->n_beams, centre, half, COARSE_STEPS * DIR_STEP_RAD, !full, &w) &&
      hough_walls(cfg, pts, scan->n_beams, w.phi_rad, (COARSE_STEPS - 1) * DIR_STEP_RAD,
                  DIR_STEP_RAD, !full, &w)) {
    // The first passes use a band that covers the Hough quantisation, the last ones the
    // configured tolerance.
    for (int pass = 0; pass < REFIT_PASSES && (w.left_ok || w.right_ok); ++pass) {
      const double tol = pass < REFIT_PASSES / 2 ? 2.0 * BIN_M + cfg->inlier_tolerance_m
                                                 : cfg->inlier_tolerance_m;
      refit_walls(cfg, pts, scan->n_beams, tol, &w);
    }
    // The axis points to the end: the sign nearest the odometry prediction, or to the front
    // half-plane without odometry. A line direction is only known modulo pi.
    const double ref = have_odom ? phi_pred : 0.0;
    if (cos(w.phi_rad - ref) < 0.0) {
      w.phi_rad = features_angle_wrap(w.phi_rad + FEAT_PI);
      const double l = w.rho_l_m;  // flipping the axis swaps left and right
      w.rho_l_m = -w.rho_r_m;
      w.rho_r_m = -l;
      const int lo = w.left_ok;
      w.left_ok = w.right_ok;
      w.right_ok = lo;
      const uint16_t nl = w.n_left;
      w.n_left = w.n_right;
      w.n_right = nl;
      w.end_s_m = -w.end_s_m;
    }
    const int sides = w.left_ok || w.right_ok;
    if (sides) {
      out->left_wall_seen = (uint8_t)(w.left_ok ? 1U : 0U);
      out->right_wall_seen = (uint8_t)(w.right_ok ? 1U : 0U);
      out->walls_seen = (uint8_t)(out->left_wall_seen + out->right_wall_seen);
      out->left_points = w.n_left;
      out->right_points = w.n_right;
      out->fit_rms_m = w.rms_m;
      // The robot centre is the origin: its offset from the centre line is minus the centre
      // line's offset.
      set_lateral(cfg, -0.5 * (w.rho_l_m + w.rho_r_m), -w.phi_rad, w.rho_l_m - w.rho_r_m, out);
      out->lateral_source = (uint8_t)FEATURES_SOURCE_LASER;
      out->valid = 1U;
    }
    if (sides || w.has_end) {
      double s_end = 0.0;
      const uint16_t n_end = find_end_wall(cfg, pts, scan->n_beams, &w, &s_end);
      const int gated = have_odom && cfg->end_gate_m > 0.0 &&
                        fabs(s_end - odom.end_distance_m) > cfg->end_gate_m;
      if (n_end > 0U && !gated) {
        out->end_distance_m = s_end > 0.0 ? s_end : 0.0;
        out->end_wall_seen = 1U;
        out->end_points = n_end;
        out->end_source = (uint8_t)FEATURES_SOURCE_LASER;
      } else if (!have_odom) {
        // Neither the end wall nor odometry: the end distance is unknown; report the corridor
        // length (far) with source NONE.
        out->end_distance_m = cfg->length_m;
        out->end_source = (uint8_t)FEATURES_SOURCE_NONE;
      }
    }
  }
  return FEATURES_OK;
}

void features_corridor_state(const features_corridor_t* f, double state[FEATURES_CORRIDOR_STATE_DIM]) {
  state[0] = f->end_distance_m;
  state[1] = f->lateral_frac;
  state[2] = f->target_angle_rad;
}
