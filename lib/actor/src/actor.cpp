// SPDX-License-Identifier: MIT
// The actor (actor/actor.h): storage layout, the network and its optimiser, the ring of recorded
// transitions, the between-run work as a resumable state machine, and the byte format.
//
// Why a state machine: the work after a run (a few hundred million instructions at 20,000
// transitions) must fit into the controller's idle ticks without ever delaying a command, so it
// is cut into atomic operations (one training sample, one optimiser update, one query's local
// regressions, a slice of a kd-tree build or of a linear pass) and resumed where it stopped. Every
// sum runs over its items in one fixed order whatever the slice boundaries, so the result of a
// sliced run equals the all-at-once run of the offline trainer bit for bit.
//
// The local models reuse lib/hedger's internals (hedger_internal): the static kd-tree with its
// (distance, id) order, the symmetric factorisation, the byte codecs. Both models index padded
// 9-D points (hg::kMaxDim): one template instantiation serves every state dimension, at the cost
// of memory (stated in the header) and of distance arithmetic on zero coordinates.
#include "actor/actor.h"

#include <rng/rng.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <new>

#include "bytes.hpp"
#include "kdtree.hpp"
#include "linalg.hpp"

namespace {

constexpr uint32_t kLive = 0x52544341u;  // "ACTR" in memory: a live instance
constexpr uint8_t kFileMagic[4] = {'A', 'C', 'T', 'R'};
constexpr int kDim = hg::kMaxDim;  // coordinates per kd-tree point (padded with zeros)
constexpr uint32_t kMaxOut = ACTOR_MAX_STATE_DIM;
constexpr double kBeta1 = 0.9;
constexpr double kBeta2 = 0.999;
constexpr double kAdamEps = 1e-8;
// The kernel exp(-d²) in bandwidth units drops below 1 % beyond d² = ln 100: neighbours farther
// away are left out, so a query far from the data finds none (no slope) instead of far ones.
constexpr double kKernelEpsilon = 0.01;

static_assert(ACTOR_MAX_STATE_DIM + 1u <= static_cast<unsigned>(hg::kMaxDim), "a model point fits the kd-tree");
static_assert(ACTOR_MAX_STATE_DIM + 2u <= static_cast<unsigned>(hg::kMaxSystem), "the model's system fits");

enum class Stage : uint32_t {
  kIdle = 0,
  kReturns,      // Monte-Carlo returns of the run, newest first
  kClone,        // behaviour cloning on the ring (after the first run)
  kWindow,       // the first run of the window (rewarded_window), newest entries first
  kPool,         // the last runs' entries
  kDraw,         // the query set drawn from them
  kModelFill,    // coordinates of the dynamics model's points
  kModelBuild,
  kValueFill,    // coordinates of the value model's points
  kValueBuild,
  kTargets,      // per query: both local regressions and the slope
  kSteps,        // per query: the target
  kFit,          // Adam on the targets
};

struct Layout {
  size_t total;
  size_t s, sn, a, r, g, run, term;                // ring
  size_t pool;                                     // u32 [capacity]
  size_t qslot, qpi, qy, qg, qv, qok;              // queries
  size_t mpts, mids, mnodes, mrows;                // dynamics model's kd-tree
  size_t vpts, vids, vnodes;                       // value model's kd-tree
  size_t nb;                                       // neighbour buffer
  size_t theta, m, v, grad, keep_theta, keep_m, keep_v;
  uint32_t n_params;
  uint32_t max_nodes;
};

size_t align_up(size_t n) { return (n + ACTOR_STORAGE_ALIGN - 1u) / ACTOR_STORAGE_ALIGN * ACTOR_STORAGE_ALIGN; }

uint32_t params_of(uint32_t sd, uint32_t hidden) { return hidden * (sd + 2u) + 1u; }

}  // namespace

struct actor {
  uint32_t magic;
  actor_config_t cfg;
  Layout lay;
  uint32_t sd;
  uint32_t np;  // parameters
  // The network's input map x = (s - in_c) * in_k and output map out_c + out_r tanh(.).
  double in_c[ACTOR_MAX_STATE_DIM];
  double in_k[ACTOR_MAX_STATE_DIM];
  double out_c;
  double out_r;
  // The models' coordinates: raw * m_k (dynamics, state then action) and raw * v_k (value).
  double m_k[ACTOR_MAX_STATE_DIM + 1];
  double v_k[ACTOR_MAX_STATE_DIM];
  double kernel_r2;
  double ln_inv_gamma;
  // The ring (slot of logical entry i: (head + capacity - count + i) % capacity).
  double* s;
  double* sn;
  double* a;
  double* r;
  double* g;
  uint32_t* run;
  uint8_t* term;
  uint32_t head;
  uint32_t count;
  uint32_t run_len;  // entries of the run under way
  uint64_t runs;     // runs ended with entries; the run under way has this id
  int trained;
  // The network: theta = [W1 (sd × hidden, a row per input, so that the loops over the hidden
  // units are contiguous), b1 (hidden), w2 (hidden), b2].
  double* theta;
  double* m;
  double* v;
  double* grad;
  double* keep_theta;
  double* keep_m;
  double* keep_v;
  uint64_t adam_t;
  uint64_t keep_t;
  rng_t rng;
  // Between-run work.
  Stage stage;
  uint64_t work_run;  // id of the run whose end is being learned
  uint64_t win_first;     // first run of the window (kWindow's result)
  uint64_t win_run;       // run kWindow is scanning
  uint32_t win_found;     // rewarded runs it has passed
  int win_rewarded;       // the scanned run has a non-zero reward
  uint32_t cursor;    // item of the stage under way
  uint32_t returns_n;
  double ret;         // running return (kReturns)
  uint32_t* pool;
  uint32_t n_pool;
  uint32_t n_draw;    // queries to draw from the pool
  uint32_t* qslot;
  double* qpi;
  double* qy;
  double* qg;
  double* qv;
  uint8_t* qok;
  uint32_t nq;
  double vmax;
  double step_sum;
  hg::KdTree mtree;
  uint32_t* mrows;
  uint32_t n_mrows;
  hg::KdTree vtree;
  hg::Neighbour* nb;
  // The fit under way (kClone, kFit).
  uint32_t fit_step;
  uint32_t fit_steps;
  uint32_t fit_n;
  double fit_loss;
  // Changes of the learned state (a sliced save checks it).
  uint64_t generation;
  actor_counters_t counters;
};

