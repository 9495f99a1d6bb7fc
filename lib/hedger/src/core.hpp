// SPDX-License-Identifier: MIT
// HEDGER core: the instance layout and the algorithms, templated on the input dimension D.
//
// Internal header of lib/hedger (hedger.cpp, white-box tests and the benchmark include it).
//
// Data (all inside the caller's storage block, see make_layout()):
//   store   pts[cap × D] scaled coordinates, val[cap] values, seq[cap] sequence numbers,
//           flags[cap]; slots 0..fill-1 are occupied (eviction replaces in place).
//   fresh   [fresh_cap] slots and coordinates of the points stored after the active tree's
//           snapshot, scanned linearly (contiguously) by every query; fresh_pos[cap] maps a slot
//           to its fresh entry, so a slot rewritten again updates its entry in place and every
//           entry is always current (no per-entry validity check in the scan).
//   trees   two kd-trees (kdtree.hpp): `active` answers queries, the other is rebuilt in slices.
//           A tree entry is valid while its slot's seq <= the tree's snapshot (replaced slots
//           are skipped; their new point is in `fresh`).
//   run     ring of the current run's experiences for the optional backward replay.
//
// Why this shape. Queries must not depend on how recently a point arrived, and the per-update
// cost must be bounded: a new point costs O(1) (append to fresh); a rebuild copies the store
// and builds the shadow tree in work slices of `rebuild_budget` units per update, then swaps and
// drops the fresh entries the new tree covers. Every neighbour set is ordered by (d², slot), so
// results are independent of tree shape, fresh-buffer order and rebuild timing: two instances
// with the same calls give bit-identical values even if one was saved and loaded in between.
#ifndef HEDGER_CORE_HPP
#define HEDGER_CORE_HPP

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

#include "hedger/hedger.h"
#include "kdtree.hpp"

