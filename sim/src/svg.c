// SPDX-License-Identifier: MIT
// Overhead SVG picture of the world and the recorded trajectories.
#define _POSIX_C_SOURCE 200809L
#include "sim/svg.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <unistd.h>

#define SVG_PX_PER_M 60.0
#define SVG_LEGEND_PX 190.0    // legend column right of the world
#define SVG_LEGEND_MAX_RUNS 12  // more runs: a colour bar instead of one entry per run
#define SVG_COLOUR_SPAN 0.9     // viridis[0, 0.9] (its palest tenth is hard to see), as tools/b21r_trajectories.py

// The viridis colour scale at 0, 0.1, ..., 1 (matplotlib's), interpolated linearly.
static const unsigned char k_viridis[11][3] = {
    {0x44, 0x01, 0x54}, {0x48, 0x24, 0x75}, {0x41, 0x44, 0x87}, {0x35, 0x5f, 0x8d},
    {0x2a, 0x78, 0x8e}, {0x21, 0x91, 0x8c}, {0x22, 0xa8, 0x84}, {0x44, 0xbf, 0x70},
    {0x7a, 0xd1, 0x51}, {0xbd, 0xdf, 0x26}, {0xfd, 0xe7, 0x25}};

typedef struct colour {
  char hex[8];
} colour_t;

// Colour of run i of n (in order of appearance).
static colour_t run_colour(size_t i, size_t n) {
  const double u = SVG_COLOUR_SPAN * (n > 1 ? (double)i / (double)(n - 1) : 0.0) * 10.0;
  const int k = u >= 10.0 ? 9 : (int)u;
  const double t = u - (double)k;
  colour_t c;
  int rgb[3];
  for (int j = 0; j < 3; ++j) {
    rgb[j] = (int)lround((1.0 - t) * k_viridis[k][j] + t * k_viridis[k + 1][j]);
  }
  (void)snprintf(c.hex, sizeof(c.hex), "#%02x%02x%02x", rgb[0], rgb[1], rgb[2]);
  return c;
}

typedef struct view {
  double min_x, max_y;  // world coordinates of the picture's top-left corner
  double w_px, h_px;
} view_t;

static double px(const view_t* v, double x_m) { return (x_m - v->min_x) * SVG_PX_PER_M; }
static double py(const view_t* v, double y_m) { return (v->max_y - y_m) * SVG_PX_PER_M; }

static void escape(FILE* f, const char* s) {
  for (; *s != '\0'; ++s) {
    switch (*s) {
      case '<': fputs("&lt;", f); break;
      case '>': fputs("&gt;", f); break;
      case '&': fputs("&amp;", f); break;
      default: fputc(*s, f); break;
    }
  }
}

static void cross(FILE* f, double cx, double cy) {
  fprintf(f, "<path d=\"M%.1f %.1fL%.1f %.1fM%.1f %.1fL%.1f %.1f\" stroke=\"#c62828\" stroke-width=\"3\"/>\n",
          cx - 6, cy - 6, cx + 6, cy + 6, cx - 6, cy + 6, cx + 6, cy - 6);
}

static void legend_text(FILE* f, double x, double y, const char* text) {
  fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"12\" fill=\"#333\">%s</text>\n",
          x, y + 4.0, text);
}

// The legend column at x0: one entry per run (its colour), or a colour bar from the first to the
// last run when there are many; then the symbols.
static void legend(FILE* f, const sim_trace_point_t* pts, size_t n, size_t n_runs, double x0,
                   const sim_world_t* w) {
  double y = 16.0;
  char text[64];
  fprintf(f, "<g>\n");
  legend_text(f, x0, y, n_runs == 1 ? "1 run (by reset)" : "runs, in order (by reset)");
  y += 18.0;
  if (n_runs <= SVG_LEGEND_MAX_RUNS) {
    size_t r = 0;
    for (size_t i = 0; i < n; ++i) {
      if (i > 0 && pts[i].run == pts[i - 1].run) {
        continue;
      }
      fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\" stroke-width=\"3\"/>\n", x0, y,
              x0 + 22.0, y, run_colour(r++, n_runs).hex);
      (void)snprintf(text, sizeof(text), "run %u", (unsigned)pts[i].run);
      legend_text(f, x0 + 28.0, y, text);
      y += 18.0;
    }
  } else {
    // A horizontal colour bar with the first and the last run's numbers under its ends.
    const double bar_w = 150.0;
    for (int k = 0; k < 30; ++k) {
      fprintf(f, "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"10\" fill=\"%s\"/>\n",
              x0 + bar_w * k / 30.0, y - 5.0, bar_w / 30.0 + 0.5, run_colour((size_t)k, 30).hex);
    }
    y += 18.0;
    (void)snprintf(text, sizeof(text), "run %u", (unsigned)pts[0].run);
    legend_text(f, x0, y, text);
    (void)snprintf(text, sizeof(text), "run %u", (unsigned)pts[n - 1].run);
    fprintf(f, "<text x=\"%.1f\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"12\" fill=\"#333\" "
               "text-anchor=\"end\">%s</text>\n", x0 + bar_w, y + 4.0, text);
    y += 18.0;
    (void)snprintf(text, sizeof(text), "%zu runs", n_runs);
    legend_text(f, x0, y, text);
    y += 18.0;
  }
  y += 6.0;
  fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"4\" fill=\"#999\" stroke=\"#000\" stroke-width=\"0.5\"/>\n",
          x0 + 11.0, y);
  legend_text(f, x0 + 28.0, y, "start of a run");
  y += 18.0;
  fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"7\" fill=\"none\" stroke=\"#555\"/>\n", x0 + 11.0, y);
  legend_text(f, x0 + 28.0, y, "robot at its end");
  y += 18.0;
  cross(f, x0 + 11.0, y);
  legend_text(f, x0 + 28.0, y, "collision");
  y += 18.0;
  fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#1565c0\" stroke-width=\"2\"/>\n",
          x0 + 4.0, y, x0 + 20.0, y);
  fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"2.5\" fill=\"#1565c0\"/>\n", x0 + 4.0, y);
  legend_text(f, x0 + 28.0, y, "evaluation start pose");
  y += 18.0;
  if (w->has_goal || w->has_corridor) {
    fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#2e7d32\" stroke-width=\"2\" "
               "stroke-dasharray=\"6 4\"/>\n", x0, y, x0 + 22.0, y);
    legend_text(f, x0 + 28.0, y, "goal");
  }
  fprintf(f, "</g>\n");
}

