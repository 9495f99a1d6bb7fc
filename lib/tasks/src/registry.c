// SPDX-License-Identifier: MIT
// The registry of declared tasks (tasks/decl.h), and the common fields of a specification read
// through its declaration's offsets. Adding a task adds one line to k_tasks.
#include <math.h>
#include <string.h>

#include "tasks/decl.h"

static const tasks_decl_t* const k_tasks[] = {
    &tasks_corridor_decl,
    &tasks_obstacles_decl,
    &tasks_doorway_decl,
};

#define N_TASKS (sizeof k_tasks / sizeof k_tasks[0])

uint32_t tasks_count(void) { return (uint32_t)N_TASKS; }

const tasks_decl_t* tasks_decl_at(uint32_t i) { return i < N_TASKS ? k_tasks[i] : NULL; }

const tasks_decl_t* tasks_find(const char* name) {
  for (size_t i = 0; name != NULL && i < N_TASKS; ++i) {
    if (strcmp(k_tasks[i]->name, name) == 0) {
      return k_tasks[i];
    }
  }
  return NULL;
}

const tasks_decl_t* tasks_by_id(int32_t id) {
  for (size_t i = 0; i < N_TASKS; ++i) {
    if ((int32_t)k_tasks[i]->id == id) {
      return k_tasks[i];
    }
  }
  return NULL;
}

const tasks_param_t* tasks_param_find(const tasks_decl_t* decl, const char* name) {
  for (uint32_t i = 0; decl != NULL && name != NULL && i < decl->n_params; ++i) {
    if (strcmp(decl->params[i].name, name) == 0) {
      return &decl->params[i];
    }
  }
  return NULL;
}

static double get_double(const void* spec, size_t off);
static void set_double(void* spec, size_t off, double v);

int tasks_spec_set_param(const tasks_decl_t* decl, void* spec, const char* name, double value) {
  const tasks_param_t* p = tasks_param_find(decl, name);
  if (p == NULL) {
    return -1;
  }
  if (!(value >= p->min && value <= p->max)) {
    return -2;
  }
  set_double(spec, p->offset, value);
  return 0;
}

double tasks_spec_get_param(const tasks_decl_t* decl, const void* spec, const char* name) {
  const tasks_param_t* p = tasks_param_find(decl, name);
  return p != NULL ? get_double(spec, p->offset) : (double)NAN;
}

static double get_double(const void* spec, size_t off) {
  double v;
  memcpy(&v, (const unsigned char*)spec + off, sizeof v);
  return v;
}

static void set_double(void* spec, size_t off, double v) { memcpy((unsigned char*)spec + off, &v, sizeof v); }

double tasks_spec_dt_s(const tasks_decl_t* decl, const void* spec) { return get_double(spec, decl->off_dt_s); }

double tasks_spec_omega_max(const tasks_decl_t* decl, const void* spec) {
  return get_double(spec, decl->off_omega_max_radps);
}

uint32_t tasks_spec_step_limit(const tasks_decl_t* decl, const void* spec) {
  uint32_t v;
  memcpy(&v, (const unsigned char*)spec + decl->off_step_limit, sizeof v);
  return v;
}

double tasks_spec_gamma(const tasks_decl_t* decl, const void* spec) { return get_double(spec, decl->off_gamma); }

double tasks_spec_robot_radius(const tasks_decl_t* decl, const void* spec) {
  return get_double(spec, decl->off_robot_radius_m);
}

features_pose_t tasks_spec_eval_start(const tasks_decl_t* decl, const void* spec, uint32_t index) {
  features_pose_t p;
  memcpy(&p, (const unsigned char*)spec + decl->off_eval_starts + (index % TASKS_N_EVAL_STARTS) * sizeof p, sizeof p);
  return p;
}

void tasks_spec_set_dt_s(const tasks_decl_t* decl, void* spec, double dt_s) { set_double(spec, decl->off_dt_s, dt_s); }

void tasks_spec_set_omega_max(const tasks_decl_t* decl, void* spec, double omega_max_radps) {
  set_double(spec, decl->off_omega_max_radps, omega_max_radps);
}

void tasks_spec_set_step_limit(const tasks_decl_t* decl, void* spec, uint32_t step_limit) {
  memcpy((unsigned char*)spec + decl->off_step_limit, &step_limit, sizeof step_limit);
}
