// SPDX-License-Identifier: MIT
// World files of the emulator: parser, builders and the analytic queries of the kinematic model.
#include "sim/world.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define WORLD_MAX_TOKENS 8
#define WORLD_FILE_MAX_BYTES (64L * 1024L)

static void set_err(char* err, size_t err_cap, const char* fmt, ...) __attribute__((format(printf, 3, 4)));

static void set_err(char* err, size_t err_cap, const char* fmt, ...) {
  if (err == NULL || err_cap == 0) {
    return;
  }
  va_list ap;
  va_start(ap, fmt);
  (void)vsnprintf(err, err_cap, fmt, ap);
  va_end(ap);
}

void sim_world_clear(sim_world_t* w) {
  memset(w, 0, sizeof(*w));
  (void)snprintf(w->name, sizeof(w->name), "%s", "empty");
  sim_world_compute_bounds(w);
}

static int all_finite(const double* v, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    if (!isfinite(v[i])) {
      return 0;
    }
  }
  return 1;
}

sim_world_status_t sim_world_add_wall(sim_world_t* w, double x0_m, double y0_m, double x1_m,
                                      double y1_m, double thickness_m) {
  const double v[5] = {x0_m, y0_m, x1_m, y1_m, thickness_m};
  if (w == NULL || !all_finite(v, 5) || !(thickness_m > 0.0) ||
      hypot(x1_m - x0_m, y1_m - y0_m) < 1e-6) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  if (w->n_walls >= SIM_WORLD_MAX_WALLS) {
    return SIM_WORLD_ERR_CAPACITY;
  }
  w->walls[w->n_walls++] = (sim_wall_t){x0_m, y0_m, x1_m, y1_m, thickness_m};
  return SIM_WORLD_OK;
}

sim_world_status_t sim_world_add_cylinder(sim_world_t* w, double x_m, double y_m, double radius_m) {
  const double v[3] = {x_m, y_m, radius_m};
  if (w == NULL || !all_finite(v, 3) || !(radius_m > 0.0)) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  if (w->n_cylinders >= SIM_WORLD_MAX_CYLINDERS) {
    return SIM_WORLD_ERR_CAPACITY;
  }
  w->cylinders[w->n_cylinders++] = (sim_cylinder_t){x_m, y_m, radius_m};
  return SIM_WORLD_OK;
}

sim_world_status_t sim_world_add_start(sim_world_t* w, double x_m, double y_m, double theta_rad) {
  const double v[3] = {x_m, y_m, theta_rad};
  if (w == NULL || !all_finite(v, 3)) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  if (w->n_starts >= SIM_WORLD_MAX_STARTS) {
    return SIM_WORLD_ERR_CAPACITY;
  }
  w->starts[w->n_starts++] = (sim_pose_t){x_m, y_m, theta_rad};
  return SIM_WORLD_OK;
}

sim_world_status_t sim_world_add_corridor(sim_world_t* w, double length_m, double width_m,
                                          int closed_end) {
  const double v[2] = {length_m, width_m};
  if (w == NULL || !all_finite(v, 2) || !(length_m > 0.0) || !(width_m > 0.0)) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  const size_t needed = closed_end ? 4U : 3U;
  if (w->n_walls + needed > SIM_WORLD_MAX_WALLS) {
    return SIM_WORLD_ERR_CAPACITY;
  }
  const double h = 0.5 * width_m;
  const double t = SIM_WORLD_WALL_THICKNESS_DEFAULT_M;
  // Each face runs so that its solid (to the right of p0 -> p1) lies outside the corridor, and
  // the side walls reach over the end walls' thickness so that the corners are closed.
  (void)sim_world_add_wall(w, -t, -h, length_m + (closed_end ? t : 0.0), -h, t);  // right wall
  (void)sim_world_add_wall(w, length_m + (closed_end ? t : 0.0), h, -t, h, t);    // left wall
  (void)sim_world_add_wall(w, 0.0, h, 0.0, -h, t);                                // behind start
  if (closed_end) {
    (void)sim_world_add_wall(w, length_m, -h, length_m, h, t);
  }
  w->has_corridor = 1;
  w->corridor_length_m = length_m;
  w->corridor_width_m = width_m;
  return SIM_WORLD_OK;
}

