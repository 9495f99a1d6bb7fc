// SPDX-License-Identifier: MIT
// Static kd-tree in caller-provided fixed arrays, built in resumable work slices.
//
// Internal header of lib/hedger (white-box tests and the benchmark include it too).
//
// Layout. The tree owns a copy of the coordinates of the points it indexes (pts, n × D, in tree
// order, so that a leaf is a contiguous run), their ids (store slots) and a node pool. A node is
// either a leaf [begin, end) or an inner node with a split dimension and the bounds lo = max of
// the left child and hi = min of the right child along it (nanoflann's divlow/divhigh), which
// give exact slab distances for pruning.
//
// Build. Median split on the dimension of largest spread, so the tree is balanced: depth
// <= ceil(log2(n / kLeafSize)) + 1 and the node count is known in advance (max_nodes()). The build
// is a state machine (copy → per node: bounding-box pass, 3-way quickselect of the median) that
// runs for a given number of work units and resumes later; one unit is one point visited in one
// pass. This bounds the rebuild cost per HEDGER update (the caller keeps a second, complete tree
// for queries while this one is built).
//
// Queries. k-NN and radius searches use the incremental distance of Arya & Mount (as nanoflann)
// and write into caller buffers. Results are ordered by (squared distance, id), and ties are
// resolved by id, so a result never depends on the tree's shape: any two trees over the same
// points return bit-identical answers, and so does the brute-force scan (brute_knn()). Entries
// are filtered by a caller predicate (HEDGER uses it to skip points replaced since the build).
#ifndef HEDGER_KDTREE_HPP
#define HEDGER_KDTREE_HPP

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>

namespace hg {

/// Largest input dimension handled by the templates.
constexpr int kMaxDim = 9;
/// Points per leaf (at most; more only when a range cannot be split). Measured on the 4-D
/// benchmark (k = 16, 1k..50k points, interleaved best-of blocks): leaf 16 runs at 0.71..0.89 ×
/// nanoflann's time, leaf 8 at 0.94..0.97 ×.
constexpr uint32_t kLeafSize = 16;
/// Largest depth of the explicit build stack (balanced tree of <= 2^32 points needs < 34).
constexpr uint32_t kMaxStack = 64;
/// Relative slack on the pruning bound: the incremental lower bound is computed with rounding,
/// so a subtree is skipped only when it is clearly farther than the current worst distance.
constexpr double kPruneSlack = 1.0 + 1e-12;

/// One neighbour: squared distance (scaled units) and id (store slot).
struct Neighbour {
  double d2;
  uint32_t id;
};

/// (d2, id) lexicographic order: the one order every query and the brute-force oracle use.
inline bool nb_less(double d2a, uint32_t ida, double d2b, uint32_t idb) {
  return d2a < d2b || (!(d2b < d2a) && ida < idb);
}

template <int D>
inline double dist2(const double* a, const double* b) {
  double s = 0.0;
  for (int i = 0; i < D; ++i) {
    const double t = a[i] - b[i];
    s += t * t;
  }
  return s;
}

/// The k smallest (d2, id) with d2 <= r2max, kept sorted in a caller buffer of capacity k.
///
/// k = 0 (or a null buffer) is rejected at construction, without exceptions: the set is then
/// empty for good (ok() is false, worst() is -inf so that every search prunes at once, add()
/// stores nothing) and never touches the buffer. Callers that cannot have k = 0 (HEDGER's
/// k_min, k_max >= 1 by config validation) need not check ok().
class KnnSet {
 public:
  KnnSet(Neighbour* buf, uint32_t k, double r2max)
      : buf_(k > 0 && buf != nullptr ? buf : nullptr),
        k_(buf_ != nullptr ? k : 0),
        n_(0),
        r2max_(r2max),
        bound_(buf_ != nullptr ? r2max : -std::numeric_limits<double>::infinity()) {}
  /// False when construction was rejected (k = 0 or no buffer).
  bool ok() const { return k_ > 0; }
  /// Current acceptance bound: r2max until full, then the k-th distance (kept in a member, so
  /// reading it never indexes the buffer).
  double worst() const { return bound_; }
  /// Adds (d2, id) if it is among the k smallest so far: a binary search for its place, then
  /// one block move (HEDGER's k is up to 64; a linear scan and shift were most of a search).
  void add(double d2, uint32_t id) {
    if (k_ == 0 || d2 > r2max_) return;
    if (n_ == k_ && !nb_less(d2, id, buf_[k_ - 1].d2, buf_[k_ - 1].id)) return;
    uint32_t lo = 0, hi = n_;  // first entry greater than (d2, id)
    while (lo < hi) {
      const uint32_t mid = (lo + hi) / 2;
      if (nb_less(d2, id, buf_[mid].d2, buf_[mid].id)) {
        hi = mid;
      } else {
        lo = mid + 1;
      }
    }
    const uint32_t end = n_ < k_ ? n_ : k_ - 1;  // entries [lo, end) move up by one
    if (end > lo) std::memmove(buf_ + lo + 1, buf_ + lo, (end - lo) * sizeof(Neighbour));
    buf_[lo] = Neighbour{d2, id};
    if (n_ < k_) ++n_;
    if (n_ == k_) bound_ = buf_[k_ - 1].d2;
  }
  uint32_t size() const { return n_; }
  const Neighbour* data() const { return buf_; }