namespace hg {

constexpr uint32_t kMagic = 0x48444752u;  // "HDGR": a live instance
/// Smallest ratio min|d_i| / max|d_i| of the pivots of the (pivoted) LDLT factorisation accepted
/// for the IVH and the LWR normal equations; below it (or with a non-positive pivot) the
/// neighbourhood is treated as singular (LWA). For these small SPD matrices the pivot ratio is a
/// cheap proxy of 1/cond; exact collinearity (e.g. every neighbour with the same action) gives a
/// ratio near 1e-17.
constexpr double kPivotRatioMin = 1e-12;

/// Factorises a symmetric matrix; false if it is not numerically positive definite.
template <class Mat>
bool factor_spd(Eigen::LDLT<Mat>& ldlt, const Mat& m) noexcept {
  ldlt.compute(m);
  if (ldlt.info() != Eigen::Success) return false;
  const auto d = ldlt.vectorD();
  double dmin = d[0], dmax = d[0];
  for (int i = 1; i < d.size(); ++i) {
    if (d[i] < dmin) dmin = d[i];
    if (d[i] > dmax) dmax = d[i];
  }
  return dmin > 0.0 && dmin > kPivotRatioMin * dmax;
}
/// Relative tolerance of the IVH comparison, so that a query exactly at the point of largest
/// leverage is inside despite rounding.
constexpr double kIvhTol = 1e-9;

/// Smallest ratio λmin / λmax of the eigenvalues of a neighbourhood's centred scatter matrix for
/// which its points count as spanning every input dimension (spans_inputs()). A ratio of 1e-12
/// is a spread ratio of 1e-6 between the thinnest and the widest direction, far above the
/// O(1e-16) rounding of an exactly rank-deficient neighbourhood.
constexpr double kScatterRatioMin = 1e-12;

/// The rank test of the local regression (hedger.h, HEDGER_FALLBACK_SINGULAR): true when the n
/// neighbours, given as rows r_i = [x_i − x, 1] (D + 1 entries, scaled units), span all D input
/// dimensions numerically, i.e. the design matrix of rows [x_i, 1] has full rank D + 1. That
/// needs at least D + 1 points, and the centred scatter matrix S = Σ (x_i − m)(x_i − m)ᵀ (m =
/// the points' mean) must have λmin(S) > kScatterRatioMin · λmax(S).
///
/// Why eigenvalues and not the pivots of an LDLT of XᵀX: the symmetric eigensolver is backward
/// stable (absolute error O(ε λmax) on every eigenvalue), so an exactly rank-deficient
/// neighbourhood always shows a ratio near 1e-16. The pivots of the uncentred XᵀX carry no such
/// bound: with D = 4, 4 neighbours and the query at one of them (rank 4 of 5), 4 of 10 000
/// random neighbourhoods passed a 1e-12 pivot-ratio test.
///
/// Cost. The eigensolver costs about 1 µs at D = 4, a third of a prediction, so two cheap
/// certificates come first, from the pivots d_i of a diagonally pivoted LDLT of S. Those are the
/// exact pivots of a matrix S' within δ = 4D²ε·tr(S) of S (backward error of the factorisation
/// of a semidefinite matrix, |L| <= 1; the bound allows twice that), and eigenvalues move by at
/// most δ between S and S'.
/// - Full rank: λmin ≥ det / λmax^(D−1) with det = Π d_i and λmax <= tr(S), so
///   det > (kScatterRatioMin·tr + δ)(tr + δ)^(D−1) proves λmin(S) > kScatterRatioMin·λmax(S).
/// - Rank deficient: every pivot is at least λmin of a leading block, hence at least λmin(S')
///   (interlacing; a non-positive pivot means S' is not positive definite at all), and
///   λmax(S) >= tr(S)/D, so min d_i + δ <= kScatterRatioMin·tr/D proves the opposite (and
///   δ < kScatterRatioMin·tr/D for every D <= 9, so a non-positive pivot always qualifies).
///   An exactly rank-deficient S typically has a last pivot of order ε·tr and lands here.
/// Whatever neither certificate settles goes to the eigensolver, which decides. Measured
/// (hedger.bench, D = 4): the eigensolver on
/// every prediction made a prediction's p50 about 35 % slower; with the certificates first the
/// change is within the benchmark's run-to-run noise. O(n D² + D³) in fixed-size Eigen types
/// (the eigensolver's QR sweeps are capped by Eigen at 30 D), no allocation, deterministic.
static_assert(4.0 * kMaxDim * kMaxDim * kMaxDim * std::numeric_limits<double>::epsilon() < kScatterRatioMin,
              "spans_inputs(): the backward-error allowance must stay below the rank threshold");

template <int D>
bool spans_inputs(const Eigen::Matrix<double, D + 1, 1>* rows, uint32_t n) noexcept {
  using VecD = Eigen::Matrix<double, D, 1>;
  using MatD = Eigen::Matrix<double, D, D>;
  if (n < static_cast<uint32_t>(D) + 1u) return false;
  VecD mean = VecD::Zero();
  for (uint32_t i = 0; i < n; ++i) mean += rows[i].template head<D>();
  mean /= static_cast<double>(n);
  MatD scatter = MatD::Zero();
  for (uint32_t i = 0; i < n; ++i) {
    const VecD c = rows[i].template head<D>() - mean;
    scatter.noalias() += c * c.transpose();
  }
  const double tr = scatter.trace();
  if (!(tr > 0.0) || !std::isfinite(tr)) return false;
  {
    constexpr double eps = std::numeric_limits<double>::epsilon();
    const double delta = 4.0 * D * D * eps * tr;
    Eigen::LDLT<MatD> ldlt(scatter);
    if (ldlt.info() == Eigen::Success) {
      const auto piv = ldlt.vectorD();
      double det = 1.0;
      double dmin = piv[0];
      for (int i = 0; i < D; ++i) {
        det *= piv[i] > 0.0 ? piv[i] : 0.0;
        dmin = piv[i] < dmin ? piv[i] : dmin;
      }
      double bound = kScatterRatioMin * tr + delta;
      for (int i = 1; i < D; ++i) bound *= tr + delta;
      if (det * (1.0 - 4.0 * D * eps) > bound) return true;
      if (dmin + delta <= kScatterRatioMin * tr / D) return false;
    }
  }
  Eigen::SelfAdjointEigenSolver<MatD> eig;
  eig.compute(scatter, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success) return false;
  const VecD& ev = eig.eigenvalues();  // ascending
  return ev[0] > kScatterRatioMin * ev[D - 1];
}

/// Offsets of every array in the storage block (bytes from its start).
struct Layout {
  size_t total;
  size_t pts, val, seq, flags, fresh_pos, fresh_slot, fresh_pts, run;
  size_t tpts[2], tids[2], tnodes[2];
  uint32_t max_nodes;
  uint32_t run_stride;  ///< doubles per run record: s, a, r, s', terminal
};

}  // namespace hg

