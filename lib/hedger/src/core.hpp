// SPDX-License-Identifier: MIT
// HEDGER core: the instance layout and the algorithms, templated on the input dimension D.
//
// Internal header of lib/hedger (hedger.cpp, white-box tests and the benchmark include it).
//
// Data (all inside the caller's storage block, see make_layout()):
//   store   pts[cap × D] scaled coordinates, val[cap] values, seq[cap] sequence numbers,
//           flags[cap], run_tag[cap] and anchor_w[cap] (hedger_weight_run); slots 0..fill-1
//           are occupied (eviction replaces in place).
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

#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

#include "hedger/hedger.h"
#include "kdtree.hpp"
#include "linalg.hpp"

namespace hg {

constexpr uint32_t kMagic = 0x48444752u;  // "HDGR": a live instance
/// Entries of the fresh buffer per block with a bounding box (query_store() skips a block whose
/// box lies beyond the search's bound). Entries arrive in time order, so a block holds a piece
/// of a trajectory and its box is tight.
constexpr uint32_t kFreshBlock = 32;
/// Entries the k_max-nearest searches gather before selecting (KnnCollect): twice the largest k.
constexpr uint32_t kCollectCap = 2u * HEDGER_MAX_K;
/// Relative tolerance of the IVH comparison, so that a query exactly at the point of largest
/// leverage is inside despite rounding.
constexpr double kIvhTol = 1e-9;

/// The normal equations' sums over n rows r_i, a column at a time, each column summed over the
/// rows in register accumulators: the lower triangle (diagonal included) of m0 = Σ_i z0_i r_iᵀ,
/// with kSecond that of m1 = Σ_i r_i r_iᵀ, with kFull the whole of mf = Σ_i zf_i r_iᵀ. Entry
/// (j, c) is Σ_i z_i[j] r_i[c] added in the order of i: the bits of rank-1 updates of the whole
/// matrices. m0's and m1's strict upper triangles are left as they were. Why only the lower:
/// those matrices are read only through the LDLᵀ factorisation, which reads no other part
/// (FixedLdlt, SymFactor), so their upper halves were work for nothing; the sums share each
/// column's load of r_i[c] (docs/development.md gives the measured gain). O(n P²), no allocation.
template <int P, bool kSecond, bool kFull, int C = 0>
void column_sums(const Eigen::Matrix<double, P, 1>* r, uint32_t n, const Eigen::Matrix<double, P, 1>* z0,
                 Eigen::Matrix<double, P, P>& m0, Eigen::Matrix<double, P, P>& m1,
                 const Eigen::Matrix<double, P, 1>* zf, Eigen::Matrix<double, P, P>& mf) noexcept {
  constexpr int L = P - C;
  using Tail = Eigen::Matrix<double, L, 1>;
  Tail a0 = Tail::Zero(), a1 = Tail::Zero();
  Eigen::Matrix<double, P, 1> af = Eigen::Matrix<double, P, 1>::Zero();
  for (uint32_t i = 0; i < n; ++i) {
    const double rc = r[i][C];
    a0.noalias() += z0[i].template tail<L>() * rc;
    if constexpr (kSecond) a1.noalias() += r[i].template tail<L>() * rc;
    if constexpr (kFull) af.noalias() += zf[i] * rc;
  }
  m0.col(C).template tail<L>() = a0;
  if constexpr (kSecond) m1.col(C).template tail<L>() = a1;
  if constexpr (kFull) mf.col(C) = af;
  if constexpr (C + 1 < P) column_sums<P, kSecond, kFull, C + 1>(r, n, z0, m0, m1, zf, mf);
}

/// Copies m's strict lower triangle onto its upper one (a column_sums() result as a whole
/// symmetric matrix, for any reader of the full matrix). O(P²).
template <int P>
void mirror_lower(Eigen::Matrix<double, P, P>& m) noexcept {
  for (int c = 1; c < P; ++c) {
    for (int j = 0; j < c; ++j) m(j, c) = m(c, j);
  }
}

/// The IVH's leverage of row r (a neighbour's, centred at the query) under the inverse vinv of
/// the IVH matrix: h = r·V⁻¹r, times the neighbour's kernel weight w with the weighted IVH
/// (HEDGER_IVH_WEIGHTED). The query lies inside the hull when its own leverage is at most the
/// largest of the neighbours' (fit_geometry, model_value). O(P²).
template <int P>
double ivh_leverage(const Eigen::Matrix<double, P, P>& vinv, const Eigen::Matrix<double, P, 1>& r, double w,
                    bool unweighted) noexcept {
  double hi = r.dot(vinv * r);
  if (!unweighted) hi *= w;
  return hi;
}

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
    FactorOf<D> ldlt;
    if (ldlt.compute(scatter)) {
      double det = 1.0;
      double dmin = ldlt.pivot(0);
      for (int i = 0; i < D; ++i) {
        const double piv = ldlt.pivot(i);
        det *= piv > 0.0 ? piv : 0.0;
        dmin = piv < dmin ? piv : dmin;
      }
      double bound = kScatterRatioMin * tr + delta;
      for (int i = 1; i < D; ++i) bound *= tr + delta;
      if (det * (1.0 - 4.0 * D * eps) > bound) return true;
      if (dmin + delta <= kScatterRatioMin * tr / D) return false;
    }
  }
  double ev_min = 0.0, ev_max = 0.0;
  if (!sym_eigen_extremes(scatter, &ev_min, &ev_max)) return false;
  return ev_min > kScatterRatioMin * ev_max;
}

