// SPDX-License-Identifier: MIT
// The B21r body on ODE: synchro-drive axes, contacts, bump panels and laser ray casts.
#include "sim/plant.h"

#include <math.h>
#include <ode/ode.h>
#include <stdlib.h>
#include <string.h>

#define PLANT_MAX_CONTACTS 8
// Obstacles reach below the floor so that their bottom faces never coincide with the base's
// bottom face (coplanar faces give contacts with vertical normals); the laser and the base
// skirt both lie within [0, SIM_WORLD_OBSTACLE_HEIGHT_M].
#define PLANT_OBSTACLE_BOTTOM_M (-0.1)

static const double k_pi = 3.14159265358979323846;

struct sim_plant {
  sim_plant_config_t cfg;
  sim_world_t world;
  dWorldID ode_world;
  dSpaceID space;          // static geoms only: walls (boxes) and cylinders
  dJointGroupID contacts;  // contact joints of one substep
  dBodyID body;
  dGeomID body_geom;       // not in `space`: the laser's ray casts never see the robot
  // Axis and pose state (the heading is integrated here, not by ODE).
  double v_cmd_mps, omega_cmd_radps;
  double v_mps, omega_radps;
  double theta_rad;
  double skirt_heading_rad;
  double odo_trans_m, odo_rot_rad;  // since the last reset
  double odo_trans_at_reset_m, odo_rot_at_reset_rad;
  uint64_t substeps;
  uint64_t contacts_total;
  int in_contact;
  int collided;
  int bumper_panel;
  uint8_t bumper_bits;
  // Scratch of the current collision pass.
  double deepest_depth_m;
  double deepest_x_m, deepest_y_m;
  int n_contacts;
};

void sim_plant_config_default(sim_plant_config_t* cfg) {
  cfg->dt_s = 0.01;
  cfg->robot_radius_m = SIM_ROBOT_RADIUS_M;
  sim_kin_limits_default(&cfg->limits);
  cfg->laser_x_m = SIM_LASER_X_DEFAULT_M;
  cfg->laser_y_m = 0.0;
  cfg->laser_yaw_rad = 0.0;
}

static int config_valid(const sim_plant_config_t* c) {
  return isfinite(c->dt_s) && c->dt_s > 0.0 && c->dt_s <= 0.1 && isfinite(c->robot_radius_m) &&
         c->robot_radius_m > 0.0 && c->robot_radius_m < 5.0 && isfinite(c->laser_x_m) &&
         isfinite(c->laser_y_m) && isfinite(c->laser_yaw_rad);
}

static void add_wall_geom(sim_plant_t* p, const sim_wall_t* w) {
  const double dx = w->x1_m - w->x0_m, dy = w->y1_m - w->y0_m;
  const double len = hypot(dx, dy);
  const double ux = dx / len, uy = dy / len;
  // The solid lies to the right of p0 -> p1: centre = face midpoint + right normal * t/2.
  const double rx = uy, ry = -ux;
  const double height = SIM_WORLD_OBSTACLE_HEIGHT_M - PLANT_OBSTACLE_BOTTOM_M;
  dGeomID g = dCreateBox(p->space, len, w->thickness_m, height);
  dGeomSetPosition(g, w->x0_m + 0.5 * dx + 0.5 * w->thickness_m * rx,
                   w->y0_m + 0.5 * dy + 0.5 * w->thickness_m * ry,
                   PLANT_OBSTACLE_BOTTOM_M + 0.5 * height);
  dMatrix3 R;
  dRFromAxisAndAngle(R, 0.0, 0.0, 1.0, atan2(dy, dx));
  dGeomSetRotation(g, R);
}

static void add_cylinder_geom(sim_plant_t* p, const sim_cylinder_t* c) {
  const double height = SIM_WORLD_OBSTACLE_HEIGHT_M - PLANT_OBSTACLE_BOTTOM_M;
  dGeomID g = dCreateCylinder(p->space, c->radius_m, height);  // axis along z
  dGeomSetPosition(g, c->x_m, c->y_m, PLANT_OBSTACLE_BOTTOM_M + 0.5 * height);
}