/// The instance. Plain data placed at the start of the caller's storage block.
struct hedger {
  uint32_t magic;
  uint32_t dim;    ///< D = state_dim + 1
  uint32_t owned;  ///< storage allocated by hedger_create()
  uint32_t replaying;
  hedger_config_t cfg;
  // Derived constants.
  double h2;        ///< bandwidth²
  double r2max;     ///< squared radius where the kernel weight drops below weight_epsilon
  double merge_r2;  ///< merge_radius²
  uint64_t rebuild_budget;
  uint32_t fresh_start;  ///< fresh entries that start a rebuild
  // Store.
  uint32_t cap;
  uint32_t fill;
  uint32_t n_protected;
  double* pts;
  double* val;
  uint64_t* seq;
  uint8_t* flags;
  uint64_t seq_counter;
  // Fresh buffer.
  uint32_t* fresh_pos;   ///< [cap] entry of each slot, or kNone
  uint32_t* fresh_slot;  ///< [fresh_cap]
  double* fresh_pts;     ///< [fresh_cap × D]
  uint32_t n_fresh;
  uint32_t fresh_cap;
  // Trees.
  hg::KdTree tree[2];
  uint32_t active;
  uint32_t building;
  uint64_t call_work;  ///< rebuild work in the current API call
  // Run buffer.
  double* run;
  uint32_t run_cap;
  uint32_t run_head;  ///< next write position
  uint32_t run_count;
  uint32_t run_stride;
  // Eviction generator (xorshift64*) and rewards seen.
  uint64_t rng;
  double r_min;
  double r_max;
  uint32_t reward_seen;
  uint32_t pad;
  hedger_counters_t counters;
};

namespace hg {

/// Neighbourhood of one query: nearest first, with kernel weights.
struct Neigh {
  Neighbour nb[HEDGER_MAX_K];
  double w[HEDGER_MAX_K];
  uint32_t n;
};

inline uint64_t rng_next(uint64_t& s) noexcept {
  s ^= s >> 12;
  s ^= s << 25;
  s ^= s >> 27;
  return s * 0x2545F4914F6CDD1Dull;
}

/// Uniform in [0, n) (Lemire's multiply-shift; n < 2^32).
inline uint32_t rng_below(uint64_t& s, uint32_t n) noexcept {
  return static_cast<uint32_t>(((rng_next(s) >> 32) * static_cast<uint64_t>(n)) >> 32);
}

inline double q_min(const hedger& h) noexcept { return (h.r_min < 0.0 ? h.r_min : 0.0) / (1.0 - h.cfg.gamma); }
inline double q_max(const hedger& h) noexcept { return (h.r_max > 0.0 ? h.r_max : 0.0) / (1.0 - h.cfg.gamma); }

template <int D>
void scale_input(const hedger& h, const double* state, double action, double* x) noexcept {
  for (int i = 0; i < D - 1; ++i) x[i] = state[i] / h.cfg.input_scale[i];
  x[D - 1] = action / h.cfg.input_scale[D - 1];
}

/// Adds every valid stored point (fresh buffer + active tree) to the set.
template <int D, class Set>
void query_store(const hedger& h, const double* x, Set& rs) noexcept {
  const double* fp = h.fresh_pts;
  for (uint32_t i = 0; i < h.n_fresh; ++i, fp += D) {
    const double d = dist2<D>(x, fp);
    if (d <= rs.worst()) rs.add(d, h.fresh_slot[i]);
  }
  const uint64_t* seq = h.seq;
  const KdTree& t = h.tree[h.active];
  const uint64_t snap = t.snapshot;
  kd_query<D>(t, x, rs, [seq, snap](uint32_t id) { return seq[id] <= snap; });
}

/// Step 1 of a prediction: up to k_max nearest points with kernel weight >= weight_epsilon.
template <int D>
void find_neighbours(const hedger& h, const double* x, Neigh& out) noexcept {
  KnnSet rs(out.nb, h.cfg.k_max, h.r2max);
  query_store<D>(h, x, rs);
  out.n = rs.size();
  for (uint32_t i = 0; i < out.n; ++i) out.w[i] = std::exp(-out.nb[i].d2 / h.h2);
}

/// Steps 2–7 of a prediction on a known neighbourhood (x scaled). Counts it.
template <int D>
void predict_from(hedger& h, const double* x, const Neigh& nb, hedger_prediction_t& p) noexcept {
  using Vec = Eigen::Matrix<double, D + 1, 1>;
  using Mat = Eigen::Matrix<double, D + 1, D + 1>;
  p.n_neighbours = nb.n;
  p.fallback = HEDGER_FALLBACK_NONE;
  if (nb.n == 0 || nb.n < h.cfg.k_min) {
    p.kind = HEDGER_KIND_UNKNOWN;
    p.value = h.cfg.default_value;
    ++h.counters.predictions_unknown;
    return;
  }
  // Rows r_i = [x_i − x, 1]: centred at the query, so the prediction is the intercept and the
  // query's row is e = [0, …, 0, 1] (leverages are invariant under this affine change).
  Vec rows[HEDGER_MAX_K];
  Mat xtwx = Mat::Zero();
  Mat xtx = Mat::Zero();
  Vec xtwq = Vec::Zero();
  double sw = 0.0, swq = 0.0;
  const bool unweighted_ivh = (h.cfg.ivh_mode == static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED));
  for (uint32_t i = 0; i < nb.n; ++i) {
    const uint32_t s = nb.nb[i].id;
    const double* xi = h.pts + static_cast<size_t>(s) * static_cast<size_t>(D);
    Vec& r = rows[i];
    for (int j = 0; j < D; ++j) r[j] = xi[j] - x[j];
    r[D] = 1.0;
    const double w = nb.w[i];
    const double q = h.val[s];
    sw += w;
    swq += w * q;
    xtwx.noalias() += (w * r) * r.transpose();
    xtwq.noalias() += (w * q) * r;
    if (unweighted_ivh) xtx.noalias() += r * r.transpose();
  }
  const double lwa = swq / sw;