/// Offsets of every array in the storage block (bytes from its start).
struct Layout {
  size_t total;
  size_t pts, val, seq, flags, run_tag, anchor_w, fresh_pos, fresh_slot, fresh_pts, fresh_box, run, replay_cache;
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
  uint32_t replay_pending;  ///< a finished run's replay is under way (replay_step)
  uint64_t generation;      ///< counts calls that may change the learned state (sliced saves check it)
  /// Changes whenever a stored point's coordinates, anchor weight or recency may have changed, and
  /// at every replay's start: a replay record's cached geometry is valid while equal to its own.
  uint64_t geom_gen;
  hedger_config_t cfg;
  // Derived constants.
  double h2;        ///< bandwidth²
  double r2max;     ///< squared radius where the kernel weight drops below weight_epsilon
  double merge_r2;  ///< merge_radius²
  uint64_t rebuild_budget;
  uint32_t fresh_start;  ///< fresh entries that start a rebuild (fresh_trigger())
  // Store.
  uint32_t cap;
  uint32_t fill;
  uint32_t n_protected;
  double* pts;
  double* val;
  uint64_t* seq;
  uint8_t* flags;
  uint32_t* run_tag;  ///< run tag current when the slot was written
  float* anchor_w;    ///< weight in the neighbours' policy (the anchor), 1 when written
  uint64_t seq_counter;
  uint32_t cur_tag;   ///< tag of the points stored from now on (hedger_set_run_tag)
  uint32_t pad_tag;
  // Fresh buffer.
  uint32_t* fresh_pos;   ///< [cap] entry of each slot, or kNone
  uint32_t* fresh_slot;  ///< [fresh_cap]
  double* fresh_pts;     ///< [fresh_cap × D]
  double* fresh_box;     ///< [blocks of kFreshBlock entries × 2 D]: each block's bounding box (lo, hi)
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
  uint32_t replay_pass;        ///< pass of the pending replay
  uint32_t replay_k;           ///< records of this pass done (from the newest)
  double replay_next_return;   ///< λ-return target of the record after the current one
  void* replay_cache;          ///< [run_cap] ReplayRecord<D> (cfg.replay_cache), or null
  // Seeds of the next k-NN searches (query_store): the neighbours of the last prediction and of
  // the last state model's query. Any stored slots will do; these are close to the next query.
  uint32_t seed_fit[HEDGER_MAX_K];
  uint32_t seed_state[HEDGER_MAX_K];
  uint32_t n_seed_fit;
  uint32_t n_seed_state;
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

/// Adds every valid stored point (fresh buffer + active tree) to the set, by the distance over
/// the first DQ coordinates (DQ = D: (state, action); DQ = D - 1: the state alone).
template <int D, int DQ = D, class Set>
void query_store(const hedger& h, const double* x, Set& rs) noexcept {
  // The fresh buffer block by block. A block is skipped when the distance to its box exceeds the
  // bound: every entry's distance is at least that (each term is rounded monotonically and the
  // terms are summed in the same order as dist2), so no entry of it could be added. The margin of
  // 1e-9 keeps that true where the compiler fuses one sum's multiply-adds and not the other's.
  for (uint32_t b0 = 0; b0 < h.n_fresh; b0 += kFreshBlock) {
    const double* box = h.fresh_box + static_cast<size_t>(b0 / kFreshBlock) * 2u * static_cast<size_t>(D);
    double lb = 0.0;
    for (int j = 0; j < DQ; ++j) {
      double g = 0.0;
      if (x[j] < box[j]) g = box[j] - x[j];
      if (x[j] > box[D + j]) g = x[j] - box[D + j];
      lb += g * g;
    }
    if (lb > rs.worst() * (1.0 + 1e-9)) continue;
    const uint32_t end = b0 + kFreshBlock < h.n_fresh ? b0 + kFreshBlock : h.n_fresh;
    const double* fp = h.fresh_pts + static_cast<size_t>(b0) * static_cast<size_t>(D);
    for (uint32_t i = b0; i < end; ++i, fp += D) {
      const double d = dist2<DQ>(x, fp);
      if (d <= rs.worst()) rs.add(d, h.fresh_slot[i]);
    }
  }
  const uint64_t* seq = h.seq;
  const KdTree& t = h.tree[h.active];
  const uint64_t snap = t.snapshot;
  kd_query<D, DQ>(t, x, rs, [seq, snap](uint32_t id) { return seq[id] <= snap; });
}

/// The radius of a search for the k nearest points within r2max (squared, DQ coordinates),
/// tightened by seeds: store slots near the query, typically the neighbours of a nearby earlier
/// query. When k of them lie within r2max, the k nearest of all lie within the farthest of those
/// k, and a search bounded by it visits far fewer nodes and finds the same points. O(n_seeds D).
template <int D, int DQ>
double seeded_r2(const hedger& h, const double* x, double r2max, uint32_t k, const uint32_t* seeds,
                 uint32_t n_seeds) noexcept {
  if (n_seeds < k) return r2max;
  uint32_t inside = 0;
  double far = 0.0;
  for (uint32_t i = 0; i < n_seeds; ++i) {
    const uint32_t s = seeds[i];
    if (s >= h.fill) continue;
    const double d = dist2<DQ>(x, h.pts + static_cast<size_t>(s) * static_cast<size_t>(D));
    if (d > r2max) continue;
    ++inside;
    far = d > far ? d : far;
  }
  // Seed lists hold at most k slots, so with k inside, `far` is the k-th of them.
  return inside >= k && n_seeds == k ? far : r2max;
}

/// Step 1 of a prediction: up to k_max nearest points with kernel weight >= weight_epsilon.
/// The search is bounded by the previous prediction's neighbours (seeded_r2(), hedger::seed_fit),
/// which it replaces.
template <int D>
void find_neighbours(hedger& h, const double* x, Neigh& out) noexcept {
  const uint32_t k = h.cfg.k_max;
  KnnCollect<kCollectCap> rs(k, seeded_r2<D, D>(h, x, h.r2max, k, h.seed_fit, h.n_seed_fit));
  query_store<D>(h, x, rs);
  out.n = rs.finish(out.nb);
  for (uint32_t i = 0; i < out.n; ++i) {
    out.w[i] = std::exp(-out.nb[i].d2 / h.h2);
    h.seed_fit[i] = out.nb[i].id;
  }
  h.n_seed_fit = out.n;
}

/// The parts of a prediction's local model (hedger.md steps 4 and 5) that depend only on the
/// neighbours' coordinates and kernel weights: the rank and hull tests, the factorisation of the
/// ridge normal equations and the weights of the standard error. A prediction is fit_geometry()
/// then fit_value(); the backward replay keeps one per replayed record and, while no stored
/// point has moved (hedger::geom_gen), repeats only fit_value() (ReplayRecord).
template <int D>
struct FitGeom {
  using Vec = Eigen::Matrix<double, D + 1, 1>;
  enum Status : uint8_t { kUnknown, kAverage, kHull, kSingular, kRegression };
  Status status;
  double sw;       ///< Σ w_i
  double var_sum;  ///< Σ (w_i r_i·c)², kRegression
  Vec c;           ///< A⁻¹ e (the intercept's row of A⁻¹), kRegression
  FactorOf<D + 1> ldlt;  ///< A = XᵀWX + λ diag(1…1, 0), kRegression
};

/// Row r_i = [x_i − x, 1] of neighbour slot s: centred at the query, so the prediction is the
/// intercept and the query's row is e = [0, …, 0, 1] (leverages are invariant under this affine
/// change).
template <int D>
void fit_row(const hedger& h, const double* x, uint32_t s, Eigen::Matrix<double, D + 1, 1>& r) noexcept {
  const double* xi = h.pts + static_cast<size_t>(s) * static_cast<size_t>(D);
  for (int j = 0; j < D; ++j) r[j] = xi[j] - x[j];
  r[D] = 1.0;
}

/// The geometry stage of a prediction at x (scaled) from n neighbours (slots ids, kernel weights
/// w). O(n D² + D³), no allocation.
template <int D>
void fit_geometry(const hedger& h, const double* x, const uint32_t* ids, const double* w, uint32_t n,
                  FitGeom<D>& g) noexcept {
  using Vec = Eigen::Matrix<double, D + 1, 1>;
  using Mat = Eigen::Matrix<double, D + 1, D + 1>;
  if (n == 0 || n < h.cfg.k_min) {
    g.status = FitGeom<D>::kUnknown;
    return;
  }
  double sw = 0.0;
  for (uint32_t i = 0; i < n; ++i) sw += w[i];
  g.sw = sw;
  if (h.cfg.local_model == static_cast<uint32_t>(HEDGER_LOCAL_LWA)) {
    g.status = FitGeom<D>::kAverage;
    return;
  }
  Vec rows[HEDGER_MAX_K];
  Vec zw[HEDGER_MAX_K];
  for (uint32_t i = 0; i < n; ++i) {
    fit_row<D>(h, x, ids[i], rows[i]);
    zw[i] = w[i] * rows[i];
  }
  // XᵀWX and XᵀX are factorised only: their lower triangles are summed (column_sums) and
  // mirrored, so that each is a whole symmetric matrix.
  Mat xtwx, xtx, unused;
  const bool unweighted_ivh = (h.cfg.ivh_mode == static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED));
  if (unweighted_ivh) {
    column_sums<D + 1, true, false>(rows, n, zw, xtwx, xtx, nullptr, unused);
    mirror_lower<D + 1>(xtx);
  } else {
    column_sums<D + 1, false, false>(rows, n, zw, xtwx, xtx, nullptr, unused);
  }
  mirror_lower<D + 1>(xtwx);
  {
    // Independent-variable hull: inside iff e^T V^-1 e <= max_i h_ii.
    const Mat& v = unweighted_ivh ? xtx : xtwx;
    FactorOf<D + 1> ldlt;
    if (!spans_inputs<D>(rows, n) || !factor_spd<D + 1>(ldlt, v)) {
      g.status = FitGeom<D>::kSingular;
      return;
    }
    // Inside iff lq <= max(0, h_ii) (1 + tol): iff lq <= 0 or some leverage admits the query
    // (the same test as against the largest: rounding is monotone), so the first that does
    // settles it; the largest leverages are at the neighbourhood's edge, so the farthest
    // neighbours go first.
    const Mat vinv = ldlt.inverse();
    const double lq = vinv(D, D);
    bool inside = lq <= 0.0;
    for (uint32_t i = n; i-- > 0 && !inside;) {
      inside = lq <= ivh_leverage<D + 1>(vinv, rows[i], w[i], unweighted_ivh) * (1.0 + kIvhTol);
    }
    if (!inside) {
      g.status = FitGeom<D>::kHull;
      return;
    }
  }
  // Ridge LWR: (X^T W X + λ diag(1…1, 0)) β = X^T W q; the intercept is not shrunk.
  Mat a = xtwx;
  for (int j = 0; j < D; ++j) a(j, j) += h.cfg.ridge;
  if (!factor_spd<D + 1>(g.ldlt, a)) {
    g.status = FitGeom<D>::kSingular;
    return;
  }
  Vec e = Vec::Zero();
  e[D] = 1.0;
  g.c = g.ldlt.solve(e);
  double var_sum = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    const double rc = w[i] * rows[i].dot(g.c);
    var_sum += rc * rc;
  }
  g.var_sum = var_sum;
  g.status = FitGeom<D>::kRegression;
}