 private:
  Neighbour* buf_;
  uint32_t k_;
  uint32_t n_;
  double r2max_;
  double bound_;
};

/// The same k smallest (d2, id) with d2 <= r2max as KnnSet, gathered unsorted in an internal
/// buffer of Cap entries (Cap >= 2 k) and selected once, by finish(). Why: a k-NN search bounded
/// by a close guess of the k-th distance (HEDGER's seeded searches) adds about 1.5 k entries, and
/// KnnSet's sorted insertion (binary search and block move) of each was as costly as computing
/// the distances (callgrind, b21r-train at k = 64); here an entry costs a comparison and a store,
/// the selection O(Cap) when the buffer fills (the bound then tightens to the k-th distance so
/// far) and O(k log k) at the end. The result is the same set in the same (d2, id) order, so
/// nothing downstream can tell the two apart. Measured on b21r-train at the controller's defaults
/// (k = 64, Cap = 128): 2.6 % fewer instructions and about 7 % less CPU time than KnnSet (an
/// early exit on partial distances, also tried, saved 1.5 % of the instructions and cost 5 % more
/// CPU time in mispredicted branches). About 16 Cap bytes; no allocation.
template <uint32_t Cap>
class KnnCollect {
 public:
  KnnCollect(uint32_t k, double r2max)
      : k_(k >= 1 && 2 * k <= Cap ? k : 0),
        n_(0),
        bound_(k_ > 0 ? r2max : -std::numeric_limits<double>::infinity()) {}
  bool ok() const { return k_ > 0; }
  /// The acceptance bound: r2max, or the k-th distance once the buffer has been compacted.
  double worst() const { return bound_; }
  void add(double d2, uint32_t id) {
    if (!(d2 <= bound_)) return;
    buf_[n_++] = Neighbour{d2, id};
    if (n_ == Cap) {
      select_k();
      bound_ = buf_[k_ - 1].d2;
    }
  }
  /// Writes the (up to) k smallest entries, sorted by (d2, id), into out (capacity k); returns
  /// their number. O(n + k log k).
  uint32_t finish(Neighbour* out) {
    if (n_ > k_) select_k();
    std::sort(buf_, buf_ + n_, Less{});
    for (uint32_t i = 0; i < n_; ++i) out[i] = buf_[i];
    return n_;
  }

 private:
  struct Less {
    bool operator()(const Neighbour& a, const Neighbour& b) const { return nb_less(a.d2, a.id, b.d2, b.id); }
  };
  /// Keeps the k smallest entries (in any order, the k-th of them last).
  void select_k() {
    std::nth_element(buf_, buf_ + (k_ - 1), buf_ + n_, Less{});
    n_ = k_;
  }
  Neighbour buf_[Cap];
  uint32_t k_;
  uint32_t n_;
  double bound_;
};

/// All (d2, id) with d2 <= r2, written into a caller buffer of capacity cap. total() counts every
/// match; if total() > cap only cap of them (which ones is unspecified) are kept.
class RadiusSet {
 public:
  RadiusSet(Neighbour* buf, uint32_t cap, double r2) : buf_(buf), cap_(cap), n_(0), total_(0), r2_(r2) {}
  double worst() const { return r2_; }
  void add(double d2, uint32_t id) {
    if (d2 > r2_) return;
    if (n_ < cap_) buf_[n_++] = Neighbour{d2, id};
    ++total_;
  }
  /// Sorts the kept matches by (d2, id) (insertion sort: no allocation; O(n^2) worst case, for
  /// the small result sets HEDGER uses).
  void sort() {
    for (uint32_t i = 1; i < n_; ++i) {
      const Neighbour x = buf_[i];
      uint32_t j = i;
      while (j > 0 && nb_less(x.d2, x.id, buf_[j - 1].d2, buf_[j - 1].id)) {
        buf_[j] = buf_[j - 1];
        --j;
      }
      buf_[j] = x;
    }
  }
  uint32_t size() const { return n_; }
  uint32_t total() const { return total_; }