sim_world_status_t sim_world_add_arena(sim_world_t* w, double min_x_m, double min_y_m,
                                       double max_x_m, double max_y_m) {
  const double v[4] = {min_x_m, min_y_m, max_x_m, max_y_m};
  if (w == NULL || !all_finite(v, 4) || !(min_x_m < max_x_m) || !(min_y_m < max_y_m)) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  if (w->n_walls + 4U > SIM_WORLD_MAX_WALLS) {
    return SIM_WORLD_ERR_CAPACITY;
  }
  const double t = SIM_WORLD_WALL_THICKNESS_DEFAULT_M;
  // Counter-clockwise round the box puts each solid outside; every face is extended by the
  // thickness at its start so that the corners are closed.
  (void)sim_world_add_wall(w, min_x_m - t, min_y_m, max_x_m, min_y_m, t);
  (void)sim_world_add_wall(w, max_x_m, min_y_m - t, max_x_m, max_y_m, t);
  (void)sim_world_add_wall(w, max_x_m + t, max_y_m, min_x_m, max_y_m, t);
  (void)sim_world_add_wall(w, min_x_m, max_y_m + t, min_x_m, min_y_m, t);
  return SIM_WORLD_OK;
}

void sim_world_compute_bounds(sim_world_t* w) {
  double lo_x = HUGE_VAL, lo_y = HUGE_VAL, hi_x = -HUGE_VAL, hi_y = -HUGE_VAL;
#define WORLD_GROW(px, py)     \
  do {                         \
    lo_x = fmin(lo_x, (px));   \
    lo_y = fmin(lo_y, (py));   \
    hi_x = fmax(hi_x, (px));   \
    hi_y = fmax(hi_y, (py));   \
  } while (0)
  for (size_t i = 0; i < w->n_walls; ++i) {
    WORLD_GROW(w->walls[i].x0_m, w->walls[i].y0_m);
    WORLD_GROW(w->walls[i].x1_m, w->walls[i].y1_m);
  }
  for (size_t i = 0; i < w->n_cylinders; ++i) {
    const sim_cylinder_t* c = &w->cylinders[i];
    WORLD_GROW(c->x_m - c->radius_m, c->y_m - c->radius_m);
    WORLD_GROW(c->x_m + c->radius_m, c->y_m + c->radius_m);
  }
  for (size_t i = 0; i < w->n_starts; ++i) {
    WORLD_GROW(w->starts[i].x_m, w->starts[i].y_m);
  }
  if (w->has_goal) {
    WORLD_GROW(w->goal.x_m - w->goal.radius_m, w->goal.y_m - w->goal.radius_m);
    WORLD_GROW(w->goal.x_m + w->goal.radius_m, w->goal.y_m + w->goal.radius_m);
  }
#undef WORLD_GROW
  if (!(lo_x <= hi_x)) {
    lo_x = lo_y = -1.0;
    hi_x = hi_y = 1.0;
  }
  const double margin = 1.0;
  w->bounds_min_x_m = lo_x - margin;
  w->bounds_min_y_m = lo_y - margin;
  w->bounds_max_x_m = hi_x + margin;
  w->bounds_max_y_m = hi_y + margin;
}

// Splits a line (modified in place) into whitespace-separated tokens; a '#' ends the line.
static size_t tokenize(char* line, char** tok, size_t cap, int* too_many) {
  size_t n = 0;
  *too_many = 0;
  char* p = line;
  for (;;) {
    while (*p == ' ' || *p == '\t' || *p == '\r') {
      ++p;
    }
    if (*p == '\0' || *p == '#') {
      break;
    }
    if (n == cap) {
      *too_many = 1;
      break;
    }
    tok[n++] = p;
    while (*p != '\0' && *p != ' ' && *p != '\t' && *p != '\r' && *p != '#') {
      ++p;
    }
    if (*p == '#') {
      *p = '\0';
      break;
    }
    if (*p != '\0') {
      *p++ = '\0';
    }
  }
  return n;
}

// A file's number: at most SIM_WORLD_MAX_ABS in magnitude (NaN fails the test too).
static int parse_number(const char* s, double* out) {
  char* end = NULL;
  errno = 0;
  const double v = strtod(s, &end);
  if (end == s || *end != '\0' || errno == ERANGE || !(fabs(v) <= SIM_WORLD_MAX_ABS)) {
    return 0;
  }
  *out = v;
  return 1;
}