/// The value stage of a prediction (hedger.md steps 2–7 on the geometry g of the same x, ids, w):
/// the regression's value, or the average where the geometry or the value rule it out. Counts
/// the prediction. O(n D + D²), no allocation.
template <int D>
void fit_value(hedger& h, const double* x, const uint32_t* ids, const double* w, uint32_t n, const FitGeom<D>& g,
               hedger_prediction_t& p) noexcept {
  using Vec = Eigen::Matrix<double, D + 1, 1>;
  p.n_neighbours = n;
  p.fallback = HEDGER_FALLBACK_NONE;
  p.std_error = 0.0;
  if (g.status == FitGeom<D>::kUnknown) {
    p.kind = HEDGER_KIND_UNKNOWN;
    p.value = h.cfg.default_value;
    ++h.counters.predictions_unknown;
    return;
  }
  Vec rows[HEDGER_MAX_K];
  Vec xtwq = Vec::Zero();
  double swq = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    Vec& r = rows[i];
    fit_row<D>(h, x, ids[i], r);
    const double q = h.val[ids[i]];
    swq += w[i] * q;
    xtwq.noalias() += (w[i] * q) * r;
  }
  const double lwa = swq / g.sw;
  if (g.status == FitGeom<D>::kAverage) {
    p.kind = HEDGER_KIND_LWA;
    p.value = lwa;
    ++h.counters.predictions_lwa;
    return;
  }
  hedger_fallback_t fb = g.status == FitGeom<D>::kHull       ? HEDGER_FALLBACK_HULL
                         : g.status == FitGeom<D>::kSingular ? HEDGER_FALLBACK_SINGULAR
                                                             : HEDGER_FALLBACK_NONE;
  double lwr = 0.0;
  if (fb == HEDGER_FALLBACK_NONE) {
    const Vec beta = g.ldlt.solve(xtwq);
    lwr = beta[D];
    if (!std::isfinite(lwr)) {
      fb = HEDGER_FALLBACK_SINGULAR;
    } else if (lwr < q_min(h) || lwr > q_max(h)) {
      fb = HEDGER_FALLBACK_IMPLAUSIBLE;
    } else {
      // Standard error of the intercept: Var = s^2 c^T (X^T W^2 X) c with c = A^-1 e, and s^2
      // the weighted residual variance with n - (D + 1) degrees of freedom (the fit is
      // unbiased only in expectation; this ranks candidate actions, it is no exact interval).
      double rss = 0.0;
      for (uint32_t i = 0; i < n; ++i) {
        const double res = h.val[ids[i]] - rows[i].dot(beta);
        rss += w[i] * res * res;
      }
      const double dof = static_cast<double>(n) - static_cast<double>(D + 1);
      const double s2 = dof > 0.0 ? (rss / g.sw) * static_cast<double>(n) / dof : 0.0;
      p.std_error = std::sqrt(s2 * g.var_sum);
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
  p.std_error = 0.0;
  ++h.counters.predictions_lwa;
}

/// A neighbourhood's slots, contiguous (the form fit_geometry() and fit_value() take).
inline void neigh_ids(const Neigh& nb, uint32_t* ids) noexcept {
  for (uint32_t i = 0; i < nb.n; ++i) ids[i] = nb.nb[i].id;
}

template <int D>
void predict_x(hedger& h, const double* x, Neigh& nb, hedger_prediction_t& p) noexcept {
  find_neighbours<D>(h, x, nb);
  uint32_t ids[HEDGER_MAX_K] = {};  // (GCC cannot see that nb.n <= HEDGER_MAX_K)
  neigh_ids(nb, ids);
  FitGeom<D> g;
  fit_geometry<D>(h, x, ids, nb.w, nb.n, g);
  fit_value<D>(h, x, ids, nb.w, nb.n, g, p);
}

struct GreedyResult {
  hedger_status_t status;
  double action;
  double value;
  hedger_kind_t kind;
};

/// The state model's judgement of one given action against the greedy action (hedger_judge()).
struct Judgement {
  double action;  ///< the action asked (raw)
  int judged;     ///< 1: a state model judged the action; 0: none answered (lo = hi = kept = action, no gap)
  double lo, hi;  ///< actions the data hold at the state (raw): the anchor ± the residuals' range
  double kept;    ///< the action asked, clamped into [lo, hi]
  double gap;     ///< q(greedy action) − q(kept) by the state model
  double gap_se;  ///< its standard error
};

/// Rank of an evaluation in the greedy search: (support, score), compared lexicographically.
/// Support: 2 = a local regression (LWR), 1 = an average (LWA), 0 = unknown; an unknown value
/// never beats a known one, and an average never beats a regression: an average's value belongs
/// to the states around the query (its neighbourhood spans the whole kernel), not to the action
/// asked, so it must not compete with a regression on value. Score: value − κ · standard error
/// (κ = cfg.greedy_pessimism), so a value the data barely support does not win on noise.
struct GreedyRank {
  int support;
  double score;
  bool beats(const GreedyRank& o) const noexcept { return support > o.support || (support == o.support && score > o.score); }
};

/// The action search of both greedy methods: a coarse scan of greedy_coarse_actions evenly spaced
/// actions (both ends included), then golden-section refinement of the rank inside the grid
/// interval around the best coarse action (greedy_refine_iters evaluations). `eval(a, &value,
/// &kind)` returns the rank of action a. Ties keep the earlier evaluation (the smaller coarse
/// action). Returns HEDGER_NO_KNOWN_ACTION when every evaluation has support 0.
template <class Eval>
GreedyResult greedy_search(const hedger& h, Eval&& eval) noexcept {
  const double amin = h.cfg.action_min, amax = h.cfg.action_max;
  GreedyResult best{HEDGER_NO_KNOWN_ACTION, 0.5 * (amin + amax), h.cfg.default_value, HEDGER_KIND_UNKNOWN};
  GreedyRank best_rank{0, -std::numeric_limits<double>::infinity()};
  auto try_action = [&](double a) {
    double v = 0.0;
    hedger_kind_t k = HEDGER_KIND_UNKNOWN;
    const GreedyRank r = eval(a, &v, &k);
    if (r.support > 0 && (best.status != HEDGER_OK || r.beats(best_rank))) {
      best = GreedyResult{HEDGER_OK, a, v, k};
      best_rank = r;
    }
    return r;
  };
  const uint32_t m = h.cfg.greedy_coarse_actions;
  const double step = (amax - amin) / static_cast<double>(m - 1);
  auto grid = [&](uint32_t j) { return (j + 1 == m) ? amax : amin + step * static_cast<double>(j); };
  uint32_t jbest = 0;
  GreedyRank rbest{0, -std::numeric_limits<double>::infinity()};
  for (uint32_t j = 0; j < m; ++j) {
    const GreedyRank r = try_action(grid(j));
    if (r.support > 0 && (rbest.support == 0 || r.beats(rbest))) {
      rbest = r;
      jbest = j;
    }
  }
  if (rbest.support == 0) return best;
  // Golden-section refinement inside the grid interval around the best coarse action.
  const uint32_t iters = h.cfg.greedy_refine_iters;
  if (iters > 0) {
    double lo = grid(jbest == 0 ? 0 : jbest - 1);
    double hi = grid(jbest + 1 >= m ? m - 1 : jbest + 1);
    constexpr double g = 0.6180339887498949;
    double x1 = hi - g * (hi - lo), x2 = lo + g * (hi - lo);
    GreedyRank f1 = try_action(x1);
    GreedyRank f2{0, -std::numeric_limits<double>::infinity()};
    uint32_t evals = 1;
    if (evals < iters) {
      f2 = try_action(x2);
      ++evals;
    }
    while (evals < iters) {
      if (!f2.beats(f1)) {
        hi = x2;
        x2 = x1;
        f2 = f1;
        x1 = hi - g * (hi - lo);
        f1 = try_action(x1);
      } else {
        lo = x1;
        x1 = x2;
        f1 = f2;
        x2 = lo + g * (hi - lo);
        f2 = try_action(x2);
      }
      ++evals;
    }
  }
  return best;
}

/// Greedy method HEDGER_GREEDY_PER_ACTION: every candidate action is a full prediction with its
/// own neighbourhood of (state, action) points.
template <int D>
GreedyResult greedy_per_action(hedger& h, double* x) noexcept {
  const double sa = h.cfg.input_scale[D - 1];
  const double kappa = h.cfg.greedy_pessimism;
  Neigh nb;
  return greedy_search(h, [&](double a, double* value, hedger_kind_t* kind) {
    x[D - 1] = a / sa;
    hedger_prediction_t p;
    predict_x<D>(h, x, nb, p);
    *value = p.value;
    *kind = p.kind;
    const int support = p.kind == HEDGER_KIND_LWR ? 2 : (p.kind == HEDGER_KIND_LWA ? 1 : 0);
    return GreedyRank{support, p.value - kappa * p.std_error};
  });
}

/// Greedy method HEDGER_GREEDY_STATE_MODEL: one local model of the action's effect at the state.
/// The neighbourhood is the k_max stored points nearest to the state alone (the action ignored,
/// within the kernel's radius), weighted by the kernel of their state distance; the model is
/// linear in the state and quadratic in the action, q ≈ β0 + β_s·Δs + β_u u + β_uu u²
/// (u = action − the neighbourhood's mean action), fitted by ridge-regularised weighted least
/// squares. Why one model: every candidate action is then judged on the same data and the same
/// fit, so the comparison between actions is not drowned by the differences between separate
/// neighbourhoods (each per-action fit carries its own bias from the states around it, larger
/// than the effect of one action), and the quadratic term lets the best action lie inside the
/// data's range instead of always on its edge.
/// - Candidates: actions within the range of the neighbours' actions (the action's hull: the
///   model never extrapolates in the action), ranked by model value − κ · standard error. The
///   state part β_s·Δs is common to every candidate, so a query state at the edge of the data
///   changes the values, never the ranking.
/// - Value of the chosen action: the model's, when (state, action) lies inside the model's
///   independent-variable hull and the value within [Q_min, Q_max] (kind LWR); otherwise the
///   weighted average of the neighbours' values (kind LWA), which never extrapolates.
/// The model fails (the caller falls back to the per-action search) with fewer than
/// max(k_min, D + 3) neighbours or a singular fit. It is formed in two stages, as a prediction
/// (fit_geometry): model_geometry() from the neighbours' coordinates and weights alone (every
/// matrix and factorisation but the right-hand side), then model_value() from their values
/// (the fit, its residuals, the action search). The replay keeps the first per record.
template <int D>
struct ModelGeom {
  static constexpr int P = D + 2;  // Δs (D − 1), u, u², 1
  using Mat = Eigen::Matrix<double, P, P>;
  enum Status : uint8_t { kFailed, kFormed };
  enum Alt : uint8_t { kAltNone, kAltFormed, kAltSingular };
  Status status;        ///< kFailed: too few neighbours, or A singular
  uint8_t anchor_ok;    ///< the anchor's regression could be factorised (else the model fails)
  uint8_t anchor_unweighted;  ///< every neighbour's anchor weight was (nearly) 0
  Alt alt;              ///< the fit without the u² column (af_alt, cov_alt), formed on demand
  uint8_t v_ok;         ///< reach <= 1 and the IVH matrix factorised: vinv valid
  uint32_t n;
  uint32_t h_scanned;   ///< hmax covers the h_scanned farthest neighbours
  double sw;            ///< Σ w_i
  double abar;          ///< the neighbours' mean action (scaled)
  double u_anchor, umin, umax, tol;  ///< the neighbours' policy and the action's hull
  /// The IVH test's largest leverage, found on demand (model_value): the largest over the
  /// h_scanned farthest neighbours. A test stops at the first leverage that admits the action,
  /// with the outcome of the full maximum (rounding is monotone); later tests of the same
  /// geometry (the replay's passes) go on from there.
  double hmax;
  uint32_t ids[HEDGER_MAX_K];
  double w[HEDGER_MAX_K];
  Mat a, b;             ///< XᵀWX + ridge and XᵀW²X, kept for the fit without u²
  Mat cov, cov_alt;     ///< A⁻¹ B A⁻¹: Var(e·β) = s² eᵀ cov e
  Mat vinv;             ///< the IVH matrix's inverse (v_ok)
  FactorOf<P> af, af_alt;
};

/// The design row e = [0…0, u, u², 1] of action act (raw) and the pessimism's direction
/// d = e − e(anchor) = [0…0, u − u_a, u² − u_a², 0] (model_value()).
template <int D>
void model_design(const hedger& h, double abar, double u_anchor, double act, Eigen::Matrix<double, D + 2, 1>& e,
                  Eigen::Matrix<double, D + 2, 1>& d) noexcept {
  const double u = act / h.cfg.input_scale[D - 1] - abar;
  e.setZero();
  e[D - 1] = u;
  e[D] = u * u;
  e[D + 1] = 1.0;
  d.setZero();
  d[D - 1] = e[D - 1] - u_anchor;
  d[D] = e[D] - u_anchor * u_anchor;
}

template <int D>
void model_row(const hedger& h, const double* x, uint32_t s, double abar, Eigen::Matrix<double, D + 2, 1>& r) noexcept {
  const double* xi = h.pts + static_cast<size_t>(s) * static_cast<size_t>(D);
  for (int j = 0; j < D - 1; ++j) r[j] = xi[j] - x[j];
  const double u = xi[D - 1] - abar;
  r[D - 1] = u;
  r[D] = u * u;
  r[D + 1] = 1.0;
}

/// The geometry stage of the state model at x (scaled state) with the kernel widened by reach.
/// Queries the store. Cost: one k-NN query, three (D+2)² factorisations, O(n D²); no allocation.
template <int D>
void model_geometry(hedger& h, const double* x, double reach, ModelGeom<D>& g) noexcept {
  constexpr int P = D + 2;
  using Vec = Eigen::Matrix<double, P, 1>;
  using Mat = Eigen::Matrix<double, P, P>;
  g.status = ModelGeom<D>::kFailed;
  g.alt = ModelGeom<D>::kAltNone;
  g.anchor_ok = 0;
  g.anchor_unweighted = 0;
  g.v_ok = 0;
  const double h2 = h.h2 * reach * reach;
  Neighbour nbuf[HEDGER_MAX_K];
  const uint32_t k = h.cfg.k_max;
  KnnCollect<kCollectCap> rs(k, seeded_r2<D, D - 1>(h, x, h.r2max * reach * reach, k, h.seed_state, h.n_seed_state));
  query_store<D, D - 1>(h, x, rs);
  const uint32_t n = rs.finish(nbuf);
  g.n = n;
  for (uint32_t i = 0; i < n; ++i) h.seed_state[i] = nbuf[i].id;
  h.n_seed_state = n;
  if (n < h.cfg.k_min || n < static_cast<uint32_t>(P + 1)) return;
  double* w = g.w;
  double sw = 0.0, swa = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    g.ids[i] = nbuf[i].id;
    w[i] = std::exp(-nbuf[i].d2 / h2);
    sw += w[i];
    swa += w[i] * h.pts[static_cast<size_t>(nbuf[i].id) * static_cast<size_t>(D) + (D - 1)];
  }
  g.sw = sw;
  const double abar = swa / sw;
  g.abar = abar;
  Vec rows[HEDGER_MAX_K];
  Mat& a = g.a;
  Mat& b = g.b;
  Mat v;
  const bool unweighted_ivh = (h.cfg.ivh_mode == static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED));
  // A = Σ (w_i r_i) r_iᵀ and V (Σ r_i r_iᵀ, or A) are factorised only: their lower triangles
  // are summed and mirrored. B = Σ (w_i² r_i) r_iᵀ enters the covariance A⁻¹ B A⁻¹ whole.
  Vec zw[HEDGER_MAX_K], zb[HEDGER_MAX_K];
  for (uint32_t i = 0; i < n; ++i) {
    Vec& r = rows[i];
    model_row<D>(h, x, g.ids[i], abar, r);
    zw[i] = w[i] * r;
    zb[i] = (w[i] * w[i]) * r;
  }
  // Only the unweighted IVH needs the second sum (the weighted one's V is A before the ridge).
  if (unweighted_ivh) {
    column_sums<P, true, true>(rows, n, zw, a, v, zb, b);
    mirror_lower<P>(v);
  } else {
    column_sums<P, false, true>(rows, n, zw, a, v, zb, b);
  }
  mirror_lower<P>(a);
  if (!unweighted_ivh) v = a;
  for (int j = 0; j < P - 1; ++j) a(j, j) += h.cfg.ridge;
  if (!factor_spd<P>(g.af, a)) return;
  {
    const Mat ainv = g.af.inverse();
    g.cov = ainv * b * ainv;
  }
  // The neighbours' policy at the query state: a locally linear regression of their actions on
  // the state, u_i ≈ α0 + α·Δs_i. Its intercept anchors the pessimism, and its residuals give
  // the range of actions the data holds at this state: the action's hull, tilted with the state.
  // Why not the plain mean and range of the neighbours' actions: where the query lies at the
  // edge of the visited states (a start pose heading off the axis: every neighbour has turned
  // part of the way already) both are biased towards the actions of the less extreme states, and
  // the robot turned too gently (measured: the first 2 s of a run from the corridor's start poses).
  // Each point's kernel weight is multiplied by its anchor weight (hedger_weight_run: runs the
  // caller ranked) and, with cfg.anchor_recency_runs, by its run's age, so the imitation can
  // follow the better of the runs it has seen; the value model above is fitted without either.
  using SVec = Eigen::Matrix<double, D, 1>;
  using SMat = Eigen::Matrix<double, D, D>;
  SMat sa_m = SMat::Zero();
  SVec sa_t = SVec::Zero();
  const double recency = h.cfg.anchor_recency_runs;
  double wa[HEDGER_MAX_K];
  double wmax = 0.0, wa_max = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t id = g.ids[i];
    wa[i] = w[i] * static_cast<double>(h.anchor_w[id]);
    if (recency > 0.0) wa[i] *= std::exp(-static_cast<double>(h.cur_tag - h.run_tag[id]) / recency);
    wmax = w[i] > wmax ? w[i] : wmax;
    wa_max = wa[i] > wa_max ? wa[i] : wa_max;
  }
  // The weights are relative: rescaled so that the largest equals the largest kernel weight,
  // the ridge keeps its strength (a neighbourhood of faded or down-weighted points would
  // otherwise see a ridge many times stronger and its anchor flattened towards the mean action).
  // A neighbourhood in which every point was weighted (nearly) zero keeps the kernel weights: the
  // caller ranked no alternative there. Unweighted, the factor is exactly 1 and nothing changes.
  const double* wz = w;
  if (wa_max > 1e-12 * wmax) {
    const double f = wmax / wa_max;
    for (uint32_t i = 0; i < n; ++i) wa[i] *= f;
    wz = wa;
  } else {
    g.anchor_unweighted = 1;
  }
  for (uint32_t i = 0; i < n; ++i) {
    SVec z;
    for (int j = 0; j < D - 1; ++j) z[j] = rows[i][j];
    z[D - 1] = 1.0;
    sa_m.noalias() += (wz[i] * z) * z.transpose();
    sa_t.noalias() += (wz[i] * rows[i][D - 1]) * z;
  }
  for (int j = 0; j < D - 1; ++j) sa_m(j, j) += h.cfg.ridge;
  FactorOf<D> sa_f;
  g.status = ModelGeom<D>::kFormed;
  if (!factor_spd<D>(sa_f, sa_m)) return;
  g.anchor_ok = 1;
  const SVec alpha = sa_f.solve(sa_t);
  const double u_anchor = alpha[D - 1];
  double rmin = std::numeric_limits<double>::infinity(), rmax = -rmin;
  for (uint32_t i = 0; i < n; ++i) {
    double pred = alpha[D - 1];
    for (int j = 0; j < D - 1; ++j) pred += alpha[j] * rows[i][j];
    const double res = rows[i][D - 1] - pred;
    rmin = res < rmin ? res : rmin;
    rmax = res > rmax ? res : rmax;
  }
  g.u_anchor = u_anchor;
  g.umin = u_anchor + rmin;
  g.umax = u_anchor + rmax;
  g.tol = 1e-12 * (1.0 + g.umax - g.umin);
  // The IVH test of the chosen action's value (model_value): a widened kernel's model only
  // ranks the actions, its value is the average.
  FactorOf<P> vf;
  if (reach <= 1.0 && factor_spd<P>(vf, v)) {
    g.vinv = vf.inverse();
    g.hmax = 0.0;
    g.h_scanned = 0;
    g.v_ok = 1;
  }
}