namespace {

Layout make_layout(const actor_config_t& c) {
  Layout l{};
  const size_t cap = c.capacity;
  const size_t sd = c.state_dim;
  size_t off = align_up(sizeof(actor));
  auto take = [&](size_t bytes) {
    const size_t at = off;
    off = align_up(off + bytes);
    return at;
  };
  l.s = take(cap * sd * sizeof(double));
  l.sn = take(cap * sd * sizeof(double));
  l.a = take(cap * sizeof(double));
  l.r = take(cap * sizeof(double));
  l.g = take(cap * sizeof(double));
  l.run = take(cap * sizeof(uint32_t));
  l.term = take(cap);
  l.pool = take(cap * sizeof(uint32_t));
  const size_t q = c.max_queries;
  l.qslot = take(q * sizeof(uint32_t));
  l.qpi = take(q * sizeof(double));
  l.qy = take(q * sizeof(double));
  l.qg = take(q * sizeof(double));
  l.qv = take(q * sizeof(double));
  l.qok = take(q);
  l.max_nodes = hg::kd_max_nodes(c.capacity);
  l.mpts = take(cap * kDim * sizeof(double));
  l.mids = take(cap * sizeof(uint32_t));
  l.mnodes = take(static_cast<size_t>(l.max_nodes) * sizeof(hg::Node));
  l.mrows = take(cap * sizeof(uint32_t));
  l.vpts = take(cap * kDim * sizeof(double));
  l.vids = take(cap * sizeof(uint32_t));
  l.vnodes = take(static_cast<size_t>(l.max_nodes) * sizeof(hg::Node));
  const uint32_t kmax = c.model_k > c.value_k ? c.model_k : c.value_k;
  l.nb = take(kmax * sizeof(hg::Neighbour));
  l.n_params = params_of(c.state_dim, c.hidden);
  const size_t pb = static_cast<size_t>(l.n_params) * sizeof(double);
  l.theta = take(pb);
  l.m = take(pb);
  l.v = take(pb);
  l.grad = take(pb);
  l.keep_theta = take(pb);
  l.keep_m = take(pb);
  l.keep_v = take(pb);
  l.total = off;
  return l;
}

bool positive_finite(double x) { return x > 0.0 && std::isfinite(x); }

bool config_valid(const actor_config_t* c) {
  if (c == nullptr || c->state_dim < 1u || c->state_dim > ACTOR_MAX_STATE_DIM) return false;
  for (uint32_t i = 0; i < c->state_dim; ++i) {
    if (!std::isfinite(c->state_min[i]) || !std::isfinite(c->state_max[i]) || !(c->state_min[i] <= c->state_max[i]) ||
        !positive_finite(c->state_scale[i])) {
      return false;
    }
  }
  return std::isfinite(c->action_min) && std::isfinite(c->action_max) && c->action_min < c->action_max &&
         positive_finite(c->action_scale) && c->gamma > 0.0 && c->gamma < 1.0 && c->capacity >= 16u &&
         c->capacity <= ACTOR_MAX_CAPACITY && c->hidden >= 1u && c->hidden <= ACTOR_MAX_HIDDEN &&
         c->recent_runs >= 1u && c->max_queries >= 1u && c->max_queries <= c->capacity && c->model_k >= 1u &&
         c->model_k <= ACTOR_MAX_K && positive_finite(c->model_bandwidth) && c->model_min_neighbours >= 1u &&
         c->model_min_neighbours <= c->model_k && c->value_k >= 1u && c->value_k <= ACTOR_MAX_K &&
         positive_finite(c->value_bandwidth) && c->value_min_neighbours >= 1u &&
         c->value_min_neighbours <= c->value_k && c->ridge >= 0.0 && std::isfinite(c->ridge) && c->step_gain >= 0.0 &&
         std::isfinite(c->step_gain) && c->step_max >= 0.0 && std::isfinite(c->step_max) &&
         c->trust_radius >= 0.0 && std::isfinite(c->trust_radius) && c->slope_min_t >= 0.0 &&
         std::isfinite(c->slope_min_t) && c->rewarded_window <= 1u && positive_finite(c->learning_rate);
}

bool live(const actor_t* a) { return a != nullptr && a->magic == kLive; }

uint32_t slot_of(const actor_t& A, uint32_t i) {
  const uint32_t cap = A.cfg.capacity;
  return (A.head + cap - A.count + i) % cap;
}

const double* state_at(const actor_t& A, uint32_t slot) { return A.s + static_cast<size_t>(slot) * A.sd; }
const double* next_at(const actor_t& A, uint32_t slot) { return A.sn + static_cast<size_t>(slot) * A.sd; }

// ---- The network ------------------------------------------------------------------------------

// Hidden activations of one evaluation (kept for the backward pass).
struct Pass {
  double x[ACTOR_MAX_STATE_DIM];
  double h[ACTOR_MAX_HIDDEN];
  double y;    // tanh of the output unit
  double out;  // the action
};

// tanh as a rational function: Eigen's fast tanh of floats (generic_fast_tanh_float, a 13/6
// Pade-type approximation on [-7.9, 7.9], clamped outside), evaluated in double and clamped to
// [-1, 1]. Error below 2e-7 (float accuracy is plenty for a network's activation), about 20
// instructions without a branch, so the loop over the hidden units vectorises: the network's
// training costs half what std::tanh's 78 instructions made it (callgrind). Pure arithmetic:
// the same on every machine, unlike libm's. NaN stays NaN.
inline double tanh_fast(double a) {
  const double c = 7.90531110763549805;
  const double x = a > c ? c : (a < -c ? -c : a);
  const double x2 = x * x;
  double p = x2 * -2.76076847742355e-16 + 2.00018790482477e-13;
  p = x2 * p + -8.60467152213735e-11;
  p = x2 * p + 5.12229709037114e-08;
  p = x2 * p + 1.48572235717979e-05;
  p = x2 * p + 6.37261928875436e-04;
  p = x2 * p + 4.89352455891786e-03;
  p = x * p;
  double q = x2 * 1.19825839466702e-06 + 1.18534705686654e-04;
  q = x2 * q + 2.26843463243900e-03;
  q = x2 * q + 4.89352518554385e-03;
  const double y = p / q;
  return y > 1.0 ? 1.0 : (y < -1.0 ? -1.0 : y);
}

void forward(const actor_t& A, const double* theta, const double* s, Pass& p) {
  const uint32_t sd = A.sd;
  const uint32_t H = A.cfg.hidden;
  for (uint32_t i = 0; i < sd; ++i) p.x[i] = (s[i] - A.in_c[i]) * A.in_k[i];
  const double* b1 = theta + H * sd;
  const double* w2 = b1 + H;
  double z[ACTOR_MAX_HIDDEN];
  for (uint32_t j = 0; j < H; ++j) z[j] = b1[j];
  // Each unit's sum runs over the inputs in order; the loop over the units vectorises.
  for (uint32_t i = 0; i < sd; ++i) {
    const double xi = p.x[i];
    const double* w = theta + static_cast<size_t>(i) * H;
    for (uint32_t j = 0; j < H; ++j) z[j] += w[j] * xi;
  }
  for (uint32_t j = 0; j < H; ++j) p.h[j] = tanh_fast(z[j]);
  double z2 = w2[H];  // b2
  for (uint32_t j = 0; j < H; ++j) z2 += w2[j] * p.h[j];
  p.y = tanh_fast(z2);
  p.out = A.out_c + A.out_r * p.y;
}

// Adds the gradient of coef · (out - target)² (after forward) to A.grad; returns the squared error.
double backward(actor_t& A, const Pass& p, double target, double coef) {
  const uint32_t sd = A.sd;
  const uint32_t H = A.cfg.hidden;
  const double err = p.out - target;
  const double dz2 = 2.0 * coef * err * A.out_r * (1.0 - p.y * p.y);
  double* gb1 = A.grad + H * sd;
  double* gw2 = gb1 + H;
  const double* w2 = A.theta + H * sd + H;
  gw2[H] += dz2;
  double dz1[ACTOR_MAX_HIDDEN];
  for (uint32_t j = 0; j < H; ++j) {
    gw2[j] += dz2 * p.h[j];
    dz1[j] = dz2 * w2[j] * (1.0 - p.h[j] * p.h[j]);
    gb1[j] += dz1[j];
  }
  for (uint32_t i = 0; i < sd; ++i) {
    const double xi = p.x[i];
    double* g = A.grad + static_cast<size_t>(i) * H;
    for (uint32_t j = 0; j < H; ++j) g[j] += dz1[j] * xi;
  }
  return err * err;
}

void adam_update(actor_t& A) {
  ++A.adam_t;
  const double t = static_cast<double>(A.adam_t);
  const double c1 = 1.0 - std::pow(kBeta1, t);
  const double c2 = 1.0 - std::pow(kBeta2, t);
  const double lr = A.cfg.learning_rate;
  for (uint32_t k = 0; k < A.np; ++k) {
    const double gk = A.grad[k];
    A.m[k] = kBeta1 * A.m[k] + (1.0 - kBeta1) * gk;
    A.v[k] = kBeta2 * A.v[k] + (1.0 - kBeta2) * gk * gk;
    A.theta[k] -= lr * (A.m[k] / c1) / (std::sqrt(A.v[k] / c2) + kAdamEps);
    A.grad[k] = 0.0;
  }
}

void init_weights(actor_t& A) {
  // Hidden weights N(0, 1/sd), output weights N(0, 1e-4), biases 0: the first action is near the
  // middle of the bounds, and behaviour cloning shapes the rest.
  const uint32_t sd = A.sd;
  const uint32_t H = A.cfg.hidden;
  const double k1 = 1.0 / std::sqrt(static_cast<double>(sd));
  std::memset(A.theta, 0, A.np * sizeof(double));
  for (uint32_t k = 0; k < H * sd; ++k) A.theta[k] = k1 * rng_normal(&A.rng);
  for (uint32_t j = 0; j < H; ++j) A.theta[H * sd + H + j] = 0.01 * rng_normal(&A.rng);
  std::memset(A.m, 0, A.np * sizeof(double));
  std::memset(A.v, 0, A.np * sizeof(double));
  std::memset(A.grad, 0, A.np * sizeof(double));
  A.adam_t = 0;
}

void keep_params(actor_t& A) {
  std::memcpy(A.keep_theta, A.theta, A.np * sizeof(double));
  std::memcpy(A.keep_m, A.m, A.np * sizeof(double));
  std::memcpy(A.keep_v, A.v, A.np * sizeof(double));
  A.keep_t = A.adam_t;
}

// After a fit: a non-finite parameter (a diverged step) undoes the whole fit.
bool settle_params(actor_t& A) {
  if (hg::finite_all(A.theta, A.np) && hg::finite_all(A.m, A.np) && hg::finite_all(A.v, A.np)) return true;
  std::memcpy(A.theta, A.keep_theta, A.np * sizeof(double));
  std::memcpy(A.m, A.keep_m, A.np * sizeof(double));
  std::memcpy(A.v, A.keep_v, A.np * sizeof(double));
  A.adam_t = A.keep_t;
  std::memset(A.grad, 0, A.np * sizeof(double));
  ++A.counters.fits_undone;
  return false;
}

// ---- Local linear regression ------------------------------------------------------------------

struct LocalFit {
  uint32_t n;  // neighbours used
  bool ok;
  double value[kMaxOut];
  double grad[kMaxOut][kDim];  // per coordinate unit
  double contrast_se[kMaxOut];  // standard error of c · grad[o] per output (infinite when not formed)
};

// Gaussian-weighted linear regression at xq over the k nearest points of tree within the
// kernel's 1 % radius (coordinates in bandwidth units: weight exp(-d²)), with ridge on the slopes
// (never on the intercept, the prediction). coord(id, x) writes point id's dims coordinates,
// out(id, y) its n_out outputs. ok: at least min_n neighbours and positive definite normal
// equations. O(search + k (dims + n_out) dims + dims³ + n_out dims²), no allocation.
//
// With contrast c (dims values, may be null) it also gives the standard error of c · grad[o] for
// every output o, robust to correlation within a group (group(id): the run a point came from; the
// points of one run share its noise, so they count as one observation): the cluster sandwich
// Var = G/(G−1) Σ_groups (Σ_j w_j (u·z_j) e_jo)² with u = M⁻¹ c and e_jo output o's residual;
// fewer than two groups: infinite. group() must not decrease with the id. Reorders A.nb (the
// neighbours) by id. O(k log k + k (dims + n_out) dims) more.
template <class Coord, class Out, class Group>
void local_linear(const actor_t& A, const hg::KdTree& tree, uint32_t k, uint32_t min_n, uint32_t dims, uint32_t n_out,
                  const double* xq, const Coord& coord, const Out& out, LocalFit& f, const double* contrast,
                  const Group& group) {
  f.n = 0;
  f.ok = false;
  for (uint32_t o = 0; o < kMaxOut; ++o) f.contrast_se[o] = std::numeric_limits<double>::infinity();
  for (uint32_t o = 0; o < n_out; ++o) {
    f.value[o] = 0.0;
    for (uint32_t i = 0; i < dims; ++i) f.grad[o][i] = 0.0;
  }
  hg::KnnSet set(A.nb, k, A.kernel_r2);
  hg::kd_query<kDim>(tree, xq, set, [](uint32_t) { return true; });
  const uint32_t n = set.size();
  f.n = n;
  if (n < min_n) return;
  const int P = static_cast<int>(dims) + 1;
  hg::SysMat M = hg::SysMat::Zero(P, P);
  double rhs[hg::kMaxSystem][kMaxOut] = {};
  double z[hg::kMaxSystem];
  double x[kDim];
  double y[kMaxOut];
  for (uint32_t j = 0; j < n; ++j) {
    const hg::Neighbour& nb = set.data()[j];
    const double w = std::exp(-nb.d2);
    coord(nb.id, x);
    out(nb.id, y);
    for (uint32_t i = 0; i < dims; ++i) z[i] = x[i] - xq[i];
    z[dims] = 1.0;
    for (int r = 0; r < P; ++r) {
      const double wz = w * z[r];
      for (int c = 0; c <= r; ++c) M(r, c) += wz * z[c];
      for (uint32_t o = 0; o < n_out; ++o) rhs[r][o] += wz * y[o];
    }
  }
  for (int r = 0; r < P; ++r) {
    for (int c = r + 1; c < P; ++c) M(r, c) = M(c, r);
  }
  for (int r = 0; r + 1 < P; ++r) M(r, r) += A.cfg.ridge;
  hg::SymFactor ldlt;
  if (!hg::factor_spd(ldlt, M)) return;
  hg::SysVec b(P);
  hg::SysVec beta(P);
  for (uint32_t o = 0; o < n_out; ++o) {
    for (int r = 0; r < P; ++r) b[r] = rhs[r][o];
    ldlt.solve(b, beta);
    for (uint32_t i = 0; i < dims; ++i) f.grad[o][i] = beta[static_cast<int>(i)];
    f.value[o] = beta[P - 1];
  }
  f.ok = hg::finite_all(f.value, n_out);
  if (!f.ok || contrast == nullptr) return;
  hg::SysVec u(P);
  for (int r = 0; r < P; ++r) b[r] = r < static_cast<int>(dims) ? contrast[r] : 0.0;
  ldlt.solve(b, u);
  // Each neighbour's share of c · β_o's error, w_j (u·z_j) e_jo, summed per group; the
  // neighbours in id order, so that a group's points are adjacent.
  hg::Neighbour* nb = A.nb;
  std::sort(nb, nb + n, [](const hg::Neighbour& p, const hg::Neighbour& q) { return p.id < q.id; });
  double var[kMaxOut] = {};
  double sum[kMaxOut] = {};
  uint32_t groups = 0;
  for (uint32_t j = 0; j < n; ++j) {
    const bool first = j == 0u || group(nb[j].id) != group(nb[j - 1u].id);
    if (first) {
      ++groups;
      for (uint32_t o = 0; o < n_out; ++o) {
        var[o] += sum[o] * sum[o];
        sum[o] = 0.0;
      }
    }
    const double w = std::exp(-nb[j].d2);
    coord(nb[j].id, x);
    out(nb[j].id, y);
    double uz = u[static_cast<int>(dims)];
    for (uint32_t i = 0; i < dims; ++i) {
      x[i] -= xq[i];
      uz += u[static_cast<int>(i)] * x[i];
    }
    for (uint32_t o = 0; o < n_out; ++o) {
      double fit = f.value[o];
      for (uint32_t i = 0; i < dims; ++i) fit += f.grad[o][i] * x[i];
      sum[o] += w * uz * (y[o] - fit);
    }
  }
  if (groups < 2u) return;
  for (uint32_t o = 0; o < n_out; ++o) {
    const double v = (var[o] + sum[o] * sum[o]) * static_cast<double>(groups) / static_cast<double>(groups - 1u);
    if (std::isfinite(v)) f.contrast_se[o] = std::sqrt(v);
  }
}

void model_coord(const actor_t& A, uint32_t slot, double* x) {
  const double* s = state_at(A, slot);
  for (uint32_t i = 0; i < A.sd; ++i) x[i] = s[i] * A.m_k[i];
  x[A.sd] = A.a[slot] * A.m_k[A.sd];
  for (int i = static_cast<int>(A.sd) + 1; i < kDim; ++i) x[i] = 0.0;
}

void value_coord(const actor_t& A, const double* s, double* x) {
  for (uint32_t i = 0; i < A.sd; ++i) x[i] = s[i] * A.v_k[i];
  for (int i = static_cast<int>(A.sd); i < kDim; ++i) x[i] = 0.0;
}

// Steps 4-6 of actor.h for query j: the old policy's action, the dynamics model at the recorded
// (s, a), the value model at the predicted next state, and the slope.
void query_targets(actor_t& A, uint32_t j) {
  const uint32_t sd = A.sd;
  const uint32_t slot = A.qslot[j];
  const double* s = state_at(A, slot);
  Pass p;
  forward(A, A.theta, s, p);
  A.qpi[j] = p.out;
  double xq[kDim];
  model_coord(A, slot, xq);
  LocalFit fm;
  local_linear(
      A, A.mtree, A.cfg.model_k, A.cfg.model_min_neighbours, sd + 1u, sd, xq,
      [&A](uint32_t id, double* x) { model_coord(A, A.mrows[id], x); },
      [&A](uint32_t id, double* y) {
        const double* s0 = state_at(A, A.mrows[id]);
        const double* s1 = next_at(A, A.mrows[id]);
        for (uint32_t i = 0; i < A.sd; ++i) y[i] = s1[i] - s0[i];
      },
      fm, nullptr, [&A](uint32_t id) { return A.run[A.mrows[id]]; });
  double effect[kMaxOut];  // B = d(s' - s)/da [state units per action unit]
  double next[kMaxOut];
  const double da = p.out - A.a[slot];
  for (uint32_t i = 0; i < sd; ++i) {
    effect[i] = fm.ok ? fm.grad[i][sd] * A.m_k[sd] : 0.0;
    next[i] = s[i] + (fm.ok ? fm.value[i] : 0.0) + effect[i] * da;
  }
  double xv[kDim];
  value_coord(A, next, xv);
  // The slope γ ∇V · B is a contrast of the value model's coefficients: c_i = γ v_k[i] B_i.
  double contrast[kDim];
  for (uint32_t i = 0; i < sd; ++i) contrast[i] = A.cfg.gamma * A.v_k[i] * effect[i];
  LocalFit fv;
  local_linear(
      A, A.vtree, A.cfg.value_k, A.cfg.value_min_neighbours, sd, 1u, xv,
      [&A](uint32_t id, double* x) { value_coord(A, state_at(A, A.pool[id]), x); },
      [&A](uint32_t id, double* y) { y[0] = A.g[A.pool[id]]; }, fv, A.cfg.slope_min_t > 0.0 ? contrast : nullptr,
      [&A](uint32_t id) { return A.run[A.pool[id]]; });
  double slope = 0.0;
  for (uint32_t i = 0; i < sd; ++i) slope += fv.grad[0][i] * A.v_k[i] * effect[i];
  slope *= A.cfg.gamma;
  const double vq = fv.ok ? fv.value[0] : 0.0;
  const bool ok = fm.ok && fv.ok && std::isfinite(slope) && std::isfinite(vq);
  // Step 7's significance test: a slope within slope_min_t of its standard error is the noise of
  // the few runs the value model saw; stepping on it would walk the actor wherever the noise
  // keeps its sign (actor.h). The query still holds π there (target = π).
  // Its error is the value model's, B taken as exact: adding B's (the dynamics model's, through
  // γ ∇V) held back the gentle teacher's early runs (docs/LEARNING.md).
  const bool significant =
      A.cfg.slope_min_t <= 0.0 || std::fabs(slope) >= A.cfg.slope_min_t * fv.contrast_se[0];
  A.qg[j] = ok && significant ? slope : 0.0;
  A.qv[j] = std::isfinite(vq) ? vq : 0.0;
  A.qok[j] = ok ? 1u : 0u;
  const double av = std::fabs(A.qv[j]);
  if (av > A.vmax) A.vmax = av;
  ++A.counters.queries;
  if (ok) ++A.counters.queries_with_slope;
  if (ok && significant) ++A.counters.queries_stepped;
}

// Step 7's target of query j (after every query's value is known: the floor of |V| needs the
// largest).
void query_step(actor_t& A, uint32_t j) {
  double step = 0.0;
  if (A.qok[j] != 0u) {
    const double floor_v = 1e-6 * A.vmax + 1e-300;
    const double av = std::fabs(A.qv[j]);
    const double ticks = A.qg[j] / ((av > floor_v ? av : floor_v) * A.ln_inv_gamma);
    step = A.cfg.step_gain * ticks;
    if (!std::isfinite(step)) step = 0.0;
    if (step > A.cfg.step_max) step = A.cfg.step_max;
    if (step < -A.cfg.step_max) step = -A.cfg.step_max;
  }
  double y = A.qpi[j] + step;
  // Within the trust radius of the recorded action, where the local models have data (actor.h,
  // step 7); this also pulls back a π that has left it. Then the bounds (a recorded action may
  // lie outside them).
  if (A.cfg.trust_radius > 0.0) {
    const double recorded = A.a[A.qslot[j]];
    if (y > recorded + A.cfg.trust_radius) y = recorded + A.cfg.trust_radius;
    if (y < recorded - A.cfg.trust_radius) y = recorded - A.cfg.trust_radius;
  }
  if (y > A.cfg.action_max) y = A.cfg.action_max;
  if (y < A.cfg.action_min) y = A.cfg.action_min;
  A.qy[j] = y;
  A.step_sum += std::fabs(step);
}

// ---- The between-run work ---------------------------------------------------------------------

void bump(actor_t& A) { ++A.generation; }

void begin_fit(actor_t& A, Stage stage, uint32_t n, uint32_t steps) {
  A.stage = stage;
  A.cursor = 0;
  A.fit_step = 0;
  A.fit_steps = steps;
  A.fit_n = n;
  A.fit_loss = 0.0;
  std::memset(A.grad, 0, A.np * sizeof(double));
  keep_params(A);
}

void finish_work(actor_t& A) {
  A.stage = Stage::kIdle;
  A.cursor = 0;
  bump(A);
}

// Sample i of the fit under way: its state and target.
void fit_sample(const actor_t& A, uint32_t i, const double** s, double* target) {
  if (A.stage == Stage::kClone) {
    const uint32_t slot = slot_of(A, i);
    *s = state_at(A, slot);
    *target = A.a[slot];
  } else {
    *s = state_at(A, A.qslot[i]);
    *target = A.qy[i];
  }
}

// One unit of the fit under way: a sample, or the update after the last sample of a step.
// Returns true when the fit is complete.
bool fit_unit(actor_t& A) {
  if (A.cursor < A.fit_n) {
    const double* s = nullptr;
    double target = 0.0;
    fit_sample(A, A.cursor, &s, &target);
    Pass p;
    forward(A, A.theta, s, p);
    A.fit_loss += backward(A, p, target, 1.0 / static_cast<double>(A.fit_n));
    ++A.cursor;
    return false;
  }
  adam_update(A);
  ++A.fit_step;
  A.cursor = 0;
  A.counters.last_fit_loss = A.fit_loss / static_cast<double>(A.fit_n);  // before this update
  A.fit_loss = 0.0;
  if (A.fit_step < A.fit_steps) return false;
  if (settle_params(A)) {
    if (A.stage == Stage::kClone) {
      ++A.counters.clones;
    } else {
      ++A.counters.fits;
    }
  }
  A.trained = 1;
  return true;
}

void start_improvement(actor_t& A) {
  A.stage = Stage::kPool;
  A.cursor = 0;
  A.n_pool = 0;
  A.win_first = A.work_run + 1u >= A.cfg.recent_runs ? A.work_run + 1u - A.cfg.recent_runs : 0u;
  if (A.cfg.rewarded_window != 0u) {
    A.stage = Stage::kWindow;
    A.win_run = A.work_run;
    A.win_found = 0;
    A.win_rewarded = 0;
    A.win_first = 0;  // the whole ring unless enough rewarded runs are found
  }
}

// Runs the due work for about budget units; returns the units done.
uint64_t run_work(actor_t& A, uint64_t budget) {
  const uint64_t per_unit = ACTOR_ITEMS_PER_UNIT;
  uint64_t work = 0;
  uint64_t items = 0;  // linear items of this slice (converted to units as they accumulate)
  auto units = [&]() { return work + items / per_unit; };
  while (A.stage != Stage::kIdle && units() < budget) {
    switch (A.stage) {
      case Stage::kIdle:
        break;
      case Stage::kReturns: {
        // The run's entries are the newest returns_n; G_t = r_t + γ G_{t+1}, 0 after a terminal.
        while (A.cursor < A.returns_n && units() < budget) {
          const uint32_t slot = slot_of(A, A.count - 1u - A.cursor);
          A.ret = A.r[slot] + A.cfg.gamma * (A.term[slot] != 0u ? 0.0 : A.ret);
          A.g[slot] = A.ret;
          ++A.cursor;
          ++items;
        }
        if (A.cursor < A.returns_n) break;
        if (A.trained) {
          start_improvement(A);
        } else {
          begin_fit(A, Stage::kClone, A.count, A.cfg.clone_steps);
        }
        break;
      }
      case Stage::kClone:
      case Stage::kFit: {
        if (A.fit_steps == 0u || A.fit_n == 0u) {
          A.trained = 1;
          finish_work(A);
          break;
        }
        ++work;
        if (fit_unit(A)) finish_work(A);
        break;
      }
      case Stage::kWindow: {
        // Back from the newest entry (the runs' entries are contiguous, ids increasing) until
        // recent_runs runs with a non-zero reward lie in the window: runs that collected none
        // (ended in a failure scored 0, or at the step limit) say nothing about where the reward
        // is, and a window of only such runs has V = 0 everywhere and no slope (actor.h, step 5).
        bool found = false;
        while (A.cursor < A.count && units() < budget) {
          const uint32_t slot = slot_of(A, A.count - 1u - A.cursor);
          if (A.run[slot] != A.win_run) {
            if (A.win_rewarded != 0) ++A.win_found;
            if (A.win_found >= A.cfg.recent_runs) {
              A.win_first = A.win_run;
              found = true;
              break;
            }
            A.win_run = A.run[slot];
            A.win_rewarded = 0;
          }
          if (A.r[slot] > 0.0 || A.r[slot] < 0.0) A.win_rewarded = 1;
          ++A.cursor;
          ++items;
        }
        if (!found && A.cursor < A.count) break;
        A.stage = Stage::kPool;
        A.cursor = 0;
        break;
      }
      case Stage::kPool: {
        const uint64_t first = A.win_first;
        while (A.cursor < A.count && units() < budget) {
          const uint32_t slot = slot_of(A, A.cursor);
          if (A.run[slot] >= first) A.pool[A.n_pool++] = slot;
          ++A.cursor;
          ++items;
        }
        if (A.cursor < A.count) break;
        A.stage = Stage::kDraw;
        A.cursor = 0;
        A.nq = 0;
        A.n_draw = A.n_pool < A.cfg.max_queries ? A.n_pool : A.cfg.max_queries;
        break;
      }
      case Stage::kDraw: {
        // Selection sampling (Knuth's algorithm S): each pool entry in order is taken with
        // probability (still needed) / (still left), so the set is uniform and in recording
        // order. A pool no larger than the set is taken whole, without draws.
        while (A.cursor < A.n_pool && units() < budget) {
          const uint32_t left = A.n_pool - A.cursor;
          const uint32_t need = A.n_draw - A.nq;
          if (need > 0u && (need == left || static_cast<double>(left) * rng_uniform(&A.rng) < need)) {
            A.qslot[A.nq++] = A.pool[A.cursor];
          }
          ++A.cursor;
          ++items;
        }
        if (A.cursor < A.n_pool) break;
        A.stage = Stage::kModelFill;
        A.cursor = 0;
        A.n_mrows = 0;
        break;
      }
      case Stage::kModelFill: {
        while (A.cursor < A.count && units() < budget) {
          const uint32_t slot = slot_of(A, A.cursor);
          if (A.term[slot] == 0u) {
            A.mrows[A.n_mrows] = slot;
            model_coord(A, slot, A.mtree.pts + static_cast<size_t>(A.n_mrows) * kDim);
            ++A.n_mrows;
          }
          ++A.cursor;
          ++items;
        }
        if (A.cursor < A.count) break;
        // The points are written where the tree keeps them: its copy pass moves each onto itself.
        hg::kd_begin_build(A.mtree, A.mtree.pts, nullptr, A.n_mrows, 0);
        A.stage = Stage::kModelBuild;
        break;
      }
      case Stage::kModelBuild:
      case Stage::kValueBuild: {
        hg::KdTree& t = A.stage == Stage::kModelBuild ? A.mtree : A.vtree;
        const uint64_t room = (budget - units()) * per_unit;
        items += hg::kd_build_step<kDim>(t, room > 0u ? room : 1u);
        if (!hg::kd_done(t)) break;
        A.cursor = 0;
        if (A.stage == Stage::kModelBuild) {
          A.stage = Stage::kValueFill;
        } else {
          A.stage = Stage::kTargets;
          A.vmax = 0.0;
        }
        break;
      }
      case Stage::kValueFill: {
        while (A.cursor < A.n_pool && units() < budget) {
          value_coord(A, state_at(A, A.pool[A.cursor]), A.vtree.pts + static_cast<size_t>(A.cursor) * kDim);
          ++A.cursor;
          ++items;
        }
        if (A.cursor < A.n_pool) break;
        hg::kd_begin_build(A.vtree, A.vtree.pts, nullptr, A.n_pool, 0);
        A.stage = Stage::kValueBuild;
        break;
      }
      case Stage::kTargets: {
        if (A.cursor < A.nq) {
          query_targets(A, A.cursor);
          ++A.cursor;
          work += ACTOR_WORK_QUERY;
          break;
        }
        A.stage = Stage::kSteps;
        A.cursor = 0;
        A.step_sum = 0.0;
        break;
      }
      case Stage::kSteps: {
        while (A.cursor < A.nq && units() < budget) {
          query_step(A, A.cursor);
          ++A.cursor;
          ++items;
        }
        if (A.cursor < A.nq) break;
        A.counters.last_mean_step = A.nq > 0u ? A.step_sum / static_cast<double>(A.nq) : 0.0;
        begin_fit(A, Stage::kFit, A.nq, A.cfg.fit_steps);
        break;
      }
    }
  }
  return units();
}

void reset_ring(actor_t& A) {
  A.head = 0;
  A.count = 0;
  A.run_len = 0;
  A.runs = 0;
  A.counters.fill = 0;
}

// ---- Byte format ------------------------------------------------------------------------------
// Little-endian. 0 magic "ACTR", 4 u32 version, 8 u64 total length (with the CRC), 16 u32
// state_dim, 20 u32 hidden, 24 u32 parameters, 28 u32 entries saved, 32 u32 trained (0/1), 36 u32
// entries of the run under way, 40 u64 runs ended, 48 u64 Adam steps, 56 4 × u64 generator state,
// 88 f64 its spare normal, 96 u32 spare held (0/1), 100 u32 reserved (0), 104 f64 action_min,
// action_max, action_scale, gamma, then f64 state_min[sd], state_max[sd], state_scale[sd], then f64
// parameters, Adam's first and second moments (3 × parameters), then the entries oldest first,
// each f64 s[sd], s'[sd], a, r, G, u32 run id, u32 terminal, then u32 CRC-32 of all before it.
constexpr size_t kHeader = 136;

size_t entry_bytes(uint32_t sd) { return 8u * (2u * static_cast<size_t>(sd) + 3u) + 8u; }

size_t format_size(uint32_t sd, uint32_t np, uint32_t count) {
  return kHeader + 24u * static_cast<size_t>(sd) + 24u * static_cast<size_t>(np) +
         static_cast<size_t>(count) * entry_bytes(sd) + 4u;
}

}  // namespace

