// SPDX-License-Identifier: MIT
// Whole-episode runner for the task tests and the optimal-controller search.
#include "task_sim.h"

#include <math.h>
#include <stddef.h>

void task_sim_opts_default(task_sim_opts_t* o) {
  (void)synth_lidar_config_lms200(&o->lidar, 180, 1.0);
  o->sensor_seed = 1U;
  o->person = 0;
  o->odom_heading_drift = 0.0;
  o->limits.acc_mps2 = 0.0;
  o->limits.acc_radps2 = 0.0;
}

// The odometry the robot believes: true pose with a heading error growing with distance.
static features_pose_t odometry(const synth_robot_t* r, double heading_err) {
  features_pose_t p = {r->x_m, r->y_m, features_angle_wrap(r->theta_rad + heading_err)};
  return p;
}

static void scan_of(features_scan_t* scan, const synth_world_t* w, const task_sim_opts_t* o,
                    synth_rng_t* rng, const synth_robot_t* r) {
  scan->angle_min_rad = o->lidar.angle_min_rad;
  scan->angle_increment_rad = o->lidar.angle_increment_rad;
  scan->n_beams = o->lidar.n_beams;
  (void)synth_lidar_scan(w, &o->lidar, rng, r->x_m, r->y_m, r->theta_rad, scan->ranges_m,
                         scan->no_return, FEATURES_MAX_BEAMS);
}

task_sim_result_t task_sim_corridor(const tasks_corridor_spec_t* spec, features_pose_t start,
                                    tasks_driver_t* driver, const task_sim_opts_t* opts) {
  task_sim_result_t res = {0};
  res.min_clearance_m = INFINITY;
  synth_world_t w;
  synth_world_init(&w);
  (void)synth_world_add_corridor(&w, spec->length_m, spec->width_m);
  if (opts->person) {
    (void)synth_world_add_circle(&w, 5.5, 0.75, 0.2);
  }
  features_corridor_config_t cfg;
  tasks_corridor_features_config(spec, &cfg);
  cfg.scan.mount.x_m = opts->lidar.mount_x_m;
  synth_rng_t rng;
  synth_rng_seed(&rng, opts->sensor_seed);
  synth_robot_t robot = {start.x_m, start.y_m, start.theta_rad, 0.0, 0.0};
  static features_scan_t scan;  // large; tests are single-threaded
  double heading_err = 0.0;
  scan_of(&scan, &w, opts, &rng, &robot);
  features_pose_t odo = odometry(&robot, heading_err);
  features_corridor_t f;
  (void)features_corridor_compute(&cfg, &scan, &odo, &f);
  for (uint32_t step = 1U;; ++step) {
    const double omega = tasks_driver_corridor(driver, &f);
    const double v = tasks_corridor_speed_mps(spec, &f);
    const double x0 = robot.x_m, y0 = robot.y_m;
    synth_drive_step(&robot, v, omega, spec->dt_s, &opts->limits);
    const double moved = hypot(robot.x_m - x0, robot.y_m - y0);
    res.path_m += moved;
    res.sum_abs_omega += fabs(omega);
    heading_err += opts->odom_heading_drift * moved;
    const double clearance = synth_world_clearance(&w, robot.x_m, robot.y_m) - spec->robot_radius_m;
    res.min_clearance_m = fmin(res.min_clearance_m, clearance);
    const uint8_t contact = (uint8_t)(clearance <= 0.0);
    scan_of(&scan, &w, opts, &rng, &robot);
    odo = odometry(&robot, heading_err);
    (void)features_corridor_compute(&cfg, &scan, &odo, &f);
    const tasks_outcome_t out = tasks_corridor_outcome(spec, &f, contact, step);
    res.return_sum += out.reward;
    if (out.end_run) {
      res.reason = out.reason;
      res.steps = step;
      break;
    }
  }
  res.final_x_m = robot.x_m;
  res.final_y_m = robot.y_m;
  return res;
}

