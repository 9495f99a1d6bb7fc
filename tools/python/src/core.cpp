// SPDX-License-Identifier: MIT
// b21r_learn._core: the C environments of sim/env.h, the example drivers of lib/tasks, HEDGER
// (lib/hedger/include/hedger/hedger.h), the two-phase learning framework (lib/learn/learn.h) and
// the controller's derivation of a learning session from its configuration (fw/config_task.h) for
// Python, through nanobind. Thin on purpose: every
// number is computed by the C libraries the robot runs; this file converts types and errors.
// Why nanobind: an environment step is a few microseconds of C, so the binding's own per-call
// cost counts, and nanobind's is lower than pybind11's; its ndarray type checks dtype, shape and
// contiguity and hands over NumPy memory without a copy; C++ exceptions become Python exceptions
// with their text. cffi would bind the C API directly but leave those checks and conversions to
// hand-written Python on every call. Built by CMake with the rest (nanobind_add_module).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <optional>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include <fw/checkpoint.h>
#include <fw/config.h>
#include <fw/config_task.h>
#include <fw/progress.h>
#include <learn/learn.h>
#include <learn/schedule.h>
#include <hedger/hedger.h>
#include <rng/rng.h>
#include <sim/env.h>
#include <tasks/episode.h>
#include <tasks/tasks.h>

namespace nb = nanobind;
using namespace nb::literals;

