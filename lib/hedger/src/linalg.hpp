// SPDX-License-Identifier: MIT
// HEDGER's small dense linear algebra (internal): the symmetric factorisation behind every
// regression and the eigenvalue check of spans_inputs(), for systems of up to kMaxSystem unknowns.
//
// Why not Eigen's decompositions on the fixed-size types of core.hpp directly: each input
// dimension D is its own translation unit, and every LDLT / eigensolver of a fixed size is a
// separate template instantiation in every unit that uses it (five sizes per D). Their
// instantiation was most of the library's compile time (about 100 s of CPU per dimension in the
// sanitizer build). Here they are instantiated once, in linalg.cpp, on dynamic-size matrices with
// a fixed maximum: the storage is still inline (no allocation, EIGEN_NO_MALLOC holds), and the
// algorithm is Eigen's, unchanged. Cost: one copy of the matrix in and of the result out, O(n²);
// the library's compile time fell from 29 s to 6 s of CPU per dimension (Release, D = 6), and
// hedger.bench's latencies stayed within their run-to-run spread (three interleaved runs each, p50
// of a prediction at 1,000 points 3.5-4.6 us before, 3.5-6.6 us after; at 20,000 points 8.0 and
// 7.7 us).
//
// HEDGER's own systems (orders D, D + 1, D + 2) are factorised by FixedLdlt up to order 8: the
// same arithmetic as SymFactor in short fixed-size loops (a small template, cheap to compile),
// without the dynamic path's copies and dispatch, which cost several times the arithmetic at these
// sizes. Larger orders (D >= 7's state model) keep SymFactor (FactorOf<N> picks).
#ifndef HEDGER_LINALG_HPP
#define HEDGER_LINALG_HPP

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>
#include <cstddef>
#include <limits>
#include <type_traits>
#include <utility>

#include "hedger/hedger.h"

namespace hg {

/// Largest system: the greedy state model's P = D + 2 parameters at the largest input dimension.
constexpr int kMaxSystem = static_cast<int>(HEDGER_MAX_INPUT_DIM) + 2;

using SysMat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor, kMaxSystem, kMaxSystem>;
using SysVec = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxSystem, 1>;

/// LDLᵀ factorisation with diagonal pivoting (Eigen::LDLT) of a symmetric n × n matrix,
/// n <= kMaxSystem. No allocation; about sizeof(double) × 2 kMaxSystem² bytes.
class SymFactor {
 public:
  /// Factorises m (its lower triangle is read). True when Eigen reports success; the pivots then
  /// tell how definite m is (see factor_spd() below). O(n³).
  bool compute(const SysMat& m) noexcept;
  /// Order n of the last factorised matrix.
  int size() const noexcept;
  /// Pivot i of D (the diagonal of the factorisation, in pivoted order), 0 <= i < size().
  double pivot(int i) const noexcept;
  /// x = m⁻¹ b. O(n²).
  void solve(const SysVec& b, SysVec& x) const noexcept;
  /// out = m⁻¹. O(n³).
  void inverse(SysMat& out) const noexcept;

  /// The same for the fixed-size types of core.hpp (copied in and out).
  template <class M>
  bool compute_from(const Eigen::MatrixBase<M>& m) noexcept {
    const SysMat s = m;
    return compute(s);
  }
  template <class V>
  V solve(const V& b) const noexcept {
    const SysVec in = b;
    SysVec x;
    solve(in, x);
    return V(x);
  }
  template <class M>
  M inverse_as() const noexcept {
    SysMat x;
    inverse(x);
    return M(x);
  }

 private:
  Eigen::LDLT<SysMat> ldlt_;
};

/// Largest order FixedLdlt factorises itself; larger ones go to SymFactor (FactorOf<N>). Up to
/// this order Eigen's triangular solves run in one panel (EIGEN_TUNE_TRIANGULAR_PANEL_WIDTH = 8),
/// whose arithmetic FixedLdlt repeats operation by operation.
constexpr int kFixedLdltMax = 8;

/// Eigen::LDLT's factorisation and solve of a symmetric N × N matrix (N <= kFixedLdltMax) on
/// fixed-size storage, without SymFactor's copies into and out of the dynamic type, its L1 norm
/// (which nothing here reads) or Eigen's dispatch: the same operations in the same order
/// (Eigen 3.4's ldlt_inplace<Lower>::unblocked, the one-panel triangular_solve_vector and its
/// sums' order), so the pivots and solutions are bit-identical to SymFactor's (checked against it
/// on random, semi-definite and indefinite matrices by hedger.linalg's test). Why: the dynamic
/// path cost about 2,700 instructions per 7 × 7 factorisation, 1,000 per solve and 9,000 per
/// inverse (callgrind on b21r-train at the controller's defaults), several times the arithmetic.
/// inverse() solves column by column; its last bits may differ from Eigen's blocked solve of the
/// identity (it feeds only comparisons with a tolerance: the IVH tests and the pessimism's ranking).
/// sizeof = 8 N² + 4 N bytes (+ padding); no allocation.
template <int N>
class FixedLdlt {
  static_assert(N >= 1 && N <= kFixedLdltMax, "FixedLdlt: order 1..kFixedLdltMax");
  static constexpr size_t kN = static_cast<size_t>(N);