/// The fit without the u² column (the least-squares fit under β_uu <= 0 with the constraint
/// active): formed once per geometry, on the first value that needs it.
template <int D>
void model_alt(ModelGeom<D>& g) noexcept {
  constexpr int D1 = D;
  using Mat = typename ModelGeom<D>::Mat;
  Mat a = g.a, b = g.b;
  a.row(D1).setZero();
  a.col(D1).setZero();
  a(D1, D1) = 1.0;
  b.row(D1).setZero();
  b.col(D1).setZero();
  if (!factor_spd<D + 2>(g.af_alt, a)) {
    g.alt = ModelGeom<D>::kAltSingular;
    return;
  }
  const Mat ainv = g.af_alt.inverse();
  g.cov_alt = ainv * b * ainv;
  g.alt = ModelGeom<D>::kAltFormed;
}

/// dᵀ c d for a d whose only non-zero entries are the action's two, d[D-1] = d1 and d[D] = d2:
/// the other terms are exact zeros (c is finite), so the sums are the ones the full product
/// rounds, and a candidate costs a few instructions instead of a 7 × 7 product (measured: 4 % of
/// b21r-train's).
template <int D, class Mat>
double action_quad(const Mat& c, double d1, double d2) noexcept {
  return d1 * (c(D - 1, D - 1) * d1 + c(D - 1, D) * d2) + d2 * (c(D, D - 1) * d1 + c(D, D) * d2);
}