// ---- C API ------------------------------------------------------------------------------------

actor_config_t actor_config_default(void) ACTOR_NOEXCEPT {
  actor_config_t c;
  std::memset(&c, 0, sizeof c);
  c.capacity = 20000u;
  c.hidden = 16u;
  c.recent_runs = 10u;
  c.max_queries = 4000u;
  c.model_k = 64u;
  c.model_bandwidth = 0.5;
  c.model_min_neighbours = 8u;
  c.value_k = 256u;
  c.value_bandwidth = 0.5;
  c.value_min_neighbours = 12u;
  c.ridge = 1e-3;
  c.step_gain = 0.3;
  c.step_max = 0.1;
  c.trust_radius = 0.0;
  c.slope_min_t = 3.0;
  c.rewarded_window = 1u;
  c.clone_steps = 300u;
  c.fit_steps = 200u;
  c.learning_rate = 3e-3;
  c.seed = 1u;
  return c;
}

actor_status_t actor_config_validate(const actor_config_t* cfg) ACTOR_NOEXCEPT {
  return config_valid(cfg) ? ACTOR_OK : ACTOR_ERR_INVALID_ARG;
}

size_t actor_storage_size(const actor_config_t* cfg) ACTOR_NOEXCEPT {
  return config_valid(cfg) ? make_layout(*cfg).total : 0u;
}

