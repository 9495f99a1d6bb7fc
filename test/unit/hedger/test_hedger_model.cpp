// SPDX-License-Identifier: MIT
// The greedy state model's geometry (model_geometry) and value (model_value) stages against the
// plain forms they replace: the normal equations (the state model's and a prediction's) equal the
// neighbour-by-neighbour rank-1 sums bit for bit where they are read, and the IVH test, which
// scans the neighbours' leverages on demand and carries the scan across the values of one
// geometry (the replay's passes), decides as the test against the largest leverage of all
// neighbours.
#include <cmath>
#include <csetjmp>
#include <cstdarg>
#include <cstddef>
#include <cstdint>

#include "core.hpp"
#include "hedger_test_internal.hpp"

extern "C" {
#include <cmocka.h>
}

namespace {

constexpr int kD = 3;  // 2-D state + action

using ht::uniform;

// A value concave in the action with its best action moving with the state, plus noise.
double value_of(const double* s, double a, double noise) {
  const double best = 0.8 * s[0] - 0.4;
  return s[1] - 2.0 * (a - best) * (a - best) + noise;
}

// The geometry with its IVH scan completed: the largest leverage over every neighbour, as the
// test compared against before the scan went on demand.
void complete_scan(const hedger& h, const double* x, hg::ModelGeom<kD>& g) {
  using Vec = Eigen::Matrix<double, kD + 2, 1>;
  const bool unweighted = h.cfg.ivh_mode == static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED);
  double hmax = 0.0;
  for (uint32_t i = 0; i < g.n; ++i) {
    Vec r;
    hg::model_row<kD>(h, x, g.ids[i], g.abar, r);
    double hi = r.dot(g.vinv * r);
    if (!unweighted) hi *= g.w[i];
    if (hi > hmax) hmax = hi;
  }
  g.hmax = hmax;
  g.h_scanned = g.n;
}

// The normal equations, summed column by column in model_geometry() (the lower triangles of A and
// of the IVH matrix V only, B whole), hold the bits of the neighbour-by-neighbour rank-1 sums
// A = Σ (w_i r_i) r_iᵀ (+ the ridge), B = Σ (w_i² r_i) r_iᵀ and V = Σ r_i r_iᵀ (unweighted IVH) or
// A without the ridge (weighted), where they are read: A's and V's lower triangles (A is mirrored,
// V is seen through its inverse, the same bits as the plain V's), B whole.
void expect_rank_one_sums(const hedger& h, const double* x, const hg::ModelGeom<kD>& g) {
  constexpr int P = kD + 2;
  using Vec = Eigen::Matrix<double, P, 1>;
  using Mat = Eigen::Matrix<double, P, P>;
  Mat a = Mat::Zero(), b = Mat::Zero(), v = Mat::Zero();
  for (uint32_t i = 0; i < g.n; ++i) {
    Vec r;
    hg::model_row<kD>(h, x, g.ids[i], g.abar, r);
    a.noalias() += (g.w[i] * r) * r.transpose();
    b.noalias() += (g.w[i] * g.w[i] * r) * r.transpose();
    v.noalias() += r * r.transpose();
  }
  if (h.cfg.ivh_mode != static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED)) v = a;
  for (int j = 0; j < kD + 1; ++j) a(j, j) += h.cfg.ridge;
  for (int j = 0; j < P; ++j) {
    for (int k = 0; k < P; ++k) {
      if (j >= k) assert_true(a(j, k) == g.a(j, k));
      assert_true(g.a(j, k) == g.a(k, j));
      assert_true(b(j, k) == g.b(j, k));
    }
  }
  hg::FactorOf<P> vf;
  assert_true(hg::factor_spd<P>(vf, v));
  const Mat vinv = vf.inverse();
  for (int j = 0; j < P; ++j) {
    for (int k = 0; k < P; ++k) assert_true(vinv(j, k) == g.vinv(j, k));
  }
}

// The same for a prediction's geometry (fit_geometry) on the neighbourhood ids, w at the query
// (x, action): its ridge regression's factorisation, seen through c = A⁻¹ e, and its IVH outcome
// equal the plain rank-1 forms'. Returns true when the regression was formed.
bool expect_fit_rank_one_sums(const hedger& h, const double* x, const uint32_t* ids, const double* w,
                              uint32_t n) {
  constexpr int P = kD + 1;
  using Vec = Eigen::Matrix<double, P, 1>;
  using Mat = Eigen::Matrix<double, P, P>;
  hg::FitGeom<kD> g;
  hg::fit_geometry<kD>(h, x, ids, w, n, g);
  Mat a = Mat::Zero(), v = Mat::Zero();
  Vec rows[HEDGER_MAX_K];
  for (uint32_t i = 0; i < n; ++i) {
    hg::fit_row<kD>(h, x, ids[i], rows[i]);
    a.noalias() += (w[i] * rows[i]) * rows[i].transpose();
    v.noalias() += rows[i] * rows[i].transpose();
  }
  const bool unweighted = h.cfg.ivh_mode == static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED);
  if (!unweighted) v = a;
  hg::FactorOf<P> vf;
  assert_true(hg::factor_spd<P>(vf, v));
  const Mat vinv = vf.inverse();
  double hmax = 0.0;
  for (uint32_t i = 0; i < n; ++i) {
    double hi = rows[i].dot(vinv * rows[i]);
    if (!unweighted) hi *= w[i];
    hmax = hi > hmax ? hi : hmax;
  }
  const bool inside = vinv(kD, kD) <= hmax * (1.0 + hg::kIvhTol);
  assert_int_equal(g.status == hg::FitGeom<kD>::kHull, !inside);
  if (!inside) return false;
  for (int j = 0; j < kD; ++j) a(j, j) += h.cfg.ridge;
  hg::FactorOf<P> af;
  assert_true(hg::factor_spd<P>(af, a));
  assert_int_equal(g.status, hg::FitGeom<kD>::kRegression);
  Vec e = Vec::Zero();
  e[kD] = 1.0;
  const Vec c = af.solve(e);
  for (int j = 0; j < P; ++j) assert_true(c[j] == g.c[j]);
  return true;
}