namespace {

// ---- arrays -------------------------------------------------------------------------------

// A read-only view of caller memory: float64, 1-D, contiguous (no copy).
using InVec = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
// A caller buffer written in place.
using OutF64 = nb::ndarray<double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using OutU32 = nb::ndarray<uint32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using NpF64 = nb::ndarray<nb::numpy, double, nb::ndim<1>>;
using NpF64x2 = nb::ndarray<nb::numpy, double, nb::ndim<2>>;
using NpU32 = nb::ndarray<nb::numpy, uint32_t, nb::ndim<1>>;

// A new NumPy array owning a copy of n values (every returned state is a fresh array, so a
// replay buffer that keeps it is never overwritten by the next step).
template <typename T>
nb::ndarray<nb::numpy, T, nb::ndim<1>> new_array(const T* values, size_t n) {
  T* data = new T[n > 0 ? n : 1];
  if (n > 0) std::memcpy(data, values, n * sizeof(T));
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
  return nb::ndarray<nb::numpy, T, nb::ndim<1>>(data, {n}, owner);
}

// ---- errors -------------------------------------------------------------------------------

struct HedgerError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

void check_hedger(hedger_status_t st, const char* what) {
  if (st == HEDGER_OK || st == HEDGER_NO_KNOWN_ACTION) return;
  throw HedgerError(std::string(what) + ": " + hedger_status_str(st));
}

void check_env(sim_env_status_t st, const char* what) {
  if (st == SIM_ENV_OK) return;
  const std::string msg = std::string(what) + ": " + sim_env_status_str(st);
  if (st == SIM_ENV_ERR_INVALID_ARG) throw nb::value_error(msg.c_str());
  throw std::runtime_error(msg);
}

// The declared task of a name (tasks/decl.h); the error lists the declared ones.
const tasks_decl_t* parse_task(const std::string& s) {
  const tasks_decl_t* d = tasks_find(s.c_str());
  if (d != nullptr) return d;
  std::string names;
  for (uint32_t i = 0; i < tasks_count(); ++i) names += std::string(i == 0 ? "" : ", ") + tasks_decl_at(i)->name;
  throw nb::value_error(("unknown task '" + s + "' (" + names + ")").c_str());
}

// ---- configuration structs as keyword arguments --------------------------------------------

// One settable field of a C struct: its name and how to read and write it from Python. A new
// field of the C API is one more line in the tables below.
template <typename S>
struct Field {
  const char* name;
  nb::object (*get)(const S&);
  void (*set)(S&, nb::handle);
};

#define B21R_F64(S, f) \
  Field<S> { #f, [](const S& s) -> nb::object { return nb::float_(s.f); }, [](S& s, nb::handle v) { s.f = nb::cast<double>(v); } }
#define B21R_U32(S, f) \
  Field<S> { #f, [](const S& s) -> nb::object { return nb::int_(s.f); }, [](S& s, nb::handle v) { s.f = nb::cast<uint32_t>(v); } }
#define B21R_U64(S, f) \
  Field<S> { #f, [](const S& s) -> nb::object { return nb::int_(s.f); }, [](S& s, nb::handle v) { s.f = nb::cast<uint64_t>(v); } }

// A field under another name (a nested member: "eval_every" for schedule.eval_every).
#define B21R_I32_AS(S, name, f) \
  Field<S> { name, [](const S& s) -> nb::object { return nb::int_(s.f); }, [](S& s, nb::handle v) { s.f = nb::cast<int32_t>(v); } }
#define B21R_F64_AS(S, name, f) \
  Field<S> { name, [](const S& s) -> nb::object { return nb::float_(s.f); }, [](S& s, nb::handle v) { s.f = nb::cast<double>(v); } }
#define B21R_BOOL_AS(S, name, f) \
  Field<S> { name, [](const S& s) -> nb::object { return nb::bool_(s.f); }, [](S& s, nb::handle v) { s.f = nb::cast<bool>(v); } }
#define B21R_I32(S, f) B21R_I32_AS(S, #f, f)
#define B21R_BOOL(S, f) B21R_BOOL_AS(S, #f, f)

template <typename S, size_t N>
void apply_fields(S& s, const Field<S> (&table)[N], const nb::dict& kwargs, const char* what) {
  for (auto [key, value] : kwargs) {
    const std::string k = nb::cast<std::string>(key);
    bool found = false;
    for (const Field<S>& f : table) {
      if (k == f.name) {
        f.set(s, value);
        found = true;
        break;
      }
    }
    if (!found) {
      std::string names;
      for (const Field<S>& f : table) names += std::string(names.empty() ? "" : ", ") + f.name;
      throw nb::type_error((std::string(what) + ": unknown setting '" + k + "' (known: " + names + ")").c_str());
    }
  }
}

template <typename S, size_t N>
nb::dict fields_dict(const S& s, const Field<S> (&table)[N]) {
  nb::dict d;
  for (const Field<S>& f : table) d[f.name] = f.get(s);
  return d;
}

nb::object input_scale_get(const hedger_config_t& c) {
  nb::list l;
  for (uint32_t i = 0; i <= c.state_dim && i < HEDGER_MAX_INPUT_DIM; ++i) l.append(c.input_scale[i]);
  return l;
}

void input_scale_set(hedger_config_t& c, nb::handle v) {
  const std::vector<double> x = nb::cast<std::vector<double>>(v);
  if (x.size() > HEDGER_MAX_INPUT_DIM) throw nb::value_error("input_scale: at most state_dim + 1 values");
  for (size_t i = 0; i < x.size(); ++i) c.input_scale[i] = x[i];
}

const Field<hedger_config_t> kHedgerFields[] = {
    B21R_U32(hedger_config_t, state_dim),
    B21R_F64(hedger_config_t, action_min),
    B21R_F64(hedger_config_t, action_max),
    B21R_U32(hedger_config_t, capacity),
    B21R_U32(hedger_config_t, k_min),
    B21R_U32(hedger_config_t, k_max),
    B21R_F64(hedger_config_t, bandwidth),
    B21R_F64(hedger_config_t, weight_epsilon),
    B21R_F64(hedger_config_t, ridge),
    B21R_F64(hedger_config_t, alpha),
    B21R_F64(hedger_config_t, gamma),
    Field<hedger_config_t>{"input_scale", input_scale_get, input_scale_set},
    B21R_F64(hedger_config_t, default_value),
    B21R_U64(hedger_config_t, seed),
    B21R_U32(hedger_config_t, greedy_coarse_actions),
    B21R_U32(hedger_config_t, greedy_refine_iters),
    B21R_U32(hedger_config_t, ivh_mode),
    B21R_F64(hedger_config_t, merge_radius),
    B21R_U32(hedger_config_t, evict_candidates),
    B21R_U32(hedger_config_t, fresh_capacity),
    B21R_U32(hedger_config_t, rebuild_work_per_update),
    B21R_U32(hedger_config_t, run_capacity),
    B21R_U32(hedger_config_t, replay),
    B21R_U32(hedger_config_t, replay_passes),
    B21R_F64(hedger_config_t, replay_lambda),
    B21R_F64(hedger_config_t, replay_alpha),
    B21R_U32(hedger_config_t, replay_cache),
    B21R_U32(hedger_config_t, greedy_method),
    B21R_F64(hedger_config_t, greedy_pessimism),
    B21R_F64(hedger_config_t, greedy_reach),
};

nb::object pose_get(const features_pose_t& p) { return nb::make_tuple(p.x_m, p.y_m, p.theta_rad); }

features_pose_t pose_from(nb::handle v) {
  const auto t = nb::cast<std::tuple<double, double, double>>(v);
  return features_pose_t{std::get<0>(t), std::get<1>(t), std::get<2>(t)};
}

// A declared task's specification as keyword arguments: its declared parameters (by name), the
// common fields every task has (through the declaration's offsets) and its evaluation poses.
double spec_double(const void* spec, size_t off) {
  double v;
  std::memcpy(&v, static_cast<const unsigned char*>(spec) + off, sizeof v);
  return v;
}

void spec_set_double(const tasks_decl_t* d, void* spec, size_t off, double v) {
  (void)d;
  std::memcpy(static_cast<unsigned char*>(spec) + off, &v, sizeof v);
}

void apply_spec(const tasks_decl_t* d, void* spec, const nb::dict& kwargs) {
  for (auto [key, value] : kwargs) {
    const std::string k = nb::cast<std::string>(key);
    if (tasks_param_find(d, k.c_str()) != nullptr) {
      const double v = nb::cast<double>(value);
      if (tasks_spec_set_param(d, spec, k.c_str(), v) != 0) {
        const tasks_param_t* p = tasks_param_find(d, k.c_str());
        throw nb::value_error((std::string(d->name) + " spec: " + k + " must be in [" + std::to_string(p->min) + ", " +
                               std::to_string(p->max) + "] (" + p->help + ")").c_str());
      }
    } else if (k == "step_limit") {
      tasks_spec_set_step_limit(d, spec, nb::cast<uint32_t>(value));
    } else if (k == "dt_s") {
      tasks_spec_set_dt_s(d, spec, nb::cast<double>(value));
    } else if (k == "gamma") {
      spec_set_double(d, spec, d->off_gamma, nb::cast<double>(value));
    } else if (k == "robot_radius_m") {
      spec_set_double(d, spec, d->off_robot_radius_m, nb::cast<double>(value));
    } else if (k == "eval_starts") {
      const nb::list l = nb::cast<nb::list>(value);
      if (l.size() != TASKS_N_EVAL_STARTS) throw nb::value_error("eval_starts: exactly 10 poses (x, y, theta)");
      for (size_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
        const features_pose_t p = pose_from(l[i]);
        std::memcpy(static_cast<unsigned char*>(spec) + d->off_eval_starts + i * sizeof p, &p, sizeof p);
      }
    } else {
      std::string names = "step_limit, dt_s, gamma, robot_radius_m, eval_starts";
      for (uint32_t i = 0; i < d->n_params; ++i) names += std::string(", ") + d->params[i].name;
      throw nb::type_error((std::string(d->name) + " spec: unknown setting '" + k + "' (known: " + names + ")").c_str());
    }
  }
}

nb::dict spec_dict(const tasks_decl_t* d, const void* spec) {
  nb::dict out;
  for (uint32_t i = 0; i < d->n_params; ++i) out[d->params[i].name] = spec_double(spec, d->params[i].offset);
  out["dt_s"] = tasks_spec_dt_s(d, spec);
  out["step_limit"] = tasks_spec_step_limit(d, spec);
  out["gamma"] = tasks_spec_gamma(d, spec);
  out["robot_radius_m"] = tasks_spec_robot_radius(d, spec);
  nb::list l;
  for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) l.append(pose_get(tasks_spec_eval_start(d, spec, i)));
  out["eval_starts"] = l;
  return out;
}

using Lim = tasks_command_limits_t;
const Field<Lim> kLimitFields[] = {
    B21R_F64(Lim, max_translation_mps),
    B21R_F64(Lim, max_rotation_radps),
    B21R_F64(Lim, max_translation_accel_mps2),
    B21R_F64(Lim, max_rotation_accel_radps2),
};

// ---- environment --------------------------------------------------------------------------

class Env {
 public:
  Env(const std::string& task, const std::string& backend, const nb::dict& spec, const nb::dict& limits,
      nb::object laser_noise_sigma_m, nb::object laser_error_code_prob) {
    sim_env_backend_t b;
    if (backend == "ode") {
      b = SIM_ENV_ODE;
    } else if (backend == "kinematic") {
      b = SIM_ENV_KINEMATIC;
    } else {
      throw nb::value_error(("unknown backend '" + backend + "' (ode, kinematic)").c_str());
    }
    sim_env_config_t cfg;
    sim_env_config_default(&cfg, parse_task(task), b);
    apply_spec(cfg.task, cfg.spec, spec);
    apply_fields(cfg.limits, kLimitFields, limits, "command limits");
    if (!laser_noise_sigma_m.is_none()) cfg.laser_noise_sigma_m = nb::cast<double>(laser_noise_sigma_m);
    if (!laser_error_code_prob.is_none()) cfg.laser_error_code_prob = nb::cast<double>(laser_error_code_prob);
    char err[256] = "";
    env_ = sim_env_create(&cfg, err, sizeof err);
    if (env_ == nullptr) throw nb::value_error(err);
    dim_ = sim_env_episode(env_)->state_dim;
  }
  ~Env() { sim_env_destroy(env_); }
  Env(const Env&) = delete;
  Env& operator=(const Env&) = delete;

  void seed(uint64_t s) { check_env(sim_env_seed(env_, s), "seed"); }

  NpF64 reset(int start, uint32_t eval_index, nb::object pose) {
    const features_pose_t p = pose.is_none() ? features_pose_t{0.0, 0.0, 0.0} : pose_from(pose);
    double state[TASKS_MAX_STATE_DIM];
    check_env(sim_env_reset(env_, static_cast<sim_env_start_t>(start), eval_index, p, state), "reset");
    return new_array(state, dim_);
  }

  // (state, reward, terminated, truncated, reason, executed action, translation, steps)
  nb::tuple step(double action) {
    sim_env_transition_t t;
    check_env(sim_env_step(env_, action, &t), "step");
    return nb::make_tuple(new_array(t.state, dim_), t.reward, t.terminated != 0, t.truncated != 0,
                          static_cast<int>(t.reason), t.action_radps, t.translation_mps, t.steps);
  }

  uint32_t state_dim() const { return dim_; }

  nb::tuple state_bounds() const {
    double lo[TASKS_MAX_STATE_DIM], hi[TASKS_MAX_STATE_DIM];
    sim_env_state_bounds(env_, lo, hi);
    return nb::make_tuple(new_array(lo, dim_), new_array(hi, dim_));
  }

  double action_bound() const { return sim_env_get_config(env_)->limits.max_rotation_radps; }

  nb::dict truth() const {
    sim_env_truth_t t;
    sim_env_get_truth(env_, &t);
    nb::dict d;
    d["pose"] = pose_get(t.pose);
    d["start_pose"] = pose_get(sim_env_episode(env_)->start_in_task);
    d["odometry_pose"] = pose_get(t.odom_pose);
    d["v_mps"] = t.v_mps;
    d["omega_radps"] = t.omega_radps;
    d["collided"] = t.collided != 0;
    d["time_s"] = t.time_s;
    return d;
  }

  nb::tuple laser_view() {
    double ranges[FEATURES_MAX_BEAMS];
    double a0 = 0.0, inc = 0.0;
    const size_t n = sim_env_laser_view(env_, &a0, &inc, ranges, FEATURES_MAX_BEAMS);
    return nb::make_tuple(a0, inc, new_array(ranges, n));
  }

  nb::dict world() const {
    const sim_world_t* w = sim_env_world(env_);
    nb::list walls, cylinders;
    for (size_t i = 0; i < w->n_walls; ++i) {
      const sim_wall_t& wl = w->walls[i];
      walls.append(nb::make_tuple(wl.x0_m, wl.y0_m, wl.x1_m, wl.y1_m, wl.thickness_m));
    }
    for (size_t i = 0; i < w->n_cylinders; ++i)
      cylinders.append(nb::make_tuple(w->cylinders[i].x_m, w->cylinders[i].y_m, w->cylinders[i].radius_m));
    nb::dict d;
    d["name"] = std::string(w->name);
    d["walls"] = walls;
    d["cylinders"] = cylinders;
    d["goal"] = w->has_goal ? nb::object(nb::make_tuple(w->goal.x_m, w->goal.y_m, w->goal.radius_m)) : nb::none();
    d["bounds"] = nb::make_tuple(w->bounds_min_x_m, w->bounds_min_y_m, w->bounds_max_x_m, w->bounds_max_y_m);
    const tasks_episode_t* ep = sim_env_episode(env_);
    d["robot_radius_m"] = tasks_episode_robot_radius(ep);
    const features_laser_mount_t& m = *tasks_episode_laser_mount(ep);
    d["laser_mount"] = nb::make_tuple(m.x_m, m.y_m, m.yaw_rad);
    return d;
  }

  // The task's settings in use (the spec, the limits), for reports and plots.
  nb::dict spec() const {
    const sim_env_config_t* c = sim_env_get_config(env_);
    const tasks_episode_t* ep = sim_env_episode(env_);
    nb::dict d = spec_dict(c->task, tasks_episode_spec_const(ep));
    d["task"] = std::string(c->task->name);
    d["omega_max_radps"] = tasks_episode_omega_max(ep);
    d["limits"] = fields_dict(c->limits, kLimitFields);
    d["laser_noise_sigma_m"] = c->laser_noise_sigma_m;
    d["laser_error_code_prob"] = c->laser_error_code_prob;
    return d;
  }

  // Feature details of the newest state (where each value came from).
  nb::dict features() const {
    const tasks_episode_t* ep = sim_env_episode(env_);
    nb::dict d;
    if (const features_corridor_t* f = tasks_corridor_state(ep)) {
      d["offset_m"] = f->offset_m;
      d["heading_rad"] = f->heading_rad;
      d["width_m"] = f->width_m;
      d["walls_seen"] = static_cast<int>(f->walls_seen);
      d["end_wall_seen"] = f->end_wall_seen != 0;
      d["lateral_source"] = static_cast<int>(f->lateral_source);
      d["end_source"] = static_cast<int>(f->end_source);
    } else if (const features_obstacles_t* o = tasks_obstacles_state(ep)) {
      d["n_visible"] = static_cast<int>(o->n_visible);
      d["nearest_any_m"] = o->nearest_any_m;
      d["obstacle_visible"] = o->obstacle[0].visible != 0;
    }
    return d;
  }

  const sim_env_t* raw() const { return env_; }

 private:
  sim_env_t* env_ = nullptr;
  uint32_t dim_ = 0;
};

// ---- example drivers ------------------------------------------------------------------------

class Driver {
 public:
  // gain: a fixed proportional gain [1/s] for every run (None: drawn per run from the task's
  // range, as the controller's phase one draws it; the human driver's is its temperament).
  Driver(const std::string& kind, const std::string& task, double omega_max_radps, std::optional<double> gain)
      : task_(parse_task(task)), omega_max_(omega_max_radps), fixed_gain_(gain) {
    if (kind == "proportional") {
      kind_ = TASKS_DRIVER_PROPORTIONAL;
    } else if (kind == "human") {
      kind_ = TASKS_DRIVER_HUMAN;
    } else if (kind == "optimal") {
      kind_ = TASKS_DRIVER_OPTIMAL;
    } else {
      throw nb::value_error(("unknown driver '" + kind + "' (proportional, human, optimal)").c_str());
    }
    if (gain.has_value()) check_gain(*gain);
    begin_run(0);
  }
  void begin_run(uint64_t seed) {
    tasks_driver_begin_run(&d_, kind_, task_, omega_max_, seed);
    if (fixed_gain_.has_value()) apply_gain(*fixed_gain_);
  }
  double act(const Env& env) {
    if (sim_env_episode(env.raw())->decl != task_) throw nb::value_error("the driver is for another task");
    return sim_env_driver_action(env.raw(), &d_);
  }
  double gain() const { return d_.gain; }
  // The controller's driver of one run (ControllerTask::begin_driver): the kind and seed the loop
  // chooses for the run; any fixed gain is dropped (the loop sets a run's gain itself).
  void begin_controller_run(tasks_driver_kind_t kind, uint64_t seed) {
    kind_ = kind;
    fixed_gain_.reset();
    tasks_driver_begin_run(&d_, kind_, task_, omega_max_, seed);
  }
  // The run's gain as the loop sets it (this run only).
  void set_run_gain(double g) { apply_gain(g); }
  const tasks_decl_t* task() const { return task_; }
  double omega_max() const { return omega_max_; }
  // Setting the gain fixes it for this and every later run.
  void set_gain(double g) {
    check_gain(g);
    fixed_gain_ = g;
    apply_gain(g);
  }

 private:
  void check_gain(double g) const {
    if (kind_ == TASKS_DRIVER_OPTIMAL) {
      throw nb::value_error("the optimal driver has no gain to set: its law's constants are searched "
                            "(gain= applies to 'proportional' and 'human')");
    }
    if (!std::isfinite(g) || g <= 0.0) throw nb::value_error("gain must be a positive number [1/s]");
  }
  // The proportional law is set again with the gain (a law may hold it, as the obstacle task's does),
  // as the controller's evaluate_example_gain.
  void apply_gain(double g) { tasks_driver_set_gain(&d_, task_, g); }

  tasks_driver_t d_{};
  tasks_driver_kind_t kind_ = TASKS_DRIVER_PROPORTIONAL;
  const tasks_decl_t* task_;
  double omega_max_;
  std::optional<double> fixed_gain_;
};

// ---- HEDGER -------------------------------------------------------------------------------

struct Prediction {
  double value;
  int kind;
  int fallback;
  uint32_t n_neighbours;
  double std_error;
};

Prediction to_py(const hedger_prediction_t& p) {
  return Prediction{p.value, static_cast<int>(p.kind), static_cast<int>(p.fallback), p.n_neighbours, p.std_error};
}

class Hedger {
 public:
  explicit Hedger(const nb::kwargs& kwargs) {
    hedger_config_t cfg = hedger_config_default();
    apply_fields(cfg, kHedgerFields, kwargs, "Hedger");
    check_hedger(hedger_config_validate(&cfg), "Hedger config");
    check_hedger(hedger_create(&h_, &cfg), "hedger_create");
  }
  ~Hedger() { hedger_destroy(h_); }
  Hedger(const Hedger&) = delete;
  Hedger& operator=(const Hedger&) = delete;

  static nb::dict default_config() {
    const hedger_config_t c = hedger_config_default();
    return fields_dict(c, kHedgerFields);
  }
  nb::dict config() const { return fields_dict(*hedger_get_config(h_), kHedgerFields); }
  uint32_t state_dim() const { return hedger_get_config(h_)->state_dim; }

  const double* state_ptr(const InVec& s, const char* what) const {
    if (s.shape(0) != state_dim())
      throw nb::value_error((std::string(what) + ": the state must have state_dim = " + std::to_string(state_dim()) +
                             " values, got " + std::to_string(s.shape(0)))
                                .c_str());
    return s.data();
  }

  Prediction predict(const InVec& s, double a) {
    hedger_prediction_t p;
    check_hedger(hedger_predict(h_, state_ptr(s, "predict"), a, &p), "hedger_predict");
    return to_py(p);
  }

  // Neighbours into the caller's arrays when given (no copy), else into new arrays.
  nb::tuple predict_ex(const InVec& s, double a, std::optional<OutU32> slots, std::optional<OutF64> weights) {
    const uint32_t kmax = hedger_get_config(h_)->k_max;
    hedger_prediction_t p;
    if (slots || weights) {
      const size_t cap_s = slots ? slots->shape(0) : SIZE_MAX;
      const size_t cap_w = weights ? weights->shape(0) : SIZE_MAX;
      const uint32_t cap = static_cast<uint32_t>(std::min<size_t>({cap_s, cap_w, kmax}));
      check_hedger(hedger_predict_ex(h_, state_ptr(s, "predict_ex"), a, &p, slots ? slots->data() : nullptr,
                                     weights ? weights->data() : nullptr, cap),
                   "hedger_predict_ex");
      return nb::make_tuple(to_py(p), slots ? nb::cast(*slots) : nb::none(), weights ? nb::cast(*weights) : nb::none());
    }
    uint32_t sl[HEDGER_MAX_K];
    double w[HEDGER_MAX_K];
    check_hedger(hedger_predict_ex(h_, state_ptr(s, "predict_ex"), a, &p, sl, w, kmax), "hedger_predict_ex");
    const size_t n = std::min<uint32_t>(p.n_neighbours, kmax);
    return nb::make_tuple(to_py(p), new_array(sl, n), new_array(w, n));
  }

  // (action, value, kind, known): known = False when every candidate action is unknown.
  nb::tuple greedy(const InVec& s) {
    double a = 0.0, v = 0.0;
    hedger_kind_t k = HEDGER_KIND_UNKNOWN;
    const hedger_status_t st = hedger_greedy(h_, state_ptr(s, "greedy"), &a, &v, &k);
    check_hedger(st, "hedger_greedy");
    return nb::make_tuple(a, v, static_cast<int>(k), st == HEDGER_OK);
  }

  nb::dict update(const InVec& s, double a, double r, nb::object s_next, bool terminal) {
    const double* sn = nullptr;
    InVec next;
    if (!s_next.is_none()) {
      next = nb::cast<InVec>(s_next);
      sn = state_ptr(next, "update (s_next)");
    } else if (!terminal) {
      throw nb::value_error("update: s_next is required unless terminal");
    }
    hedger_update_info_t info;
    check_hedger(hedger_update(h_, state_ptr(s, "update"), a, r, sn, terminal ? 1 : 0, &info), "hedger_update");
    nb::dict d;
    d["next_known"] = info.next_status == HEDGER_OK;
    d["next_action"] = info.next_action;
    d["next_value"] = info.next_value;
    d["next_kind"] = static_cast<int>(info.next_kind);
    d["q_next"] = info.q_next;
    d["q_old"] = info.q_old;
    d["kind"] = static_cast<int>(info.kind);
    d["target"] = info.target;
    d["q_new"] = info.q_new;
    d["n_pulled"] = info.n_pulled;
    d["store_op"] = static_cast<int>(info.store_op);
    return d;
  }

  uint32_t end_run() {
    uint32_t replayed = 0;
    check_hedger(hedger_end_run(h_, &replayed), "hedger_end_run");
    return replayed;
  }

  int insert(const InVec& s, double a, double q, uint32_t flags) {
    hedger_store_op_t op = HEDGER_STORE_NONE;
    check_hedger(hedger_insert(h_, state_ptr(s, "insert"), a, q, flags, &op), "hedger_insert");
    return static_cast<int>(op);
  }

  void observe_reward(double r) { check_hedger(hedger_observe_reward(h_, r), "hedger_observe_reward"); }

  uint32_t size() const { return hedger_size(h_); }

  nb::dict get_point(uint32_t slot) const {
    hedger_point_t p;
    check_hedger(hedger_get_point(h_, slot, &p), "hedger_get_point");
    nb::dict d;
    d["state"] = new_array(p.state, state_dim());
    d["action"] = p.action;
    d["value"] = p.value;
    d["flags"] = p.flags;
    return d;
  }

  // Every stored point: (states [n x state_dim], actions [n], values [n], flags [n]).
  nb::tuple points() const {
    const uint32_t n = hedger_size(h_);
    const uint32_t d = state_dim();
    double* st = new double[static_cast<size_t>(n) * d + 1];
    std::vector<double> act(n), val(n);
    std::vector<uint32_t> fl(n);
    for (uint32_t i = 0; i < n; ++i) {
      hedger_point_t p;
      check_hedger(hedger_get_point(h_, i, &p), "hedger_get_point");
      std::memcpy(st + static_cast<size_t>(i) * d, p.state, d * sizeof(double));
      act[i] = p.action;
      val[i] = p.value;
      fl[i] = p.flags;
    }
    nb::capsule owner(st, [](void* q) noexcept { delete[] static_cast<double*>(q); });
    NpF64x2 states(st, {n, d}, owner);
    return nb::make_tuple(states, new_array(act.data(), n), new_array(val.data(), n), new_array(fl.data(), n));
  }

  nb::dict counters() const {
    const hedger_counters_t* c = hedger_counters(h_);
    nb::dict d;
#define B21R_C(f) d[#f] = c->f
    B21R_C(predictions_lwr);
    B21R_C(predictions_lwa);
    B21R_C(predictions_unknown);
    B21R_C(fallback_hull);
    B21R_C(fallback_implausible);
    B21R_C(fallback_singular);
    B21R_C(greedy_calls);
    B21R_C(greedy_all_unknown);
    B21R_C(greedy_state_model);
    B21R_C(greedy_reached);
    B21R_C(updates);
    B21R_C(replayed_updates);
    B21R_C(replay_reused);
    B21R_C(run_overflows);
    B21R_C(inserts);
    B21R_C(merges);
    B21R_C(evictions);
    B21R_C(protected_evictions);
    B21R_C(rebuilds);
    B21R_C(forced_rebuild_work);
    B21R_C(rejected_non_finite);
    B21R_C(loads);
    B21R_C(max_rebuild_work);
    B21R_C(store_fill);
    B21R_C(store_protected);
    B21R_C(fresh_fill);
    B21R_C(run_fill);
    B21R_C(reward_min);
    B21R_C(reward_max);
#undef B21R_C
    return d;
  }

  nb::bytes save() const {
    const size_t n = hedger_serialized_size(h_);
    std::vector<uint8_t> buf(n);
    size_t written = 0;
    check_hedger(hedger_save(h_, buf.data(), buf.size(), &written), "hedger_save");
    return nb::bytes(reinterpret_cast<const char*>(buf.data()), written);
  }

  void load(const nb::bytes& data) { check_hedger(hedger_load(h_, data.c_str(), data.size()), "hedger_load"); }

  size_t serialized_size() const { return hedger_serialized_size(h_); }
  size_t serialized_max_size() const { return hedger_serialized_max_size(hedger_get_config(h_)); }

 private:
  hedger_t* h_ = nullptr;
};

// ---- the learning framework (lib/learn) -----------------------------------------------------

// The task as the framework knows it (learn_task_t) and the framework's settings (learn_config_t),
// by their C names. A new field of either struct is one more line here: every caller (the Python
// Learner, tests) then sets it by name.
nb::object task_vec_get(const learn_task_t& t, const double* v) {
  nb::list l;
  for (uint32_t i = 0; i < t.state_dim && i < LEARN_MAX_TASK_STATE; ++i) l.append(v[i]);
  return l;
}

void task_vec_set(double* out, nb::handle v, const char* what) {
  const std::vector<double> x = nb::cast<std::vector<double>>(v);
  if (x.size() > LEARN_MAX_TASK_STATE)
    throw nb::value_error((std::string(what) + ": at most " + std::to_string(LEARN_MAX_TASK_STATE) +
                           " values (LEARN_MAX_TASK_STATE)").c_str());
  for (size_t i = 0; i < x.size(); ++i) out[i] = x[i];
}

const Field<learn_task_t> kTaskFields[] = {
    B21R_U32(learn_task_t, state_dim),
    Field<learn_task_t>{"state_scale", [](const learn_task_t& t) { return task_vec_get(t, t.state_scale); },
                        [](learn_task_t& t, nb::handle v) { task_vec_set(t.state_scale, v, "state_scale"); }},
    Field<learn_task_t>{"state_min", [](const learn_task_t& t) { return task_vec_get(t, t.state_min); },
                        [](learn_task_t& t, nb::handle v) { task_vec_set(t.state_min, v, "state_min"); }},
    Field<learn_task_t>{"state_max", [](const learn_task_t& t) { return task_vec_get(t, t.state_max); },
                        [](learn_task_t& t, nb::handle v) { task_vec_set(t.state_max, v, "state_max"); }},
    B21R_F64(learn_task_t, action_min),
    B21R_F64(learn_task_t, action_max),
    B21R_F64(learn_task_t, action_scale),
    B21R_F64(learn_task_t, gamma),
    B21R_U32(learn_task_t, step_limit),
    B21R_F64(learn_task_t, greedy_reach),
};

nb::object learn_input_scale_get(const learn_config_t& c) {
  nb::list l;
  for (uint32_t i = 0; i < c.input_scale_n && i <= LEARN_MAX_STATE; ++i) l.append(c.input_scale[i]);
  return l;
}

void learn_input_scale_set(learn_config_t& c, nb::handle v) {
  const std::vector<double> x = nb::cast<std::vector<double>>(v);
  if (x.size() > LEARN_MAX_STATE + 1U)
    throw nb::value_error("input_scale: at most the learner's state dimension + 1 values");
  c.input_scale_n = static_cast<uint32_t>(x.size());
  for (size_t i = 0; i < x.size(); ++i) c.input_scale[i] = x[i];
}

using LC = learn_config_t;
const Field<LC> kLearnFields[] = {
    B21R_I32(LC, mode),
    B21R_I32(LC, phase_one_driver),
    B21R_I32_AS(LC, "eval_every", schedule.eval_every),
    B21R_I32_AS(LC, "eval_starts", schedule.eval_starts),
    B21R_BOOL_AS(LC, "eval_at_start", schedule.eval_at_start),
    B21R_I32_AS(LC, "phase_one_runs", schedule.phase_one_runs),
    B21R_I32_AS(LC, "phase_two_runs", schedule.phase_two_runs),
    B21R_I32_AS(LC, "switch_mode", schedule.switch_mode),
    B21R_I32_AS(LC, "auto_min_runs", schedule.auto_min_runs),
    B21R_F64_AS(LC, "auto_ratio", schedule.auto_ratio),
    B21R_I32(LC, learner),
    B21R_F64(LC, alpha),
    B21R_F64(LC, gamma),
    B21R_BOOL(LC, state_last_action),
    B21R_F64(LC, last_action_scale),
    B21R_U32(LC, capacity),
    B21R_U32(LC, k_min),
    B21R_U32(LC, k_max),
    B21R_F64(LC, bandwidth),
    B21R_F64(LC, merge_radius),
    B21R_U32(LC, greedy_actions),
    B21R_I32(LC, greedy_method),
    B21R_F64(LC, greedy_pessimism),
    B21R_F64(LC, greedy_reach),
    B21R_BOOL(LC, replay),
    B21R_U32(LC, replay_passes),
    B21R_F64(LC, replay_lambda),
    B21R_F64(LC, replay_alpha),
    Field<LC>{"input_scale", learn_input_scale_get, learn_input_scale_set},
    B21R_U32(LC, tabular_bins),
    B21R_U32(LC, tabular_actions),
    B21R_F64(LC, explore_sigma),
    B21R_F64(LC, explore_probability),
    B21R_U32(LC, explore_hold_steps),
    B21R_U32(LC, decision_ticks),
    B21R_F64(LC, example_dither_sigma),
    B21R_BOOL(LC, advisor),
    B21R_U32(LC, replay_updates_per_slice),
    B21R_U64(LC, explore_seed),
    B21R_U64(LC, learner_seed),
};

nb::dict plan_dict(const learn_plan_t& p) {
  static const char* const kinds[] = {"training", "eval", "none"};
  nb::dict d;
  d["kind"] = kinds[p.kind >= 0 && p.kind <= 2 ? p.kind : 2];
  d["phase"] = p.phase;
  d["eval_index"] = p.eval_index;
  d["training_index"] = p.training_index;
  return d;
}

nb::dict block_dict(const learn_eval_block_t& b) {
  nb::dict d;
  d["block"] = b.block;
  d["training_runs"] = b.training_runs;
  d["phase"] = b.phase;
  d["n_starts"] = b.n_starts;
  nb::list steps, success;
  for (int32_t i = 0; i < b.n_starts && i < LEARN_SCHEDULE_MAX_STARTS; ++i) {
    steps.append(b.steps[i]);
    success.append(b.success[i]);
  }
  d["steps"] = steps;
  d["success"] = success;
  d["successes"] = b.successes;
  d["mean_steps"] = b.mean_steps;
  d["ci95_halfwidth"] = b.ci95_halfwidth;
  return d;
}

nb::dict run_end_dict(const learn_run_end_t& e) {
  nb::dict d;
  d["run_id"] = e.run_id;
  d["plan"] = plan_dict(e.plan);
  d["goal"] = e.goal;
  d["aborted"] = e.aborted;
  d["steps"] = e.steps;
  d["total_reward"] = e.total_reward;
  nb::list src;
  for (int i = 0; i < LEARN_N_SOURCES; ++i) src.append(e.steps_by_source[i]);
  d["steps_by_source"] = src;
  d["eval_block"] = e.eval_block;
  d["learning"] = e.learning;
  d["block"] = e.block_done ? nb::object(block_dict(e.block)) : nb::none();
  return d;
}

// One agent of the two-phase framework (learn/learn.h) in storage it owns, allocated once here
// (learn_storage_size bytes, LEARN_STORAGE_ALIGN): nothing is allocated by the calls of a run.
class Agent {
 public:
  Agent(const nb::dict& task, const nb::dict& config) {
    std::memset(&task_, 0, sizeof task_);
    task_.greedy_reach = 1.0;
    apply_fields(task_, kTaskFields, task, "learn task");
    cfg_ = learn_config_default();
    apply_fields(cfg_, kLearnFields, config, "learn config");
    char err[LEARN_ERR_MAX] = "";
    const size_t bytes = learn_storage_size(&task_, &cfg_);
    if (bytes == 0) {
      // learn_init names the invalid setting (the task's, or the learner's: too small a store).
      alignas(LEARN_STORAGE_ALIGN) unsigned char probe[LEARN_STORAGE_ALIGN];
      (void)learn_init(probe, sizeof probe, &task_, &cfg_, err, sizeof err);
      throw nb::value_error(err);
    }
    storage_ = static_cast<unsigned char*>(::operator new(bytes, std::align_val_t{LEARN_STORAGE_ALIGN}));
    bytes_ = bytes;
    a_ = learn_init(storage_, bytes_, &task_, &cfg_, err, sizeof err);
    if (a_ == nullptr) {
      release();
      throw nb::value_error(err);
    }
    std::memset(&exp_, 0, sizeof exp_);
  }
  ~Agent() { release(); }
  Agent(const Agent&) = delete;
  Agent& operator=(const Agent&) = delete;

  nb::dict task() const { return fields_dict(task_, kTaskFields); }
  nb::dict config() const { return fields_dict(cfg_, kLearnFields); }
  size_t storage_bytes() const { return bytes_; }
  uint32_t state_dim() const { return learn_agent_state_dim(a_); }

  // The learner's settings as derived by learn_learner_config (HEDGER's, by their C names).
  nb::dict learner_config() const {
    learn_learner_config_t lc;
    learn_learner_config(&task_, &cfg_, &lc);
    nb::dict d = fields_dict(lc.hedger, kHedgerFields);
    d["kind"] = lc.kind;
    return d;
  }

  nb::dict plan() const { return plan_dict(learn_plan(a_)); }
  void begin_run() { learn_begin_run(a_); }
  bool running() const { return learn_running(a_); }

  bool observe(const InVec& features, double last_command) {
    if (features.shape(0) != task_.state_dim)
      throw nb::value_error(("observe: the task's state has state_dim = " + std::to_string(task_.state_dim) +
                             " values, got " + std::to_string(features.shape(0)))
                                .c_str());
    return learn_observe(a_, features.data(), last_command);
  }

  NpF64 state() const { return new_array(learn_state(a_), learn_agent_state_dim(a_)); }
  bool has_transition() const { return learn_has_transition(a_); }
  int32_t run_actions() const { return learn_run_actions(a_); }

  // The outcome of the last executed action; the run's end record when it ended the run.
  nb::object transition(double reward, bool terminal, bool end_run, bool goal, int reason) {
    const learn_outcome_t o = {reward, terminal, end_run, goal, static_cast<int8_t>(reason)};
    learn_run_end_t e;
    if (!learn_transition(a_, &o, &e)) return nb::none();
    return run_end_dict(e);
  }

  nb::object abort_run() {
    learn_run_end_t e;
    if (!learn_abort_run(a_, &e)) return nb::none();
    return run_end_dict(e);
  }

  nb::tuple act(double advice, double joystick) {
    double a = 0.0;
    int8_t source = 0;
    learn_act(a_, advice, joystick, &a, &source);
    return nb::make_tuple(a, static_cast<int>(source));
  }

  void executed(double action, double translation) { learn_executed(a_, action, translation); }

  // learn_after_command: true when a transition was learned (or, evaluating, predicted); its
  // record is then experience().
  bool after_command() { return learn_after_command(a_, &exp_); }
  bool finish_now() { return learn_finish_now(a_, &exp_); }
  bool idle() const { return learn_idle(a_); }
  bool replaying() const { return learn_between_runs_busy(a_); }
  void request_phase_two() { learn_request_phase_two(a_); }

  nb::dict experience() const {
    nb::dict d;
    d["run_id"] = exp_.run_id;
    d["step_id"] = exp_.step_id;
    d["phase"] = exp_.phase;
    d["evaluating"] = exp_.evaluating;
    d["source"] = static_cast<int>(exp_.source);
    d["reason"] = static_cast<int>(exp_.reason);
    d["s"] = new_array(exp_.s, exp_.state_dim);
    d["a"] = exp_.a;
    d["v"] = exp_.v;
    d["reward"] = exp_.reward;
    d["s_next"] = new_array(exp_.s_next, exp_.state_dim);
    d["terminal"] = exp_.terminal;
    d["q"] = exp_.q;
    d["q_kind"] = static_cast<int>(exp_.q_kind);
    return d;
  }

  nb::dict schedule() const {
    const learn_schedule_t* s = learn_schedule(a_);
    nb::dict d;
    d["phase"] = s->p.phase;
    d["training_runs"] = s->p.training_runs;
    d["phase_one_runs"] = s->p.phase_one_runs;
    d["phase_two_runs"] = s->p.phase_two_runs;
    d["eval_blocks"] = s->p.eval_blocks;
    d["example_runs"] = s->p.example_runs;
    d["example_steps_sum"] = s->p.example_steps_sum;
    d["best_example_steps"] = s->p.best_example_steps;
    d["in_eval"] = s->in_eval;
    d["done"] = s->done;
    return d;
  }

  int32_t run_id() const { return learn_run_id(a_); }
  int64_t steps() const { return learn_steps(a_); }

  // The learned policy at a learner state (learn_agent_state_dim values): (action, value, known).
  nb::tuple greedy(const InVec& s) {
    double a = 0.0, v = 0.0;
    const bool known = learn_learner_greedy(learn_get_learner(a_), learner_state(s, "greedy"), &a, &v);
    return nb::make_tuple(a, v, known);
  }

  // Q(s, a) and how it was obtained (0 unknown, 1 LWA, 2 LWR).
  nb::tuple predict(const InVec& s, double a) {
    double q = 0.0;
    hedger_kind_t kind = HEDGER_KIND_UNKNOWN;
    if (!learn_learner_predict(learn_get_learner(a_), learner_state(s, "predict"), a, &q, &kind))
      throw nb::value_error("predict: the learner refused the query (a non-finite value?)");
    return nb::make_tuple(q, static_cast<int>(kind));
  }

  nb::dict stats() const {
    const learn_learner_stats_t st = learn_learner_stats(learn_get_learner_const(a_));
    nb::dict d;
    d["fill"] = st.fill;
    d["capacity"] = st.capacity;
    d["predictions_lwr"] = st.predictions_lwr;
    d["predictions_lwa"] = st.predictions_lwa;
    d["predictions_unknown"] = st.predictions_unknown;
    d["evictions"] = st.evictions;
    d["rebuilds"] = st.rebuilds;
    return d;
  }

  // HEDGER's learned state in the controller's checkpoint format (Hedger.load reads it).
  nb::bytes save() const {
    const hedger_t* h = learn_get_learner_const(a_)->hedger;
    if (h == nullptr) throw nb::value_error("save: the tabular learner keeps no saved state");
    std::vector<uint8_t> buf(hedger_serialized_size(h));
    size_t written = 0;
    check_hedger(hedger_save(h, buf.data(), buf.size(), &written), "hedger_save");
    return nb::bytes(reinterpret_cast<const char*>(buf.data()), written);
  }

 private:
  const double* learner_state(const InVec& s, const char* what) const {
    if (s.shape(0) != learn_agent_state_dim(a_))
      throw nb::value_error((std::string(what) + ": the learner's state has " +
                             std::to_string(learn_agent_state_dim(a_)) + " values, got " +
                             std::to_string(s.shape(0)))
                                .c_str());
    return s.data();
  }
  void release() {
    if (storage_ != nullptr) ::operator delete(storage_, std::align_val_t{LEARN_STORAGE_ALIGN});
    storage_ = nullptr;
    a_ = nullptr;
  }

  learn_task_t task_{};
  learn_config_t cfg_{};
  unsigned char* storage_ = nullptr;
  size_t bytes_ = 0;
  learn_t* a_ = nullptr;
  learn_experience_t exp_{};
};

// ---- a controller configuration as the learner's set-up -------------------------------------

// Takes the keys of an experiment file that are not the controller's (experiment.*): they say what
// to run around the controller, not how it learns.
int skip_experiment_key(void* user, const char* key, const char* value, const char* source, char* err,
                        size_t err_cap) {
  (void)user;
  (void)value;
  (void)source;
  (void)err;
  (void)err_cap;
  return std::strncmp(key, "experiment.", 11) == 0 ? 0 : 1;
}

// What a controller configuration (fw/config.h keys) makes of a run, derived by the controller's
// own functions (fw/config_task.h): the task as the learner sees it, the framework's settings, the
// seeds, the environment's specification and command limits, the evaluation poses, and the run's
// training start pose and driver. Two things the loop keeps private (firmware/core/src/run.c,
// begin_run and next_start_pose) are repeated here and named where they are: the drivers' per-run
// seed and kind, and the gain range's rescaling. test_learner_controller.py checks the whole
// against b21r-experiment, block for block.
class ControllerTask {
 public:
  ControllerTask(const nb::dict& settings, std::optional<std::string> config_file) {
    fw_config_defaults(&cfg_);
    char err[FW_CONFIG_ERR_MAX] = "";
    if (config_file.has_value() && fw_config_load_file_with(&cfg_, config_file->c_str(), skip_experiment_key,
                                                            nullptr, err, sizeof err) != 0)
      throw nb::value_error(err);
    for (auto [key, value] : settings) {
      const std::string k = nb::cast<std::string>(key);
      const std::string v = nb::isinstance<nb::bool_>(value) ? (nb::cast<bool>(value) ? "true" : "false")
                                                             : nb::cast<std::string>(nb::str(value));
      if (fw_config_set(&cfg_, k.c_str(), v.c_str(), "settings", err, sizeof err) != 0)
        throw nb::value_error(err);
    }
    if (fw_config_validate(&cfg_, err, sizeof err) != 0) throw nb::value_error(err);
    if (cfg_.phase_driver == FW_DRIVER_JOYSTICK)
      throw nb::value_error("phase_one_driver = joystick: a Learner has no operator; use example or human");
    if (fw_config_task(&cfg_, &ep_, &limits_, err, sizeof err) != 0) throw nb::value_error(err);
    seeds_ = fw_config_derive_seeds(cfg_.seed);
    rng_seed(&pose_rng_, seeds_.pose);
  }

  std::string task_name() const { return ep_.decl->name; }
  std::string env_id() const { return ep_.decl->env_id; }
  uint64_t seed() const { return cfg_.seed; }

  nb::dict learn_task() const {
    learn_task_t t;
    fw_config_learn_task(&cfg_, &ep_, &t);
    return fields_dict(t, kTaskFields);
  }

  nb::dict learn_settings() const {
    learn_config_t c;
    fw_config_learn_settings(&cfg_, &c);
    return fields_dict(c, kLearnFields);
  }

  nb::dict seeds() const {
    nb::dict d;
    d["pose"] = seeds_.pose;
    d["explore"] = seeds_.explore;
    d["learner"] = seeds_.learner;
    d["driver"] = seeds_.driver;
    return d;
  }

  // The environment's settings for this configuration (B21rEnv spec= and limits=): the task's
  // specification as fw_config_task made it; its own 10 evaluation poses are left out (runs start
  // from the poses given here, which may be more or fewer).
  nb::dict env_spec() const {
    nb::dict d = spec_dict(ep_.decl, tasks_episode_spec_const(&ep_));
    nb::dict out;
    for (auto [k, v] : d) {
      if (nb::cast<std::string>(k) != "eval_starts") out[k] = v;
    }
    return out;
  }
  nb::dict env_limits() const { return fields_dict(limits_, kLimitFields); }

  nb::list eval_starts() const {
    nb::list l;
    for (uint32_t i = 0; i < tasks_episode_n_eval_starts(&ep_); ++i)
      l.append(pose_get(tasks_episode_eval_start(&ep_, i)));
    return l;
  }

  uint32_t step_limit() const { return tasks_episode_step_limit(&ep_); }

  // The next training start pose, as the loop draws it (one per training run, in order).
  nb::object training_start() { return pose_get(tasks_episode_training_start(&ep_, &pose_rng_)); }

  // The driver of run run_id as the loop begins it (run.c begin_run): the example policy (or the
  // evaluated reference, or the simulated person of phase one), its stream seeded per run.
  void begin_driver(Driver& d, int32_t run_id, bool eval, int32_t phase) const {
    if (d.task() != ep_.decl) throw nb::value_error("begin_driver: the driver is for another task");
    const uint64_t id = static_cast<uint64_t>(static_cast<uint32_t>(run_id));
    uint64_t st = seeds_.driver ^ (id * 0x9E3779B97F4A7C15ULL);
    const uint64_t run_seed = rng_splitmix64(&st);
    tasks_driver_kind_t kind = TASKS_DRIVER_PROPORTIONAL;
    const bool evaluate = cfg_.mode == FW_MODE_EVALUATE;
    if (evaluate && cfg_.evaluate_policy == FW_EVAL_OPTIMAL) {
      kind = TASKS_DRIVER_OPTIMAL;
    } else if (evaluate && cfg_.evaluate_policy == FW_EVAL_HUMAN) {
      kind = TASKS_DRIVER_HUMAN;
    } else if (cfg_.phase_driver == FW_DRIVER_HUMAN && !eval && phase == 1) {
      kind = TASKS_DRIVER_HUMAN;
    }
    d.begin_controller_run(kind, run_seed);
    const double task_lo = ep_.decl->gain_min;
    const double task_hi = ep_.decl->gain_max;
    const bool ranged = cfg_.example_gain_range_n == 2;
    const double lo = ranged ? cfg_.example_gain_range[0] : task_lo;
    const double hi = ranged ? cfg_.example_gain_range[1] : task_hi;
    if (ranged && kind == TASKS_DRIVER_PROPORTIONAL) {
      d.set_run_gain(lo + (d.gain() - task_lo) * ((hi - lo) / (task_hi - task_lo)));
    }
    if (evaluate && cfg_.evaluate_policy == FW_EVAL_EXAMPLE) {
      d.set_run_gain(cfg_.evaluate_example_gain > 0.0 ? cfg_.evaluate_example_gain : 0.5 * (lo + hi));
    }
  }

 private:
  fw_config_t cfg_{};
  tasks_episode_t ep_{};
  tasks_command_limits_t limits_{};
  fw_config_seeds_t seeds_{};
  rng_t pose_rng_{};
};

// ---- the controller's files and settings ----------------------------------------------------

// (meta, payload) of a controller checkpoint file (fw/checkpoint.h), verified by its CRCs.
nb::tuple read_checkpoint(const std::string& path) {
  char err[FW_CHECKPOINT_ERR_MAX] = "";
  size_t meta_size = 0, payload_size = 0;
  int r = fw_checkpoint_peek(path.c_str(), &meta_size, &payload_size, err, sizeof err);
  if (r == 0) throw nb::value_error(("no checkpoint file at " + path).c_str());
  if (r < 0) throw nb::value_error(err);
  std::vector<uint8_t> meta(meta_size + 1), payload(payload_size + 1);
  r = fw_checkpoint_read(path.c_str(), meta.data(), meta.size(), &meta_size, payload.data(), payload.size(),
                         &payload_size, err, sizeof err);
  if (r <= 0) throw nb::value_error(r == 0 ? ("no checkpoint file at " + path).c_str() : err);
  return nb::make_tuple(nb::bytes(reinterpret_cast<const char*>(meta.data()), meta_size),
                        nb::bytes(reinterpret_cast<const char*>(payload.data()), payload_size));
}

// The learner configuration the controller derives for a task from its default settings, with
// `settings` applied as controller config keys (the ones of b21r-controller.conf).
nb::dict controller_learner_config(const std::string& task, const nb::dict& settings) {
  fw_config_t cfg;
  fw_config_defaults(&cfg);
  char err[FW_CONFIG_ERR_MAX] = "";
  if (fw_config_set(&cfg, "task", task.c_str(), "controller_learner_config", err, sizeof err) != 0)
    throw nb::value_error(err);
  for (auto [key, value] : settings) {
    const std::string k = nb::cast<std::string>(key);
    // A Python bool prints as True/False; the config language says true/false.
    const std::string v = nb::isinstance<nb::bool_>(value) ? (nb::cast<bool>(value) ? "true" : "false")
                                                           : nb::cast<std::string>(nb::str(value));
    if (fw_config_set(&cfg, k.c_str(), v.c_str(), "controller_learner_config", err, sizeof err) != 0)
      throw nb::value_error(err);
  }
  hedger_config_t hc;
  fw_config_hedger(&cfg, &hc);
  return fields_dict(hc, kHedgerFields);
}

// Mean and 95 % half-width (Student t) of a sample, as the controller's evaluation blocks report.
// The corridor's kinematic lower bound on the steps to the goal from each evaluation pose, for a
// corridor of length_m (the other settings at their defaults, as the controller uses them).
std::vector<uint32_t> corridor_steps_lower_bound(double length_m) {
  tasks_corridor_spec_t spec;
  tasks_corridor_spec_default(&spec);
  spec.length_m = length_m;
  std::vector<uint32_t> out;
  for (uint32_t i = 0; i < TASKS_N_EVAL_STARTS; ++i) {
    out.push_back(tasks_corridor_steps_lower_bound(&spec, tasks_corridor_eval_start(&spec, i)));
  }
  return out;
}

// The controller's section of a checkpoint (read_checkpoint's meta), decoded and validated by the
// controller's own decoder (fw/progress.h): what was learned besides HEDGER's store.
nb::dict read_checkpoint_progress(const nb::bytes& meta) {
  fw_progress_t p;
  char why[FW_PROGRESS_WHY_MAX] = "";
  if (fw_progress_decode(reinterpret_cast<const uint8_t*>(meta.c_str()), meta.size(), &p, why, sizeof why) != 0)
    throw nb::value_error((std::string("checkpoint progress section: ") + why).c_str());
  nb::dict d;
  d["task"] = fw_task_name(p.task);
  d["state_dim"] = p.state_dim;
  d["phase"] = p.schedule.phase;
  d["training_runs"] = p.schedule.training_runs;
  d["phase_one_runs"] = p.schedule.phase_one_runs;
  d["phase_two_runs"] = p.schedule.phase_two_runs;
  d["eval_blocks"] = p.schedule.eval_blocks;
  d["run_id"] = p.run_id;
  d["legacy_shift"] = p.legacy_shift;
  d["revision"] = p.revision;
  d["policy"] = p.policy == LEARN_POLICY_ACTOR ? "actor" : (p.policy == LEARN_POLICY_SELECT ? "select" : "greedy");
  d["greedy_saved_steps"] = p.selection.greedy_saved_steps;
  d["ranked_pairs"] = p.selection.pairs;
  d["actor_bytes"] = p.actor_bytes;
  return d;
}

nb::tuple mean_ci95(const std::vector<double>& values) {
  double mean = 0.0, half = 0.0;
  learn_mean_ci95(values.data(), static_cast<int32_t>(values.size()), &mean, &half);
  return nb::make_tuple(mean, half);
}

// The registry's declarations, for the Gymnasium registration and for tools.
nb::list declared_tasks() {
  nb::list out;
  for (uint32_t i = 0; i < tasks_count(); ++i) {
    const tasks_decl_t* d = tasks_decl_at(i);
    nb::dict t;
    t["name"] = d->name;
    t["title"] = d->title;
    t["env_id"] = d->env_id;
    t["id"] = static_cast<int>(d->id);
    nb::list names;
    for (uint32_t k = 0; k < d->state_dim; ++k) names.append(d->state_names[k]);
    t["state_names"] = names;
    t["gain_range"] = nb::make_tuple(d->gain_min, d->gain_max);
    nb::dict params;
    for (uint32_t k = 0; k < d->n_params; ++k)
      params[d->params[k].name] = nb::make_tuple(d->params[k].min, d->params[k].max, d->params[k].help);
    t["parameters"] = params;
    out.append(t);
  }
  return out;
}

}  // namespace

NB_MODULE(_core, m) {
  m.doc() = "C core of b21r_learn: the B21r task environments, example drivers and HEDGER.";
  nb::exception<HedgerError>(m, "HedgerError", PyExc_ValueError);

  nb::class_<Env>(m, "Env", "One task on one back-end (sim/env.h).")
      .def(nb::init<const std::string&, const std::string&, const nb::dict&, const nb::dict&, nb::object, nb::object>(),
           "task"_a, "backend"_a, "spec"_a = nb::dict(), "limits"_a = nb::dict(), "laser_noise_sigma_m"_a = nb::none(),
           "laser_error_code_prob"_a = nb::none())
      .def("seed", &Env::seed, "seed"_a)
      .def("reset", &Env::reset, "start"_a, "eval_index"_a = 0, "pose"_a = nb::none())
      .def("step", &Env::step, "action"_a)
      .def_prop_ro("state_dim", &Env::state_dim)
      .def_prop_ro("action_bound", &Env::action_bound)
      .def("state_bounds", &Env::state_bounds)
      .def("truth", &Env::truth)
      .def("laser_view", &Env::laser_view)
      .def("world", &Env::world)
      .def("spec", &Env::spec)
      .def("features", &Env::features);
  m.attr("START_TRAINING") = static_cast<int>(SIM_ENV_START_TRAINING);
  m.attr("START_EVAL") = static_cast<int>(SIM_ENV_START_EVAL);
  m.attr("START_POSE") = static_cast<int>(SIM_ENV_START_POSE);
  m.attr("N_EVAL_STARTS") = TASKS_N_EVAL_STARTS;

  nb::class_<Driver>(m, "Driver", "An example driver of lib/tasks (phase one's teacher).")
      .def(nb::init<const std::string&, const std::string&, double, std::optional<double>>(), "kind"_a, "task"_a,
           "omega_max_radps"_a = 1.0, "gain"_a = nb::none(),
           "kind: 'proportional' (the example policy), 'human' (the simulated joystick driver) or 'optimal' (the "
           "hand-tuned reference); task: a declared task's name ('corridor', 'obstacles', 'doorway', ...); gain: a "
           "fixed gain [1/s] for every run (default: drawn per run, as the controller's phase one does)")
      .def("begin_run", &Driver::begin_run, "seed"_a)
      .def("act", &Driver::act, "env"_a)
      .def_prop_rw("gain", &Driver::gain, &Driver::set_gain);

  nb::class_<Prediction>(m, "Prediction", "A HEDGER prediction: value, kind (0 unknown, 1 LWA, 2 LWR), ...")
      .def_ro("value", &Prediction::value)
      .def_ro("kind", &Prediction::kind)
      .def_ro("fallback", &Prediction::fallback)
      .def_ro("n_neighbours", &Prediction::n_neighbours)
      .def_ro("std_error", &Prediction::std_error)
      .def("__repr__", [](const Prediction& p) {
        return "Prediction(value=" + std::to_string(p.value) + ", kind=" + hedger_kind_str(static_cast<hedger_kind_t>(p.kind)) +
               ", n_neighbours=" + std::to_string(p.n_neighbours) + ")";
      });

  nb::class_<Hedger>(m, "Hedger", "HEDGER over its C API (hedger.h); settings as keyword arguments.")
      .def(nb::init<const nb::kwargs&>())
      .def_static("default_config", &Hedger::default_config)
      .def_prop_ro("config", &Hedger::config)
      .def_prop_ro("state_dim", &Hedger::state_dim)
      .def("predict", &Hedger::predict, "state"_a, "action"_a)
      .def("predict_ex", &Hedger::predict_ex, "state"_a, "action"_a, "slots"_a = nb::none(), "weights"_a = nb::none())
      .def("greedy", &Hedger::greedy, "state"_a)
      .def("update", &Hedger::update, "state"_a, "action"_a, "reward"_a, "state_next"_a.none(), "terminal"_a = false)
      .def("end_run", &Hedger::end_run)
      .def("insert", &Hedger::insert, "state"_a, "action"_a, "value"_a, "flags"_a = 0)
      .def("observe_reward", &Hedger::observe_reward, "reward"_a)
      .def("__len__", &Hedger::size)
      .def("get_point", &Hedger::get_point, "slot"_a)
      .def("points", &Hedger::points)
      .def_prop_ro("counters", &Hedger::counters)
      .def("save", &Hedger::save)
      .def("load", &Hedger::load, "data"_a)
      .def_prop_ro("serialized_size", &Hedger::serialized_size)
      .def_prop_ro("serialized_max_size", &Hedger::serialized_max_size);
  m.attr("POINT_PROTECTED") = HEDGER_POINT_PROTECTED;

  m.def("tasks", &declared_tasks,
        "The declared tasks (lib/tasks registry) as dicts: name, title, env_id, id, state_names, "
        "gain_range (the example policy's (min, max) gain [1/s]), parameters (name -> (min, max, help)).");
  m.def("read_checkpoint", &read_checkpoint, "path"_a);
  m.def("read_checkpoint_progress", &read_checkpoint_progress, "meta"_a,
        "The controller's section of a checkpoint (the meta bytes of read_checkpoint) as a dict: task, "
        "state dimension, phase, run counts, run id, legacy_shift (an older controller's file whose "
        "policy shift had moved; not used), revision, policy ('actor' or 'greedy': the learned policy the "
        "payload holds) and actor_bytes (the actor's section at the payload's end; HEDGER's bytes come "
        "first and declare their own length).");
  m.def("mean_ci95", &mean_ci95, "values"_a,
        "(mean, 95 % half-width) with Student's t, as the controller's evaluation blocks report them.");
  m.def("corridor_steps_lower_bound", &corridor_steps_lower_bound, "length_m"_a = 10.0,
        "Per evaluation pose: fewest steps any policy can need to reach the corridor's goal, from "
        "kinematics (tasks_corridor_steps_lower_bound).");
  m.def("controller_learner_config", &controller_learner_config, "task"_a, "settings"_a = nb::dict());

  nb::class_<Agent>(m, "Agent",
                    "One agent of the two-phase learning framework (lib/learn, learn/learn.h): task and "
                    "settings as dicts of learn_task_t / learn_config_t fields by their C names. Its storage "
                    "is allocated once, here; b21r_learn.Learner drives it.")
      .def(nb::init<const nb::dict&, const nb::dict&>(), "task"_a, "config"_a = nb::dict())
      .def_prop_ro("task", &Agent::task)
      .def_prop_ro("config", &Agent::config)
      .def_prop_ro("learner_config", &Agent::learner_config)
      .def_prop_ro("storage_bytes", &Agent::storage_bytes)
      .def_prop_ro("state_dim", &Agent::state_dim)
      .def("plan", &Agent::plan)
      .def("begin_run", &Agent::begin_run)
      .def_prop_ro("running", &Agent::running)
      .def("observe", &Agent::observe, "features"_a, "last_command"_a)
      .def("state", &Agent::state)
      .def("has_transition", &Agent::has_transition)
      .def("run_actions", &Agent::run_actions)
      .def("transition", &Agent::transition, "reward"_a, "terminal"_a, "end_run"_a, "goal"_a, "reason"_a = 0)
      .def("abort_run", &Agent::abort_run)
      .def("act", &Agent::act, "advice"_a, "joystick"_a = 0.0)
      .def("executed", &Agent::executed, "action"_a, "translation"_a = 0.0)
      .def("after_command", &Agent::after_command)
      .def("finish_now", &Agent::finish_now)
      .def("idle", &Agent::idle)
      .def("replaying", &Agent::replaying)
      .def("request_phase_two", &Agent::request_phase_two)
      .def("experience", &Agent::experience)
      .def("schedule", &Agent::schedule)
      .def_prop_ro("run_id", &Agent::run_id)
      .def_prop_ro("steps", &Agent::steps)
      .def("greedy", &Agent::greedy, "state"_a)
      .def("predict", &Agent::predict, "state"_a, "action"_a)
      .def("stats", &Agent::stats)
      .def("save", &Agent::save);
  m.def("learn_config_default", []() { return fields_dict(learn_config_default(), kLearnFields); },
        "lib/learn's defaults (learn_config_default) by field name.");
  m.def(
      "controller_seeds",
      [](uint64_t root) {
        const fw_config_seeds_t sd = fw_config_derive_seeds(root);
        return nb::make_tuple(sd.pose, sd.explore, sd.learner, sd.driver);
      },
      "root"_a,
      "The seeds the controller derives from its seed (fw_config_derive_seeds): (pose, explore, learner, "
      "driver).");
  m.attr("LEARN_MAX_TASK_STATE") = LEARN_MAX_TASK_STATE;
  m.attr("LEARN_SCHEDULE_MAX_STARTS") = LEARN_SCHEDULE_MAX_STARTS;

  nb::class_<ControllerTask>(m, "ControllerTask",
                             "What a controller configuration makes of a learning session, by the controller's "
                             "own derivations (fw/config_task.h): settings as controller keys, optionally over a "
                             "config or experiment file (its experiment.* keys are skipped).")
      .def(nb::init<const nb::dict&, std::optional<std::string>>(), "settings"_a = nb::dict(),
           "config_file"_a = nb::none())
      .def_prop_ro("task_name", &ControllerTask::task_name)
      .def_prop_ro("env_id", &ControllerTask::env_id)
      .def_prop_ro("seed", &ControllerTask::seed)
      .def_prop_ro("step_limit", &ControllerTask::step_limit)
      .def("learn_task", &ControllerTask::learn_task,
           "The task as the framework sees it (fw_config_learn_task): learn_task_t fields by name.")
      .def("learn_settings", &ControllerTask::learn_settings,
           "The framework's settings (fw_config_learn_settings, seeds included): learn_config_t fields by "
           "name.")
      .def("seeds", &ControllerTask::seeds,
           "The derived seeds (fw_config_derive_seeds): pose, explore, learner, driver.")
      .def("env_spec", &ControllerTask::env_spec,
           "The task's specification as B21rEnv spec= (fw_config_task; without its own evaluation poses).")
      .def("env_limits", &ControllerTask::env_limits, "The command limits as B21rEnv limits=.")
      .def("eval_starts", &ControllerTask::eval_starts,
           "The evaluation poses (x m, y m, theta rad; task frame): eval_poses, or the task's 10.")
      .def("training_start", &ControllerTask::training_start,
           "The next training start pose (x m, y m, theta rad), drawn from the controller's pose stream: "
           "call once per training run, in order.")
      .def("begin_driver", &ControllerTask::begin_driver, "driver"_a, "run_id"_a, "eval"_a, "phase"_a,
           "Begins driver for run run_id as the controller's loop does: kind (example, the simulated person "
           "of phase one, or the evaluated reference), the per-run seed, the gain (example_gain_range, "
           "evaluate_example_gain).");
}