actor_status_t actor_init(actor_t** out, void* storage, size_t storage_size, const actor_config_t* cfg) ACTOR_NOEXCEPT {
  if (out == nullptr || storage == nullptr || !config_valid(cfg)) return ACTOR_ERR_INVALID_ARG;
  if (reinterpret_cast<uintptr_t>(storage) % ACTOR_STORAGE_ALIGN != 0u) return ACTOR_ERR_ALIGNMENT;
  const Layout l = make_layout(*cfg);
  if (storage_size < l.total) return ACTOR_ERR_CAPACITY;
  uint8_t* base = static_cast<uint8_t*>(storage);
  std::memset(base, 0, l.total);
  actor_t* A = new (base) actor_t();
  A->cfg = *cfg;
  A->lay = l;
  A->sd = cfg->state_dim;
  A->np = l.n_params;
  for (uint32_t i = 0; i < A->sd; ++i) {
    const double half = 0.5 * (cfg->state_max[i] - cfg->state_min[i]);
    A->in_c[i] = 0.5 * (cfg->state_max[i] + cfg->state_min[i]);
    A->in_k[i] = half > 0.0 ? 1.0 / half : 1.0;
    A->m_k[i] = 1.0 / (cfg->state_scale[i] * cfg->model_bandwidth);
    A->v_k[i] = 1.0 / (cfg->state_scale[i] * cfg->value_bandwidth);
  }
  A->m_k[A->sd] = 1.0 / (cfg->action_scale * cfg->model_bandwidth);
  A->out_c = 0.5 * (cfg->action_max + cfg->action_min);
  A->out_r = 0.5 * (cfg->action_max - cfg->action_min);
  A->kernel_r2 = std::log(1.0 / kKernelEpsilon);
  A->ln_inv_gamma = std::log(1.0 / cfg->gamma);
  A->s = reinterpret_cast<double*>(base + l.s);
  A->sn = reinterpret_cast<double*>(base + l.sn);
  A->a = reinterpret_cast<double*>(base + l.a);
  A->r = reinterpret_cast<double*>(base + l.r);
  A->g = reinterpret_cast<double*>(base + l.g);
  A->run = reinterpret_cast<uint32_t*>(base + l.run);
  A->term = base + l.term;
  A->pool = reinterpret_cast<uint32_t*>(base + l.pool);
  A->qslot = reinterpret_cast<uint32_t*>(base + l.qslot);
  A->qpi = reinterpret_cast<double*>(base + l.qpi);
  A->qy = reinterpret_cast<double*>(base + l.qy);
  A->qg = reinterpret_cast<double*>(base + l.qg);
  A->qv = reinterpret_cast<double*>(base + l.qv);
  A->qok = base + l.qok;
  hg::kd_bind(A->mtree, reinterpret_cast<double*>(base + l.mpts), reinterpret_cast<uint32_t*>(base + l.mids),
              reinterpret_cast<hg::Node*>(base + l.mnodes), cfg->capacity);
  A->mrows = reinterpret_cast<uint32_t*>(base + l.mrows);
  hg::kd_bind(A->vtree, reinterpret_cast<double*>(base + l.vpts), reinterpret_cast<uint32_t*>(base + l.vids),
              reinterpret_cast<hg::Node*>(base + l.vnodes), cfg->capacity);
  A->nb = reinterpret_cast<hg::Neighbour*>(base + l.nb);
  A->theta = reinterpret_cast<double*>(base + l.theta);
  A->m = reinterpret_cast<double*>(base + l.m);
  A->v = reinterpret_cast<double*>(base + l.v);
  A->grad = reinterpret_cast<double*>(base + l.grad);
  A->keep_theta = reinterpret_cast<double*>(base + l.keep_theta);
  A->keep_m = reinterpret_cast<double*>(base + l.keep_m);
  A->keep_v = reinterpret_cast<double*>(base + l.keep_v);
  rng_seed(&A->rng, cfg->seed);
  init_weights(*A);
  A->stage = Stage::kIdle;
  reset_ring(*A);
  A->magic = kLive;
  *out = A;
  return ACTOR_OK;
}