  hedger_fallback_t fb = HEDGER_FALLBACK_NONE;
  double lwr = 0.0;
  {
    // Independent-variable hull: inside iff e^T V^-1 e <= max_i h_ii.
    const Mat& v = unweighted_ivh ? xtx : xtwx;
    Eigen::LDLT<Mat> ldlt;
    if (!spans_inputs<D>(rows, nb.n) || !factor_spd(ldlt, v)) {
      fb = HEDGER_FALLBACK_SINGULAR;
    } else {
      const Mat vinv = ldlt.solve(Mat::Identity());
      const double lq = vinv(D, D);
      double hmax = 0.0;
      for (uint32_t i = 0; i < nb.n; ++i) {
        double hi = rows[i].dot(vinv * rows[i]);
        if (!unweighted_ivh) hi *= nb.w[i];
        if (hi > hmax) hmax = hi;
      }
      if (!(lq <= hmax * (1.0 + kIvhTol))) fb = HEDGER_FALLBACK_HULL;
    }
  }
  if (fb == HEDGER_FALLBACK_NONE) {
    // Ridge LWR: (X^T W X + λ diag(1…1, 0)) β = X^T W q; the intercept is not shrunk.
    Mat a = xtwx;
    for (int j = 0; j < D; ++j) a(j, j) += h.cfg.ridge;
    Eigen::LDLT<Mat> ldlt;
    if (!factor_spd(ldlt, a)) {
      fb = HEDGER_FALLBACK_SINGULAR;
    } else {
      const Vec beta = ldlt.solve(xtwq);
      lwr = beta[D];
      if (!std::isfinite(lwr)) {
        fb = HEDGER_FALLBACK_SINGULAR;
      } else if (lwr < q_min(h) || lwr > q_max(h)) {
        fb = HEDGER_FALLBACK_IMPLAUSIBLE;
      }
    }
  }
  p.fallback = fb;
  switch (fb) {
    case HEDGER_FALLBACK_NONE:
      p.kind = HEDGER_KIND_LWR;
      p.value = lwr;
      ++h.counters.predictions_lwr;
      return;
    case HEDGER_FALLBACK_HULL:
      ++h.counters.fallback_hull;
      break;
    case HEDGER_FALLBACK_IMPLAUSIBLE:
      ++h.counters.fallback_implausible;
      break;
    case HEDGER_FALLBACK_SINGULAR:
      ++h.counters.fallback_singular;
      break;
  }
  p.kind = HEDGER_KIND_LWA;
  p.value = lwa;
  ++h.counters.predictions_lwa;
}

template <int D>
void predict_x(hedger& h, const double* x, Neigh& nb, hedger_prediction_t& p) noexcept {
  find_neighbours<D>(h, x, nb);
  predict_from<D>(h, x, nb, p);
}

struct GreedyResult {
  hedger_status_t status;
  double action;
  double value;
  hedger_kind_t kind;
};

