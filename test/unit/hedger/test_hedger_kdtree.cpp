// SPDX-License-Identifier: MIT
// The kd-tree's k-NN and radius queries must equal a brute-force scan, bit for bit.
#include <b21r_test/alloc_counter.h>

#include <algorithm>
#include <cstdarg>
#include <cstddef>
#include <csetjmp>
#include <cstdint>
#include <vector>

#include "hedger_test_internal.hpp"
#include "kdtree.hpp"

extern "C" {
#include <cmocka.h>
}

namespace {

using hg::KdTree;
using hg::KnnSet;
using hg::Neighbour;
using hg::Node;
using hg::RadiusSet;

using ht::splitmix;
using ht::uniform;

struct TreeMem {
  std::vector<double> pts;
  std::vector<uint32_t> ids;
  std::vector<Node> nodes;
  KdTree t{};
  explicit TreeMem(uint32_t cap, int dim)
      : pts(static_cast<size_t>(cap) * static_cast<size_t>(dim) + 1), ids(cap + 1), nodes(hg::kd_max_nodes(cap)) {
    hg::kd_bind(t, pts.data(), ids.data(), nodes.data(), cap);
  }
};

// Data: uniform, or drawn from a coarse grid so that exact duplicates and distance ties abound.
std::vector<double> make_points(uint32_t n, int dim, bool grid, uint64_t seed) {
  std::vector<double> p(static_cast<size_t>(n) * static_cast<size_t>(dim));
  for (double& x : p) x = grid ? static_cast<double>(splitmix(seed) % 4) * 0.25 : uniform(seed) * 2.0 - 1.0;
  return p;
}

void expect_same(const Neighbour* a, uint32_t na, const Neighbour* b, uint32_t nb) {
  assert_int_equal(na, nb);
  for (uint32_t i = 0; i < na; ++i) {
    assert_int_equal(a[i].id, b[i].id);
    assert_true(a[i].d2 == b[i].d2);
  }
}

template <int D>
void check_dim(uint32_t n, bool grid, uint64_t seed, uint64_t slice) {
  const std::vector<double> pts = make_points(n, D, grid, seed);
  TreeMem mem(n, D);
  if (slice == 0) {
    hg::kd_build_all<D>(mem.t, pts.data(), nullptr, n, 0);
  } else {
    hg::kd_begin_build(mem.t, pts.data(), nullptr, n, 0);
    uint64_t steps = 0;
    while (!hg::kd_done(mem.t)) {
      const uint64_t w = hg::kd_build_step<D>(mem.t, slice);
      // A slice may overrun its budget by at most one unit of bookkeeping.
      assert_true(w <= slice + 1);
      ++steps;
      assert_true(steps < 100000000u);
    }
  }
  assert_int_equal(mem.t.n, n);
  assert_true(mem.t.n_nodes <= mem.t.max_nodes);
  uint64_t qs = seed ^ 0xABCDEFull;
  const uint32_t ks[] = {1, 2, 3, 10, 64};
  const double radii[] = {0.0, 0.05, 0.3, 1.0, 1e9};
  Neighbour a[64], b[64];
  std::vector<Neighbour> ra(n + 1), rb(n + 1);
  auto all = [](uint32_t) { return true; };
  for (int qi = 0; qi < 24; ++qi) {
    double q[static_cast<size_t>(D)];
    // Half the queries sit exactly on a stored point (zero distances, ties).
    if (n > 0 && (qi % 2) == 0) {
      const size_t j = splitmix(qs) % n;
      for (int d = 0; d < D; ++d) q[d] = pts[j * static_cast<size_t>(D) + static_cast<size_t>(d)];
    } else {
      for (int d = 0; d < D; ++d) q[d] = grid ? static_cast<double>(splitmix(qs) % 5) * 0.25 - 0.125 : uniform(qs) * 2.4 - 1.2;
    }
    for (uint32_t k : ks) {
      for (double r : radii) {
        const double r2 = r * r;
        KnnSet sa(a, k, r2), sb(b, k, r2);
        hg::kd_query<D>(mem.t, q, sa, all);
        hg::brute_query<D>(pts.data(), n, q, sb);
        expect_same(a, sa.size(), b, sb.size());
        // KnnCollect: the same entries in the same order, with a buffer that rarely fills (256)
        // and one that fills and compacts often (the smallest allowed, 2 k).
        Neighbour c[64];
        hg::KnnCollect<256> sc(k, r2);
        hg::kd_query<D>(mem.t, q, sc, all);
        expect_same(c, sc.finish(c), b, sb.size());
        if (k <= 3) {
          hg::KnnCollect<6> sd(k, r2);
          hg::kd_query<D>(mem.t, q, sd, all);
          expect_same(c, sd.finish(c), b, sb.size());
        }
        if (D > 1) {
          // State-only distances (the first D - 1 coordinates).
          constexpr int DQ = D > 1 ? D - 1 : 1;
          KnnSet se(b, k, r2);
          hg::brute_query<D, DQ>(pts.data(), n, q, se);
          hg::KnnCollect<128> sf(k, r2);
          hg::kd_query<D, DQ>(mem.t, q, sf, all);
          expect_same(c, sf.finish(c), b, se.size());
        }
      }
    }
    for (double r : radii) {
      RadiusSet sa(ra.data(), n, r * r), sb(rb.data(), n, r * r);
      hg::kd_query<D>(mem.t, q, sa, all);
      hg::brute_query<D>(pts.data(), n, q, sb);
      assert_int_equal(sa.total(), sb.total());
      auto by_d_id = [](const Neighbour& x, const Neighbour& y) { return hg::nb_less(x.d2, x.id, y.d2, y.id); };
      std::sort(ra.begin(), ra.begin() + sa.size(), by_d_id);
      std::sort(rb.begin(), rb.begin() + sb.size(), by_d_id);
      expect_same(ra.data(), sa.size(), rb.data(), sb.size());
    }
  }
}

template <int D>
void check_all_sizes() {
  const uint32_t sizes[] = {0, 1, 2, 7, 8, 9, 37, 300, 3000};
  for (uint32_t n : sizes) {
    for (int grid = 0; grid < 2; ++grid) {
      check_dim<D>(n, grid != 0, 1000u * n + static_cast<uint64_t>(D) * 7u + static_cast<uint64_t>(grid), 0);
    }
  }
}

// k-NN and radius results equal brute force in every dimension 1..9 and size 0..3000.
void test_kdtree_queries_match_brute_force(void**) {
  check_all_sizes<1>();
  check_all_sizes<2>();
  check_all_sizes<3>();
  check_all_sizes<4>();
  check_all_sizes<5>();
  check_all_sizes<6>();
  check_all_sizes<7>();
  check_all_sizes<8>();
  check_all_sizes<9>();
}

// A tree built in tiny work slices answers exactly like brute force too.
void test_kdtree_sliced_build_matches_brute_force(void**) {
  check_dim<4>(3000, false, 11, 1);
  check_dim<4>(3000, true, 12, 7);
  check_dim<3>(500, false, 13, 64);
  check_dim<9>(1000, false, 14, 1000);
}

// Entries refused by the validity predicate never appear; the rest equal a filtered scan.
void test_kdtree_predicate_filters_entries(void**) {
  constexpr int D = 4;
  const uint32_t n = 2000;
  const std::vector<double> pts = make_points(n, D, false, 99);
  TreeMem mem(n, D);
  hg::kd_build_all<D>(mem.t, pts.data(), nullptr, n, 0);
  auto odd_out = [](uint32_t id) { return (id % 3u) != 1u; };
  uint64_t qs = 5;
  for (int qi = 0; qi < 100; ++qi) {
    double q[static_cast<size_t>(D)];
    for (double& x : q) x = uniform(qs) * 2.0 - 1.0;
    Neighbour a[16], b[16];
    KnnSet sa(a, 16, 1e300), sb(b, 16, 1e300);
    hg::kd_query<D>(mem.t, q, sa, odd_out);
    for (uint32_t i = 0; i < n; ++i) {
      if (odd_out(i)) sb.add(hg::dist2<D>(q, pts.data() + static_cast<size_t>(i) * static_cast<size_t>(D)), i);
    }
    expect_same(a, sa.size(), b, sb.size());
  }
}

// Building with a sequence filter copies only the points with sequence <= snapshot.
void test_kdtree_snapshot_filter_copies_old_points_only(void**) {
  constexpr int D = 2;
  const uint32_t n = 100;
  const std::vector<double> pts = make_points(n, D, false, 3);
  std::vector<uint64_t> seq(n);
  for (uint32_t i = 0; i < n; ++i) seq[i] = i + 1;
  TreeMem mem(n, D);
  hg::kd_build_all<D>(mem.t, pts.data(), seq.data(), n, 60);
  assert_int_equal(mem.t.n, 60);
  for (uint32_t i = 0; i < mem.t.n; ++i) assert_true(mem.t.ids[i] < 60);
}

// RadiusSet::sort orders by (distance, id).
void test_kdtree_radius_sort_orders_by_distance_then_id(void**) {
  Neighbour buf[6];
  RadiusSet s(buf, 6, 1.0);
  const double d[] = {0.5, 0.1, 0.5, 0.0, 0.1, 2.0};
  const uint32_t id[] = {7, 9, 3, 4, 2, 1};
  for (int i = 0; i < 6; ++i) s.add(d[i], id[i]);
  s.sort();
  assert_int_equal(s.total(), 5);
  const uint32_t want[] = {4, 2, 9, 3, 7};
  for (uint32_t i = 0; i < 5; ++i) assert_int_equal(buf[i].id, want[i]);
}

// k = 0 (or no buffer) is rejected at construction: the set stays empty, prunes every search at
// once and never reads or writes the buffer (a guard element around it must stay untouched).
void test_kdtree_knn_set_rejects_k_zero(void**) {
  constexpr int D = 3;
  const uint32_t n = 200;
  const std::vector<double> pts = make_points(n, D, false, 21);
  TreeMem mem(n, D);
  hg::kd_build_all<D>(mem.t, pts.data(), nullptr, n, 0);
  const Neighbour guard{-1.0, 0xDEADBEEFu};
  Neighbour buf[3] = {guard, guard, guard};
  const double q[D] = {0.0, 0.0, 0.0};
  KnnSet zero(buf + 1, 0, 1e300);
  assert_false(zero.ok());
  assert_true(zero.worst() < -1e308);
  zero.add(0.0, 7);
  hg::kd_query<D>(mem.t, q, zero, [](uint32_t) { return true; });
  hg::brute_query<D>(pts.data(), n, q, zero);
  assert_int_equal(zero.size(), 0);
  KnnSet no_buffer(nullptr, 4, 1e300);
  assert_false(no_buffer.ok());
  no_buffer.add(0.0, 7);
  hg::kd_query<D>(mem.t, q, no_buffer, [](uint32_t) { return true; });
  assert_int_equal(no_buffer.size(), 0);
  for (const Neighbour& b : buf) {
    assert_true(b.d2 == guard.d2);
    assert_int_equal(b.id, guard.id);
  }
  // k = 1 is accepted and finds the nearest point.
  KnnSet one(buf + 1, 1, 1e300);
  assert_true(one.ok());
  hg::kd_query<D>(mem.t, q, one, [](uint32_t) { return true; });
  Neighbour want[1];
  KnnSet brute(want, 1, 1e300);
  hg::brute_query<D>(pts.data(), n, q, brute);
  expect_same(buf + 1, one.size(), want, brute.size());
  assert_true(one.worst() == want[0].d2);
  assert_int_equal(buf[0].id, guard.id);
  assert_int_equal(buf[2].id, guard.id);
}

// Queries and sliced builds allocate nothing.
void test_kdtree_queries_do_not_allocate(void**) {
  constexpr int D = 4;
  const uint32_t n = 5000;
  const std::vector<double> pts = make_points(n, D, false, 8);
  TreeMem mem(n, D);
  alloc_counter_begin();
  hg::kd_begin_build(mem.t, pts.data(), nullptr, n, 0);
  while (!hg::kd_done(mem.t)) hg::kd_build_step<D>(mem.t, 1000);
  uint64_t qs = 1;
  Neighbour a[32];
  double sum = 0.0;
  for (int i = 0; i < 5000; ++i) {
    double q[static_cast<size_t>(D)];
    for (double& x : q) x = uniform(qs) * 2.0 - 1.0;
    KnnSet s(a, 32, 0.25);
    hg::kd_query<D>(mem.t, q, s, [](uint32_t) { return true; });
    sum += s.size() ? a[0].d2 : 0.0;
    hg::KnnCollect<64> c(32, 0.25);
    hg::kd_query<D>(mem.t, q, c, [](uint32_t) { return true; });
    sum += c.finish(a) ? a[0].d2 : 0.0;
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_true(sum >= 0.0);
}

// KnnCollect rejects a k it cannot hold (0, or more than half its buffer) as KnnSet rejects 0.
void test_kdtree_knn_collect_rejects_bad_k(void**) {
  hg::KnnCollect<8> zero(0, 1.0), big(5, 1.0), fine(4, 1.0);
  assert_false(zero.ok());
  assert_false(big.ok());
  assert_true(fine.ok());
  big.add(0.5, 1);
  Neighbour out[8];
  assert_int_equal(big.finish(out), 0);
}

// The node count formula is exact for a full build.
void test_kdtree_node_count_formula_exact(void**) {
  constexpr int D = 3;
  const uint32_t sizes[] = {0, 1, 8, 9, 16, 17, 100, 1023, 1024, 1025, 4097};
  for (uint32_t n : sizes) {
    const std::vector<double> pts = make_points(n, D, false, n);
    TreeMem mem(n, D);
    hg::kd_build_all<D>(mem.t, pts.data(), nullptr, n, 0);
    assert_int_equal(mem.t.n_nodes, hg::kd_nodes_for(n));
  }
}

}  // namespace

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_kdtree_queries_match_brute_force),
      cmocka_unit_test(test_kdtree_sliced_build_matches_brute_force),
      cmocka_unit_test(test_kdtree_predicate_filters_entries),
      cmocka_unit_test(test_kdtree_snapshot_filter_copies_old_points_only),
      cmocka_unit_test(test_kdtree_radius_sort_orders_by_distance_then_id),
      cmocka_unit_test(test_kdtree_knn_set_rejects_k_zero),
      cmocka_unit_test(test_kdtree_queries_do_not_allocate),
      cmocka_unit_test(test_kdtree_knn_collect_rejects_bad_k),
      cmocka_unit_test(test_kdtree_node_count_formula_exact),
  };
  return cmocka_run_group_tests_name("hedger.kdtree", tests, nullptr, nullptr);
}