sim_plant_t* sim_plant_create(const sim_world_t* world, const sim_plant_config_t* cfg) {
  if (world == NULL || cfg == NULL || !config_valid(cfg)) {
    return NULL;
  }
  if (!dInitODE2(0)) {
    return NULL;
  }
  if (!dAllocateODEDataForThread((unsigned)dAllocateMaskAll)) {
    dCloseODE();
    return NULL;
  }
  sim_plant_t* p = calloc(1, sizeof(*p));
  if (p == NULL) {
    dCloseODE();
    return NULL;
  }
  p->cfg = *cfg;
  p->world = *world;
  p->ode_world = dWorldCreate();
  dWorldSetGravity(p->ode_world, 0.0, 0.0, 0.0);
  dWorldSetERP(p->ode_world, 0.2);
  dWorldSetCFM(p->ode_world, 1e-7);
  dWorldSetContactSurfaceLayer(p->ode_world, 0.0005);
  p->space = dSimpleSpaceCreate(0);
  p->contacts = dJointGroupCreate(0);
  for (size_t i = 0; i < world->n_walls; ++i) {
    add_wall_geom(p, &world->walls[i]);
  }
  for (size_t i = 0; i < world->n_cylinders; ++i) {
    add_cylinder_geom(p, &world->cylinders[i]);
  }
  p->body = dBodyCreate(p->ode_world);
  dMass m;
  dMassSetCylinderTotal(&m, 150.0, 3, cfg->robot_radius_m, SIM_ROBOT_HEIGHT_M);
  dBodySetMass(p->body, &m);
  p->body_geom = dCreateCylinder(0, cfg->robot_radius_m, SIM_ROBOT_HEIGHT_M);
  dGeomSetBody(p->body_geom, p->body);
  const sim_pose_t start = world->n_starts > 0 ? world->starts[0] : (sim_pose_t){0.0, 0.0, 0.0};
  sim_plant_reset(p, start.x_m, start.y_m, start.theta_rad);
  return p;
}

void sim_plant_destroy(sim_plant_t* p) {
  if (p == NULL) {
    return;
  }
  dGeomDestroy(p->body_geom);
  dJointGroupDestroy(p->contacts);
  dSpaceDestroy(p->space);  // destroys the static geoms it holds (cleanup mode is on)
  dWorldDestroy(p->ode_world);
  free(p);
  dCloseODE();
}

const sim_world_t* sim_plant_world(const sim_plant_t* p) { return &p->world; }

const sim_plant_config_t* sim_plant_get_config(const sim_plant_t* p) { return &p->cfg; }

void sim_plant_reset(sim_plant_t* p, double x_m, double y_m, double theta_rad) {
  if (!isfinite(x_m) || !isfinite(y_m) || !isfinite(theta_rad)) {
    return;
  }
  dBodySetPosition(p->body, x_m, y_m, 0.5 * SIM_ROBOT_HEIGHT_M);
  dMatrix3 R;
  dRSetIdentity(R);
  dBodySetRotation(p->body, R);
  dBodySetLinearVel(p->body, 0.0, 0.0, 0.0);
  dBodySetAngularVel(p->body, 0.0, 0.0, 0.0);
  p->theta_rad = sim_angle_wrap(theta_rad);
  p->skirt_heading_rad = p->theta_rad;
  p->odo_trans_at_reset_m += p->odo_trans_m;
  p->odo_rot_at_reset_rad += p->odo_rot_rad;
  p->odo_trans_m = p->odo_rot_rad = 0.0;
  p->v_cmd_mps = p->omega_cmd_radps = 0.0;
  p->v_mps = p->omega_radps = 0.0;
  p->in_contact = 0;
  p->collided = 0;
  p->bumper_panel = -1;
  p->bumper_bits = 0;
}

