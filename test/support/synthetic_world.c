// SPDX-License-Identifier: MIT
// Analytic 2-D world for tests: exact ray casting against segments and circles, LMS200-like
// scans with seeded imperfections, and the kinematic synchro-drive stepper.
#include "b21r_test/synthetic_world.h"

#include <math.h>
#include <stddef.h>

#define SYNTH_PI 3.14159265358979323846

void synth_world_init(synth_world_t* w) {
  w->n_segments = 0U;
  w->n_circles = 0U;
}

int synth_world_add_segment(synth_world_t* w, double x0_m, double y0_m, double x1_m, double y1_m) {
  if (w->n_segments >= SYNTH_MAX_SEGMENTS || !isfinite(x0_m) || !isfinite(y0_m) ||
      !isfinite(x1_m) || !isfinite(y1_m) || hypot(x1_m - x0_m, y1_m - y0_m) <= 0.0) {
    return -1;
  }
  synth_segment_t* s = &w->segments[w->n_segments++];
  s->x0_m = x0_m;
  s->y0_m = y0_m;
  s->x1_m = x1_m;
  s->y1_m = y1_m;
  return 0;
}

int synth_world_add_circle(synth_world_t* w, double x_m, double y_m, double radius_m) {
  if (w->n_circles >= SYNTH_MAX_CIRCLES || !isfinite(x_m) || !isfinite(y_m) ||
      !isfinite(radius_m) || radius_m <= 0.0) {
    return -1;
  }
  synth_circle_t* c = &w->circles[w->n_circles++];
  c->x_m = x_m;
  c->y_m = y_m;
  c->radius_m = radius_m;
  return 0;
}

int synth_world_add_box(synth_world_t* w, double min_x_m, double min_y_m, double max_x_m,
                        double max_y_m) {
  if (w->n_segments + 4U > SYNTH_MAX_SEGMENTS || !(max_x_m > min_x_m) || !(max_y_m > min_y_m)) {
    return -1;
  }
  (void)synth_world_add_segment(w, min_x_m, min_y_m, max_x_m, min_y_m);
  (void)synth_world_add_segment(w, max_x_m, min_y_m, max_x_m, max_y_m);
  (void)synth_world_add_segment(w, max_x_m, max_y_m, min_x_m, max_y_m);
  (void)synth_world_add_segment(w, min_x_m, max_y_m, min_x_m, min_y_m);
  return 0;
}

int synth_world_add_corridor(synth_world_t* w, double length_m, double width_m) {
  if (!(length_m > 0.0) || !(width_m > 0.0)) {
    return -1;
  }
  return synth_world_add_box(w, 0.0, -0.5 * width_m, length_m, 0.5 * width_m);
}

// Ray o + t d (|d| = 1) against segment a + s (b - a): Cramer's rule on the 2x2 system.
static double ray_segment(double ox, double oy, double dx, double dy, const synth_segment_t* s) {
  const double ex = s->x1_m - s->x0_m;
  const double ey = s->y1_m - s->y0_m;
  const double denom = dx * ey - dy * ex;  // cross(d, e)
  if (fabs(denom) < 1e-15) {
    return HUGE_VAL;  // parallel (a collinear grazing ray sees the wall edge-on: no return)
  }
  const double wx = s->x0_m - ox;
  const double wy = s->y0_m - oy;
  const double t = (wx * ey - wy * ex) / denom;
  const double u = (wx * dy - wy * dx) / denom;
  if (t < 0.0 || u < 0.0 || u > 1.0) {
    return HUGE_VAL;
  }
  return t;
}

static double ray_circle(double ox, double oy, double dx, double dy, const synth_circle_t* c) {
  const double fx = ox - c->x_m;
  const double fy = oy - c->y_m;
  const double b = fx * dx + fy * dy;
  const double cc = fx * fx + fy * fy - c->radius_m * c->radius_m;
  if (cc <= 0.0) {
    return 0.0;  // origin inside the cylinder
  }
  const double disc = b * b - cc;
  if (disc < 0.0) {
    return HUGE_VAL;
  }
  // The nearer root, in the cancellation-free form cc / q.
  const double q = -b + sqrt(disc);
  if (b >= 0.0 || q <= 0.0) {
    return HUGE_VAL;  // circle behind the origin
  }
  return cc / q;
}

