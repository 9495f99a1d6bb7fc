// SPDX-License-Identifier: MIT
// The allocation counter must see C and C++ allocations, and only the calling thread's.
#include <b21r_test/alloc_counter.h>

#include <atomic>
#include <cstdarg>
#include <cstddef>
#include <csetjmp>
#include <cstdlib>
#include <memory>
#include <string>
#include <thread>
#include <vector>

extern "C" {
#include <cmocka.h>
}

namespace {

// Keeps the optimiser from removing an allocation whose result is unused.
void* volatile g_sink;

// A window with no allocation reports zero.
void test_alloc_counter_no_allocation_counts_zero(void**) {
  alloc_counter_begin();
  int x = 0;
  for (int i = 0; i < 1000; ++i) {
    x += i;
  }
  g_sink = &x;
  assert_int_equal(alloc_counter_end(), 0);
}

// malloc, calloc and realloc are each counted.
void test_alloc_counter_c_allocations_counted(void**) {
  alloc_counter_begin();
  void* a = std::malloc(16);
  g_sink = a;
  void* b = std::calloc(4, 8);
  g_sink = b;
  void* c = std::realloc(a, 64);
  g_sink = c;
  const uint64_t n = alloc_counter_end();
  std::free(b);
  std::free(c);
  assert_int_equal(n, 3);
}

// operator new (direct and inside the standard library) is counted.
void test_alloc_counter_cpp_allocations_counted(void**) {
  alloc_counter_begin();
  auto p = std::make_unique<double[]>(100);
  g_sink = p.get();
  std::vector<int> v;
  v.reserve(1000);
  g_sink = v.data();
  std::string s(200, 'x');
  g_sink = &s[0];
  const uint64_t n = alloc_counter_end();
  assert_true(n >= 3);
}

// Another thread's allocations do not count in this thread's window.
void test_alloc_counter_other_thread_not_counted(void**) {
  std::atomic<int> stage{0};
  std::thread worker([&stage] {
    while (stage.load() != 1) {
    }
    for (int i = 0; i < 100; ++i) {
      void* p = std::malloc(32);
      g_sink = p;
      std::free(p);
    }
    stage.store(2);
  });
  alloc_counter_begin();  // after the thread's own set-up, which allocates in this thread
  stage.store(1);
  while (stage.load() != 2) {
  }
  const uint64_t n = alloc_counter_end();
  worker.join();
  assert_int_equal(n, 0);
}

}  // namespace

int main() {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_alloc_counter_no_allocation_counts_zero),
      cmocka_unit_test(test_alloc_counter_c_allocations_counted),
      cmocka_unit_test(test_alloc_counter_cpp_allocations_counted),
      cmocka_unit_test(test_alloc_counter_other_thread_not_counted),
  };
  return cmocka_run_group_tests_name("support.alloc_counter", tests, nullptr, nullptr);
}