const actor_config_t* actor_get_config(const actor_t* self) ACTOR_NOEXCEPT { return live(self) ? &self->cfg : nullptr; }

actor_status_t actor_act(actor_t* self, const double* state, double* action) ACTOR_NOEXCEPT {
  if (!live(self) || state == nullptr || action == nullptr) return ACTOR_ERR_INVALID_ARG;
  *action = self->out_c;
  if (!hg::finite_all(state, self->sd)) return ACTOR_ERR_NON_FINITE;
  if (!self->trained) return ACTOR_UNTRAINED;
  Pass p;
  forward(*self, self->theta, state, p);
  if (!std::isfinite(p.out)) {
    ++self->counters.output_faults;
    return ACTOR_ERR_NON_FINITE;
  }
  // tanh keeps the output inside the bounds; the clamp only absorbs rounding at the edges.
  *action = p.out < self->cfg.action_min ? self->cfg.action_min
                                         : (p.out > self->cfg.action_max ? self->cfg.action_max : p.out);
  return ACTOR_OK;
}

int actor_trained(const actor_t* self) ACTOR_NOEXCEPT { return live(self) && self->trained ? 1 : 0; }

actor_status_t actor_record(actor_t* self, const double* state, double action, double reward, const double* state_next,
                            int terminal) ACTOR_NOEXCEPT {
  if (!live(self) || state == nullptr || (terminal == 0 && state_next == nullptr)) return ACTOR_ERR_INVALID_ARG;
  actor_t& A = *self;
  if (A.stage != Stage::kIdle) return ACTOR_ERR_BUSY;
  if (!hg::finite_all(state, A.sd) || !std::isfinite(action) || !std::isfinite(reward) ||
      (terminal == 0 && !hg::finite_all(state_next, A.sd))) {
    ++A.counters.rejected_non_finite;
    return ACTOR_ERR_NON_FINITE;
  }
  const uint32_t slot = A.head;
  std::memcpy(A.s + static_cast<size_t>(slot) * A.sd, state, A.sd * sizeof(double));
  // A terminal transition's next state is never used (no model point): keep the state there.
  std::memcpy(A.sn + static_cast<size_t>(slot) * A.sd, terminal != 0 ? state : state_next, A.sd * sizeof(double));
  A.a[slot] = action;
  A.r[slot] = reward;
  A.g[slot] = 0.0;
  A.run[slot] = static_cast<uint32_t>(A.runs);
  A.term[slot] = terminal != 0 ? 1u : 0u;
  A.head = (A.head + 1u) % A.cfg.capacity;
  if (A.count < A.cfg.capacity) ++A.count;
  if (A.run_len < A.count) ++A.run_len;
  ++A.counters.recorded;
  A.counters.fill = A.count;
  bump(A);
  return ACTOR_OK;
}

