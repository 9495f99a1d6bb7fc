// SPDX-License-Identifier: MIT
// Emulator speed: lockstep simulated seconds per wall second (181-beam laser, 10 m corridor)
// and kinematic-model steps per second; exits 1 when a target is missed.
#define _POSIX_C_SOURCE 200809L
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>
#include <time.h>

#include <proto/lms200.h>
#include <proto/rflex.h>

#include "sim/emulator.h"
#include "sim/kinematic.h"
#include "sim/plant.h"

#define TARGET_REALTIME_FACTOR 200.0
#define TARGET_KIN_STEPS_PER_S 10e6

static double wall_s(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (double)ts.tv_sec + (double)ts.tv_nsec * 1e-9;
}

static void write_rflex(sim_emu_t* e, const rflex_packet_t* p) {
  uint8_t b[RFLEX_MAX_STUFFED_BYTES];
  sim_emu_base_write(e, b, rflex_encode(b, sizeof(b), p, RFLEX_HOST_STRICT));
}

// Lockstep run in the corridor: a controller that weaves down the corridor, decodes every scan
// and odometry packet, and restarts at the start pose when it reaches the end or touches a wall.
static int bench_lockstep(double* factor_out) {
  char path[512], err[256];
  static sim_world_t world;
  (void)snprintf(path, sizeof(path), "%s/corridor10.world", SIM_WORLDS_DIR);
  if (sim_world_load(path, &world, err, sizeof(err)) != SIM_WORLD_OK) {
    fprintf(stderr, "%s\n", err);
    return -1;
  }
  sim_emu_config_t cfg;
  sim_emu_config_default(&cfg);
  sim_emu_t* e = sim_emu_create(&world, &cfg);
  if (e == NULL) {
    return -1;
  }
  static lms_decoder_t lms;
  static rflex_decoder_t rdec;
  static lms_scan_t scan;
  (void)lms_decoder_init(&lms, LMS_ROLE_HOST, 0);
  rflex_decoder_init(&rdec);
  rflex_b21r_params_t params;
  rflex_b21r_params_default(&params);
  uint8_t req[32];
  sim_emu_laser_write(e, req, lms_encode_start_stream(req, sizeof(req)));
  rflex_packet_t p;
  (void)rflex_make_odometry_request(&p, 100000, 3);
  write_rflex(e, &p);
  rflex_make_brake_release(&p);
  write_rflex(e, &p);
  static uint8_t buf[65536];
  const int cycles = 20000;  // 2000 s simulated
  long scans = 0, reports = 0, resets = 0;
  const double t0 = wall_s();
  for (int k = 0; k < cycles; ++k) {
    size_t n = sim_emu_laser_read(e, buf, sizeof(buf));
    const uint8_t* q = buf;
    while (n > 0) {
      lms_event_t ev;
      const size_t used = lms_decoder_push(&lms, q, n, &ev);
      q += used;
      n -= used;
      if (ev.kind == LMS_EVENT_TELEGRAM && lms_parse_scan(&ev.telegram, 13, &scan) == PROTO_OK) {
        ++scans;
      }
    }
    n = sim_emu_base_read(e, buf, sizeof(buf));
    size_t used = 0;
    while (used < n) {
      bool got = false;
      rflex_packet_t pkt;
      used += rflex_decoder_push(&rdec, buf + used, n - used, &pkt, &got);
      reports += got;
    }
    sim_plant_state_t s;
    sim_emu_state(e, &s);
    if (s.collided || s.x_m > 9.0) {
      sim_emu_reset(e, 1.0, 0.0, 0.0);
      ++resets;
    }
    // Weave: steer back towards the centre line with a periodic disturbance.
    const double w = -1.2 * s.y_m - 0.8 * s.theta_rad + 0.3 * sin(0.05 * k);
    rflex_packet_t cmd[2];
    (void)rflex_make_velocity(cmd, &params, 0.6, w, 0.0);
    write_rflex(e, &cmd[0]);
    write_rflex(e, &cmd[1]);
  }
  const double wall = wall_s() - t0;
  const double simulated = sim_emu_time(e);
  *factor_out = simulated / wall;
  printf("sim.bench lockstep corridor10, 181 beams, rFLEX: %.0f s simulated in %.3f s wall = %.0fx "
         "real time (%ld scans, %ld base packets, %ld runs, %.1f us per control period)\n",
         simulated, wall, *factor_out, scans, reports, resets + 1, wall / cycles * 1e6);
  sim_emu_destroy(e);
  return scans == cycles && reports >= 2L * cycles ? 0 : -1;
}