int sim_svg_write_stream(FILE* f, const sim_world_t* w, const sim_trace_point_t* pts, size_t n,
                         double robot_radius_m, const char* title) {
  view_t v;
  double min_x = w->bounds_min_x_m, min_y = w->bounds_min_y_m;
  double max_x = w->bounds_max_x_m, max_y = w->bounds_max_y_m;
  for (size_t i = 0; i < n; ++i) {  // runs that left the drawing area still show
    min_x = fmin(min_x, pts[i].x_m - 1.0);
    max_x = fmax(max_x, pts[i].x_m + 1.0);
    min_y = fmin(min_y, pts[i].y_m - 1.0);
    max_y = fmax(max_y, pts[i].y_m + 1.0);
  }
  v.min_x = min_x;
  v.max_y = max_y;
  v.w_px = (max_x - min_x) * SVG_PX_PER_M;
  v.h_px = (max_y - min_y) * SVG_PX_PER_M;
  const double caption_px = 24.0;
  size_t n_runs = 0;
  for (size_t i = 0; i < n; ++i) {
    n_runs += (i == 0 || pts[i].run != pts[i - 1].run) ? 1U : 0U;
  }
  // The legend lists each run up to SVG_LEGEND_MAX_RUNS, then the symbols.
  const double legend_h = 30.0 + 18.0 * (double)(n_runs <= SVG_LEGEND_MAX_RUNS ? n_runs : 3) + 18.0 * 6.0;
  const double total_w = v.w_px + SVG_LEGEND_PX;
  const double total_h = fmax(v.h_px, legend_h) + caption_px;
  fprintf(f, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
  fprintf(f,
          "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
          "viewBox=\"0 0 %.1f %.1f\">\n",
          total_w, total_h, total_w, total_h);
  fprintf(f, "<rect x=\"0\" y=\"0\" width=\"%.1f\" height=\"%.1f\" fill=\"#fdfdf8\"/>\n", total_w, total_h);
  // 1 m grid.
  fprintf(f, "<g stroke=\"#e4e4dc\" stroke-width=\"1\">\n");
  for (double gx = ceil(min_x); gx <= max_x; gx += 1.0) {
    fprintf(f, "<line x1=\"%.1f\" y1=\"0\" x2=\"%.1f\" y2=\"%.1f\"/>\n", px(&v, gx), px(&v, gx), v.h_px);
  }
  for (double gy = ceil(min_y); gy <= max_y; gy += 1.0) {
    fprintf(f, "<line x1=\"0\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", py(&v, gy), v.w_px, py(&v, gy));
  }
  fprintf(f, "</g>\n");
  // Walls: the solid rectangle to the right of each face.
  fprintf(f, "<g fill=\"#555\" stroke=\"none\">\n");
  for (size_t i = 0; i < w->n_walls; ++i) {
    const sim_wall_t* wl = &w->walls[i];
    const double dx = wl->x1_m - wl->x0_m, dy = wl->y1_m - wl->y0_m;
    const double len = hypot(dx, dy);
    const double rx = dy / len * wl->thickness_m, ry = -dx / len * wl->thickness_m;
    fprintf(f, "<polygon points=\"%.1f,%.1f %.1f,%.1f %.1f,%.1f %.1f,%.1f\"/>\n", px(&v, wl->x0_m),
            py(&v, wl->y0_m), px(&v, wl->x1_m), py(&v, wl->y1_m), px(&v, wl->x1_m + rx),
            py(&v, wl->y1_m + ry), px(&v, wl->x0_m + rx), py(&v, wl->y0_m + ry));
  }
  fprintf(f, "</g>\n<g fill=\"#8a6d3b\" stroke=\"#5a4520\" stroke-width=\"1.5\">\n");
  for (size_t i = 0; i < w->n_cylinders; ++i) {
    const sim_cylinder_t* c = &w->cylinders[i];
    fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\"/>\n", px(&v, c->x_m), py(&v, c->y_m),
            c->radius_m * SVG_PX_PER_M);
  }
  fprintf(f, "</g>\n");
  if (w->has_goal) {
    fprintf(f,
            "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" fill=\"#b8e6b8\" stroke=\"#2e7d32\" "
            "stroke-width=\"2\" stroke-dasharray=\"6 4\"/>\n",
            px(&v, w->goal.x_m), py(&v, w->goal.y_m), w->goal.radius_m * SVG_PX_PER_M);
  }
  if (w->has_corridor) {  // the corridor task's goal line (1 m before the end wall)
    const double gx = w->corridor_length_m - 1.0;
    fprintf(f,
            "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#2e7d32\" "
            "stroke-width=\"2\" stroke-dasharray=\"6 4\"/>\n",
            px(&v, gx), py(&v, 0.5 * w->corridor_width_m), px(&v, gx),
            py(&v, -0.5 * w->corridor_width_m));
  }
  // Start poses: short arrows.
  fprintf(f, "<g stroke=\"#1565c0\" stroke-width=\"2\" fill=\"none\">\n");
  for (size_t i = 0; i < w->n_starts; ++i) {
    const sim_pose_t* s = &w->starts[i];
    const double ex = s->x_m + 0.3 * cos(s->theta_rad), ey = s->y_m + 0.3 * sin(s->theta_rad);
    fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\"/>\n", px(&v, s->x_m),
            py(&v, s->y_m), px(&v, ex), py(&v, ey));
    fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"2.5\" fill=\"#1565c0\"/>\n", px(&v, s->x_m),
            py(&v, s->y_m));
  }
  fprintf(f, "</g>\n");
  // Trajectories, one polyline per run coloured in run order; a dot at each run's start, the
  // robot outline at its end, a cross where it first collided.
  size_t i = 0;
  size_t run_index = 0;
  while (i < n) {
    size_t j = i;
    while (j < n && pts[j].run == pts[i].run) {
      ++j;
    }
    const colour_t c = run_colour(run_index++, n_runs);
    fprintf(f, "<polyline fill=\"none\" stroke=\"%s\" stroke-width=\"2\" points=\"", c.hex);
    for (size_t k = i; k < j; ++k) {
      fprintf(f, "%.1f,%.1f ", px(&v, pts[k].x_m), py(&v, pts[k].y_m));
    }
    fprintf(f, "\"/>\n");
    fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"4\" fill=\"%s\" stroke=\"#000\" stroke-width=\"0.5\"/>\n",
            px(&v, pts[i].x_m), py(&v, pts[i].y_m), c.hex);
    const sim_trace_point_t* e = &pts[j - 1];
    fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" fill=\"none\" stroke=\"%s\"/>\n",
            px(&v, e->x_m), py(&v, e->y_m), robot_radius_m * SVG_PX_PER_M, c.hex);
    fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n",
            px(&v, e->x_m), py(&v, e->y_m), px(&v, e->x_m + robot_radius_m * cos(e->theta_rad)),
            py(&v, e->y_m + robot_radius_m * sin(e->theta_rad)), c.hex);
    for (size_t k = i; k < j; ++k) {
      if (pts[k].collided) {
        cross(f, px(&v, pts[k].x_m), py(&v, pts[k].y_m));
        break;
      }
    }
    i = j;
  }
  legend(f, pts, n, n_runs, v.w_px + 10.0, w);
  fprintf(f, "<text x=\"6\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"14\" fill=\"#333\">",
          total_h - caption_px + 17.0);
  escape(f, w->name);
  if (title != NULL && title[0] != '\0') {
    fputs(" — ", f);
    escape(f, title);
  }
  fprintf(f, " (grid 1 m)</text>\n</svg>\n");
  return ferror(f) ? -1 : 0;
}

int sim_svg_write(const char* path, const sim_world_t* world, const sim_trace_point_t* points,
                  size_t n_points, double robot_radius_m, const char* title) {
  char tmp[4096];
  if (snprintf(tmp, sizeof(tmp), "%s.tmp.%ld", path, (long)getpid()) >= (int)sizeof(tmp)) {
    errno = ENAMETOOLONG;
    return -1;
  }
  FILE* f = fopen(tmp, "w");
  if (f == NULL) {
    return -1;
  }
  int rc = sim_svg_write_stream(f, world, points, n_points, robot_radius_m, title);
  if (fflush(f) != 0 || fsync(fileno(f)) != 0) {
    rc = -1;
  }
  if (fclose(f) != 0) {
    rc = -1;
  }
  if (rc == 0 && rename(tmp, path) != 0) {
    rc = -1;
  }
  if (rc != 0) {
    const int e = errno;
    (void)unlink(tmp);
    errno = e;
  }
  return rc;
}