task_sim_result_t task_sim_obstacles(const tasks_obstacles_spec_t* spec, features_pose_t start,
                                     tasks_driver_t* driver, const task_sim_opts_t* opts) {
  task_sim_result_t res = {0};
  res.min_clearance_m = INFINITY;
  synth_world_t w;
  synth_world_init(&w);
  (void)synth_world_add_box(&w, spec->arena_min_x_m, spec->arena_min_y_m, spec->arena_max_x_m,
                            spec->arena_max_y_m);
  for (uint32_t k = 0U; k < spec->n_obstacles && k < TASKS_MAX_OBSTACLES; ++k) {
    (void)synth_world_add_circle(&w, spec->obstacles[k].x_m, spec->obstacles[k].y_m,
                                 spec->obstacles[k].radius_m);
  }
  features_obstacles_config_t cfg;
  tasks_obstacles_features_config(spec, &cfg);
  cfg.scan.mount.x_m = opts->lidar.mount_x_m;
  synth_rng_t rng;
  synth_rng_seed(&rng, opts->sensor_seed);
  synth_robot_t robot = {start.x_m, start.y_m, start.theta_rad, 0.0, 0.0};
  static features_scan_t scan;
  double heading_err = 0.0;
  scan_of(&scan, &w, opts, &rng, &robot);
  features_pose_t odo = odometry(&robot, heading_err);
  features_obstacles_t f;
  (void)features_obstacles_compute(&cfg, &scan, &odo, spec->goal_x_m, spec->goal_y_m, &f);
  const double v = tasks_obstacles_speed_mps(spec);
  for (uint32_t step = 1U;; ++step) {
    const double omega = tasks_driver_obstacles(driver, &f);
    const double x0 = robot.x_m, y0 = robot.y_m;
    synth_drive_step(&robot, v, omega, spec->dt_s, &opts->limits);
    const double moved = hypot(robot.x_m - x0, robot.y_m - y0);
    res.path_m += moved;
    res.sum_abs_omega += fabs(omega);
    heading_err += opts->odom_heading_drift * moved;
    const double clearance = synth_world_clearance(&w, robot.x_m, robot.y_m) - spec->robot_radius_m;
    res.min_clearance_m = fmin(res.min_clearance_m, clearance);
    const uint8_t contact = (uint8_t)(clearance <= 0.0);
    scan_of(&scan, &w, opts, &rng, &robot);
    odo = odometry(&robot, heading_err);
    (void)features_obstacles_compute(&cfg, &scan, &odo, spec->goal_x_m, spec->goal_y_m, &f);
    const tasks_outcome_t out = tasks_obstacles_outcome(spec, &f, contact, step);
    res.return_sum += out.reward;
    if (out.end_run) {
      res.reason = out.reason;
      res.steps = step;
      break;
    }
  }
  res.final_x_m = robot.x_m;
  res.final_y_m = robot.y_m;
  return res;
}

task_sim_result_t task_sim_doorway(const tasks_doorway_spec_t* spec, features_pose_t start,
                                   tasks_driver_t* driver, const task_sim_opts_t* opts) {
  task_sim_result_t res = {0};
  res.min_clearance_m = INFINITY;
  synth_world_t w;
  synth_world_init(&w);
  const double h = 0.5 * spec->wall_thickness_m;
  (void)synth_world_add_box(&w, spec->room_min_x_m, spec->room_min_y_m, spec->room_max_x_m, spec->room_max_y_m);
  (void)synth_world_add_box(&w, spec->wall_x_m - h, spec->room_min_y_m, spec->wall_x_m + h,
                            spec->door_y_m - 0.5 * spec->door_width_m);
  (void)synth_world_add_box(&w, spec->wall_x_m - h, spec->door_y_m + 0.5 * spec->door_width_m, spec->wall_x_m + h,
                            spec->room_max_y_m);
  features_doorway_config_t cfg;
  tasks_doorway_features_config(spec, &cfg);
  cfg.scan.mount.x_m = opts->lidar.mount_x_m;
  synth_rng_t rng;
  synth_rng_seed(&rng, opts->sensor_seed);
  synth_robot_t robot = {start.x_m, start.y_m, start.theta_rad, 0.0, 0.0};
  static features_scan_t scan;
  double heading_err = 0.0;
  scan_of(&scan, &w, opts, &rng, &robot);
  features_pose_t odo = odometry(&robot, heading_err);
  features_doorway_t f;
  (void)features_doorway_compute(&cfg, &scan, &odo, &f);
  for (uint32_t step = 1U;; ++step) {
    const double omega = tasks_driver_doorway(driver, spec, &f);
    const double x0 = robot.x_m, y0 = robot.y_m;
    synth_drive_step(&robot, spec->v_mps, omega, spec->dt_s, &opts->limits);
    const double moved = hypot(robot.x_m - x0, robot.y_m - y0);
    res.path_m += moved;
    res.sum_abs_omega += fabs(omega);
    heading_err += opts->odom_heading_drift * moved;
    // Inside a block the segments' distance is not a clearance: the spec's solid test decides.
    double clearance = synth_world_clearance(&w, robot.x_m, robot.y_m) - spec->robot_radius_m;
    if (tasks_doorway_disc_collides(spec, robot.x_m, robot.y_m, spec->robot_radius_m)) {
      clearance = fmin(clearance, 0.0);
    }
    res.min_clearance_m = fmin(res.min_clearance_m, clearance);
    const uint8_t contact = (uint8_t)(clearance <= 0.0);
    scan_of(&scan, &w, opts, &rng, &robot);
    odo = odometry(&robot, heading_err);
    (void)features_doorway_compute(&cfg, &scan, &odo, &f);
    const tasks_outcome_t out = tasks_doorway_outcome(spec, &f, contact, step);
    res.return_sum += out.reward;
    if (out.end_run) {
      res.reason = out.reason;
      res.steps = step;
      break;
    }
  }
  res.final_x_m = robot.x_m;
  res.final_y_m = robot.y_m;
  return res;
}