static int valid_name(const char* s) {
  const size_t n = strlen(s);
  if (n == 0 || n >= SIM_WORLD_NAME_CAP) {
    return 0;
  }
  for (size_t i = 0; i < n; ++i) {
    const char c = s[i];
    const int ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                   c == '_' || c == '.' || c == '-';
    if (!ok) {
      return 0;
    }
  }
  return 1;
}

typedef struct directive {
  const char* name;
  size_t min_args;
  size_t max_args;
} directive_t;

static const directive_t k_directives[] = {
    {"b21r-world", 1, 1}, {"name", 1, 1},  {"corridor", 2, 3}, {"wall", 4, 5},
    {"cylinder", 3, 3},   {"goal", 3, 3},  {"start", 3, 3},    {"bounds", 4, 4},
    {"arena", 4, 4},
};

static sim_world_status_t parse_line(sim_world_t* w, char** tok, size_t n, int* seen_magic,
                                     int* has_bounds, char* err, size_t err_cap, size_t line_no) {
  const directive_t* d = NULL;
  for (size_t i = 0; i < sizeof(k_directives) / sizeof(k_directives[0]); ++i) {
    if (strcmp(tok[0], k_directives[i].name) == 0) {
      d = &k_directives[i];
    }
  }
  if (d == NULL) {
    set_err(err, err_cap, "line %zu: unknown directive '%s'", line_no, tok[0]);
    return SIM_WORLD_ERR_SYNTAX;
  }
  const size_t n_args = n - 1;
  if (n_args < d->min_args || n_args > d->max_args) {
    set_err(err, err_cap, "line %zu: '%s' takes %zu to %zu arguments, got %zu", line_no, d->name,
            d->min_args, d->max_args, n_args);
    return SIM_WORLD_ERR_SYNTAX;
  }
  if (!*seen_magic && strcmp(d->name, "b21r-world") != 0) {
    set_err(err, err_cap, "line %zu: the file must start with 'b21r-world 1'", line_no);
    return SIM_WORLD_ERR_SYNTAX;
  }
  if (strcmp(d->name, "name") == 0) {
    if (!valid_name(tok[1])) {
      set_err(err, err_cap, "line %zu: bad name '%s' (use [A-Za-z0-9_.-], at most %d characters)",
              line_no, tok[1], SIM_WORLD_NAME_CAP - 1);
      return SIM_WORLD_ERR_SYNTAX;
    }
    (void)snprintf(w->name, sizeof(w->name), "%s", tok[1]);
    return SIM_WORLD_OK;
  }
  double a[WORLD_MAX_TOKENS] = {0};
  for (size_t i = 0; i < n_args; ++i) {
    if (!parse_number(tok[i + 1], &a[i])) {
      set_err(err, err_cap, "line %zu: '%s' is not a number of magnitude at most %g", line_no, tok[i + 1],
              SIM_WORLD_MAX_ABS);
      return SIM_WORLD_ERR_SYNTAX;
    }
  }
  sim_world_status_t st = SIM_WORLD_OK;
  if (strcmp(d->name, "b21r-world") == 0) {
    if (*seen_magic || a[0] < 0.5 || a[0] > 1.5) {
      set_err(err, err_cap, "line %zu: expected 'b21r-world 1' once, as the first directive",
              line_no);
      return SIM_WORLD_ERR_SYNTAX;
    }
    *seen_magic = 1;
  } else if (strcmp(d->name, "corridor") == 0) {
    st = sim_world_add_corridor(w, a[0], a[1], n_args > 2 && a[2] > 0.5);
  } else if (strcmp(d->name, "arena") == 0) {
    st = sim_world_add_arena(w, a[0], a[1], a[2], a[3]);
  } else if (strcmp(d->name, "wall") == 0) {
    st = sim_world_add_wall(w, a[0], a[1], a[2], a[3],
                            n_args > 4 ? a[4] : SIM_WORLD_WALL_THICKNESS_DEFAULT_M);
  } else if (strcmp(d->name, "cylinder") == 0) {
    st = sim_world_add_cylinder(w, a[0], a[1], a[2]);
  } else if (strcmp(d->name, "goal") == 0) {
    if (!(a[2] > 0.0)) {
      st = SIM_WORLD_ERR_INVALID_ARG;
    } else {
      w->has_goal = 1;
      w->goal = (sim_cylinder_t){a[0], a[1], a[2]};
    }
  } else if (strcmp(d->name, "start") == 0) {
    st = sim_world_add_start(w, a[0], a[1], a[2]);
  } else if (strcmp(d->name, "bounds") == 0) {
    if (!(a[0] < a[2]) || !(a[1] < a[3])) {
      st = SIM_WORLD_ERR_INVALID_ARG;
    } else {
      *has_bounds = 1;
      w->bounds_min_x_m = a[0];
      w->bounds_min_y_m = a[1];
      w->bounds_max_x_m = a[2];
      w->bounds_max_y_m = a[3];
    }
  }
  if (st == SIM_WORLD_ERR_CAPACITY) {
    set_err(err, err_cap, "line %zu: too many '%s' entries (capacity reached)", line_no, d->name);
  } else if (st != SIM_WORLD_OK) {
    set_err(err, err_cap, "line %zu: invalid '%s' geometry (sizes must be > 0, walls non-empty)",
            line_no, d->name);
  }
  return st;
}