/// Greedy search at a raw state (see hedger_greedy()).
template <int D>
GreedyResult greedy_at(hedger& h, const double* state) noexcept {
  double x[static_cast<size_t>(D)];
  for (int i = 0; i < D - 1; ++i) x[i] = state[i] / h.cfg.input_scale[i];
  const double sa = h.cfg.input_scale[D - 1];
  const double amin = h.cfg.action_min, amax = h.cfg.action_max;
  Neigh nb;
  GreedyResult best{HEDGER_NO_KNOWN_ACTION, 0.5 * (amin + amax), h.cfg.default_value, HEDGER_KIND_UNKNOWN};
  // Value of an evaluation for the search: unknown never beats known.
  auto eval = [&](double a) {
    x[D - 1] = a / sa;
    hedger_prediction_t p;
    predict_x<D>(h, x, nb, p);
    if (p.kind == HEDGER_KIND_UNKNOWN) return -std::numeric_limits<double>::infinity();
    if (best.status != HEDGER_OK || p.value > best.value) best = GreedyResult{HEDGER_OK, a, p.value, p.kind};
    return p.value;
  };
  ++h.counters.greedy_calls;
  const uint32_t m = h.cfg.greedy_coarse_actions;
  const double step = (amax - amin) / static_cast<double>(m - 1);
  uint32_t jbest = 0;
  double fbest = -std::numeric_limits<double>::infinity();
  bool any = false;
  for (uint32_t j = 0; j < m; ++j) {
    const double a = (j + 1 == m) ? amax : amin + step * static_cast<double>(j);
    const double f = eval(a);
    if (f > fbest) {
      fbest = f;
      jbest = j;
      any = true;
    }
  }
  if (!any) {
    ++h.counters.greedy_all_unknown;
    return best;
  }
  // Golden-section refinement inside the grid interval around the best coarse action.
  const uint32_t r = h.cfg.greedy_refine_iters;
  if (r > 0) {
    auto grid = [&](uint32_t j) { return (j + 1 == m) ? amax : amin + step * static_cast<double>(j); };
    double lo = grid(jbest == 0 ? 0 : jbest - 1);
    double hi = grid(jbest + 1 >= m ? m - 1 : jbest + 1);
    constexpr double g = 0.6180339887498949;
    double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
    double f1 = eval(x1);
    double f2 = -std::numeric_limits<double>::infinity();
    uint32_t evals = 1;
    if (evals < r) {
      f2 = eval(x2);
      ++evals;
    }
    while (evals < r) {
      if (f1 >= f2) {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - g * (hi - lo);
        f1 = eval(x1);
      } else {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + g * (hi - lo);
        f2 = eval(x2);
      }
      ++evals;
    }
  }
  return best;
}

// ---- Store maintenance ---------------------------------------------------------------------

inline void note_work(hedger& h, uint64_t w) noexcept {
  h.call_work += w;
  const uint64_t cw = h.call_work;
  if (cw > h.counters.max_rebuild_work) {
    h.counters.max_rebuild_work = cw > 0xFFFFFFFFull ? 0xFFFFFFFFu : static_cast<uint32_t>(cw);
  }
}

template <int D>
void start_build(hedger& h) noexcept {
  KdTree& t = h.tree[1 - h.active];
  kd_begin_build(t, h.pts, h.seq, h.fill, h.seq_counter);
  h.building = 1;
}

/// Swaps the finished shadow tree in and drops the fresh entries it covers.
template <int D>
uint64_t swap_trees(hedger& h) noexcept {
  h.active = 1 - h.active;
  h.building = 0;
  ++h.counters.rebuilds;
  const uint64_t snap = h.tree[h.active].snapshot;
  uint32_t n = 0;
  for (uint32_t i = 0; i < h.n_fresh; ++i) {
    const uint32_t slot = h.fresh_slot[i];
    if (h.seq[slot] <= snap) {
      h.fresh_pos[slot] = kNone;
      continue;
    }
    if (n != i) {
      h.fresh_slot[n] = slot;
      double* dst = h.fresh_pts + static_cast<size_t>(n) * static_cast<size_t>(D);
      const double* src = h.fresh_pts + static_cast<size_t>(i) * static_cast<size_t>(D);
      for (int j = 0; j < D; ++j) dst[j] = src[j];
    }
    h.fresh_pos[slot] = n++;
  }
  const uint64_t work = h.n_fresh;
  h.n_fresh = n;
  return work;
}

/// Finishes a rebuild now (outside the budget): only when the fresh buffer is full.
template <int D>
void force_rebuild(hedger& h) noexcept {
  if (!h.building) start_build<D>(h);
  uint64_t w = kd_build_step<D>(h.tree[1 - h.active], std::numeric_limits<uint64_t>::max());
  w += swap_trees<D>(h);
  h.counters.forced_rebuild_work += w;
  note_work(h, w);
}

/// Records slot (just written) in the fresh buffer: in place if it is there already.
template <int D>
void add_fresh(hedger& h, uint32_t slot) noexcept {
  uint32_t pos = h.fresh_pos[slot];
  if (pos == kNone) {
    // Two forced rebuilds at most: the first covers everything stored before it started.
    for (int tries = 0; tries < 2 && h.n_fresh >= h.fresh_cap; ++tries) force_rebuild<D>(h);
    pos = h.n_fresh++;
    h.fresh_slot[pos] = slot;
    h.fresh_pos[slot] = pos;
  }
  const double* p = h.pts + static_cast<size_t>(slot) * static_cast<size_t>(D);
  double* f = h.fresh_pts + static_cast<size_t>(pos) * static_cast<size_t>(D);
  for (int j = 0; j < D; ++j) f[j] = p[j];
}