/// The value stage of the state model on the geometry g of the same x: fit, residual variance,
/// action search, value of the chosen action. False when the model fails. O(n D + D² per
/// candidate), no allocation (forms g's fit without u² once if the values ask for it).
template <int D>
bool model_value(hedger& h, const double* x, ModelGeom<D>& g, GreedyResult& out, Judgement* judge = nullptr) noexcept {
  constexpr int P = D + 2;
  using Vec = Eigen::Matrix<double, P, 1>;
  using Mat = Eigen::Matrix<double, P, P>;
  if (g.status != ModelGeom<D>::kFormed) return false;
  const uint32_t n = g.n;
  const double* w = g.w;
  Vec rows[HEDGER_MAX_K];
  Vec xtwq = Vec::Zero();
  double swq = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    Vec& r = rows[i];
    model_row<D>(h, x, g.ids[i], g.abar, r);
    const double q = h.val[g.ids[i]];
    swq += w[i] * q;
    xtwq.noalias() += (w[i] * q) * r;
  }
  Vec beta = g.af.solve(xtwq);
  const Mat* cov = &g.cov;
  if (beta[D] > 0.0) {
    // Concave in the action, or linear: a value convex in the action has its maximum on an edge
    // of the data, and which edge wins is decided by the noise in the curvature (measured on the
    // corridor: the robot took the wrong edge and drove into a wall). The least-squares fit
    // under β_uu <= 0 with the constraint active is the fit without the u² column.
    if (g.alt == ModelGeom<D>::kAltNone) model_alt<D>(g);
    if (g.alt != ModelGeom<D>::kAltFormed) return false;
    xtwq[D] = 0.0;
    beta = g.af_alt.solve(xtwq);
    cov = &g.cov_alt;
  }
  double rss = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    const double res = h.val[g.ids[i]] - rows[i].dot(beta);
    rss += w[i] * res * res;
  }
  const double s2 = (rss / g.sw) * static_cast<double>(n) / static_cast<double>(static_cast<int>(n) - P);
  if (g.anchor_unweighted) ++h.counters.anchor_unweighted;
  if (!g.anchor_ok) return false;
  const double kappa = h.cfg.greedy_pessimism;
  const double u_anchor = g.u_anchor, umin = g.umin, umax = g.umax, tol = g.tol;
  GreedyResult res = greedy_search(h, [&](double act, double* value, hedger_kind_t* kind) {
    Vec e, d;
    model_design<D>(h, g.abar, u_anchor, act, e, d);
    *kind = HEDGER_KIND_UNKNOWN;
    *value = h.cfg.default_value;
    if (e[D - 1] < umin - tol || e[D - 1] > umax + tol) return GreedyRank{0, 0.0};
    const double q = e.dot(beta);
    if (!std::isfinite(q)) return GreedyRank{0, 0.0};
    *value = q;
    *kind = HEDGER_KIND_LWR;
    // Pessimism on the action's effect relative to the neighbourhood's mean action (u = 0):
    // the state part and the intercept are common to every candidate, so only the uncertainty
    // of β_u u + β_uu u² matters for the choice.
    const double quad = action_quad<D>(*cov, d[D - 1], d[D]);
    return GreedyRank{2, q - kappa * std::sqrt(s2 * quad)};
  });
  if (res.status != HEDGER_OK) return false;
  if (judge != nullptr) {
    // The asked action within the data's actions at the state, and how far below the greedy
    // action the model puts it: the difference of the two design rows has only the action's two
    // entries, so its error is that of β_u Δu + β_uu Δ(u²) alone (the state part cancels).
    // u is formed as model_design forms it, so that the greedy action itself differs by exact
    // zeros (no round trip through raw units).
    const double scale = h.cfg.input_scale[D - 1];
    const double u_asked = judge->action / scale - g.abar;
    const double u = u_asked < umin ? umin : (u_asked > umax ? umax : u_asked);
    Vec eg, d;
    model_design<D>(h, g.abar, u_anchor, res.action, eg, d);
    const double d1 = eg[D - 1] - u, d2 = eg[D] - u * u;
    const double quad = action_quad<D>(*cov, d1, d2);
    judge->judged = 1;
    judge->lo = (umin + g.abar) * scale;
    judge->hi = (umax + g.abar) * scale;
    judge->kept = u_asked < umin ? judge->lo : (u_asked > umax ? judge->hi : judge->action);
    judge->gap = d1 * beta[D - 1] + d2 * beta[D];
    judge->gap_se = std::sqrt(s2 * quad);
  }
  // The value of the chosen action: the regression where it interpolates, else the average.
  bool lwr = false;
  if (g.v_ok && res.value >= q_min(h) && res.value <= q_max(h)) {
    Vec e, d;
    model_design<D>(h, g.abar, u_anchor, res.action, e, d);
    const double le = e.dot(g.vinv * e);
    lwr = le <= g.hmax * (1.0 + kIvhTol);
    const bool unweighted_ivh = (h.cfg.ivh_mode == static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED));
    while (!lwr && g.h_scanned < n) {
      // Farthest first: the largest leverages are at the neighbourhood's edge.
      const uint32_t i = n - 1u - g.h_scanned++;
      const double hi = ivh_leverage<P>(g.vinv, rows[i], w[i], unweighted_ivh);
      if (hi > g.hmax) g.hmax = hi;
      lwr = le <= g.hmax * (1.0 + kIvhTol);
    }
  }
  if (!lwr) {
    res.value = swq / g.sw;
    res.kind = HEDGER_KIND_LWA;
  }
  out = res;
  return true;
}