sim_world_status_t sim_world_parse(const char* text, size_t len, sim_world_t* out, char* err,
                                   size_t err_cap) {
  if (out == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_clear(out);
  if (text == NULL) {
    set_err(err, err_cap, "no text");
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  set_err(err, err_cap, "%s", "");
  int seen_magic = 0;
  int has_bounds = 0;
  size_t line_no = 0;
  size_t pos = 0;
  char line[512];
  while (pos < len) {
    ++line_no;
    size_t end = pos;
    while (end < len && text[end] != '\n') {
      ++end;
    }
    const size_t n_line = end - pos;
    if (n_line >= sizeof(line)) {
      set_err(err, err_cap, "line %zu: longer than %zu characters", line_no, sizeof(line) - 1);
      sim_world_clear(out);
      return SIM_WORLD_ERR_SYNTAX;
    }
    memcpy(line, text + pos, n_line);
    line[n_line] = '\0';
    pos = end + 1;
    if (memchr(line, '\0', n_line) != NULL) {
      set_err(err, err_cap, "line %zu: contains a NUL byte", line_no);
      sim_world_clear(out);
      return SIM_WORLD_ERR_SYNTAX;
    }
    char* tok[WORLD_MAX_TOKENS];
    int too_many = 0;
    const size_t n = tokenize(line, tok, WORLD_MAX_TOKENS, &too_many);
    if (too_many) {
      set_err(err, err_cap, "line %zu: too many fields", line_no);
      sim_world_clear(out);
      return SIM_WORLD_ERR_SYNTAX;
    }
    if (n == 0) {
      continue;
    }
    const sim_world_status_t st =
        parse_line(out, tok, n, &seen_magic, &has_bounds, err, err_cap, line_no);
    if (st != SIM_WORLD_OK) {
      sim_world_clear(out);
      return st;
    }
  }
  if (!seen_magic) {
    set_err(err, err_cap, "line 1: the file must start with 'b21r-world 1'");
    sim_world_clear(out);
    return SIM_WORLD_ERR_SYNTAX;
  }
  if (!has_bounds) {
    sim_world_compute_bounds(out);
  }
  return SIM_WORLD_OK;
}

sim_world_status_t sim_world_load(const char* path, sim_world_t* out, char* err, size_t err_cap) {
  if (path == NULL || out == NULL) {
    return SIM_WORLD_ERR_INVALID_ARG;
  }
  sim_world_clear(out);
  FILE* f = fopen(path, "rb");
  if (f == NULL) {
    set_err(err, err_cap, "%s: %s", path, strerror(errno));
    return SIM_WORLD_ERR_IO;
  }
  char* buf = malloc((size_t)WORLD_FILE_MAX_BYTES + 1U);
  if (buf == NULL) {
    (void)fclose(f);
    set_err(err, err_cap, "%s: out of memory", path);
    return SIM_WORLD_ERR_IO;
  }
  const size_t n = fread(buf, 1, (size_t)WORLD_FILE_MAX_BYTES + 1U, f);
  const int read_error = ferror(f);
  (void)fclose(f);
  sim_world_status_t st;
  if (read_error) {
    set_err(err, err_cap, "%s: read error", path);
    st = SIM_WORLD_ERR_IO;
  } else if (n > (size_t)WORLD_FILE_MAX_BYTES) {
    set_err(err, err_cap, "%s: larger than %ld bytes", path, WORLD_FILE_MAX_BYTES);
    st = SIM_WORLD_ERR_IO;
  } else {
    char msg[256];
    st = sim_world_parse(buf, n, out, msg, sizeof(msg));
    if (st != SIM_WORLD_OK) {
      set_err(err, err_cap, "%s: %s", path, msg);
    }
  }
  free(buf);
  return st;
}

int sim_world_disc_collides(const sim_world_t* w, double x_m, double y_m, double radius_m) {
  const double r2 = radius_m * radius_m;
  for (size_t i = 0; i < w->n_walls; ++i) {
    const sim_wall_t* wl = &w->walls[i];
    const double dx = wl->x1_m - wl->x0_m;
    const double dy = wl->y1_m - wl->y0_m;
    const double len = hypot(dx, dy);
    const double ux = dx / len, uy = dy / len;
    // Local frame of the wall's rectangle: u along the face, n into the solid (to the right).
    const double px = x_m - wl->x0_m, py = y_m - wl->y0_m;
    const double u = px * ux + py * uy;
    const double n = px * uy - py * ux;
    const double cu = fmin(fmax(u, 0.0), len);
    const double cn = fmin(fmax(n, 0.0), wl->thickness_m);
    const double du = u - cu, dn = n - cn;
    if (du * du + dn * dn < r2) {
      return 1;
    }
  }
  for (size_t i = 0; i < w->n_cylinders; ++i) {
    const sim_cylinder_t* c = &w->cylinders[i];
    const double rr = radius_m + c->radius_m;
    const double dx = x_m - c->x_m, dy = y_m - c->y_m;
    if (dx * dx + dy * dy < rr * rr) {
      return 1;
    }
  }
  return 0;
}

// Clips the ray's parameter interval [*s_in, *s_out] to the slab lo <= o + s d <= hi of one
// axis; returns 0 when nothing of it is left.
static int clip_slab(double o, double d, double lo, double hi, double* s_in, double* s_out) {
  if (fabs(d) < 1e-15 * (fabs(lo) + fabs(hi) + 1.0)) {  // parallel to the slab: inside it or never
    return o >= lo && o <= hi;
  }
  const double a = (lo - o) / d;
  const double b = (hi - o) / d;
  const double near = a < b ? a : b;
  const double far = a < b ? b : a;
  *s_in = near > *s_in ? near : *s_in;
  *s_out = far < *s_out ? far : *s_out;
  return *s_in <= *s_out;
}

double sim_world_raycast(const sim_world_t* w, double x_m, double y_m, double dir_rad, double max_range_m) {
  const double dx = cos(dir_rad);
  const double dy = sin(dir_rad);
  double best = HUGE_VAL;
  for (size_t i = 0; i < w->n_walls; ++i) {
    // The wall's rectangle in its own (unnormalised) frame: along the face f = p1 - p0 the
    // coordinate p.f runs over [0, |f|^2]; across it, p.(fy, -fx) (into the solid, to the
    // right of p0 -> p1) over [0, thickness |f|].
    const sim_wall_t* wl = &w->walls[i];
    const double fx = wl->x1_m - wl->x0_m;
    const double fy = wl->y1_m - wl->y0_m;
    const double len2 = fx * fx + fy * fy;
    const double px = x_m - wl->x0_m, py = y_m - wl->y0_m;
    double s_in = 0.0, s_out = best;
    if (clip_slab(px * fx + py * fy, dx * fx + dy * fy, 0.0, len2, &s_in, &s_out) &&
        clip_slab(px * fy - py * fx, dx * fy - dy * fx, 0.0, wl->thickness_m * sqrt(len2), &s_in, &s_out)) {
      best = s_in;
    }
  }
  for (size_t i = 0; i < w->n_cylinders; ++i) {
    const sim_cylinder_t* c = &w->cylinders[i];
    const double ox = x_m - c->x_m, oy = y_m - c->y_m;
    const double b = ox * dx + oy * dy;
    const double cc = ox * ox + oy * oy - c->radius_m * c->radius_m;
    if (cc <= 0.0) {
      return 0.0;  // inside the cylinder
    }
    const double disc = b * b - cc;
    if (b < 0.0 && disc >= 0.0) {
      const double s = -b - sqrt(disc);
      best = s < best ? s : best;
    }
  }
  return best <= max_range_m ? best : (double)INFINITY;
}

int sim_world_in_goal(const sim_world_t* w, double x_m, double y_m) {
  if (!w->has_goal) {
    return 0;
  }
  const double dx = x_m - w->goal.x_m, dy = y_m - w->goal.y_m;
  return dx * dx + dy * dy <= w->goal.radius_m * w->goal.radius_m;
}
