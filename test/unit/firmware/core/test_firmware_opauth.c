// SPDX-License-Identifier: MIT
// fw/opauth.h and fw/lcm_scope.h: authenticated operator messages (every refusal reason, and that a
// refused message changes nothing, the seq window included), the seq window (reordering, replays,
// messages below it), the session announcement, the key file's checks, shared test vectors with
// tools/b21r_opauth.py (test/unit/tools/test_tools_opauth.py), and which LCM URLs lcm_scope = host takes.
#define _POSIX_C_SOURCE 200809L
#include "fw/lcm_scope.h"
#include "fw/opauth.h"

#include <b21r/b21r_command_v1_t.h>
#include <b21r/b21r_teleop_v1_t.h>
#include <b21r_test/alloc_counter.h>

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cmocka.h>

static uint8_t g_key[FW_OPAUTH_KEY_BYTES];
static uint8_t g_nonce[FW_OPAUTH_NONCE_BYTES];
static fw_opauth_t g_auth;

static int setup(void** state) {
  (void)state;
  for (unsigned i = 0; i < FW_OPAUTH_KEY_BYTES; ++i) {
    g_key[i] = (uint8_t)i;
  }
  for (unsigned i = 0; i < FW_OPAUTH_NONCE_BYTES; ++i) {
    g_nonce[i] = (uint8_t)(100 + i);
  }
  fw_opauth_init(&g_auth, g_key, g_nonce, 1700000000000002LL);
  return 0;
}

static void from_hex(const char* text, uint8_t* out, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    unsigned v = 0;
    assert_int_equal(sscanf(text + 2 * i, "%2x", &v), 1);
    out[i] = (uint8_t)v;
  }
}

// A message of this session signed with the key (the operator tools' way).
static b21r_teleop_t teleop(int64_t seq, const uint8_t* key, const uint8_t* nonce) {
  b21r_teleop_t m;
  memset(&m, 0, sizeof m);
  m.utime = 1700000000000000LL;
  m.seq = seq;
  m.deadman = 1;
  m.rotation_radps = 0.5;
  m.translation_mps = -0.25;
  fw_opauth_key_id(key, m.key_id);
  memcpy(m.session, nonce, sizeof m.session);
  fw_opauth_sign_teleop(key, &m);
  return m;
}

static b21r_command_t command(int64_t seq, int8_t what) {
  b21r_command_t m;
  memset(&m, 0, sizeof m);
  m.utime = 1700000000000001LL;
  m.seq = seq;
  m.command = what;
  m.argument = 7;
  fw_opauth_key_id(g_key, m.key_id);
  memcpy(m.session, g_nonce, sizeof m.session);
  fw_opauth_sign_command(g_key, &m);
  return m;
}

static fw_opauth_verdict_t take(const b21r_teleop_t* m) {
  uint8_t buf[256];
  const int n = b21r_teleop_t_encode(buf, 0, (int)sizeof buf, m);
  assert_true(n > 0);
  b21r_teleop_t out;
  return fw_opauth_take_teleop(&g_auth, buf, (size_t)n, &out);
}

static fw_opauth_verdict_t take_signed(int64_t seq, const uint8_t* key, const uint8_t* nonce) {
  const b21r_teleop_t m = teleop(seq, key, nonce);
  return take(&m);
}

// The macs agree with tools/b21r_opauth.py on the same inputs (values computed there with Python's
// hmac module): the two sides sign the same bytes.
static void test_opauth_vectors_match_python(void** state) {
  (void)state;
  uint8_t want[FW_OPAUTH_MAC_BYTES];
  uint8_t id[FW_OPAUTH_KEY_ID_BYTES];
  fw_opauth_key_id(g_key, id);
  from_hex("630dcd2966c43366", want, FW_OPAUTH_KEY_ID_BYTES);
  assert_memory_equal(id, want, FW_OPAUTH_KEY_ID_BYTES);
  b21r_teleop_t t = teleop(42, g_key, g_nonce);
  from_hex("86348780984268ef02ddbf51d1d9e41167205a69eb8e40d42344803e4974beaf", want, sizeof want);
  assert_memory_equal(t.mac, want, sizeof want);
  b21r_command_t c = command(43, B21R_COMMAND_T_PAUSE);
  from_hex("dc95dee438ec21afe2a547d2d6de4ad3dffc6660b3fa2a1e27aa541f58c83d66", want, sizeof want);
  assert_memory_equal(c.mac, want, sizeof want);
  b21r_session_t s;
  fw_opauth_session(&g_auth, 5, &s);
  from_hex("c5b4a2ad23d3849357b595a18137fafadaa99139fb100be9bf9915154aba8a49", want, sizeof want);
  assert_memory_equal(s.mac, want, sizeof want);
  assert_true(fw_opauth_session_valid(g_key, &s));
  s.started_us += 1;  // an altered announcement no longer verifies
  assert_false(fw_opauth_session_valid(g_key, &s));
}