uint32_t actor_run_length(const actor_t* self) ACTOR_NOEXCEPT { return live(self) ? self->run_len : 0u; }

actor_status_t actor_end_run_begin(actor_t* self, int* pending) ACTOR_NOEXCEPT {
  if (pending != nullptr) *pending = 0;
  if (!live(self)) return ACTOR_ERR_INVALID_ARG;
  actor_t& A = *self;
  if (A.stage != Stage::kIdle) return ACTOR_ERR_BUSY;
  if (A.run_len == 0u) return ACTOR_OK;
  A.work_run = A.runs;
  A.returns_n = A.run_len;
  A.run_len = 0;
  ++A.runs;
  ++A.counters.runs;
  A.ret = 0.0;
  A.cursor = 0;
  A.stage = Stage::kReturns;
  bump(A);
  if (pending != nullptr) *pending = 1;
  return ACTOR_OK;
}

actor_status_t actor_end_run_step(actor_t* self, uint32_t max_work, int* remaining) ACTOR_NOEXCEPT {
  if (remaining != nullptr) *remaining = 0;
  if (!live(self)) return ACTOR_ERR_INVALID_ARG;
  actor_t& A = *self;
  if (A.stage == Stage::kIdle) return ACTOR_OK;
  const uint64_t w = run_work(A, max_work > 0u ? max_work : 1u);
  ++A.counters.slices;
  const uint32_t w32 = w > UINT32_MAX ? UINT32_MAX : static_cast<uint32_t>(w);
  if (w32 > A.counters.max_slice_work) A.counters.max_slice_work = w32;
  if (remaining != nullptr) *remaining = A.stage != Stage::kIdle ? 1 : 0;
  return ACTOR_OK;
}

