// SPDX-License-Identifier: MIT
// libFuzzer target: the authenticated decoder of the operator messages (fw/opauth.h) and the LCM
// URL check of lcm_scope (fw/lcm_scope.h).
//
// Input: a sequence of records, each [op u8][len u8][len bytes]; op & 3 selects:
//   0: raw bytes on B21R_TELEOP (op & 4: on B21R_COMMAND), as a datagram's payload would bring them;
//   1: a message built from the bytes (seq i64, deadman/command u8, rotation f64, argument i32, then
//      a choice byte: bit 0 another key, bit 1 another session, bit 2 no signature), signed for the
//      session (or not), then optionally damaged: bit 3 of the choice flips the byte at the next
//      byte's offset; op & 4: B21R_COMMAND;
//   2: the same message again (the last one built by op 1), as a replay;
//   3: the bytes as an LCM URL, checked for lcm_scope = host (op & 4: network).
// Properties: every message gets one verdict and one count; the seq window moves exactly when a
// message is taken; a taken message decodes from the bytes, carries this session's nonce and key id
// and the mac its contents call for, has a seq not taken before and at most 63 below the newest
// (a shadow model of the window); an undamaged signed message of this session gets exactly the
// verdict the shadow model predicts; the same bytes again right after being taken are a replay; a
// URL taken for the host scope is memq, file or udpm with ttl 0, a refused one has a message.
#include "fw/lcm_scope.h"
#include "fw/opauth.h"
#include "fuzz_util.h"

#define MAX_TAKEN 4096

typedef struct shadow {
  bool any;
  int64_t newest;
  int64_t taken[MAX_TAKEN];
  size_t n;
} shadow_t;

static bool shadow_has(const shadow_t* s, int64_t seq) {
  for (size_t i = 0; i < s->n; ++i) {
    if (s->taken[i] == seq) {
      return true;
    }
  }
  return false;
}

// The verdict of the window for an authentic message of this session.
static fw_opauth_verdict_t shadow_expect(const shadow_t* s, int64_t seq) {
  if (!s->any || seq > s->newest) {
    return FW_OPAUTH_TAKEN;
  }
  if ((uint64_t)s->newest - (uint64_t)seq >= FW_OPAUTH_WINDOW) {
    return FW_OPAUTH_OLD;
  }
  return shadow_has(s, seq) ? FW_OPAUTH_REPLAY : FW_OPAUTH_TAKEN;
}

static void shadow_take(shadow_t* s, int64_t seq) {
  FUZZ_CHECK(s->n < MAX_TAKEN);
  s->taken[s->n++] = seq;
  if (!s->any || seq > s->newest) {
    s->newest = seq;
  }
  s->any = true;
}

static uint8_t g_key[FW_OPAUTH_KEY_BYTES];
static uint8_t g_other_key[FW_OPAUTH_KEY_BYTES];
static uint8_t g_nonce[FW_OPAUTH_NONCE_BYTES];
static uint8_t g_other_nonce[FW_OPAUTH_NONCE_BYTES];