// A signed message of this session is taken, decoded as sent, and counted.
static void test_opauth_take_signed_taken(void** state) {
  (void)state;
  const b21r_teleop_t m = teleop(10, g_key, g_nonce);
  uint8_t buf[256];
  const int n = b21r_teleop_t_encode(buf, 0, (int)sizeof buf, &m);
  b21r_teleop_t out;
  memset(&out, 0, sizeof out);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, buf, (size_t)n, &out), FW_OPAUTH_TAKEN);
  assert_int_equal(out.seq, 10);
  assert_true(out.deadman);
  assert_true(out.rotation_radps == 0.5);
  const fw_opauth_counters_t c = fw_opauth_counters(&g_auth);
  assert_int_equal(c.taken[FW_OPAUTH_TELEOP], 1);
  assert_int_equal(c.refused[FW_OPAUTH_TELEOP], 0);
  // The command channel has its window of its own: seq 10 is new there.
  const b21r_command_t cm = command(10, B21R_COMMAND_T_RESUME);
  const int cn = b21r_command_t_encode(buf, 0, (int)sizeof buf, &cm);
  b21r_command_t cout;
  assert_int_equal(fw_opauth_take_command(&g_auth, buf, (size_t)cn, &cout), FW_OPAUTH_TAKEN);
  assert_int_equal(cout.command, B21R_COMMAND_T_RESUME);
}

// Every kind of refusal is named and counted, and none moves the window: after each, the
// operator's next message (seq 11) is still taken.
static void test_opauth_refusals_counted_change_nothing(void** state) {
  (void)state;
  const b21r_teleop_t unsigned_msg = {.seq = INT64_MAX, .deadman = 1, .rotation_radps = 0.8};
  assert_int_equal(take(&unsigned_msg), FW_OPAUTH_KEY);  // unsigned: key id all zero
  b21r_teleop_t forged = teleop(INT64_MAX, g_key, g_nonce);
  forged.mac[0] ^= 1U;  // a forged seq of 2^63 - 1 with a wrong mac
  assert_int_equal(take(&forged), FW_OPAUTH_MAC);
  b21r_teleop_t altered = teleop(INT64_MAX - 1, g_key, g_nonce);
  altered.rotation_radps = 1.0;  // signed, then changed
  assert_int_equal(take(&altered), FW_OPAUTH_MAC);
  uint8_t other_key[FW_OPAUTH_KEY_BYTES];
  memset(other_key, 0x5A, sizeof other_key);
  assert_int_equal(take_signed(INT64_MAX, other_key, g_nonce), FW_OPAUTH_KEY);
  uint8_t old_nonce[FW_OPAUTH_NONCE_BYTES];
  memset(old_nonce, 0x11, sizeof old_nonce);
  assert_int_equal(take_signed(INT64_MAX, g_key, old_nonce), FW_OPAUTH_SESSION);
  // Malformed: truncated, one byte too many, garbage, empty, NULL.
  const b21r_teleop_t good = teleop(11, g_key, g_nonce);
  uint8_t buf[256];
  const int n = b21r_teleop_t_encode(buf, 0, (int)sizeof buf, &good);
  b21r_teleop_t out;
  assert_int_equal(fw_opauth_take_teleop(&g_auth, buf, (size_t)n - 1, &out), FW_OPAUTH_MALFORMED);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, buf, (size_t)n + 1, &out), FW_OPAUTH_MALFORMED);
  uint8_t junk[300];
  memset(junk, 0xA5, sizeof junk);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, junk, sizeof junk, &out), FW_OPAUTH_MALFORMED);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, junk, 0, &out), FW_OPAUTH_MALFORMED);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, NULL, 10, &out), FW_OPAUTH_MALFORMED);
  // A command on the teleop channel is malformed there.
  const b21r_command_t cm = command(12, B21R_COMMAND_T_SHUTDOWN);
  const int cn = b21r_command_t_encode(junk, 0, (int)sizeof junk, &cm);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, junk, (size_t)cn, &out), FW_OPAUTH_MALFORMED);
  // The old unauthenticated types.
  const b21r_teleop_v1_t v1 = {.utime = 1, .seq = INT64_MAX, .deadman = 1, .rotation_radps = 0.8};
  const int vn = b21r_teleop_v1_t_encode(junk, 0, (int)sizeof junk, &v1);
  assert_int_equal(fw_opauth_take_teleop(&g_auth, junk, (size_t)vn, &out), FW_OPAUTH_UNAUTHENTICATED);
  const b21r_command_v1_t c1 = {.utime = 1, .seq = INT64_MAX, .command = B21R_COMMAND_T_SHUTDOWN};
  const int c1n = b21r_command_v1_t_encode(junk, 0, (int)sizeof junk, &c1);
  b21r_command_t cout;
  assert_int_equal(fw_opauth_take_command(&g_auth, junk, (size_t)c1n, &cout), FW_OPAUTH_UNAUTHENTICATED);

  assert_false(g_auth.window[FW_OPAUTH_TELEOP].any);
  assert_false(g_auth.window[FW_OPAUTH_COMMAND].any);
  assert_int_equal(take(&good), FW_OPAUTH_TAKEN);
  assert_int_equal(g_auth.window[FW_OPAUTH_TELEOP].newest, 11);
  const fw_opauth_counters_t c = fw_opauth_counters(&g_auth);
  assert_int_equal(c.by_verdict[FW_OPAUTH_KEY], 2);
  assert_int_equal(c.by_verdict[FW_OPAUTH_MAC], 2);
  assert_int_equal(c.by_verdict[FW_OPAUTH_SESSION], 1);
  assert_int_equal(c.by_verdict[FW_OPAUTH_MALFORMED], 6);
  assert_int_equal(c.by_verdict[FW_OPAUTH_UNAUTHENTICATED], 2);
  assert_int_equal(c.refused[FW_OPAUTH_TELEOP], 12);
  assert_int_equal(c.refused[FW_OPAUTH_COMMAND], 1);
  assert_int_equal(c.taken[FW_OPAUTH_TELEOP], 1);
}