int actor_working(const actor_t* self) ACTOR_NOEXCEPT { return live(self) && self->stage != Stage::kIdle ? 1 : 0; }

actor_status_t actor_clone(actor_t* self, uint32_t n, actor_sample_fn get, void* user) ACTOR_NOEXCEPT {
  if (!live(self) || get == nullptr) return ACTOR_ERR_INVALID_ARG;
  actor_t& A = *self;
  if (A.stage != Stage::kIdle) return ACTOR_ERR_BUSY;
  // First pass: how many samples are usable (the loss is their mean).
  uint32_t usable = 0;
  double s[ACTOR_MAX_STATE_DIM];
  double act = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    if (get(user, i, s, &act) == 0 && hg::finite_all(s, A.sd) && std::isfinite(act)) ++usable;
  }
  if (usable == 0u || A.cfg.clone_steps == 0u) return ACTOR_OK;
  keep_params(A);
  std::memset(A.grad, 0, A.np * sizeof(double));
  const double coef = 1.0 / static_cast<double>(usable);
  double loss = 0.0;
  for (uint32_t step = 0; step < A.cfg.clone_steps; ++step) {
    loss = 0.0;
    for (uint32_t i = 0; i < n; ++i) {
      if (get(user, i, s, &act) != 0 || !hg::finite_all(s, A.sd) || !std::isfinite(act)) continue;
      Pass p;
      forward(A, A.theta, s, p);
      loss += backward(A, p, act, coef);
    }
    adam_update(A);
  }
  A.counters.last_fit_loss = loss * coef;
  if (settle_params(A)) ++A.counters.clones;
  A.trained = 1;
  bump(A);
  return ACTOR_OK;
}

const actor_counters_t* actor_counters(const actor_t* self) ACTOR_NOEXCEPT { return live(self) ? &self->counters : nullptr; }

size_t actor_serialized_size(const actor_t* self) ACTOR_NOEXCEPT {
  return live(self) ? format_size(self->sd, self->np, self->count) : 0u;
}

size_t actor_serialized_max_size(const actor_config_t* cfg) ACTOR_NOEXCEPT {
  return config_valid(cfg) ? format_size(cfg->state_dim, params_of(cfg->state_dim, cfg->hidden), cfg->capacity) : 0u;
}

actor_status_t actor_save_begin(const actor_t* self, void* buf, size_t size, actor_save_cursor_t* cursor) ACTOR_NOEXCEPT {
  if (!live(self) || buf == nullptr || cursor == nullptr) return ACTOR_ERR_INVALID_ARG;
  const actor_t& A = *self;
  if (A.stage != Stage::kIdle) return ACTOR_ERR_BUSY;
  const size_t total = format_size(A.sd, A.np, A.count);
  if (size < total) return ACTOR_ERR_CAPACITY;
  uint8_t* p = static_cast<uint8_t*>(buf);
  std::memcpy(p, kFileMagic, 4);
  hg::put_u32(p + 4, ACTOR_FORMAT_VERSION);
  hg::put_u64(p + 8, total);
  hg::put_u32(p + 16, A.sd);
  hg::put_u32(p + 20, A.cfg.hidden);
  hg::put_u32(p + 24, A.np);
  hg::put_u32(p + 28, A.count);
  hg::put_u32(p + 32, A.trained ? 1u : 0u);
  hg::put_u32(p + 36, A.run_len);
  hg::put_u64(p + 40, A.runs);
  hg::put_u64(p + 48, A.adam_t);
  for (int i = 0; i < 4; ++i) hg::put_u64(p + 56 + 8 * i, A.rng.s[i]);
  hg::put_f64(p + 88, A.rng.spare_normal);
  hg::put_u32(p + 96, A.rng.has_spare);
  hg::put_u32(p + 100, 0u);
  hg::put_f64(p + 104, A.cfg.action_min);
  hg::put_f64(p + 112, A.cfg.action_max);
  hg::put_f64(p + 120, A.cfg.action_scale);
  hg::put_f64(p + 128, A.cfg.gamma);
  size_t off = kHeader;
  for (const double* arr : {A.cfg.state_min, A.cfg.state_max, A.cfg.state_scale}) {
    for (uint32_t i = 0; i < A.sd; ++i, off += 8) hg::put_f64(p + off, arr[i]);
  }
  for (const double* arr : {A.theta, A.m, A.v}) {
    for (uint32_t k = 0; k < A.np; ++k, off += 8) hg::put_f64(p + off, arr[k]);
  }
  cursor->buf = p;
  cursor->size = total;
  cursor->offset = off;
  cursor->next = 0;
  cursor->crc = hg::crc32_update(0xFFFFFFFFu, p, off);
  cursor->generation = A.generation;
  cursor->done = 0;
  return ACTOR_OK;
}

actor_status_t actor_save_step(const actor_t* self, actor_save_cursor_t* cursor, uint32_t max_entries,
                               size_t* written) ACTOR_NOEXCEPT {
  if (written != nullptr) *written = 0;
  if (!live(self) || cursor == nullptr || cursor->buf == nullptr) return ACTOR_ERR_INVALID_ARG;
  const actor_t& A = *self;
  if (cursor->done) {
    if (written != nullptr) *written = cursor->size;
    return ACTOR_OK;
  }
  if (cursor->generation != A.generation) return ACTOR_ERR_CHANGED;
  uint8_t* p = cursor->buf;
  size_t off = cursor->offset;
  const size_t start = off;
  uint32_t i = cursor->next;
  const uint32_t end = A.count - i > max_entries ? i + max_entries : A.count;
  for (; i < end; ++i) {
    const uint32_t slot = slot_of(A, i);
    const double* s = state_at(A, slot);
    const double* sn = next_at(A, slot);
    for (uint32_t k = 0; k < A.sd; ++k, off += 8) hg::put_f64(p + off, s[k]);
    for (uint32_t k = 0; k < A.sd; ++k, off += 8) hg::put_f64(p + off, sn[k]);
    hg::put_f64(p + off, A.a[slot]);
    hg::put_f64(p + off + 8, A.r[slot]);
    hg::put_f64(p + off + 16, A.g[slot]);
    hg::put_u32(p + off + 24, A.run[slot]);
    hg::put_u32(p + off + 28, A.term[slot]);
    off += 32;
  }
  cursor->crc = hg::crc32_update(cursor->crc, p + start, off - start);
  cursor->offset = off;
  cursor->next = i;
  if (i == A.count) {
    hg::put_u32(p + off, cursor->crc ^ 0xFFFFFFFFu);
    cursor->done = 1;
    if (written != nullptr) *written = cursor->size;
  }
  return ACTOR_OK;
}

