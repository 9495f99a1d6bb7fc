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
#ifndef HEDGER_LINALG_HPP
#define HEDGER_LINALG_HPP

#include <Eigen/Cholesky>
#include <Eigen/Core>

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

/// Smallest and largest eigenvalue of the symmetric matrix m (Eigen::SelfAdjointEigenSolver,
/// eigenvalues only). False when the solver does not converge. O(n³), no allocation.
bool sym_eigen_extremes(const SysMat& m, double* lo, double* hi) noexcept;
/// Smallest ratio min|d_i| / max|d_i| of the pivots of the (pivoted) LDLT factorisation accepted
/// for the IVH and the LWR normal equations; below it (or with a non-positive pivot) the
/// neighbourhood is treated as singular (LWA). For these small SPD matrices the pivot ratio is a
/// cheap proxy of 1/cond; exact collinearity (e.g. every neighbour with the same action) gives a
/// ratio near 1e-17.
constexpr double kPivotRatioMin = 1e-12;

/// Factorises a symmetric matrix; false if it is not numerically positive definite.
template <class Mat>
bool factor_spd(SymFactor& ldlt, const Eigen::MatrixBase<Mat>& m) noexcept {
  if (!ldlt.compute_from(m)) return false;
  double dmin = ldlt.pivot(0), dmax = dmin;
  for (int i = 1; i < ldlt.size(); ++i) {
    const double d = ldlt.pivot(i);
    if (d < dmin) dmin = d;
    if (d > dmax) dmax = d;
  }
  return dmin > 0.0 && dmin > kPivotRatioMin * dmax;
}

}  // namespace hg

#endif  // HEDGER_LINALG_HPP