// The window: newer seqs move it, reordered ones inside it are taken once, a repeat is a replay,
// anything 64 or more below the newest is old; a jump far ahead empties it.
static void test_opauth_window_reorder_replay_old(void** state) {
  (void)state;
  assert_int_equal(take_signed(1000, g_key, g_nonce), FW_OPAUTH_TAKEN);
  assert_int_equal(take_signed(1000, g_key, g_nonce), FW_OPAUTH_REPLAY);
  assert_int_equal(take_signed(1002, g_key, g_nonce), FW_OPAUTH_TAKEN);
  assert_int_equal(take_signed(1001, g_key, g_nonce), FW_OPAUTH_TAKEN);  // late, in the window
  assert_int_equal(take_signed(1001, g_key, g_nonce), FW_OPAUTH_REPLAY);
  assert_int_equal(take_signed(1002 - 63, g_key, g_nonce), FW_OPAUTH_TAKEN);  // the window's edge
  assert_int_equal(take_signed(1002 - 64, g_key, g_nonce), FW_OPAUTH_OLD);
  assert_int_equal(take_signed(INT64_MIN, g_key, g_nonce), FW_OPAUTH_OLD);
  assert_int_equal(take_signed(1002 + 64, g_key, g_nonce), FW_OPAUTH_TAKEN);
  assert_int_equal(g_auth.window[FW_OPAUTH_TELEOP].taken, 1U);  // everything before fell out
  assert_int_equal(take_signed(1002 + 1, g_key, g_nonce), FW_OPAUTH_TAKEN);  // not taken before
  assert_int_equal(take_signed(1002, g_key, g_nonce), FW_OPAUTH_OLD);
  assert_int_equal(take_signed(INT64_MAX, g_key, g_nonce), FW_OPAUTH_TAKEN);
  assert_int_equal(take_signed(INT64_MAX, g_key, g_nonce), FW_OPAUTH_REPLAY);
  const fw_opauth_counters_t c = fw_opauth_counters(&g_auth);
  assert_int_equal(c.by_verdict[FW_OPAUTH_REPLAY], 3);
  assert_int_equal(c.by_verdict[FW_OPAUTH_OLD], 3);
  assert_int_equal(c.taken[FW_OPAUTH_TELEOP], 7);
}