/// The greedy search's geometry kept per replayed record: the state model of the attempt that
/// answers (which), valid while hedger::geom_gen == gen.
template <int D>
struct GreedyGeom {
  enum Which : uint8_t { kPerAction, kReach1, kReachWide };
  uint64_t gen;
  Which which;  ///< kReach1: m is the model at reach 1; kReachWide: reach 1 failed, m is the wide one
  ModelGeom<D> m;
};

/// Greedy search at a scaled state x (x[D-1] is overwritten). With a cache (the replay's record),
/// the state model's geometry is taken from it while it is valid, else formed into it.
template <int D>
GreedyResult greedy_x(hedger& h, double* x, GreedyGeom<D>* cache, Judgement* judge = nullptr) noexcept {
  ++h.counters.greedy_calls;
  GreedyResult g;
  if (h.cfg.greedy_method == static_cast<uint32_t>(HEDGER_GREEDY_STATE_MODEL) &&
      h.cfg.local_model == static_cast<uint32_t>(HEDGER_LOCAL_LWR)) {
    const double reach = h.cfg.greedy_reach;
    ModelGeom<D> local;
    bool tried_wide = false;
    if (cache != nullptr && cache->gen == h.geom_gen) ++h.counters.replay_reused;
    if (cache != nullptr && cache->gen != h.geom_gen) {
      // Form the geometry of the attempt that can answer: the wide one only where the first
      // fails on the neighbours' coordinates alone (model_value may still fail on the values).
      cache->gen = h.geom_gen;
      model_geometry<D>(h, x, 1.0, cache->m);
      cache->which = GreedyGeom<D>::kReach1;
      if (cache->m.status != ModelGeom<D>::kFormed) {
        cache->which = GreedyGeom<D>::kPerAction;
        if (reach > 1.0) {
          model_geometry<D>(h, x, reach, cache->m);
          if (cache->m.status == ModelGeom<D>::kFormed) cache->which = GreedyGeom<D>::kReachWide;
        }
      }
    }
    if (cache == nullptr) {
      model_geometry<D>(h, x, 1.0, local);
      if (model_value<D>(h, x, local, g, judge)) {
        ++h.counters.greedy_state_model;
        return g;
      }
    } else if (cache->which == GreedyGeom<D>::kReach1) {
      if (model_value<D>(h, x, cache->m, g)) {
        ++h.counters.greedy_state_model;
        return g;
      }
    } else {
      tried_wide = true;
      if (cache->which == GreedyGeom<D>::kReachWide && model_value<D>(h, x, cache->m, g)) {
        ++h.counters.greedy_state_model;
        ++h.counters.greedy_reached;
        return g;
      }
    }
    if (!tried_wide && reach > 1.0) {
      model_geometry<D>(h, x, reach, local);
      if (model_value<D>(h, x, local, g, judge)) {
        ++h.counters.greedy_state_model;
        ++h.counters.greedy_reached;
        return g;
      }
    }
  }
  g = greedy_per_action<D>(h, x);
  if (g.status != HEDGER_OK) ++h.counters.greedy_all_unknown;
  return g;
}