/// Per-update rebuild work: start a rebuild when enough fresh points wait, then advance it by
/// at most rebuild_budget units (+ the O(fresh) swap).
template <int D>
void maintain(hedger& h) noexcept {
  if (!h.building && h.n_fresh >= h.fresh_start) start_build<D>(h);
  if (h.building) {
    KdTree& t = h.tree[1 - h.active];
    uint64_t w = kd_build_step<D>(t, h.rebuild_budget);
    if (kd_done(t)) w += swap_trees<D>(h);
    note_work(h, w);
  }
}

template <int D>
void write_slot(hedger& h, uint32_t slot, const double* x, double q, uint8_t fl) noexcept {
  double* p = h.pts + static_cast<size_t>(slot) * static_cast<size_t>(D);
  for (int j = 0; j < D; ++j) p[j] = x[j];
  h.val[slot] = q;
  h.seq[slot] = ++h.seq_counter;
  h.flags[slot] = fl;
  if (fl & HEDGER_POINT_PROTECTED) ++h.n_protected;
  add_fresh<D>(h, slot);
}

/// Folds a new experience into stored point j (at squared distance d2 from the new point).
/// Update (td): j stands for the new point as in state aggregation, so it gets the Q-learning
/// step itself, q_j += α (target − q_j); this keeps the whole update even when j is not very
/// close (a full small store merges most new points). Insert: q_j += κ (q − q_j) with the kernel
/// weight κ between them. Flags are OR-ed, so a reward-bearing transition protects the point it
/// is merged into.
inline void merge_into(hedger& h, uint32_t j, double d2, double q, bool td, double target, uint8_t fl) noexcept {
  if (td) {
    h.val[j] += h.cfg.alpha * (target - h.val[j]);
  } else {
    h.val[j] += std::exp(-d2 / h.h2) * (q - h.val[j]);
  }
  if ((fl & HEDGER_POINT_PROTECTED) && !(h.flags[j] & HEDGER_POINT_PROTECTED)) ++h.n_protected;
  h.flags[j] = static_cast<uint8_t>(h.flags[j] | fl);
  ++h.counters.merges;
}

/// Where a new point goes (store_point() arguments): value, flags, nearest stored point and the
/// new point's redundancy; for an update also the Q-learning target (merge rule).
struct NewPoint {
  double q;
  uint8_t flags;
  bool td;
  double target;
  bool have_near;
  uint32_t near_slot;
  double near_d2;
  double red_d2;  ///< squared distance to its k_min-th nearest stored point (+inf if fewer)
};

/// Redundancy of stored point c: squared distance to its k-th nearest other stored point
/// (k = k_min; +inf if it has fewer than k others). Small = many points close by.
template <int D>
double redundancy_d2(const hedger& h, uint32_t c) noexcept {
  Neighbour buf[HEDGER_MAX_K + 1];
  const uint32_t k = h.cfg.k_min;
  KnnSet rs(buf, k + 1, std::numeric_limits<double>::infinity());
  query_store<D>(h, h.pts + static_cast<size_t>(c) * static_cast<size_t>(D), rs);
  uint32_t others = 0;
  for (uint32_t i = 0; i < rs.size(); ++i) {
    if (buf[i].id == c) continue;
    if (++others == k) return buf[i].d2;
  }
  return std::numeric_limits<double>::infinity();
}