 private:
  Neighbour* buf_;
  uint32_t cap_;
  uint32_t n_;
  uint32_t total_;
  double r2_;
};

/// Tree node: a leaf (dim == kLeaf, [a, b) = point range) or inner (a = left, b = right child).
struct Node {
  double lo;  ///< inner: max coordinate of the left child along dim
  double hi;  ///< inner: min coordinate of the right child along dim
  uint32_t a;
  uint32_t b;
  uint32_t dim;
  uint32_t pad;
};
constexpr uint32_t kLeaf = 0xFFFFFFFFu;
constexpr uint32_t kNone = 0xFFFFFFFFu;

/// Exact node count of a median-split tree over n points (1 for n <= kLeafSize, including 0).
/// Sizes on one level differ by at most one, so each level is two (size, count) pairs: O(log n).
inline uint64_t kd_nodes_for(uint64_t n) {
  uint64_t s[2] = {n, 0}, c[2] = {1, 0};
  uint64_t total = 0;
  while (c[0] + c[1] > 0) {
    uint64_t ns[2] = {0, 0}, nc[2] = {0, 0};
    for (int j = 0; j < 2; ++j) {
      if (c[j] == 0) continue;
      total += c[j];
      if (s[j] <= kLeafSize) continue;
      const uint64_t parts[2] = {s[j] / 2, s[j] - s[j] / 2};
      for (uint64_t p : parts) {
        if (nc[0] != 0 && ns[0] == p) {
          nc[0] += c[j];
        } else if (nc[1] != 0 && ns[1] == p) {
          nc[1] += c[j];
        } else if (nc[0] == 0) {
          ns[0] = p;
          nc[0] = c[j];
        } else {
          ns[1] = p;
          nc[1] = c[j];
        }
      }
    }
    s[0] = ns[0];
    s[1] = ns[1];
    c[0] = nc[0];
    c[1] = nc[1];
  }
  return total;
}

/// Build-job: one node over [begin, end), whose bounding box patches its parent's lo/hi.
struct KdJob {
  uint32_t node, begin, end, parent;
  uint32_t side;  // 0 = left child of parent, 1 = right
};

enum class KdPhase : uint32_t { kIdle = 0, kCopy, kJob, kBbox, kSelect, kDone };

/// A kd-tree over fixed arrays (see the file comment). Data are plain; the algorithms are
/// templates on the dimension D (kd_* functions below). Not copyable by design of use: it lives
/// inside the HEDGER instance in caller storage.
struct KdTree {
  // Arrays (caller storage), sized for `cap` points and max_nodes nodes.
  double* pts;
  uint32_t* ids;
  Node* nodes;
  uint32_t cap;
  uint32_t max_nodes;
  // Complete tree (valid when phase == kDone).
  uint32_t n;
  uint32_t n_nodes;
  uint64_t snapshot;  ///< HEDGER: points with sequence number <= snapshot were copied
  // Build state.
  KdPhase phase;
  const double* src;         ///< source coordinates (n_src × D, row-major)
  const uint64_t* src_seq;   ///< per-source sequence numbers, or null = take every source point
  uint32_t n_src;
  uint32_t copy_i;
  KdJob stack[kMaxStack];
  uint32_t sp;
  KdJob cur;
  uint32_t it;  ///< bbox / partition cursor
  double bmin[kMaxDim];
  double bmax[kMaxDim];
  uint32_t sel_dim, sel_lo, sel_hi, sel_k, sel_lt, sel_gt;
  double sel_pivot;
  double root_lo[kMaxDim];  ///< bounding box of all points (initial lower bound of a query)
  double root_hi[kMaxDim];
};

/// Words of memory a tree for cap points needs (for the storage layout).
inline uint32_t kd_max_nodes(uint32_t cap) { return static_cast<uint32_t>(kd_nodes_for(cap)); }

/// Binds arrays and makes an empty, complete tree.
inline void kd_bind(KdTree& t, double* pts, uint32_t* ids, Node* nodes, uint32_t cap) {
  t.pts = pts;
  t.ids = ids;
  t.nodes = nodes;
  t.cap = cap;
  t.max_nodes = kd_max_nodes(cap);
  t.n = 0;
  t.n_nodes = 0;
  t.snapshot = 0;
  t.phase = KdPhase::kDone;
  t.src = nullptr;
  t.src_seq = nullptr;
  t.n_src = 0;
  t.copy_i = 0;
  t.sp = 0;
  t.it = 0;
}

/// Starts a build over source points 0..n_src-1 (n_src <= cap); with src_seq, only those with
/// src_seq[i] <= snapshot are taken. The source must not move until the build is done (entries
/// that change meanwhile must be filtered out by the query predicate, which HEDGER does).
inline void kd_begin_build(KdTree& t, const double* src, const uint64_t* src_seq, uint32_t n_src, uint64_t snapshot) {
  t.src = src;
  t.src_seq = src_seq;
  t.n_src = n_src;
  t.snapshot = snapshot;
  t.copy_i = 0;
  t.n = 0;
  t.n_nodes = 0;
  t.sp = 0;
  t.phase = KdPhase::kCopy;
}

inline bool kd_done(const KdTree& t) { return t.phase == KdPhase::kDone; }

/// Runs the build for about `budget` work units (it stops at the first unit boundary at or
/// after the budget). Returns the units done. No allocation.
template <int D>
uint64_t kd_build_step(KdTree& t, uint64_t budget) {
  uint64_t work = 0;
  while (work < budget && t.phase != KdPhase::kDone) {
    switch (t.phase) {
      case KdPhase::kIdle:
      case KdPhase::kDone:
        return work;
      case KdPhase::kCopy: {
        while (t.copy_i < t.n_src && work < budget) {
          const uint32_t i = t.copy_i++;
          ++work;
          if (t.src_seq != nullptr && t.src_seq[i] > t.snapshot) continue;
          const double* s = t.src + static_cast<size_t>(i) * static_cast<size_t>(D);
          double* d = t.pts + static_cast<size_t>(t.n) * static_cast<size_t>(D);
          for (int j = 0; j < D; ++j) d[j] = s[j];
          t.ids[t.n] = i;
          ++t.n;
        }
        if (t.copy_i >= t.n_src) {
          t.n_nodes = 1;
          t.stack[0] = KdJob{0, 0, t.n, kNone, 0};
          t.sp = 1;
          t.phase = KdPhase::kJob;
        }
        break;
      }
      case KdPhase::kJob: {
        if (t.sp == 0) {
          t.phase = KdPhase::kDone;
          break;
        }
        t.cur = t.stack[--t.sp];
        t.it = t.cur.begin;
        for (int j = 0; j < D; ++j) {
          t.bmin[j] = std::numeric_limits<double>::infinity();
          t.bmax[j] = -std::numeric_limits<double>::infinity();
        }
        ++work;
        t.phase = KdPhase::kBbox;
        break;
      }
      case KdPhase::kBbox: {
        while (t.it < t.cur.end && work < budget) {
          const double* p = t.pts + static_cast<size_t>(t.it) * static_cast<size_t>(D);
          for (int j = 0; j < D; ++j) {
            if (p[j] < t.bmin[j]) t.bmin[j] = p[j];
            if (p[j] > t.bmax[j]) t.bmax[j] = p[j];
          }
          ++t.it;
          ++work;
        }
        if (t.it < t.cur.end) break;
        const KdJob& c = t.cur;
        if (c.parent == kNone) {
          for (int j = 0; j < D; ++j) {
            t.root_lo[j] = t.bmin[j];
            t.root_hi[j] = t.bmax[j];
          }
        }
        if (c.parent != kNone && c.end > c.begin) {
          Node& p = t.nodes[c.parent];
          if (c.side == 0) {
            p.lo = t.bmax[p.dim];
          } else {
            p.hi = t.bmin[p.dim];
          }
        }
        Node& nd = t.nodes[c.node];
        const uint32_t m = c.end - c.begin;
        if (m <= kLeafSize || t.n_nodes + 2 > t.max_nodes || t.sp + 2 > kMaxStack) {
          nd = Node{0.0, 0.0, c.begin, c.end, kLeaf, 0};
          t.phase = KdPhase::kJob;
          break;
        }
        uint32_t dim = 0;
        double spread = t.bmax[0] - t.bmin[0];
        for (int j = 1; j < D; ++j) {
          const double s = t.bmax[j] - t.bmin[j];
          if (s > spread) {
            spread = s;
            dim = static_cast<uint32_t>(j);
          }
        }
        t.sel_dim = dim;
        t.sel_lo = c.begin;
        t.sel_hi = c.end;
        t.sel_k = c.begin + m / 2;
        t.sel_lt = kNone;  // no partition pass in progress
        t.phase = KdPhase::kSelect;
        break;
      }
      case KdPhase::kSelect: {
        const uint32_t dim = t.sel_dim;
        auto key = [&](uint32_t i) { return t.pts[static_cast<size_t>(i) * static_cast<size_t>(D) + dim]; };
        auto swap_pts = [&](uint32_t i, uint32_t j) {
          double* a = t.pts + static_cast<size_t>(i) * static_cast<size_t>(D);
          double* b = t.pts + static_cast<size_t>(j) * static_cast<size_t>(D);
          for (int q = 0; q < D; ++q) {
            const double x = a[q];
            a[q] = b[q];
            b[q] = x;
          }
          const uint32_t x = t.ids[i];
          t.ids[i] = t.ids[j];
          t.ids[j] = x;
        };
        if (t.sel_lt == kNone) {
          // New 3-way partition pass on [sel_lo, sel_hi) around the median of three.
          const double a = key(t.sel_lo);
          const double b = key(t.sel_lo + (t.sel_hi - t.sel_lo) / 2);
          const double c = key(t.sel_hi - 1);
          double piv;
          if (a < b) {
            piv = (b < c) ? b : ((a < c) ? c : a);
          } else {
            piv = (a < c) ? a : ((b < c) ? c : b);
          }
          t.sel_pivot = piv;
          t.sel_lt = t.sel_lo;
          t.it = t.sel_lo;
          t.sel_gt = t.sel_hi;
          ++work;
        }
        const double piv = t.sel_pivot;
        while (t.it < t.sel_gt && work < budget) {
          const double v = key(t.it);
          if (v < piv) {
            swap_pts(t.sel_lt, t.it);
            ++t.sel_lt;
            ++t.it;
          } else if (piv < v) {
            --t.sel_gt;
            swap_pts(t.it, t.sel_gt);
          } else {
            ++t.it;
          }
          ++work;
        }
        if (t.it < t.sel_gt) break;
        // Pass finished: [lo, lt) < pivot, [lt, gt) == pivot, [gt, hi) > pivot.
        if (t.sel_k < t.sel_lt) {
          t.sel_hi = t.sel_lt;
          t.sel_lt = kNone;
          break;
        }
        if (t.sel_k >= t.sel_gt) {
          t.sel_lo = t.sel_gt;
          t.sel_lt = kNone;
          break;
        }
        // The median is in place: [begin, k) <= x_k <= [k, end) along dim.
        const KdJob c = t.cur;
        const uint32_t left = t.n_nodes++;
        const uint32_t right = t.n_nodes++;
        const double split = key(t.sel_k);
        t.nodes[c.node] = Node{split, split, left, right, dim, 0};
        t.stack[t.sp++] = KdJob{right, t.sel_k, c.end, c.node, 1};
        t.stack[t.sp++] = KdJob{left, c.begin, t.sel_k, c.node, 0};
        t.phase = KdPhase::kJob;
        break;
      }
    }
  }
  return work;
}

/// Builds completely (no slicing). O(n log n) expected. Returns the work units.
template <int D>
uint64_t kd_build_all(KdTree& t, const double* src, const uint64_t* src_seq, uint32_t n_src, uint64_t snapshot) {
  kd_begin_build(t, src, src_seq, n_src, snapshot);
  return kd_build_step<D>(t, std::numeric_limits<uint64_t>::max());
}

/// An upper estimate of the work units of a build over n points (for the automatic per-update
/// budget): copy + per level (bbox + ~3 quickselect passes) + leaves.
inline uint64_t kd_build_work_estimate(uint64_t n) {
  uint64_t levels = 1;
  for (uint64_t m = n; m > kLeafSize; m = (m + 1) / 2) ++levels;
  return n * (2 + 4 * levels) + 2 * kd_nodes_for(n) + 16;
}

/// Recursive search. Distances count the first DQ coordinates only (DQ = D: the full point;
/// DQ = D - 1: HEDGER's state-only neighbourhoods, the action ignored); a split along an ignored
/// dimension prunes nothing.
template <int D, int DQ, class Set, class Valid>
void kd_search(const KdTree& t, uint32_t ni, const double* q, Set& rs, double rdist, double* dists,
               const Valid& valid) {
  const Node& nd = t.nodes[ni];
  if (nd.dim == kLeaf) {
    for (uint32_t i = nd.a; i < nd.b; ++i) {
      const double d = dist2<DQ>(q, t.pts + static_cast<size_t>(i) * static_cast<size_t>(D));
      if (d <= rs.worst()) {
        const uint32_t id = t.ids[i];
        if (valid(id)) rs.add(d, id);
      }
    }
    return;
  }
  const uint32_t dim = nd.dim;
  if (dim >= static_cast<uint32_t>(DQ)) {
    kd_search<D, DQ>(t, nd.a, q, rs, rdist, dists, valid);
    kd_search<D, DQ>(t, nd.b, q, rs, rdist, dists, valid);
    return;
  }
  const double v = q[dim];
  const double diff1 = v - nd.lo;
  const double diff2 = v - nd.hi;
  uint32_t best, other;
  double cut;
  if (diff1 + diff2 < 0.0) {
    best = nd.a;
    other = nd.b;
    cut = diff2 * diff2;
  } else {
    best = nd.b;
    other = nd.a;
    cut = diff1 * diff1;
  }
  kd_search<D, DQ>(t, best, q, rs, rdist, dists, valid);
  const double saved = dists[dim];
  const double nr = rdist + cut - saved;
  if (nr <= rs.worst() * kPruneSlack) {
    dists[dim] = cut;
    kd_search<D, DQ>(t, other, q, rs, nr, dists, valid);
    dists[dim] = saved;
  }
}

/// Adds the tree's valid points to a KnnSet or RadiusSet, by the distance over the first DQ
/// coordinates (default: all D). Cost O(log n + visited leaves · D) for DQ = D; with DQ < D every
/// split along an ignored dimension visits both children.
template <int D, int DQ = D, class Set, class Valid>
void kd_query(const KdTree& t, const double* q, Set& rs, const Valid& valid) {
  static_assert(DQ >= 1 && DQ <= D, "DQ counts leading coordinates");
  if (t.n == 0 || t.n_nodes == 0) return;
  // Start from the distance to the bounding box of all points (nanoflann does the same): a
  // query outside the data prunes from the first split on.
  double dists[static_cast<size_t>(D)];
  double rdist = 0.0;
  for (int j = 0; j < DQ; ++j) {
    double d = 0.0;
    if (q[j] < t.root_lo[j]) d = t.root_lo[j] - q[j];
    if (q[j] > t.root_hi[j]) d = q[j] - t.root_hi[j];
    dists[j] = d * d;
    rdist += dists[j];
  }
  if (rdist > rs.worst() * kPruneSlack) return;
  kd_search<D, DQ>(t, 0, q, rs, rdist, dists, valid);
}

/// Brute-force reference over n points (row-major n × D, ids = index), distance over the first DQ
/// coordinates: the oracle of the tests.
template <int D, int DQ = D, class Set>
void brute_query(const double* pts, uint32_t n, const double* q, Set& rs) {
  for (uint32_t i = 0; i < n; ++i) {
    const double d = dist2<DQ>(q, pts + static_cast<size_t>(i) * static_cast<size_t>(D));
    if (d <= rs.worst()) rs.add(d, i);
  }
}

}  // namespace hg

#endif  // HEDGER_KDTREE_HPP