double synth_world_raycast(const synth_world_t* w, double ox_m, double oy_m, double dir_rad,
                           synth_hit_t* hit) {
  const double dx = cos(dir_rad);
  const double dy = sin(dir_rad);
  double best = HUGE_VAL;
  synth_hit_t h = {(uint8_t)SYNTH_HIT_NONE, 0U};
  for (uint32_t i = 0U; i < w->n_segments; ++i) {
    const double t = ray_segment(ox_m, oy_m, dx, dy, &w->segments[i]);
    if (t < best) {
      best = t;
      h.kind = (uint8_t)SYNTH_HIT_SEGMENT;
      h.index = i;
    }
  }
  for (uint32_t i = 0U; i < w->n_circles; ++i) {
    const double t = ray_circle(ox_m, oy_m, dx, dy, &w->circles[i]);
    if (t < best) {
      best = t;
      h.kind = (uint8_t)SYNTH_HIT_CIRCLE;
      h.index = i;
    }
  }
  if (hit != NULL) {
    *hit = h;
  }
  return best;
}

static double point_segment_distance(double px, double py, const synth_segment_t* s) {
  const double ex = s->x1_m - s->x0_m;
  const double ey = s->y1_m - s->y0_m;
  const double len2 = ex * ex + ey * ey;
  double u = ((px - s->x0_m) * ex + (py - s->y0_m) * ey) / len2;
  u = u < 0.0 ? 0.0 : (u > 1.0 ? 1.0 : u);
  return hypot(px - (s->x0_m + u * ex), py - (s->y0_m + u * ey));
}

double synth_world_clearance(const synth_world_t* w, double x_m, double y_m) {
  double best = HUGE_VAL;
  for (uint32_t i = 0U; i < w->n_segments; ++i) {
    best = fmin(best, point_segment_distance(x_m, y_m, &w->segments[i]));
  }
  for (uint32_t i = 0U; i < w->n_circles; ++i) {
    const synth_circle_t* c = &w->circles[i];
    best = fmin(best, hypot(x_m - c->x_m, y_m - c->y_m) - c->radius_m);
  }
  return best;
}

int synth_world_collides(const synth_world_t* w, double x_m, double y_m, double radius_m) {
  return synth_world_clearance(w, x_m, y_m) <= radius_m;
}

void synth_rng_seed(synth_rng_t* r, uint64_t seed) { r->state = seed; }