/// Greedy search at a raw state (see hedger_greedy()); with judge, also its judgement of
/// judge->action (judged = 0 where no state model answers).
template <int D>
GreedyResult greedy_at(hedger& h, const double* state, GreedyGeom<D>* cache = nullptr,
                       Judgement* judge = nullptr) noexcept {
  double x[static_cast<size_t>(D)];
  for (int i = 0; i < D - 1; ++i) x[i] = state[i] / h.cfg.input_scale[i];
  x[D - 1] = 0.0;
  if (judge != nullptr) {
    // Not judged until a state model answers: the action as asked, no gap.
    judge->judged = 0;
    judge->lo = judge->hi = judge->kept = judge->action;
    judge->gap = judge->gap_se = 0.0;
  }
  return greedy_x<D>(h, x, cache, judge);
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

/// Takes fresh entry pos into its block's box; `first` starts the box at it (the block's first
/// entry, newly appended). An entry rewritten in place only widens the box (still a bound).
template <int D>
void fresh_box_add(hedger& h, uint32_t pos, bool first) noexcept {
  const double* f = h.fresh_pts + static_cast<size_t>(pos) * static_cast<size_t>(D);
  double* box = h.fresh_box + static_cast<size_t>(pos / kFreshBlock) * 2u * static_cast<size_t>(D);
  for (int j = 0; j < D; ++j) {
    if (first || f[j] < box[j]) box[j] = f[j];
    if (first || f[j] > box[D + j]) box[D + j] = f[j];
  }
}

/// Fresh entries at which the next rebuild starts, for the store's current fill. A rebuild costs
/// about kd_build_work_estimate(fill) work units (about 50 instructions each), spread over the
/// updates until the next one, and every query scans the fresh buffer (block by block, skipping
/// blocks beyond its bound): twice the square root of the units balances the two (measured with
/// callgrind on b21r-train's corridor session: once or four times the units give the same total,
/// and four means rarer rebuilds): about 350 entries at 1,000 points, 2,000 at 20,000. Kept within
/// [fresh_capacity/16, fresh_capacity/2], so the automatic rebuild budget (fresh_capacity/2
/// updates per rebuild) always finishes before the buffer is full. O(log fill).
inline uint32_t fresh_trigger(const hedger& h) noexcept {
  const double f = std::sqrt(4.0 * static_cast<double>(kd_build_work_estimate(h.fill)));
  const uint32_t lo = h.fresh_cap / 16 > 0 ? h.fresh_cap / 16 : 1;
  const uint32_t hi = h.fresh_cap / 2 > lo ? h.fresh_cap / 2 : lo;
  return f <= static_cast<double>(lo) ? lo : (f >= static_cast<double>(hi) ? hi : static_cast<uint32_t>(f));
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
  for (uint32_t i = 0; i < n; ++i) fresh_box_add<D>(h, i, i % kFreshBlock == 0);
  h.fresh_start = fresh_trigger(h);
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
  fresh_box_add<D>(h, pos, pos % kFreshBlock == 0 && pos + 1 == h.n_fresh);
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
  ++h.geom_gen;
  h.run_tag[slot] = h.cur_tag;
  h.anchor_w[slot] = 1.0f;
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
inline void merge_into(hedger& h, uint32_t j, double d2, double q, bool td, double target, double alpha,
                       uint8_t fl) noexcept {
  if (td) {
    h.val[j] += alpha * (target - h.val[j]);
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
  double alpha;  ///< an update's learning rate (the merge rule's step)
  bool have_near;
  uint32_t near_slot;
  double near_d2;
  double red_d2;  ///< squared distance to its k_min-th nearest stored point (+inf if fewer)
};

/// Redundancy of stored point c: squared distance to its k-th nearest other stored point
/// (k = k_min; +inf if it has fewer than k others). Small = many points close by. Only an exact
/// value up to cap is asked for (the search stays within it): a redundancy above cap comes back
/// as +inf.
template <int D>
double redundancy_d2(const hedger& h, uint32_t c, double cap) noexcept {
  Neighbour buf[HEDGER_MAX_K + 1];
  const uint32_t k = h.cfg.k_min;
  KnnSet rs(buf, k + 1, cap);
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
    merge_into(h, np.near_slot, np.near_d2, np.q, np.td, np.target, np.alpha, np.flags);
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
  // Only redundancies up to the new point's own matter exactly (above it, the new point is the
  // most redundant and merges, whichever candidate is least redundant), and up to the best
  // candidate's so far: each search is bounded by both (inclusive, for the tie rule), which
  // gives the same victim and decision as exact values everywhere.
  const double cap = np.have_near ? np.red_d2 : std::numeric_limits<double>::infinity();
  uint32_t victim = pool[0];
  double vd2 = redundancy_d2<D>(h, victim, cap);
  for (uint32_t i = 1; i < npool; ++i) {
    const double d2 = redundancy_d2<D>(h, pool[i], vd2 < cap ? vd2 : cap);
    if (d2 < vd2 || (!(vd2 < d2) && pool[i] < victim)) {
      vd2 = d2;
      victim = pool[i];
    }
  }
  if (np.have_near && np.red_d2 < vd2) {
    merge_into(h, np.near_slot, np.near_d2, np.q, np.td, np.target, np.alpha, np.flags);
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

/// The geometry of the prediction at a replayed record's (s, a), valid while hedger::geom_gen ==
/// gen: the neighbourhood (with the two distances the store rule needs) and its FitGeom.
template <int D>
struct FitCache {
  uint64_t gen;
  uint32_t n;
  double near_d2;  ///< squared distance to the nearest neighbour (n > 0)
  double red_d2;   ///< to the k_min-th (+inf if fewer): the new point's redundancy
  uint32_t ids[HEDGER_MAX_K];
  double w[HEDGER_MAX_K];
  FitGeom<D> g;
};

/// A generation no instance reaches: a record constructed with it is invalid.
constexpr uint64_t kNeverGen = ~0ull;

/// What the backward replay keeps per record of the run (see replay_step()).
template <int D>
struct ReplayRecord {
  GreedyGeom<D> greedy;  ///< of the greedy search at s'
  FitCache<D> fit;       ///< of the prediction at (s, a)
};

/// Steps 2–6 of the training update for (s, a) with a given target r + γ q' (info.target set by
/// the caller) and learning rate alpha (cfg.alpha; the replay's cfg.replay_alpha): q = Q(s, a),
/// q_new = q + α (target − q), store (s, a) with q_new, pull the neighbours, track r. With a
/// cache (the replay's record) the neighbourhood and the geometry of the prediction are taken
/// from it while valid, else found and kept in it.
template <int D>
void learn_target(hedger& h, const double* s, double a, double r, int terminal, double alpha,
                  hedger_update_info_t& info, FitCache<D>* cache = nullptr) noexcept {
  // 2. q = Q(s, a) with its neighbourhood.
  double x[static_cast<size_t>(D)];
  scale_input<D>(h, s, a, x);
  FitCache<D> local;
  FitCache<D>& fc = cache != nullptr ? *cache : local;
  if (cache != nullptr && cache->gen == h.geom_gen) ++h.counters.replay_reused;
  if (cache == nullptr || cache->gen != h.geom_gen) {
    Neigh nb;
    find_neighbours<D>(h, x, nb);
    const uint32_t km = h.cfg.k_min;
    fc.gen = h.geom_gen;
    fc.n = nb.n;
    fc.near_d2 = nb.n > 0 ? nb.nb[0].d2 : 0.0;
    fc.red_d2 = nb.n >= km ? nb.nb[km - 1].d2 : std::numeric_limits<double>::infinity();
    neigh_ids(nb, fc.ids);
    for (uint32_t i = 0; i < nb.n; ++i) fc.w[i] = nb.w[i];
    fit_geometry<D>(h, x, fc.ids, fc.w, fc.n, fc.g);
  }
  const uint32_t n = fc.n;
  hedger_prediction_t p;
  fit_value<D>(h, x, fc.ids, fc.w, n, fc.g, p);
  info.q_old = p.value;
  info.kind = p.kind;
  // 3. New value.
  const double q_new = p.value + alpha * (info.target - p.value);
  info.q_new = q_new;
  // 4. Store (s, a). Remember the neighbours' sequence numbers: a neighbour evicted by the
  //    store step is not pulled (its slot now holds the new point).
  uint64_t nseq[HEDGER_MAX_K];
  for (uint32_t i = 0; i < n; ++i) nseq[i] = h.seq[fc.ids[i]];
  const uint8_t fl = (terminal || !(r >= 0.0 && r <= 0.0)) ? HEDGER_POINT_PROTECTED : 0;
  const bool have = n > 0;
  const NewPoint np{q_new, fl, true, info.target, alpha, have, have ? fc.ids[0] : 0, fc.near_d2, fc.red_d2};
  uint32_t merged;
  info.store_op = store_point<D>(h, x, np, &merged);
  // 5. Pull each neighbour toward q_new by α κ_i (a merged point had its update already).
  uint32_t pulled = 0;
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t sl = fc.ids[i];
    if (h.seq[sl] != nseq[i] || sl == merged) continue;
    h.val[sl] += alpha * fc.w[i] * (q_new - h.val[sl]);
    ++pulled;
  }
  info.n_pulled = pulled;
  // 6. Rewards seen bound plausible values from now on.
  track_reward(h, r);
  ++h.counters.updates;
  maintain<D>(h);
}

/// The greedy result at s' as the update's q' (q' = 0 for a terminal transition).
template <int D>
void next_greedy(hedger& h, const double* sn, int terminal, hedger_update_info_t& info,
                 GreedyGeom<D>* cache = nullptr) noexcept {
  if (terminal) {
    info.next_status = HEDGER_NO_KNOWN_ACTION;
    info.next_action = 0.5 * (h.cfg.action_min + h.cfg.action_max);
    info.next_value = h.cfg.default_value;
    info.next_kind = HEDGER_KIND_UNKNOWN;
    info.q_next = 0.0;
    return;
  }
  const GreedyResult g = greedy_at<D>(h, sn, cache);
  info.next_status = g.status;
  info.next_action = g.action;
  info.next_value = g.value;
  info.next_kind = g.kind;
  info.q_next = g.value;
}

template <int D>
uint32_t replay_step(hedger& h, uint32_t max_updates) noexcept;

/// The training update (hedger.md steps 1–6), Q-learning target r + γ max_a' Q(s', a'). Inputs
/// are validated by the caller. A pending replay is completed first (see hedger_end_run_begin).
template <int D>
void update(hedger& h, const double* s, double a, double r, const double* sn, int terminal,
            hedger_update_info_t& info) noexcept {
  if (h.replay_pending) replay_step<D>(h, std::numeric_limits<uint32_t>::max());
  h.call_work = 0;
  // 1. q' from the greedy search at s' (done once; returned for reuse as the next action).
  next_greedy<D>(h, sn, terminal, info);
  info.target = r + h.cfg.gamma * info.q_next;
  learn_target<D>(h, s, a, r, terminal, h.cfg.alpha, info);
  record_run(h, s, a, r, sn, terminal);
}

/// Steps 2–6 with q' given by the caller (hedger_learn): the second half of update().
template <int D>
void learn(hedger& h, const double* s, double a, double r, const double* sn, int terminal, double q_next,
           hedger_update_info_t& info) noexcept {
  if (h.replay_pending) replay_step<D>(h, std::numeric_limits<uint32_t>::max());
  h.call_work = 0;
  info.next_status = HEDGER_OK;
  info.q_next = terminal ? 0.0 : q_next;
  info.target = r + h.cfg.gamma * info.q_next;
  learn_target<D>(h, s, a, r, terminal, h.cfg.alpha, info);
  record_run(h, s, a, r, sn, terminal);
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
  const NewPoint np{q, fl, false, 0.0, 0.0, have, have ? buf[0].id : 0, have ? buf[0].d2 : 0.0,
                    rs.size() >= km ? buf[km - 1].d2 : std::numeric_limits<double>::infinity()};
  uint32_t merged;
  const hedger_store_op_t op = store_point<D>(h, x, np, &merged);
  maintain<D>(h);
  return op;
}

/// Starts the replay of the recorded run (cfg.replay): replay_passes backward passes. Returns the
/// number of updates it will take.
inline uint32_t replay_begin(hedger& h) noexcept {
  if (!h.cfg.replay || h.run_count == 0) {
    h.run_head = 0;
    h.run_count = 0;
    return 0;
  }
  h.replay_pending = 1;
  ++h.geom_gen;  // the records are new: nothing cached belongs to them
  h.replay_pass = 0;
  h.replay_k = 0;
  h.replay_next_return = 0.0;
  return h.run_count * h.cfg.replay_passes;
}

/// Work units of a slice of the replay (hedger_end_run_step()): a replayed update costs
/// kReplayUnitsPerUpdate, less kReplayUnitsSaved for each of its two searches (the greedy one at
/// s', the prediction at (s, a)) that takes its geometry from the record (cfg.replay_cache).
/// Measured with callgrind on the corridor at the firmware's defaults: an update that reuses both
/// costs about a fifteenth of one that forms both; counted as an eighth (2 units of 16), so that
/// a slice never costs more than the same number of updates without the cache did, and without
/// it every update counts whole.
/// In a full store every replayed update's store step evicts or merges, and an eviction searches
/// the neighbourhoods of evict_candidates points whether or not the geometry is reused: measured
/// (callgrind, hedger.update_instructions: the firmware's corridor learner, 20k and 100k points,
/// store full) a reused update then costs about a quarter of one that forms its geometry, so it
/// counts kReplayUnitsFull more. So does a reused update while the kd-tree is being rebuilt (or a
/// rebuild is due to start): every update advances it by rebuild_budget units whether or not it
/// reuses its geometry
/// (measured: firmware.tick_instructions at 20k points, capacity 110k, a rebuild under way during
/// the second pass: 32 reused updates in one slice took 5.7 M instructions against about 0.5 M
/// for 32 without a rebuild).
constexpr uint64_t kReplayUnitsPerUpdate = 16;
constexpr uint64_t kReplayUnitsSaved = 7;
constexpr uint64_t kReplayUnitsFull = 4;

/// Advances the pending replay by updates worth at most max_updates full updates (see
/// kReplayUnitsPerUpdate; at least one update when max_updates >= 1); returns the updates done.
/// When the last pass ends the run buffer is cleared. Each pass goes newest first with the
/// λ-return target
///   T_t = r_t + γ ((1 − λ) V(s_{t+1}) + λ T_{t+1}),   T of the newest = r (terminal) or r + γ V(s'),
/// V = the greedy value (HEDGER_GREEDY_* at s'): λ = 0 is the Q-learning target, λ = 1 the
/// return of the run as driven, bootstrapped only where the run was cut short.
/// With the record cache, each record keeps the geometry of its two searches (ReplayRecord):
/// the first pass forms it, and later passes, as long as no stored point has moved
/// (hedger::geom_gen), repeat only what depends on the values; the results are bit-identical.
template <int D>
uint32_t replay_step(hedger& h, uint32_t max_updates) noexcept {
  const uint32_t sd = h.cfg.state_dim;
  const double lambda = h.cfg.replay_lambda;
  const double replay_alpha = h.cfg.replay_alpha > 0.0 ? h.cfg.replay_alpha : h.cfg.alpha;
  const uint64_t budget = static_cast<uint64_t>(max_updates) * kReplayUnitsPerUpdate;
  uint64_t spent = 0;
  uint32_t done = 0;
  while (h.replay_pending) {
    // Record k of the pass counts back from the newest.
    uint32_t idx = (h.run_head + h.run_cap - 1u - h.replay_k % h.run_cap) % h.run_cap;
    const double* rec = h.run + static_cast<size_t>(idx) * h.run_stride;
    const double* s = rec;
    const double a = rec[sd];
    const double r = rec[sd + 1];
    const double* sn = rec + sd + 2;
    const int terminal = rec[2 * sd + 2] > 0.5 ? 1 : 0;
    ReplayRecord<D>* rc = h.replay_cache != nullptr ? static_cast<ReplayRecord<D>*>(h.replay_cache) + idx : nullptr;
    const bool search = !terminal && (h.replay_k == 0 || lambda < 1.0);
    const bool reuse_greedy = search && rc != nullptr && rc->greedy.gen == h.geom_gen;
    const bool reuse_fit = rc != nullptr && rc->fit.gen == h.geom_gen;
    const uint32_t reuses = (reuse_greedy ? 1u : 0u) + (reuse_fit ? 1u : 0u);
    const bool store_work = h.fill >= h.cfg.capacity || h.building || h.n_fresh >= h.fresh_start;
    const uint64_t cost = kReplayUnitsPerUpdate - kReplayUnitsSaved * reuses +
                          (reuses > 0 && store_work ? kReplayUnitsFull : 0u);
    if (spent + cost > budget) break;
    spent += cost;
    hedger_update_info_t info;
    h.call_work = 0;
    if (h.replay_k == 0 || lambda < 1.0) {
      next_greedy<D>(h, sn, terminal, info, rc != nullptr ? &rc->greedy : nullptr);
    } else {
      info = hedger_update_info_t{};
      info.next_status = HEDGER_NO_KNOWN_ACTION;
      info.q_next = 0.0;
    }
    const double boot = terminal ? 0.0 : info.q_next;
    info.target = (h.replay_k == 0) ? r + h.cfg.gamma * boot
                                    : r + h.cfg.gamma * ((1.0 - lambda) * boot + lambda * h.replay_next_return);
    if (terminal) info.target = r;
    learn_target<D>(h, s, a, r, terminal, replay_alpha, info, rc != nullptr ? &rc->fit : nullptr);
    ++h.counters.replayed_updates;
    h.replay_next_return = info.target;
    ++done;
    if (++h.replay_k == h.run_count) {
      h.replay_k = 0;
      if (++h.replay_pass == h.cfg.replay_passes) {
        h.replay_pending = 0;
        h.run_head = 0;
        h.run_count = 0;
      }
    }
  }
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
  h.fresh_start = fresh_trigger(h);
}

}  // namespace hg

#endif  // HEDGER_CORE_HPP