// Without a key every message is refused (KEY), and the announcement carries no key id or mac.
static void test_opauth_no_key_refuses_everything(void** state) {
  (void)state;
  fw_opauth_init(&g_auth, NULL, g_nonce, 0);
  assert_int_equal(take_signed(1, g_key, g_nonce), FW_OPAUTH_KEY);
  b21r_session_t s;
  fw_opauth_session(&g_auth, 1, &s);
  const uint8_t zeros[FW_OPAUTH_MAC_BYTES] = {0};
  assert_memory_equal(s.mac, zeros, sizeof zeros);
  assert_memory_equal(s.key_id, zeros, FW_OPAUTH_KEY_ID_BYTES);
}

// Taking a message allocates nothing in the project's code (OpenSSL's own short-lived HMAC context
// lives inside libcrypto, which the counter does not see; ASan's leak check covers the process).
static void test_opauth_take_allocates_nothing_of_ours(void** state) {
  (void)state;
  alloc_counter_begin();
  for (int64_t i = 6; i < 106; ++i) {
    assert_int_equal(take_signed(i, g_key, g_nonce), FW_OPAUTH_TAKEN);
  }
  assert_int_equal(alloc_counter_end(), 0);
}

// Two fresh nonces differ (128 random bits each).
static void test_opauth_new_nonce_random(void** state) {
  (void)state;
  uint8_t a[FW_OPAUTH_NONCE_BYTES];
  uint8_t b[FW_OPAUTH_NONCE_BYTES];
  assert_int_equal(fw_opauth_new_nonce(a), 0);
  assert_int_equal(fw_opauth_new_nonce(b), 0);
  assert_memory_not_equal(a, b, sizeof a);
}

// ---- the key file ---------------------------------------------------------------------------

static char g_dir[64];

static int setup_dir(void** state) {
  (void)state;
  strcpy(g_dir, "/tmp/b21r-opauth-XXXXXX");
  assert_non_null(mkdtemp(g_dir));
  return setup(state);
}

static int teardown_dir(void** state) {
  (void)state;
  char cmd[128];
  snprintf(cmd, sizeof cmd, "rm -rf %s", g_dir);
  assert_int_equal(system(cmd), 0);
  return 0;
}

static void write_key_file(const char* path, const char* text, mode_t mode) {
  FILE* f = fopen(path, "w");
  assert_non_null(f);
  fputs(text, f);
  assert_int_equal(fclose(f), 0);
  assert_int_equal(chmod(path, mode), 0);
}

#define HEX_KEY "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f"

// A good key file loads (with or without its newline); every refusal names the fix and leaves the
// key as it was.
static void test_opauth_load_key_checks(void** state) {
  (void)state;
  char path[128];
  char err[512];
  uint8_t key[FW_OPAUTH_KEY_BYTES];
  snprintf(path, sizeof path, "%s/operator.key", g_dir);
  write_key_file(path, HEX_KEY "\n", 0600);
  memset(key, 0, sizeof key);
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), 0);
  assert_memory_equal(key, g_key, sizeof key);
  write_key_file(path, HEX_KEY, 0400);
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), 0);

  memset(key, 0x77, sizeof key);
  uint8_t before[FW_OPAUTH_KEY_BYTES];
  memcpy(before, key, sizeof key);
  write_key_file(path, HEX_KEY "\n", 0644);
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), -1);
  assert_non_null(strstr(err, "chmod 600"));
  assert_non_null(strstr(err, "0644"));
  write_key_file(path, HEX_KEY "\n", 0620);  // group may write: not the owner's key any more
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), -1);
  assert_non_null(strstr(err, "chmod 600"));
  write_key_file(path, "00010203\n", 0600);
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), -1);
  assert_non_null(strstr(err, "64 hexadecimal digits"));
  write_key_file(path, "zz0102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f\n", 0600);
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), -1);
  write_key_file(path, HEX_KEY "00\n", 0600);
  assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), -1);
  char missing[160];
  snprintf(missing, sizeof missing, "%s/none.key", g_dir);
  assert_int_equal(fw_opauth_load_key(missing, key, err, sizeof err), -1);
  assert_non_null(strstr(err, "tools/b21r_key.py create"));
  assert_int_equal(fw_opauth_load_key(g_dir, key, err, sizeof err), -1);  // a folder
  assert_non_null(strstr(err, "not a regular file"));
  assert_memory_equal(key, before, sizeof key);
  if (geteuid() == 0) {
    // Owned by someone else (root may make such a file): refused, naming chown.
    write_key_file(path, HEX_KEY "\n", 0600);
    assert_int_equal(chown(path, 12345, 12345), 0);
    assert_int_equal(fw_opauth_load_key(path, key, err, sizeof err), -1);
    assert_non_null(strstr(err, "chown"));
  }
}