/// Stores x with value q (hedger.md step 4). The rule:
///  1. merge: if the nearest stored point is within merge_radius, fold q into it (merge_into);
///  2. insert into the next free slot while the store is not full;
///  3. full: draw 4·C slots from the seeded generator, keep the first C distinct unprotected ones
///     (protected ones only if none is unprotected); the most redundant candidate is the one
///     with the smallest distance to its k_min-th nearest other point (ties: lower slot). If the
///     new point's own k_min-th neighbour is closer than that, the new point is the most
///     redundant: merge it into its nearest; otherwise evict the candidate and store the new
///     point in its slot.
/// Dense regions are thinned first while every region keeps about k_min points, so it stays
/// known (measured: with the nearest-neighbour distance instead, a region holding 90 % of the
/// stream was thinned to a single point, i.e. unknown). Reward-bearing / terminal points are
/// evicted only when every candidate drawn is protected.
template <int D>
hedger_store_op_t store_point(hedger& h, const double* x, const NewPoint& np, uint32_t* merged) noexcept {
  *merged = kNone;
  if (np.have_near && np.near_d2 <= h.merge_r2) {
    merge_into(h, np.near_slot, np.near_d2, np.q, np.td, np.target, np.flags);
    *merged = np.near_slot;
    return HEDGER_STORE_MERGED;
  }
  if (h.fill < h.cap) {
    const uint32_t slot = h.fill++;
    write_slot<D>(h, slot, x, np.q, np.flags);
    ++h.counters.inserts;
    return HEDGER_STORE_INSERTED;
  }
  const uint32_t c_max = h.cfg.evict_candidates;
  uint32_t cand[HEDGER_MAX_EVICT_CANDIDATES];
  uint32_t prot[HEDGER_MAX_EVICT_CANDIDATES];
  uint32_t nc = 0, npr = 0;
  for (uint32_t draw = 0; draw < 4 * c_max; ++draw) {
    const uint32_t s = rng_below(h.rng, h.fill);
    const bool is_prot = (h.flags[s] & HEDGER_POINT_PROTECTED) != 0;
    uint32_t* list = is_prot ? prot : cand;
    uint32_t& n = is_prot ? npr : nc;
    bool dup = false;
    for (uint32_t i = 0; i < n; ++i) dup = dup || (list[i] == s);
    if (!dup && n < c_max) list[n++] = s;
  }
  const uint32_t* pool = (nc > 0) ? cand : prot;
  const uint32_t npool = (nc > 0) ? nc : npr;
  uint32_t victim = pool[0];
  double vd2 = redundancy_d2<D>(h, victim);
  for (uint32_t i = 1; i < npool; ++i) {
    const double d2 = redundancy_d2<D>(h, pool[i]);
    if (d2 < vd2 || (!(vd2 < d2) && pool[i] < victim)) {
      vd2 = d2;
      victim = pool[i];
    }
  }
  if (np.have_near && np.red_d2 < vd2) {
    merge_into(h, np.near_slot, np.near_d2, np.q, np.td, np.target, np.flags);
    *merged = np.near_slot;
    return HEDGER_STORE_MERGED;
  }
  if (h.flags[victim] & HEDGER_POINT_PROTECTED) {
    --h.n_protected;
    ++h.counters.protected_evictions;
  }
  ++h.counters.evictions;
  write_slot<D>(h, victim, x, np.q, np.flags);
  return HEDGER_STORE_REPLACED;
}

inline void track_reward(hedger& h, double r) noexcept {
  if (!h.reward_seen) {
    h.r_min = r;
    h.r_max = r;
    h.reward_seen = 1;
  } else {
    if (r < h.r_min) h.r_min = r;
    if (r > h.r_max) h.r_max = r;
  }
  h.counters.reward_min = h.r_min < 0.0 ? h.r_min : 0.0;
  h.counters.reward_max = h.r_max > 0.0 ? h.r_max : 0.0;
}

inline void record_run(hedger& h, const double* s, double a, double r, const double* sn, int terminal) noexcept {
  if (h.run_cap == 0) return;
  const uint32_t sd = h.cfg.state_dim;
  double* rec = h.run + static_cast<size_t>(h.run_head) * h.run_stride;
  for (uint32_t i = 0; i < sd; ++i) rec[i] = s[i];
  rec[sd] = a;
  rec[sd + 1] = r;
  for (uint32_t i = 0; i < sd; ++i) rec[sd + 2 + i] = terminal ? 0.0 : sn[i];
  rec[2 * sd + 2] = terminal ? 1.0 : 0.0;
  h.run_head = (h.run_head + 1 == h.run_cap) ? 0 : h.run_head + 1;
  if (h.run_count < h.run_cap) {
    ++h.run_count;
  } else {
    ++h.counters.run_overflows;
  }
}