uint64_t synth_rng_next(synth_rng_t* r) {
  uint64_t z = (r->state += 0x9E3779B97F4A7C15ULL);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

double synth_rng_uniform(synth_rng_t* r) { return (double)(synth_rng_next(r) >> 11) * 0x1.0p-53; }

double synth_rng_normal(synth_rng_t* r) {
  const double u1 = 1.0 - synth_rng_uniform(r);  // (0, 1]
  const double u2 = synth_rng_uniform(r);
  return sqrt(-2.0 * log(u1)) * cos(2.0 * SYNTH_PI * u2);
}

int synth_lidar_config_lms200(synth_lidar_config_t* cfg, int field_deg, double resolution_deg) {
  double steps = 0.0;
  if (fabs(resolution_deg - 1.0) < 1e-9) {
    steps = 1.0;
  } else if (fabs(resolution_deg - 0.5) < 1e-9) {
    steps = 2.0;
  } else if (fabs(resolution_deg - 0.25) < 1e-9 && field_deg == 100) {
    steps = 4.0;
  } else {
    return -1;
  }
  if (field_deg != 180 && field_deg != 100) {
    return -1;
  }
  const double deg = SYNTH_PI / 180.0;
  cfg->angle_min_rad = -0.5 * (double)field_deg * deg;
  cfg->angle_increment_rad = deg / steps;
  cfg->n_beams = (uint16_t)(field_deg * (int)steps + 1);
  cfg->mount_x_m = 0.15;
  cfg->mount_y_m = 0.0;
  cfg->mount_yaw_rad = 0.0;
  cfg->max_range_m = SYNTH_LMS200_MAX_RANGE_M;
  cfg->noise_sigma_m = 0.01;
  cfg->quantum_m = 0.001;
  cfg->dropout_prob = 0.0;
  cfg->error_code_prob = 0.0;
  cfg->raw_error_codes = 0U;
  return 0;
}

static void write_no_return(const synth_lidar_config_t* cfg, uint8_t reason, float* range,
                            uint8_t* nr) {
  if (cfg->raw_error_codes != 0U) {
    *nr = 0U;
    *range = reason == (uint8_t)SYNTH_NR_DAZZLE ? 8.190f
             : reason == (uint8_t)SYNTH_NR_SNR  ? 8.187f
                                                : (float)SYNTH_LMS200_NO_ECHO_M;
  } else {
    *nr = reason;
    *range = 0.0f;
  }
}

int synth_lidar_scan(const synth_world_t* w, const synth_lidar_config_t* cfg, synth_rng_t* rng,
                     double robot_x_m, double robot_y_m, double robot_theta_rad, float* ranges_m,
                     uint8_t* no_return, uint16_t capacity) {
  if (cfg->n_beams > SYNTH_MAX_BEAMS || cfg->n_beams > capacity || !(cfg->angle_increment_rad > 0.0)) {
    return -1;
  }
  const int random = cfg->noise_sigma_m > 0.0 || cfg->dropout_prob > 0.0 || cfg->error_code_prob > 0.0;
  if (random && rng == NULL) {
    return -1;
  }
  const double c = cos(robot_theta_rad);
  const double s = sin(robot_theta_rad);
  const double lx = robot_x_m + c * cfg->mount_x_m - s * cfg->mount_y_m;
  const double ly = robot_y_m + s * cfg->mount_x_m + c * cfg->mount_y_m;
  for (uint16_t i = 0U; i < cfg->n_beams; ++i) {
    const double a = robot_theta_rad + cfg->mount_yaw_rad + cfg->angle_min_rad +
                     (double)i * cfg->angle_increment_rad;
    double r = synth_world_raycast(w, lx, ly, a, NULL);
    // Imperfections are drawn for every beam in a fixed order so that enabling one kind never
    // shifts the random stream of another between runs with the same seed.
    const double noise = cfg->noise_sigma_m > 0.0 ? cfg->noise_sigma_m * synth_rng_normal(rng) : 0.0;
    const double u_drop = cfg->dropout_prob > 0.0 ? synth_rng_uniform(rng) : 1.0;
    const double u_code = cfg->error_code_prob > 0.0 ? synth_rng_uniform(rng) : 1.0;
    if (u_drop < cfg->dropout_prob) {
      write_no_return(cfg, (uint8_t)SYNTH_NR_DROPOUT, &ranges_m[i], &no_return[i]);
      continue;
    }
    if (u_code < cfg->error_code_prob) {
      const uint8_t reason = u_code < 0.5 * cfg->error_code_prob ? (uint8_t)SYNTH_NR_DAZZLE
                                                                  : (uint8_t)SYNTH_NR_SNR;
      write_no_return(cfg, reason, &ranges_m[i], &no_return[i]);
      continue;
    }
    if (!(r < cfg->max_range_m)) {
      write_no_return(cfg, (uint8_t)SYNTH_NR_NO_ECHO, &ranges_m[i], &no_return[i]);
      continue;
    }
    r += noise;
    if (cfg->quantum_m > 0.0) {
      r = cfg->quantum_m * floor(r / cfg->quantum_m + 0.5);
    }
    if (r < 0.0) {
      r = 0.0;
    }
    ranges_m[i] = (float)r;
    no_return[i] = (uint8_t)SYNTH_NR_VALID;
  }
  return (int)cfg->n_beams;
}

static double wrap(double a) {
  double x = fmod(a, 2.0 * SYNTH_PI);
  if (x > SYNTH_PI) {
    x -= 2.0 * SYNTH_PI;
  } else if (x <= -SYNTH_PI) {
    x += 2.0 * SYNTH_PI;
  }
  return x;
}

static double approach(double current, double target, double max_step) {
  if (max_step <= 0.0) {
    return target;
  }
  const double d = target - current;
  return current + (d > max_step ? max_step : (d < -max_step ? -max_step : d));
}

void synth_drive_step(synth_robot_t* r, double v_cmd_mps, double omega_cmd_radps, double dt_s,
                      const synth_drive_limits_t* limits) {
  const double acc_v = limits != NULL ? limits->acc_mps2 : 0.0;
  const double acc_w = limits != NULL ? limits->acc_radps2 : 0.0;
  r->v_mps = approach(r->v_mps, v_cmd_mps, acc_v > 0.0 ? acc_v * dt_s : 0.0);
  r->omega_radps = approach(r->omega_radps, omega_cmd_radps, acc_w > 0.0 ? acc_w * dt_s : 0.0);
  r->theta_rad = wrap(r->theta_rad + r->omega_radps * dt_s);
  r->x_m += r->v_mps * dt_s * cos(r->theta_rad);
  r->y_m += r->v_mps * dt_s * sin(r->theta_rad);
}