 public:
  using Mat = Eigen::Matrix<double, N, N>;
  using Vec = Eigen::Matrix<double, N, 1>;
  /// Factorises m (its lower triangle is read). False where Eigen reports NumericalIssue. O(N³).
  bool compute(const Mat& m) noexcept {
    for (int j = 0; j < N; ++j) {
      for (int i = j; i < N; ++i) l_[j][i] = m(i, j);
    }
    if (N <= 1) {
      t_[0] = 0;
      return true;
    }
    bool found_zero_pivot = false;
    bool ret = true;
    double temp[kN];
    for (int k = 0; k < N; ++k) {
      // The largest |diagonal| of the trailing corner, the first of equal ones (maxCoeff).
      int big = k;
      double bv = std::abs(l_[k][k]);
      for (int i = k + 1; i < N; ++i) {
        const double v = std::abs(l_[i][i]);
        if (v > bv) {
          bv = v;
          big = i;
        }
      }
      t_[k] = big;
      if (k != big) {
        for (int j = 0; j < k; ++j) std::swap(l_[j][k], l_[j][big]);
        for (int i = big + 1; i < N; ++i) std::swap(l_[k][i], l_[big][i]);
        std::swap(l_[k][k], l_[big][big]);
        for (int i = k + 1; i < big; ++i) {
          const double tmp = l_[k][i];
          l_[k][i] = l_[i][big];
          l_[i][big] = tmp;
        }
      }
      const int rs = N - k - 1;
      if (k > 0) {
        for (int i = 0; i < k; ++i) temp[i] = l_[i][i] * l_[i][k];
        // (A10 · temp): a strided sum, first term first.
        double s = l_[0][k] * temp[0];
        for (int i = 1; i < k; ++i) s += l_[i][k] * temp[i];
        l_[k][k] -= s;
        if (rs == 1) {
          // Eigen's product falls back to a dot product for a single row.
          double d = l_[0][k + 1] * temp[0];
          for (int i = 1; i < k; ++i) d += l_[i][k + 1] * temp[i];
          l_[k][k + 1] += -1.0 * d;
        } else if (rs > 1) {
          // General matrix-vector product: each row's sum from zero, then added times -1.
          for (int r = k + 1; r < N; ++r) {
            double c = 0.0;
            for (int i = 0; i < k; ++i) c += l_[i][r] * temp[i];
            l_[k][r] += c * -1.0;
          }
        }
      }
      const double akk = l_[k][k];
      const bool pivot_is_valid = std::abs(akk) > 0.0;
      if (k == 0 && !pivot_is_valid) {
        for (int j = 0; j < N; ++j) {
          t_[j] = j;
          for (int i = j + 1; i < N; ++i) ret = ret && l_[j][i] >= 0.0 && l_[j][i] <= 0.0;
        }
        return ret;
      }
      if (rs > 0 && pivot_is_valid) {
        for (int r = k + 1; r < N; ++r) l_[k][r] /= akk;
      } else if (rs > 0) {
        for (int r = k + 1; r < N; ++r) ret = ret && l_[k][r] >= 0.0 && l_[k][r] <= 0.0;
      }
      if (found_zero_pivot && pivot_is_valid) {
        ret = false;
      } else if (!pivot_is_valid) {
        found_zero_pivot = true;
      }
    }
    return ret;
  }
  int size() const noexcept { return N; }
  /// Pivot i of D (pivoted order).
  double pivot(int i) const noexcept { return l_[i][i]; }
  /// m⁻¹ b. O(N²).
  Vec solve(const Vec& b) const noexcept {
    double x[kN];
    for (int i = 0; i < N; ++i) x[i] = b[i];
    solve_in_place(x);
    Vec out;
    for (int i = 0; i < N; ++i) out[i] = x[i];
    return out;
  }
  /// m⁻¹, column by column. O(N³).
  Mat inverse() const noexcept {
    Mat out;
    for (int j = 0; j < N; ++j) {
      double x[kN];
      for (int i = 0; i < N; ++i) x[i] = i == j ? 1.0 : 0.0;
      solve_in_place(x);
      for (int i = 0; i < N; ++i) out(i, j) = x[i];
    }
    return out;
  }