// Feeds one payload on a channel; checks the generic properties; returns the verdict and, when
// taken, the decoded seq.
static fw_opauth_verdict_t feed(fw_opauth_t* a, shadow_t* sh, int ch, const uint8_t* data, size_t n) {
  const fw_opauth_window_t before = a->window[ch];
  const fw_opauth_counters_t c0 = fw_opauth_counters(a);
  b21r_teleop_t t;
  b21r_command_t c;
  const fw_opauth_verdict_t v =
      ch == FW_OPAUTH_TELEOP ? fw_opauth_take_teleop(a, data, n, &t) : fw_opauth_take_command(a, data, n, &c);
  FUZZ_CHECK((unsigned)v < FW_OPAUTH_VERDICT_COUNT);
  const fw_opauth_counters_t c1 = fw_opauth_counters(a);
  FUZZ_CHECK(c1.by_verdict[v] == c0.by_verdict[v] + 1);
  FUZZ_CHECK(c1.taken[ch] + c1.refused[ch] == c0.taken[ch] + c0.refused[ch] + 1);
  if (v != FW_OPAUTH_TAKEN) {
    FUZZ_CHECK(memcmp(&before, &a->window[ch], sizeof before) == 0);
    return v;
  }
  // Taken: authentic, this session, fresh, and exactly the bytes received.
  uint8_t again[256];
  int64_t seq;
  if (ch == FW_OPAUTH_TELEOP) {
    FUZZ_CHECK(b21r_teleop_t_encode(again, 0, (int)sizeof again, &t) == (int)n && memcmp(again, data, n) == 0);
    b21r_teleop_t s = t;
    fw_opauth_sign_teleop(g_key, &s);
    FUZZ_CHECK(memcmp(s.mac, t.mac, sizeof s.mac) == 0);
    FUZZ_CHECK(memcmp(t.session, g_nonce, sizeof g_nonce) == 0 && memcmp(t.key_id, a->key_id, 8) == 0);
    seq = t.seq;
  } else {
    FUZZ_CHECK(b21r_command_t_encode(again, 0, (int)sizeof again, &c) == (int)n && memcmp(again, data, n) == 0);
    b21r_command_t s = c;
    fw_opauth_sign_command(g_key, &s);
    FUZZ_CHECK(memcmp(s.mac, c.mac, sizeof s.mac) == 0);
    FUZZ_CHECK(memcmp(c.session, g_nonce, sizeof g_nonce) == 0 && memcmp(c.key_id, a->key_id, 8) == 0);
    seq = c.seq;
  }
  FUZZ_CHECK(shadow_expect(sh, seq) == FW_OPAUTH_TAKEN);
  shadow_take(sh, seq);
  FUZZ_CHECK(a->window[ch].any && a->window[ch].newest == sh->newest);
  // The very same bytes again: a replay, refused without a change.
  const fw_opauth_window_t after = a->window[ch];
  const fw_opauth_verdict_t v2 =
      ch == FW_OPAUTH_TELEOP ? fw_opauth_take_teleop(a, data, n, &t) : fw_opauth_take_command(a, data, n, &c);
  FUZZ_CHECK(v2 == FW_OPAUTH_REPLAY);
  FUZZ_CHECK(memcmp(&after, &a->window[ch], sizeof after) == 0);
  return v;
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  for (unsigned i = 0; i < FW_OPAUTH_KEY_BYTES; ++i) {
    g_key[i] = (uint8_t)i;
    g_other_key[i] = (uint8_t)(0xFF - i);
  }
  for (unsigned i = 0; i < FW_OPAUTH_NONCE_BYTES; ++i) {
    g_nonce[i] = (uint8_t)(100 + i);
    g_other_nonce[i] = (uint8_t)(200 + i);
  }
  static fw_opauth_t a;
  static shadow_t shadow[FW_OPAUTH_CHANNEL_COUNT];
  fw_opauth_init(&a, g_key, g_nonce, 1);
  memset(shadow, 0, sizeof shadow);
  uint8_t last[256];
  size_t last_n = 0;
  int last_ch = 0;
  fuzz_in_t in = {data, size};
  while (fuzz_more(&in) && shadow[0].n + 1 < MAX_TAKEN && shadow[1].n + 1 < MAX_TAKEN) {
    const uint8_t op = fuzz_u8(&in);
    const uint8_t len = fuzz_u8(&in);
    uint8_t rec[256];
    memset(rec, 0, sizeof rec);
    (void)fuzz_bytes(&in, rec, len);
    const int ch = (op & 4) ? FW_OPAUTH_COMMAND : FW_OPAUTH_TELEOP;
    switch (op & 3) {
      case 0:
        (void)feed(&a, &shadow[ch], ch, rec, len);
        break;
      case 1: {
        fuzz_in_t r = {rec, len};
        const int64_t seq = (int64_t)fuzz_u64(&r);
        const uint8_t what = fuzz_u8(&r);
        const double rot = fuzz_f64(&r);
        const int32_t arg = (int32_t)fuzz_u32(&r);
        const uint8_t choice = fuzz_u8(&r);
        const uint8_t where = fuzz_u8(&r);
        const uint8_t* key = (choice & 1) ? g_other_key : g_key;
        const uint8_t* nonce = (choice & 2) ? g_other_nonce : g_nonce;
        int n;
        if (ch == FW_OPAUTH_TELEOP) {
          b21r_teleop_t m = {.utime = arg, .seq = seq, .deadman = (int8_t)what, .rotation_radps = rot,
                             .translation_mps = -rot};
          fw_opauth_key_id(key, m.key_id);
          memcpy(m.session, nonce, sizeof m.session);
          if (!(choice & 4)) {
            fw_opauth_sign_teleop(key, &m);
          }
          n = b21r_teleop_t_encode(last, 0, (int)sizeof last, &m);
        } else {
          b21r_command_t m = {.utime = arg, .seq = seq, .command = (int8_t)what, .argument = arg};
          fw_opauth_key_id(key, m.key_id);
          memcpy(m.session, nonce, sizeof m.session);
          if (!(choice & 4)) {
            fw_opauth_sign_command(key, &m);
          }
          n = b21r_command_t_encode(last, 0, (int)sizeof last, &m);
        }
        FUZZ_CHECK(n > 0);
        last_n = (size_t)n;
        last_ch = ch;
        const bool damaged = (choice & 8) != 0;
        if (damaged) {
          last[where % last_n] ^= (uint8_t)(1U << (where & 7));
        }
        const bool authentic = !damaged && (choice & 7) == 0;
        const fw_opauth_verdict_t want = shadow_expect(&shadow[ch], seq);
        const fw_opauth_verdict_t v = feed(&a, &shadow[ch], ch, last, last_n);
        if (authentic) {
          FUZZ_CHECK(v == want);
        } else if (!damaged) {
          FUZZ_CHECK(v == ((choice & 1) ? FW_OPAUTH_KEY : (choice & 4) ? FW_OPAUTH_MAC : FW_OPAUTH_SESSION));
        }
        break;
      }
      case 2:
        if (last_n > 0) {
          (void)feed(&a, &shadow[last_ch], last_ch, last, last_n);
        }
        break;
      default: {
        char url[257];
        memcpy(url, rec, len);
        url[len] = '\0';
        fw_lcm_url_t u;
        char err[512];
        err[0] = '\0';
        const bool network = (op & 4) != 0;
        if (fw_lcm_url_check(url, network, &u, err, sizeof err) == 0) {
          if (u.udpm) {
            FUZZ_CHECK(u.port >= 1 && (u.group >> 28) == 0xEU);
            FUZZ_CHECK(network || u.ttl == 0);
          } else if (!network) {
            FUZZ_CHECK(strncmp(url, "memq://", 7) == 0 || strncmp(url, "file://", 7) == 0);
          }
        } else {
          FUZZ_CHECK(err[0] != '\0' && memchr(err, '\0', sizeof err) != NULL);
        }
        break;
      }
    }
  }
  return 0;
}