void sim_plant_set_command(sim_plant_t* p, double v_mps, double omega_radps) {
  p->v_cmd_mps = isfinite(v_mps) ? v_mps : 0.0;
  p->omega_cmd_radps = isfinite(omega_radps) ? omega_radps : 0.0;
}

void sim_plant_set_limits(sim_plant_t* p, const sim_kin_limits_t* limits) { p->cfg.limits = *limits; }

static void contact_callback(void* data, dGeomID o1, dGeomID o2) {
  sim_plant_t* p = data;
  dContact c[PLANT_MAX_CONTACTS];
  const int n = dCollide(o1, o2, PLANT_MAX_CONTACTS, &c[0].geom, (int)sizeof(dContact));
  for (int i = 0; i < n; ++i) {
    c[i].surface.mode = dContactApprox1;
    c[i].surface.mu = dInfinity;
    dJointID j = dJointCreateContact(p->ode_world, p->contacts, &c[i]);
    dJointAttach(j, p->body, 0);
    if (p->n_contacts == 0 || c[i].geom.depth > p->deepest_depth_m) {
      p->deepest_depth_m = c[i].geom.depth;
      p->deepest_x_m = c[i].geom.pos[0];
      p->deepest_y_m = c[i].geom.pos[1];
    }
    ++p->n_contacts;
  }
}

static void update_bumper(sim_plant_t* p, double x_m, double y_m) {
  if (p->n_contacts == 0) {
    p->bumper_panel = -1;
    p->bumper_bits = 0;
    return;
  }
  const double width = 2.0 * k_pi / SIM_BASE_PANELS;
  double rel = atan2(p->deepest_y_m - y_m, p->deepest_x_m - x_m) - p->skirt_heading_rad;
  rel = sim_angle_wrap(rel) + 0.5 * width;  // panel 0 is centred on the skirt's front
  if (rel < 0.0) {
    rel += 2.0 * k_pi;
  }
  int panel = (int)floor(rel / width);
  double frac = rel / width - (double)panel;
  if (panel >= SIM_BASE_PANELS) {
    panel -= SIM_BASE_PANELS;
  }
  int quarter = (int)floor(frac * 4.0);
  quarter = quarter < 0 ? 0 : (quarter > 3 ? 3 : quarter);
  p->bumper_panel = panel;
  p->bumper_bits = (uint8_t)(1U << (unsigned)quarter);
}

static void substep(sim_plant_t* p) {
  const double dt = p->cfg.dt_s;
  p->v_mps = sim_kin_axis_approach(p->v_mps, p->v_cmd_mps, p->cfg.limits.accel_trans_mps2, dt);
  p->omega_radps =
      sim_kin_axis_approach(p->omega_radps, p->omega_cmd_radps, p->cfg.limits.accel_rot_radps2, dt);
  // Heading first, then translation along the new heading (as sim_kin_step).
  const double theta = sim_angle_wrap(p->theta_rad + p->omega_radps * dt);
  const double c = cos(theta), s = sin(theta);
  const dReal* pos0 = dBodyGetPosition(p->body);
  const double x0 = pos0[0], y0 = pos0[1];
  dBodySetLinearVel(p->body, p->v_mps * c, p->v_mps * s, 0.0);
  dBodySetAngularVel(p->body, 0.0, 0.0, 0.0);

  p->n_contacts = 0;
  p->deepest_depth_m = 0.0;
  dSpaceCollide2(p->body_geom, (dGeomID)p->space, p, &contact_callback);
  dWorldStep(p->ode_world, dt);
  dJointGroupEmpty(p->contacts);

  const dReal* pos = dBodyGetPosition(p->body);
  const double x = pos[0], y = pos[1];
  // Keep the body on the floor, upright: contacts may leave tiny out-of-plane components.
  dBodySetPosition(p->body, x, y, 0.5 * SIM_ROBOT_HEIGHT_M);
  dMatrix3 R;
  dRSetIdentity(R);
  dBodySetRotation(p->body, R);
  dBodySetAngularVel(p->body, 0.0, 0.0, 0.0);

  p->theta_rad = theta;
  p->odo_rot_rad += p->omega_radps * dt;
  if (p->n_contacts > 0) {
    // The wheels cannot turn faster than the body moves: clamp the translation axis to the
    // motion the contact allowed (odometry stops when the robot is pinned).
    const double moved = (x - x0) * c + (y - y0) * s;
    const double v_meas = moved / dt;
    if (p->v_mps > 0.0) {
      p->v_mps = fmax(0.0, fmin(p->v_mps, v_meas));
    } else if (p->v_mps < 0.0) {
      p->v_mps = fmin(0.0, fmax(p->v_mps, v_meas));
    }
    p->odo_trans_m += moved;
    p->in_contact = 1;
    p->collided = 1;
    ++p->contacts_total;
  } else {
    p->odo_trans_m += p->v_mps * dt;
    p->in_contact = 0;
  }
  update_bumper(p, x, y);
  ++p->substeps;
}

