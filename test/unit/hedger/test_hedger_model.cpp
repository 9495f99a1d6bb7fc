// SPDX-License-Identifier: MIT
// The greedy state model's geometry (model_geometry) and value (model_value) stages against the
// plain forms they replace: the normal equations equal the neighbour-by-neighbour rank-1 sums bit
// for bit, and the IVH test, which scans the neighbours' leverages on demand and carries the scan
// across the values of one geometry (the replay's passes), decides as the test against the
// largest leverage of all neighbours.
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

// The normal equations, summed column by column in model_geometry(), hold the bits of the
// neighbour-by-neighbour rank-1 sums A = Σ (w_i r_i) r_iᵀ (+ the ridge) and B = Σ (w_i² r_i) r_iᵀ.
void expect_rank_one_sums(const hedger& h, const double* x, const hg::ModelGeom<kD>& g) {
  using Vec = Eigen::Matrix<double, kD + 2, 1>;
  using Mat = Eigen::Matrix<double, kD + 2, kD + 2>;
  Mat a = Mat::Zero(), b = Mat::Zero();
  for (uint32_t i = 0; i < g.n; ++i) {
    Vec r;
    hg::model_row<kD>(h, x, g.ids[i], g.abar, r);
    a.noalias() += (g.w[i] * r) * r.transpose();
    b.noalias() += (g.w[i] * g.w[i] * r) * r.transpose();
  }
  for (int j = 0; j < kD + 1; ++j) a(j, j) += h.cfg.ridge;
  for (int j = 0; j < kD + 2; ++j) {
    for (int k = 0; k < kD + 2; ++k) {
      assert_true(a(j, k) == g.a(j, k));
      assert_true(b(j, k) == g.b(j, k));
    }
  }
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
  uint32_t models = 0, lwr = 0, lwa = 0, stopped_early = 0;
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
