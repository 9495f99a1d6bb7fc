// SPDX-License-Identifier: MIT
// FixedLdlt (linalg.hpp) must give bit for bit SymFactor's (Eigen::LDLT's) success flag, pivots
// and solutions, on the matrices HEDGER factorises (weighted normal matrices with a ridge, of
// full or deficient rank) and on harder ones (indefinite, zero pivots, tied diagonals, zeros);
// its inverse must be the inverse.
#include <cmath>
#include <csetjmp>
#include <cstdarg>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <type_traits>

#include "hedger_test_internal.hpp"
#include "linalg.hpp"

extern "C" {
#include <cmocka.h>
}

namespace {

using ht::kExact;
using ht::splitmix;
using ht::uniform;

// Bit for bit where ht::kExact; elsewhere the two agree to rounding on the positive definite
// matrices only.

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }
bool close(double a, double b) { return std::abs(a - b) <= 1e-8 * (1.0 + std::abs(a) + std::abs(b)); }

enum Kind { kNormal, kDeficient, kGrid, kIndefinite, kZeroRows, kKinds };

// A symmetric N × N matrix of the given kind (the lower triangle is what both factorisations read;
// the upper one is filled too, with other values, to check that).
template <int N>
Eigen::Matrix<double, N, N> make_matrix(Kind kind, uint64_t& s) {
  using Mat = Eigen::Matrix<double, N, N>;
  using Vec = Eigen::Matrix<double, N, 1>;
  Mat m = Mat::Zero();
  if (kind == kIndefinite) {
    for (int j = 0; j < N; ++j) {
      for (int i = j; i < N; ++i) m(i, j) = uniform(s) * 2.0 - 1.0;
    }
  } else {
    // Σ w_i r_i r_iᵀ over rows r_i = [x_i, 1] (+ a ridge on all but the last entry, sometimes).
    const int rows = kind == kDeficient ? 1 + static_cast<int>(splitmix(s) % static_cast<uint64_t>(N))
                                        : N + static_cast<int>(splitmix(s) % 24u);
    for (int k = 0; k < rows; ++k) {
      Vec r;
      for (int j = 0; j + 1 < N; ++j) {
        r[j] = kind == kGrid ? static_cast<double>(splitmix(s) % 3u) * 0.5 - 0.5 : uniform(s) * 0.4 - 0.2;
      }
      r[N - 1] = 1.0;
      if (kind == kZeroRows && N > 1) r[static_cast<int>(splitmix(s) % static_cast<uint64_t>(N - 1))] = 0.0;
      const double w = kind == kGrid ? 1.0 : uniform(s);
      m.noalias() += (w * r) * r.transpose();
    }
    if (splitmix(s) % 2u == 0) {
      for (int j = 0; j + 1 < N; ++j) m(j, j) += 1e-3;
    }
    if (kind == kZeroRows) {
      const int z = static_cast<int>(splitmix(s) % static_cast<uint64_t>(N));
      m.row(z).setZero();
      m.col(z).setZero();
    }
  }
  for (int j = 0; j < N; ++j) {
    for (int i = 0; i < j; ++i) m(i, j) = uniform(s);  // never read
  }
  return m;
}

template <int N>
void check_order(uint64_t seed, int trials) {
  using Mat = Eigen::Matrix<double, N, N>;
  using Vec = Eigen::Matrix<double, N, 1>;
  uint64_t s = seed;
  int spd = 0;
  for (int t = 0; t < trials; ++t) {
    const Kind kind = static_cast<Kind>(t % kKinds);
    const Mat m = make_matrix<N>(kind, s);
    hg::SymFactor ref;
    hg::FixedLdlt<N> fix;
    const bool ok_ref = ref.compute_from(m);
    const bool ok_fix = fix.compute(m);
    assert_int_equal(ref.size(), fix.size());
    const bool spd_ref = hg::factor_spd(ref, m);
    const bool spd_fix = hg::factor_spd<N>(fix, m);
    if (kExact || (spd_ref && spd_fix)) {
      if (kExact) assert_int_equal(ok_ref, ok_fix);
      for (int i = 0; i < N; ++i) {
        assert_true(kExact ? same_bits(ref.pivot(i), fix.pivot(i)) : close(ref.pivot(i), fix.pivot(i)));
      }
      for (int rhs = 0; rhs < 3; ++rhs) {
        Vec b;
        for (int i = 0; i < N; ++i) b[i] = rhs == 2 && i % 2 == 0 ? 0.0 : uniform(s) * 2.0 - 1.0;
        if (rhs == 1) b = Vec::Unit(static_cast<int>(splitmix(s) % static_cast<uint64_t>(N)));
        const Vec x_ref = ref.solve(b);
        const Vec x_fix = fix.solve(b);
        for (int i = 0; i < N; ++i) assert_true(kExact ? same_bits(x_ref[i], x_fix[i]) : close(x_ref[i], x_fix[i]));
      }
    }
    if (kExact) assert_int_equal(spd_ref, spd_fix);
    if (spd_fix) {
      ++spd;
      // The inverse: m · m⁻¹ = I within rounding (the normal matrices here are well conditioned
      // enough for 1e-6 after the pivot-ratio test).
      Mat sym = m.template selfadjointView<Eigen::Lower>();
      const Mat prod = sym * fix.inverse();
      const double err = (prod - Mat::Identity()).cwiseAbs().maxCoeff();
      assert_true(err < 1e-6 * (1.0 + sym.cwiseAbs().maxCoeff() * fix.inverse().cwiseAbs().maxCoeff() * 1e-6));
    }
  }
  assert_true(spd > 0);
}

void test_fixed_ldlt_matches_eigen_bit_for_bit(void**) {
  constexpr int kTrials = 3000;
  check_order<2>(2, kTrials);
  check_order<3>(3, kTrials);
  check_order<4>(4, kTrials);
  check_order<5>(5, kTrials);
  check_order<6>(6, kTrials);
  check_order<7>(7, kTrials);
  check_order<8>(8, kTrials);
}

// Above kFixedLdltMax the factorisation is SymFactor itself.
void test_factor_of_large_orders_is_symfactor(void**) {
  static_assert(std::is_same<hg::FactorOf<8>, hg::FixedLdlt<8>>::value, "orders up to 8 are fixed");
  static_assert(std::is_same<hg::FactorOf<9>, hg::DynLdlt<9>>::value, "order 9 is SymFactor's");
  uint64_t s = 9;
  const Eigen::Matrix<double, 9, 9> m = make_matrix<9>(kNormal, s);
  hg::FactorOf<9> f;
  hg::SymFactor ref;
  assert_int_equal(f.compute(m), ref.compute_from(m));
  // The same code on both sides: equal on every architecture.
  for (int i = 0; i < 9; ++i) assert_true(same_bits(f.pivot(i), ref.pivot(i)));
}

}  // namespace

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_fixed_ldlt_matches_eigen_bit_for_bit),
      cmocka_unit_test(test_factor_of_large_orders_is_symfactor),
  };
  return cmocka_run_group_tests_name("hedger.linalg", tests, nullptr, nullptr);
}