actor_status_t actor_save(const actor_t* self, void* buf, size_t size, size_t* written) ACTOR_NOEXCEPT {
  actor_save_cursor_t c;
  const actor_status_t st = actor_save_begin(self, buf, size, &c);
  if (st != ACTOR_OK) return st;
  return actor_save_step(self, &c, UINT32_MAX, written);
}

size_t actor_saved_length(const void* buf, size_t size) ACTOR_NOEXCEPT {
  if (buf == nullptr || size < 16u) return 0u;
  const uint8_t* p = static_cast<const uint8_t*>(buf);
  if (std::memcmp(p, kFileMagic, 4) != 0) return 0u;
  const uint64_t n = hg::get_u64(p + 8);
  return n > SIZE_MAX ? 0u : static_cast<size_t>(n);
}

actor_status_t actor_load(actor_t* self, const void* buf, size_t size) ACTOR_NOEXCEPT {
  if (!live(self) || buf == nullptr) return ACTOR_ERR_INVALID_ARG;
  actor_t& A = *self;
  if (A.stage != Stage::kIdle) return ACTOR_ERR_BUSY;
  const uint8_t* p = static_cast<const uint8_t*>(buf);
  if (size < 8u || std::memcmp(p, kFileMagic, 4) != 0) return ACTOR_ERR_FORMAT;
  if (hg::get_u32(p + 4) != ACTOR_FORMAT_VERSION) return ACTOR_ERR_VERSION;
  if (size < kHeader) return ACTOR_ERR_TRUNCATED;
  const uint64_t total = hg::get_u64(p + 8);
  if (total > size) return ACTOR_ERR_TRUNCATED;
  if (total < kHeader + 4u) return ACTOR_ERR_FORMAT;
  const size_t n = static_cast<size_t>(total);
  if (hg::get_u32(p + n - 4) != hg::crc32(p, n - 4)) return ACTOR_ERR_CHECKSUM;
  const uint32_t sd = hg::get_u32(p + 16);
  const uint32_t count = hg::get_u32(p + 28);
  if (sd != A.sd || hg::get_u32(p + 20) != A.cfg.hidden || hg::get_u32(p + 24) != A.np || count > A.cfg.capacity ||
      !hg::same_bits(hg::get_f64(p + 104), A.cfg.action_min) || !hg::same_bits(hg::get_f64(p + 112), A.cfg.action_max) ||
      !hg::same_bits(hg::get_f64(p + 120), A.cfg.action_scale) || !hg::same_bits(hg::get_f64(p + 128), A.cfg.gamma)) {
    return ACTOR_ERR_CONFIG_MISMATCH;
  }
  size_t off = kHeader;
  for (const double* arr : {A.cfg.state_min, A.cfg.state_max, A.cfg.state_scale}) {
    for (uint32_t i = 0; i < sd; ++i, off += 8) {
      if (!hg::same_bits(hg::get_f64(p + off), arr[i])) return ACTOR_ERR_CONFIG_MISMATCH;
    }
  }
  if (n != format_size(sd, A.np, count)) return ACTOR_ERR_FORMAT;
  // Contents: everything checked before anything is changed.
  const uint32_t trained = hg::get_u32(p + 32);
  const uint32_t run_len = hg::get_u32(p + 36);
  const uint64_t runs = hg::get_u64(p + 40);
  const uint32_t has_spare = hg::get_u32(p + 96);
  uint64_t st[4];
  for (int i = 0; i < 4; ++i) st[i] = hg::get_u64(p + 56 + 8 * i);
  const double spare = hg::get_f64(p + 88);
  if (trained > 1u || run_len > count || has_spare > 1u || (st[0] | st[1] | st[2] | st[3]) == 0u ||
      !std::isfinite(spare) || runs > UINT32_MAX) {
    return ACTOR_ERR_FORMAT;
  }
  for (uint32_t k = 0; k < 3u * A.np; ++k) {
    const double x = hg::get_f64(p + off + 8u * k);
    if (!std::isfinite(x) || (k >= 2u * A.np && x < 0.0)) return ACTOR_ERR_FORMAT;
  }
  const size_t entries = off + 24u * A.np;
  const size_t eb = entry_bytes(sd);
  for (uint32_t i = 0; i < count; ++i) {
    const uint8_t* e = p + entries + i * eb;
    for (uint32_t k = 0; k < 2u * sd + 3u; ++k) {
      if (!std::isfinite(hg::get_f64(e + 8u * k))) return ACTOR_ERR_FORMAT;
    }
    const uint32_t run = hg::get_u32(e + 8u * (2u * sd + 3u));
    const uint32_t term = hg::get_u32(e + 8u * (2u * sd + 3u) + 4u);
    // Entries of ended runs have ids below runs; those of the run under way (the newest run_len)
    // have id runs.
    const bool in_run = i >= count - run_len;
    if (term > 1u || (in_run ? run != runs : run >= runs)) return ACTOR_ERR_FORMAT;
  }
  // Apply.
  for (double* arr : {A.theta, A.m, A.v}) {
    for (uint32_t k = 0; k < A.np; ++k, off += 8) arr[k] = hg::get_f64(p + off);
  }
  for (uint32_t i = 0; i < count; ++i) {
    const uint8_t* e = p + entries + i * eb;
    double* s = A.s + static_cast<size_t>(i) * sd;
    double* sn = A.sn + static_cast<size_t>(i) * sd;
    for (uint32_t k = 0; k < sd; ++k) s[k] = hg::get_f64(e + 8u * k);
    for (uint32_t k = 0; k < sd; ++k) sn[k] = hg::get_f64(e + 8u * (sd + k));
    A.a[i] = hg::get_f64(e + 16u * sd);
    A.r[i] = hg::get_f64(e + 16u * sd + 8u);
    A.g[i] = hg::get_f64(e + 16u * sd + 16u);
    A.run[i] = hg::get_u32(e + 16u * sd + 24u);
    A.term[i] = static_cast<uint8_t>(hg::get_u32(e + 16u * sd + 28u));
  }
  A.count = count;
  A.head = count % A.cfg.capacity;
  A.run_len = run_len;
  A.runs = runs;
  A.trained = static_cast<int>(trained);
  A.adam_t = hg::get_u64(p + 48);
  for (int i = 0; i < 4; ++i) A.rng.s[i] = st[i];
  A.rng.spare_normal = spare;
  A.rng.has_spare = static_cast<uint8_t>(has_spare);
  std::memset(A.grad, 0, A.np * sizeof(double));
  A.counters.fill = count;
  bump(A);
  return ACTOR_OK;
}

const char* actor_status_str(actor_status_t status) ACTOR_NOEXCEPT {
  switch (status) {
    case ACTOR_OK:
      return "ok";
    case ACTOR_UNTRAINED:
      return "untrained";
    case ACTOR_ERR_INVALID_ARG:
      return "invalid argument";
    case ACTOR_ERR_NON_FINITE:
      return "non-finite value";
    case ACTOR_ERR_CAPACITY:
      return "capacity exceeded";
    case ACTOR_ERR_ALIGNMENT:
      return "storage not aligned";
    case ACTOR_ERR_BUSY:
      return "between-run work under way";
    case ACTOR_ERR_FORMAT:
      return "not an actor's saved state";
    case ACTOR_ERR_VERSION:
      return "another format version";
    case ACTOR_ERR_TRUNCATED:
      return "truncated";
    case ACTOR_ERR_CHECKSUM:
      return "checksum mismatch";
    case ACTOR_ERR_CONFIG_MISMATCH:
      return "saved under another configuration";
    case ACTOR_ERR_CHANGED:
      return "changed during the save";
  }
  return "unknown status";
}