// ---- lcm_scope --------------------------------------------------------------------------------

// Host scope takes what stays on this host and refuses the rest, naming lcm_scope; network takes
// every well-formed URL; a bad udpm address is refused in both.
static void test_lcm_scope_urls(void** state) {
  (void)state;
  fw_lcm_url_t u;
  char err[512];
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:7667?ttl=0", false, &u, err, sizeof err), 0);
  assert_true(u.udpm);
  assert_int_equal(u.port, 7667);
  assert_int_equal(u.group, 0xEFFF4C43U);
  assert_int_equal(fw_lcm_url_check("udpm://", false, &u, err, sizeof err), 0);
  assert_int_equal(u.port, 7667);
  assert_int_equal(fw_lcm_url_check(FW_LCM_DEFAULT_URL, false, &u, err, sizeof err), 0);
  assert_int_equal(fw_lcm_url_check("udpm://239.1.2.3:9000?recv_buf_size=4096&ttl=0x0", false, &u, err, sizeof err),
                   0);
  assert_int_equal(u.port, 9000);
  assert_int_equal(fw_lcm_url_check("memq://", false, &u, err, sizeof err), 0);
  assert_false(u.udpm);
  assert_int_equal(fw_lcm_url_check("file:///tmp/x.lcmlog?mode=w", false, &u, err, sizeof err), 0);

  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:7667?ttl=1", false, &u, err, sizeof err), -1);
  assert_non_null(strstr(err, "lcm_scope = network"));
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:7667?ttl=0&ttl=1", false, &u, err, sizeof err), -1);
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:7667?ttl=256", false, &u, err, sizeof err), -1);
  assert_int_equal(fw_lcm_url_check("tcpq://192.0.2.1:7700", false, &u, err, sizeof err), -1);
  assert_non_null(strstr(err, "lcm_scope = network"));
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:7667?ttl=1", true, &u, err, sizeof err), 0);
  assert_int_equal(u.ttl, 1);
  assert_int_equal(fw_lcm_url_check("tcpq://192.0.2.1:7700", true, &u, err, sizeof err), 0);

  assert_int_equal(fw_lcm_url_check("udpm://10.0.0.1:7667", true, &u, err, sizeof err), -1);
  assert_non_null(strstr(err, "multicast"));
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67", true, &u, err, sizeof err), -1);
  assert_non_null(strstr(err, "no port"));
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:0", true, &u, err, sizeof err), -1);
  assert_int_equal(fw_lcm_url_check("udpm://239.255.76.67:70000", true, &u, err, sizeof err), -1);
  assert_int_equal(fw_lcm_url_check("239.255.76.67:7667", true, &u, err, sizeof err), -1);

  assert_string_equal(fw_lcm_url_effective("memq://", "udpm://x"), "memq://");
  assert_string_equal(fw_lcm_url_effective("", "udpm://239.1.1.1:1"), "udpm://239.1.1.1:1");
  assert_string_equal(fw_lcm_url_effective("", NULL), FW_LCM_DEFAULT_URL);
  assert_string_equal(fw_lcm_url_effective("", ""), FW_LCM_DEFAULT_URL);
}

int main(void) {
  const struct CMUnitTest tests[] = {
      cmocka_unit_test_setup(test_opauth_vectors_match_python, setup),
      cmocka_unit_test_setup(test_opauth_take_signed_taken, setup),
      cmocka_unit_test_setup(test_opauth_refusals_counted_change_nothing, setup),
      cmocka_unit_test_setup(test_opauth_window_reorder_replay_old, setup),
      cmocka_unit_test_setup(test_opauth_no_key_refuses_everything, setup),
      cmocka_unit_test_setup(test_opauth_take_allocates_nothing_of_ours, setup),
      cmocka_unit_test_setup(test_opauth_new_nonce_random, setup),
      cmocka_unit_test_setup_teardown(test_opauth_load_key_checks, setup_dir, teardown_dir),
      cmocka_unit_test(test_lcm_scope_urls),
  };
  return cmocka_run_group_tests_name("firmware.opauth", tests, NULL, NULL);
}