 private:
  void solve_in_place(double* x) const noexcept {
    for (int k = 0; k < N; ++k) {
      if (t_[k] != k) std::swap(x[k], x[t_[k]]);
    }
    // L (unit lower, column by column; a zero entry is skipped as Eigen does).
    for (int i = 0; i < N; ++i) {
      if (!(x[i] >= 0.0 && x[i] <= 0.0)) {  // x[i] != 0 (NaN included)
        for (int r = i + 1; r < N; ++r) x[r] -= x[i] * l_[i][r];
      }
    }
    // D's pseudo-inverse.
    for (int i = 0; i < N; ++i) {
      const double d = l_[i][i];
      if (std::abs(d) > std::numeric_limits<double>::min()) {
        x[i] /= d;
      } else {
        x[i] = 0.0;
      }
    }
    // Lᵀ (unit upper, row by row): each row's sum in Eigen's vectorised reduction order.
    for (int k = 1; k < N; ++k) {
      const int i = N - k - 1;
      x[i] -= redux_sum(&l_[i][i + 1], x + i + 1, k);
    }
    for (int k = N - 1; k >= 0; --k) {
      if (t_[k] != k) std::swap(x[k], x[t_[k]]);
    }
  }
  /// Σ a_j b_j, j < n, in the order of Eigen's redux over packets of two doubles (two packet
  /// accumulators over blocks of four, then one more packet, the packet's two lanes, the tail).
  static double redux_sum(const double* a, const double* b, int n) noexcept {
    if (n < 2) return a[0] * b[0];
    const int size2 = (n / 4) * 4;
    const int size1 = (n / 2) * 2;
    double p0 = a[0] * b[0], p1 = a[1] * b[1];
    if (size1 > 2) {
      double q0 = a[2] * b[2], q1 = a[3] * b[3];
      for (int j = 4; j < size2; j += 4) {
        p0 = p0 + a[j] * b[j];
        p1 = p1 + a[j + 1] * b[j + 1];
        q0 = q0 + a[j + 2] * b[j + 2];
        q1 = q1 + a[j + 3] * b[j + 3];
      }
      p0 = p0 + q0;
      p1 = p1 + q1;
      if (size1 > size2) {
        p0 = p0 + a[size2] * b[size2];
        p1 = p1 + a[size2 + 1] * b[size2 + 1];
      }
    }
    double res = p0 + p1;
    for (int j = size1; j < n; ++j) res = res + a[j] * b[j];
    return res;
  }

  double l_[kN][kN];  ///< column-major: l_[j][i] = entry (i, j); the strict lower part is L, the diagonal D
  int t_[kN];      ///< transpositions
};

/// SymFactor with FixedLdlt's interface for one order N (orders above kFixedLdltMax).
template <int N>
class DynLdlt {
 public:
  using Mat = Eigen::Matrix<double, N, N>;
  using Vec = Eigen::Matrix<double, N, 1>;
  bool compute(const Mat& m) noexcept { return f_.compute_from(m); }
  int size() const noexcept { return f_.size(); }
  double pivot(int i) const noexcept { return f_.pivot(i); }
  Vec solve(const Vec& b) const noexcept { return f_.solve(b); }
  Mat inverse() const noexcept { return f_.template inverse_as<Mat>(); }

 private:
  SymFactor f_;
};

/// The factorisation of a symmetric N × N matrix: FixedLdlt up to kFixedLdltMax, else SymFactor.
template <int N>
using FactorOf = typename std::conditional<(N <= kFixedLdltMax), FixedLdlt<N>, DynLdlt<N>>::type;

/// Smallest and largest eigenvalue of the symmetric matrix m (Eigen::SelfAdjointEigenSolver,
/// eigenvalues only). False when the solver does not converge. O(n³), no allocation.
bool sym_eigen_extremes(const SysMat& m, double* lo, double* hi) noexcept;
/// Smallest ratio min|d_i| / max|d_i| of the pivots of the (pivoted) LDLT factorisation accepted
/// for the IVH and the LWR normal equations; below it (or with a non-positive pivot) the
/// neighbourhood is treated as singular (LWA). For these small SPD matrices the pivot ratio is a
/// cheap proxy of 1/cond; exact collinearity (e.g. every neighbour with the same action) gives a
/// ratio near 1e-17.
constexpr double kPivotRatioMin = 1e-12;

/// True when a successful factorisation's pivots show a numerically positive definite matrix.
template <class F>
bool pivots_spd(const F& ldlt) noexcept {
  double dmin = ldlt.pivot(0), dmax = dmin;
  for (int i = 1; i < ldlt.size(); ++i) {
    const double d = ldlt.pivot(i);
    if (d < dmin) dmin = d;
    if (d > dmax) dmax = d;
  }
  return dmin > 0.0 && dmin > kPivotRatioMin * dmax;
}

/// Factorises a symmetric matrix; false if it is not numerically positive definite.
template <class Mat>
bool factor_spd(SymFactor& ldlt, const Eigen::MatrixBase<Mat>& m) noexcept {
  if (!ldlt.compute_from(m)) return false;
  return pivots_spd(ldlt);
}

/// The same for FactorOf<N>.
template <int N>
bool factor_spd(FactorOf<N>& ldlt, const Eigen::Matrix<double, N, N>& m) noexcept {
  if (!ldlt.compute(m)) return false;
  return pivots_spd(ldlt);
}

}  // namespace hg

#endif  // HEDGER_LINALG_HPP