// The kinematic model as the random-exploration studies use it: a new rotation command every
// 10 steps, a fixed translation speed.
static double bench_kinematic(void) {
  sim_kin_limits_t lim = {0.0, 0.0};  // the idealised model: velocities change at once
  sim_kin_state_t s;
  sim_kin_reset(&s, 0.0, 0.0, 0.0);
  const uint64_t steps = 100000000ULL;
  uint64_t x = 88172645463325252ULL;  // xorshift: cheap command noise
  double w = 0.0;
  const double t0 = wall_s();
  for (uint64_t i = 0; i < steps; ++i) {
    if (i % 10U == 0U) {
      x ^= x << 13;
      x ^= x >> 7;
      x ^= x << 17;
      w = ((double)(x >> 11) * 0x1.0p-53 - 0.5) * 0.5;
    }
    sim_kin_step(&s, &lim, 0.3, w, 0.1);
  }
  const double wall = wall_s() - t0;
  const double rate = (double)steps / wall;
  printf("sim.bench kinematic model: %llu steps in %.3f s = %.1f million steps/s (final pose %.3f "
         "%.3f)\n",
         (unsigned long long)steps, wall, rate * 1e-6, s.x_m, s.y_m);
  return rate;
}

// For information: raw ODE costs (ray casts, substeps) in the corridor.
static void bench_plant(void) {
  static sim_world_t world;
  char path[512], err[256];
  (void)snprintf(path, sizeof(path), "%s/corridor10.world", SIM_WORLDS_DIR);
  if (sim_world_load(path, &world, err, sizeof(err)) != SIM_WORLD_OK) {
    return;
  }
  sim_plant_config_t cfg;
  sim_plant_config_default(&cfg);
  sim_plant_t* p = sim_plant_create(&world, &cfg);
  if (p == NULL) {
    return;
  }
  double out[181];
  const int scans = 20000;
  double t0 = wall_s();
  for (int i = 0; i < scans; ++i) {
    sim_plant_scan(p, -1.5707963267948966, 3.14159265358979 / 180.0, 181, 30.0, out);
  }
  const double scan_wall = wall_s() - t0;
  sim_plant_set_command(p, 0.3, 0.0);
  const uint32_t substeps = 200000;
  t0 = wall_s();
  for (uint32_t i = 0; i < substeps; i += 100) {
    sim_plant_reset(p, 1.0, 0.0, 0.0);
    sim_plant_step(p, 100);
  }
  const double step_wall = wall_s() - t0;
  printf("sim.bench ODE plant: %.2f us per ray (181-beam scan %.1f us), %.2f us per substep\n",
         scan_wall / scans / 181.0 * 1e6, scan_wall / scans * 1e6, step_wall / substeps * 1e6);
  sim_plant_destroy(p);
}

int main(void) {
  int rc = 0;
  double factor = 0.0;
  if (bench_lockstep(&factor) != 0) {
    fprintf(stderr, "sim.bench: the lockstep run did not deliver one scan and odometry per period\n");
    rc = 1;
  }
  if (factor < TARGET_REALTIME_FACTOR) {
    fprintf(stderr, "sim.bench: lockstep %.0fx real time is below the target %.0fx\n", factor,
            TARGET_REALTIME_FACTOR);
    rc = 1;
  }
  const double rate = bench_kinematic();
  if (rate < TARGET_KIN_STEPS_PER_S) {
    fprintf(stderr, "sim.bench: %.1f million kinematic steps/s is below the target %.0f million\n",
            rate * 1e-6, TARGET_KIN_STEPS_PER_S * 1e-6);
    rc = 1;
  }
  bench_plant();
  printf("sim.bench: %s (targets: >= %.0fx real time, >= %.0f million steps/s)\n",
         rc == 0 ? "targets met" : "TARGET MISSED", TARGET_REALTIME_FACTOR,
         TARGET_KIN_STEPS_PER_S * 1e-6);
  return rc;
}