void sim_plant_step(sim_plant_t* p, uint32_t n) {
  for (uint32_t i = 0; i < n; ++i) {
    substep(p);
  }
}

int32_t sim_plant_axis_counts(double at_reset, double since, double counts_per_unit) {
  const double c = nearbyint(at_reset * counts_per_unit) + nearbyint(since * counts_per_unit);
  const double m = fmod(c, 4294967296.0);
  const uint32_t u = (uint32_t)(int64_t)(m < 0.0 ? m + 4294967296.0 : m);
  int32_t s;
  memcpy(&s, &u, sizeof(s));
  return s;
}

void sim_plant_get_state(const sim_plant_t* p, sim_plant_state_t* out) {
  const dReal* pos = dBodyGetPosition(p->body);
  memset(out, 0, sizeof(*out));  // padding too: states are compared byte for byte
  out->substeps = p->substeps;
  out->t_s = (double)p->substeps * p->cfg.dt_s;
  out->x_m = pos[0];
  out->y_m = pos[1];
  out->theta_rad = p->theta_rad;
  out->v_mps = p->v_mps;
  out->omega_radps = p->omega_radps;
  out->odo_trans_m = p->odo_trans_m;
  out->odo_rot_rad = p->odo_rot_rad;
  out->odo_trans_at_reset_m = p->odo_trans_at_reset_m;
  out->odo_rot_at_reset_rad = p->odo_rot_at_reset_rad;
  out->in_contact = p->in_contact;
  out->collided = p->collided;
  out->bumper_panel = p->bumper_panel;
  out->bumper_bits = p->bumper_bits;
  out->contacts_total = p->contacts_total;
}

double sim_plant_ray(sim_plant_t* p, double x_m, double y_m, double dir_rad, double max_range_m) {
  if (!(max_range_m > 0.0) || !isfinite(max_range_m)) {
    return HUGE_VAL;
  }
  // The laser's plane (0.355 m) crosses every wall and cylinder (1 m tall) and never the robot:
  // the exact 2-D intersection with the world's geometry equals a ray cast against the ODE geoms
  // built from it, at a fraction of the cost of ODE's generic collision interface.
  return sim_world_raycast(&p->world, x_m, y_m, dir_rad, max_range_m);
}

void sim_plant_scan(sim_plant_t* p, double angle_min_rad, double increment_rad, size_t n,
                    double max_range_m, double* out_m) {
  const dReal* pos = dBodyGetPosition(p->body);
  const double c = cos(p->theta_rad), s = sin(p->theta_rad);
  const double ox = pos[0] + c * p->cfg.laser_x_m - s * p->cfg.laser_y_m;
  const double oy = pos[1] + s * p->cfg.laser_x_m + c * p->cfg.laser_y_m;
  const double base = p->theta_rad + p->cfg.laser_yaw_rad + angle_min_rad;
  for (size_t i = 0; i < n; ++i) {
    out_m[i] = sim_plant_ray(p, ox, oy, base + (double)i * increment_rad, max_range_m);
  }
}