/// The training update (hedger.md steps 1–6). Inputs are validated by the caller.
template <int D>
void update(hedger& h, const double* s, double a, double r, const double* sn, int terminal,
            hedger_update_info_t& info) noexcept {
  h.call_work = 0;
  // 1. q' from the greedy search at s' (done once; returned for reuse as the next action).
  if (terminal) {
    info.next_status = HEDGER_NO_KNOWN_ACTION;
    info.next_action = 0.5 * (h.cfg.action_min + h.cfg.action_max);
    info.next_value = h.cfg.default_value;
    info.next_kind = HEDGER_KIND_UNKNOWN;
    info.q_next = 0.0;
  } else {
    const GreedyResult g = greedy_at<D>(h, sn);
    info.next_status = g.status;
    info.next_action = g.action;
    info.next_value = g.value;
    info.next_kind = g.kind;
    info.q_next = g.value;
  }
  // 2. q = Q(s, a) with its neighbourhood.
  double x[static_cast<size_t>(D)];
  scale_input<D>(h, s, a, x);
  Neigh nb;
  hedger_prediction_t p;
  predict_x<D>(h, x, nb, p);
  info.q_old = p.value;
  info.kind = p.kind;
  // 3. Q-learning target and new value.
  info.target = r + h.cfg.gamma * info.q_next;
  const double q_new = p.value + h.cfg.alpha * (info.target - p.value);
  info.q_new = q_new;
  // 4. Store (s, a). Remember the neighbours' sequence numbers: a neighbour evicted by the
  //    store step is not pulled (its slot now holds the new point).
  uint64_t nseq[HEDGER_MAX_K];
  for (uint32_t i = 0; i < nb.n; ++i) nseq[i] = h.seq[nb.nb[i].id];
  const uint8_t fl = (terminal || !(r >= 0.0 && r <= 0.0)) ? HEDGER_POINT_PROTECTED : 0;
  const uint32_t km = h.cfg.k_min;
  const bool have = nb.n > 0;
  const NewPoint np{q_new, fl, true, info.target, have, have ? nb.nb[0].id : 0, have ? nb.nb[0].d2 : 0.0,
                    nb.n >= km ? nb.nb[km - 1].d2 : std::numeric_limits<double>::infinity()};
  uint32_t merged;
  info.store_op = store_point<D>(h, x, np, &merged);
  // 5. Pull each neighbour toward q_new by α κ_i (a merged point had its update already).
  uint32_t pulled = 0;
  for (uint32_t i = 0; i < nb.n; ++i) {
    const uint32_t sl = nb.nb[i].id;
    if (h.seq[sl] != nseq[i] || sl == merged) continue;
    h.val[sl] += h.cfg.alpha * nb.w[i] * (q_new - h.val[sl]);
    ++pulled;
  }
  info.n_pulled = pulled;
  // 6. Rewards seen bound plausible values from now on.
  track_reward(h, r);
  ++h.counters.updates;
  if (h.replaying) {
    ++h.counters.replayed_updates;
  } else {
    record_run(h, s, a, r, sn, terminal);
  }
  maintain<D>(h);
}

/// hedger_insert(): store with value q, no pull.
template <int D>
hedger_store_op_t insert(hedger& h, const double* s, double a, double q, uint8_t fl) noexcept {
  h.call_work = 0;
  double x[static_cast<size_t>(D)];
  scale_input<D>(h, s, a, x);
  Neighbour buf[HEDGER_MAX_K];
  const uint32_t km = h.cfg.k_min;
  KnnSet rs(buf, km, std::numeric_limits<double>::infinity());
  query_store<D>(h, x, rs);
  const bool have = rs.size() > 0;
  const NewPoint np{q, fl, false, 0.0, have, have ? buf[0].id : 0, have ? buf[0].d2 : 0.0,
                    rs.size() >= km ? buf[km - 1].d2 : std::numeric_limits<double>::infinity()};
  uint32_t merged;
  const hedger_store_op_t op = store_point<D>(h, x, np, &merged);
  maintain<D>(h);
  return op;
}

/// Replays the run buffer newest first (hedger_end_run()).
template <int D>
uint32_t replay_run(hedger& h) noexcept {
  const uint32_t sd = h.cfg.state_dim;
  uint32_t done = 0;
  h.replaying = 1;
  uint32_t idx = h.run_head;
  for (uint32_t k = 0; k < h.run_count; ++k) {
    idx = (idx == 0) ? h.run_cap - 1 : idx - 1;
    const double* rec = h.run + static_cast<size_t>(idx) * h.run_stride;
    const int terminal = rec[2 * sd + 2] > 0.5 ? 1 : 0;
    hedger_update_info_t info;
    update<D>(h, rec, rec[sd], rec[sd + 1], rec + sd + 2, terminal, info);
    ++done;
  }
  h.replaying = 0;
  return done;
}

/// Full synchronous rebuild of the active tree over the whole store (init / load).
template <int D>
void rebuild_now(hedger& h) noexcept {
  h.active = 0;
  h.building = 0;
  kd_build_all<D>(h.tree[0], h.pts, h.seq, h.fill, h.seq_counter);
  kd_bind(h.tree[1], h.tree[1].pts, h.tree[1].ids, h.tree[1].nodes, h.tree[1].cap);
  for (uint32_t i = 0; i < h.n_fresh; ++i) h.fresh_pos[h.fresh_slot[i]] = kNone;
  h.n_fresh = 0;
}

}  // namespace hg

#endif  // HEDGER_CORE_HPP
