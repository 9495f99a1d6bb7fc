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
  fprintf(f, "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
  fprintf(f,
          "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%.0f\" height=\"%.0f\" "
          "viewBox=\"0 0 %.1f %.1f\">\n",
          v.w_px, v.h_px + caption_px, v.w_px, v.h_px + caption_px);
  fprintf(f, "<rect x=\"0\" y=\"0\" width=\"%.1f\" height=\"%.1f\" fill=\"#fdfdf8\"/>\n", v.w_px,
          v.h_px + caption_px);
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
  // Trajectories, one polyline per run; the robot outline at each run's end; collision marks.
  static const char* colours[] = {"#d81b60", "#1e88e5", "#43a047", "#fb8c00", "#8e24aa", "#00897b"};
  size_t i = 0;
  while (i < n) {
    size_t j = i;
    while (j < n && pts[j].run == pts[i].run) {
      ++j;
    }
    const char* colour = colours[pts[i].run % (sizeof(colours) / sizeof(colours[0]))];
    fprintf(f, "<polyline fill=\"none\" stroke=\"%s\" stroke-width=\"2\" points=\"", colour);
    for (size_t k = i; k < j; ++k) {
      fprintf(f, "%.1f,%.1f ", px(&v, pts[k].x_m), py(&v, pts[k].y_m));
    }
    fprintf(f, "\"/>\n");
    const sim_trace_point_t* e = &pts[j - 1];
    fprintf(f, "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"%.1f\" fill=\"none\" stroke=\"%s\"/>\n",
            px(&v, e->x_m), py(&v, e->y_m), robot_radius_m * SVG_PX_PER_M, colour);
    fprintf(f, "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>\n",
            px(&v, e->x_m), py(&v, e->y_m), px(&v, e->x_m + robot_radius_m * cos(e->theta_rad)),
            py(&v, e->y_m + robot_radius_m * sin(e->theta_rad)), colour);
    for (size_t k = i; k < j; ++k) {
      if (pts[k].collided) {
        const double cx = px(&v, pts[k].x_m), cy = py(&v, pts[k].y_m);
        fprintf(f,
                "<path d=\"M%.1f %.1fL%.1f %.1fM%.1f %.1fL%.1f %.1f\" stroke=\"#c62828\" "
                "stroke-width=\"3\"/>\n",
                cx - 6, cy - 6, cx + 6, cy + 6, cx - 6, cy + 6, cx + 6, cy - 6);
        break;
      }
    }
    i = j;
  }
  fprintf(f, "<text x=\"6\" y=\"%.1f\" font-family=\"sans-serif\" font-size=\"14\" fill=\"#333\">",
          v.h_px + 17.0);
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