void check_against_plain_forms(uint32_t ivh_mode) {
  // The plain forms are the same sums in the same order: the same bits, unless the compiler fuses
  // multiplies and adds differently in the two (AArch64), where the test has nothing exact to say.
  if (!ht::kExact) skip();
  hedger_config_t c = hedger_config_default();
  c.state_dim = 2;
  c.capacity = 3000;
  c.k_max = 32;
  c.greedy_method = static_cast<uint32_t>(HEDGER_GREEDY_STATE_MODEL);
  c.ivh_mode = ivh_mode;
  hedger_t* hp = nullptr;
  assert_int_equal(hedger_create(&hp, &c), HEDGER_OK);
  hedger& h = *hp;
  uint64_t rng = 7;
  for (int i = 0; i < 2500; ++i) {
    const double s[2] = {uniform(rng), uniform(rng)};
    const double a = 2.0 * uniform(rng) - 1.0;
    assert_int_equal(hedger_insert(hp, s, a, value_of(s, a, 0.05 * (uniform(rng) - 0.5)), 0, nullptr), HEDGER_OK);
  }
  hedger_observe_reward(hp, -1.0);
  hedger_observe_reward(hp, 1.0);
  uint32_t models = 0, lwr = 0, lwa = 0, stopped_early = 0, fits = 0;
  double* const val = h.val;
  const uint32_t fill = h.fill;
  double base[3000];
  for (uint32_t i = 0; i < fill; ++i) base[i] = val[i];
  for (int q = 0; q < 300; ++q) {
    // States up to a fifth beyond the data: some chosen actions fall outside the hull.
    double x[kD] = {1.4 * uniform(rng) - 0.2, 1.4 * uniform(rng) - 0.2, 0.0};
    for (uint32_t i = 0; i < fill; ++i) val[i] = base[i];
    hg::ModelGeom<kD> g;
    hg::model_geometry<kD>(h, x, 1.0, g);
    if (g.status != hg::ModelGeom<kD>::kFormed || !g.v_ok) continue;
    expect_rank_one_sums(h, x, g);
    // A prediction at (x, the neighbourhood's mean action) on the same neighbours.
    x[kD - 1] = g.abar;
    if (expect_fit_rank_one_sums(h, x, g.ids, g.w, g.n)) ++fits;
    x[kD - 1] = 0.0;
    hg::ModelGeom<kD> full = g;
    complete_scan(h, x, full);
    // Three passes over one geometry with other values, as the replay's: the chosen action moves.
    for (int pass = 0; pass < 3; ++pass) {
      for (uint32_t i = 0; i < fill; ++i) {
        const double* p = h.pts + static_cast<size_t>(i) * kD;
        val[i] = base[i] + 0.6 * pass * p[kD - 1];
      }
      hg::GreedyResult got{}, want{};
      const bool ok_got = hg::model_value<kD>(h, x, g, got);
      const bool ok_want = hg::model_value<kD>(h, x, full, want);
      assert_int_equal(ok_got, ok_want);
      if (!ok_got) continue;
      ++models;
      assert_int_equal(got.kind, want.kind);
      assert_true(got.action == want.action);
      assert_true(got.value == want.value);
      if (got.kind == HEDGER_KIND_LWR) ++lwr;
      if (got.kind == HEDGER_KIND_LWA) ++lwa;
      if (got.kind == HEDGER_KIND_LWR && g.h_scanned < g.n) ++stopped_early;
    }
  }
  // Not vacuous: both outcomes occur, and the scan often stops before the last neighbour.
  assert_true(models > 300);
  assert_true(lwr > 50);
  assert_true(lwa > 5);
  assert_true(stopped_early > 50);
  assert_true(fits > 100);
  hedger_destroy(hp);
}

void test_model_matches_plain_forms(void** state) {
  (void)state;
  check_against_plain_forms(static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED));
}

void test_model_matches_plain_forms_weighted_ivh(void** state) {
  (void)state;
  check_against_plain_forms(static_cast<uint32_t>(HEDGER_IVH_WEIGHTED));
}

}  // namespace

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_model_matches_plain_forms),
      cmocka_unit_test(test_model_matches_plain_forms_weighted_ivh),
  };
  return cmocka_run_group_tests_name("hedger.model", tests, nullptr, nullptr);
}
