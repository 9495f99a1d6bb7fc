// SPDX-License-Identifier: MIT
// The one place where Eigen's decompositions are instantiated for HEDGER (see linalg.hpp).
#include "linalg.hpp"

#include <Eigen/Eigenvalues>

namespace hg {

bool SymFactor::compute(const SysMat& m) noexcept {
  ldlt_.compute(m);
  return ldlt_.info() == Eigen::Success;
}

int SymFactor::size() const noexcept { return static_cast<int>(ldlt_.rows()); }

double SymFactor::pivot(int i) const noexcept { return ldlt_.vectorD()[i]; }

void SymFactor::solve(const SysVec& b, SysVec& x) const noexcept { x = ldlt_.solve(b); }

void SymFactor::inverse(SysMat& out) const noexcept {
  out = ldlt_.solve(SysMat::Identity(ldlt_.rows(), ldlt_.cols()));
}

bool sym_eigen_extremes(const SysMat& m, double* lo, double* hi) noexcept {
  Eigen::SelfAdjointEigenSolver<SysMat> eig;
  eig.compute(m, Eigen::EigenvaluesOnly);
  if (eig.info() != Eigen::Success) return false;
  const auto& ev = eig.eigenvalues();  // ascending
  *lo = ev[0];
  *hi = ev[ev.size() - 1];
  return true;
}

}  // namespace hg
