// SPDX-License-Identifier: MIT
// Publisher queue: FIFO order, drops counted per kind when full (never blocking), no allocation
// on the producer side, and a publisher thread that writes a gap-free LCM event log.
#define _POSIX_C_SOURCE 200809L
#include "fw/publisher.h"
#include "fw/pubq.h"

#include <b21r_test/alloc_counter.h>
#include <lcm/eventlog.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include <cmocka.h>

// Messages come out in the order they went in, with their contents.
static void test_pubq_fifo_order_preserved(void** state) {
  (void)state;
  fw_pubq_t* q = fw_pubq_create(8);
  assert_non_null(q);
  for (int round = 0; round < 5; ++round) {
    for (int i = 0; i < 6; ++i) {
      fw_msg_t* m = fw_pubq_reserve(q, FW_MSG_EXPERIENCE);
      assert_non_null(m);
      m->u.experience.seq = round * 100 + i;
      fw_pubq_commit(q);
    }
    assert_int_equal(fw_pubq_depth(q), 6);
    for (int i = 0; i < 6; ++i) {
      const fw_msg_t* m = fw_pubq_peek(q);
      assert_non_null(m);
      assert_int_equal(m->kind, FW_MSG_EXPERIENCE);
      assert_int_equal(m->u.experience.seq, round * 100 + i);
      fw_pubq_pop(q);
    }
    assert_null(fw_pubq_peek(q));
  }
  assert_int_equal(fw_pubq_drops(q, -1), 0);
  fw_pubq_destroy(q);
}

// A full queue refuses (NULL, immediately) and counts the drop under the message's kind; the
// queued messages are untouched; producing allocates nothing.
static void test_pubq_full_drops_counted_per_kind(void** state) {
  (void)state;
  fw_pubq_t* q = fw_pubq_create(4);
  assert_non_null(q);
  alloc_counter_begin();
  int accepted = 0;
  for (int i = 0; i < 10; ++i) {
    fw_msg_t* m = fw_pubq_reserve(q, i % 2 == 0 ? FW_MSG_EXPERIENCE : FW_MSG_STATUS);
    if (m != NULL) {
      m->u.experience.seq = i;
      fw_pubq_commit(q);
      accepted++;
    }
  }
  assert_int_equal(alloc_counter_end(), 0);
  assert_int_equal(accepted, 4);
  assert_int_equal(fw_pubq_drops(q, FW_MSG_EXPERIENCE), 3);
  assert_int_equal(fw_pubq_drops(q, FW_MSG_STATUS), 3);
  assert_int_equal(fw_pubq_drops(q, -1), 6);
  assert_int_equal(fw_pubq_committed(q), 4);
  for (int i = 0; i < 4; ++i) {
    const fw_msg_t* m = fw_pubq_peek(q);
    assert_int_equal(m->u.experience.seq, i);
    fw_pubq_pop(q);
  }
  fw_pubq_destroy(q);
}

// Bad capacities are refused.
static void test_pubq_bad_capacity_refused(void** state) {
  (void)state;
  assert_null(fw_pubq_create(0));
  assert_null(fw_pubq_create(1));
  assert_null(fw_pubq_create(12));
  assert_string_equal(fw_msg_channel(FW_MSG_EVAL), "B21R_EVAL");
  assert_string_equal(fw_msg_channel(99), "");
}

// The publisher thread drains everything into the event logs in order; the experience log holds
// only experiences, with their utime as the event time; the counters add up.
static void test_publisher_writes_ordered_gap_free_logs(void** state) {
  (void)state;
  char dir[] = "/tmp/b21r-pubq-XXXXXX";
  assert_non_null(mkdtemp(dir));
  char all_path[128];
  char exp_path[128];
  snprintf(all_path, sizeof all_path, "%s/all.lcmlog", dir);
  snprintf(exp_path, sizeof exp_path, "%s/exp.lcmlog", dir);
  fw_pubq_t* q = fw_pubq_create(64);
  assert_non_null(q);
  const fw_publisher_config_t pc = {.lcm = NULL, .log_file = all_path, .experience_log_file = exp_path};
  char err[256];
  fw_publisher_t* p = fw_publisher_create(q, &pc, err, sizeof err);
  assert_non_null(p);
  const int n = 2000;
  int sent = 0;
  for (int i = 0; i < n; ++i) {
    fw_msg_t* m = NULL;
    while ((m = fw_pubq_reserve(q, i % 4 == 3 ? FW_MSG_STATUS : FW_MSG_EXPERIENCE)) == NULL) {
      fw_publisher_notify(p);
      const struct timespec ts = {0, 100000};  // test only: wait for room, the log must be complete
      nanosleep(&ts, NULL);
    }
    if (m->kind == FW_MSG_STATUS) {
      memset(&m->u.status.msg, 0, sizeof m->u.status.msg);
      m->u.status.msg.utime = i;
      snprintf(m->u.status.detail, sizeof m->u.status.detail, "detail %d", i);
    } else {
      memset(&m->u.experience, 0, sizeof m->u.experience);
      m->u.experience.utime = 1000 + i;
      m->u.experience.seq = sent++;
      m->u.experience.state_dim = 3;
    }
    fw_pubq_commit(q);
    fw_publisher_notify(p);
  }
  fw_publisher_flush(p);
  const fw_publisher_counters_t c = fw_publisher_counters(p);
  assert_int_equal(c.published, n);
  assert_int_equal(c.log_errors, 0);
  fw_publisher_destroy(p);
  fw_pubq_destroy(q);

  lcm_eventlog_t* log = lcm_eventlog_create(exp_path, "r");
  assert_non_null(log);
  int64_t expect_seq = 0;
  lcm_eventlog_event_t* ev;
  while ((ev = lcm_eventlog_read_next_event(log)) != NULL) {
    assert_string_equal(ev->channel, "B21R_EXPERIENCE");
    b21r_experience_t e;
    assert_true(b21r_experience_t_decode(ev->data, 0, ev->datalen, &e) > 0);
    assert_int_equal(e.seq, expect_seq);
    assert_int_equal(ev->timestamp, e.utime);
    expect_seq++;
    lcm_eventlog_free_event(ev);
  }
  lcm_eventlog_destroy(log);
  assert_int_equal(expect_seq, sent);

  log = lcm_eventlog_create(all_path, "r");
  assert_non_null(log);
  int events = 0;
  int statuses = 0;
  while ((ev = lcm_eventlog_read_next_event(log)) != NULL) {
    if (strcmp(ev->channel, "B21R_STATUS") == 0) {
      b21r_status_t s;
      assert_true(b21r_status_t_decode(ev->data, 0, ev->datalen, &s) > 0);
      char want[32];
      snprintf(want, sizeof want, "detail %d", (int)s.utime);
      assert_string_equal(s.stop_detail, want);
      b21r_status_t_decode_cleanup(&s);
      statuses++;
    }
    events++;
    lcm_eventlog_free_event(ev);
  }
  lcm_eventlog_destroy(log);
  assert_int_equal(events, n);
  assert_int_equal(statuses, n / 4);
  char cmd[200];
  snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
  assert_int_equal(system(cmd), 0);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test(test_pubq_fifo_order_preserved),
      cmocka_unit_test(test_pubq_full_drops_counted_per_kind),
      cmocka_unit_test(test_pubq_bad_capacity_refused),
      cmocka_unit_test(test_publisher_writes_ordered_gap_free_logs),
  };
  return cmocka_run_group_tests_name("firmware.pubq", tests, NULL, NULL);
}
