// SPDX-License-Identifier: MIT
// Authenticated operator messages (fw/opauth.h): decode, key id, HMAC-SHA256, session, seq window.
#define _POSIX_C_SOURCE 200809L
#include "fw/opauth.h"

#include "fw/errfmt.h"

#include <b21r/b21r_command_v1_t.h>
#include <b21r/b21r_teleop_v1_t.h>

#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/rand.h>
#include <openssl/sha.h>

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

// The largest encoding of the three types (teleop_t: 8 + 8 + 8 + 1 + 8 + 8 + 8 + 16 + 32 bytes).
#define MAX_ENCODED 160
// Domain separation: the channel's name and a zero byte come first, so a mac of one channel
// never verifies on another even for equal bytes.
#define MAX_CHANNEL 16

static const char k_teleop[] = "B21R_TELEOP";
static const char k_command[] = "B21R_COMMAND";
static const char k_session[] = "B21R_SESSION";

// HMAC-SHA256(key, channel 0x00 encoded) with the mac field all zero. The three types end with
// their mac (teleop_t.lcm, command_t.lcm, session_t.lcm), so it is the encoding's last bytes.
static void mac_of(const uint8_t key[FW_OPAUTH_KEY_BYTES], const char* channel, const uint8_t* encoded, size_t n,
                   uint8_t mac[FW_OPAUTH_MAC_BYTES]) {
  uint8_t input[MAX_CHANNEL + MAX_ENCODED];
  const size_t c = strlen(channel) + 1;  // with its NUL
  memset(mac, 0xFF, FW_OPAUTH_MAC_BYTES);
  if (n < FW_OPAUTH_MAC_BYTES || n > MAX_ENCODED) {
    return;  // no message of ours: a mac of all ones never verifies by more than chance
  }
  memcpy(input, channel, c);
  memcpy(input + c, encoded, n - FW_OPAUTH_MAC_BYTES);
  memset(input + c + n - FW_OPAUTH_MAC_BYTES, 0, FW_OPAUTH_MAC_BYTES);
  unsigned int len = FW_OPAUTH_MAC_BYTES;
  if (HMAC(EVP_sha256(), key, (int)FW_OPAUTH_KEY_BYTES, input, c + n, mac, &len) == NULL) {
    memset(mac, 0xFF, FW_OPAUTH_MAC_BYTES);  // only a broken libcrypto fails: as any wrong mac
  }
}

// The mac a message should carry: its encoding's.
#define MESSAGE_MAC(type, channel, key, m, mac)                          \
  do {                                                                   \
    uint8_t buf_[MAX_ENCODED];                                           \
    const int n_ = type##_encode(buf_, 0, (int)sizeof buf_, (m));        \
    mac_of((key), (channel), buf_, n_ > 0 ? (size_t)n_ : 0, (mac));      \
  } while (0)

void fw_opauth_key_id(const uint8_t key[FW_OPAUTH_KEY_BYTES], uint8_t id[FW_OPAUTH_KEY_ID_BYTES]) {
  uint8_t digest[SHA256_DIGEST_LENGTH];
  (void)SHA256(key, FW_OPAUTH_KEY_BYTES, digest);
  memcpy(id, digest, FW_OPAUTH_KEY_ID_BYTES);
}

void fw_opauth_init(fw_opauth_t* a, const uint8_t* key, const uint8_t* nonce, int64_t started_us) {
  memset(a->key, 0, sizeof a->key);
  memset(a->key_id, 0, sizeof a->key_id);
  a->have_key = key != NULL;
  if (key != NULL) {
    memcpy(a->key, key, FW_OPAUTH_KEY_BYTES);
    fw_opauth_key_id(a->key, a->key_id);
  }
  memcpy(a->nonce, nonce, FW_OPAUTH_NONCE_BYTES);
  a->started_us = started_us;
  memset(a->window, 0, sizeof a->window);
  memset(a->count, 0, sizeof a->count);
}

int fw_opauth_new_nonce(uint8_t nonce[FW_OPAUTH_NONCE_BYTES]) {
  uint8_t fresh[FW_OPAUTH_NONCE_BYTES];
  if (RAND_bytes(fresh, (int)sizeof fresh) != 1) {
    return -1;
  }
  memcpy(nonce, fresh, sizeof fresh);
  return 0;
}

// The window's verdict for seq, and (taken) the window after it. O(1).
static fw_opauth_verdict_t window_check(const fw_opauth_window_t* w, int64_t seq, fw_opauth_window_t* next) {
  *next = *w;
  if (!w->any || seq > w->newest) {
    // Unsigned difference: seq - newest cannot overflow this way (both are int64).
    const uint64_t ahead = w->any ? (uint64_t)seq - (uint64_t)w->newest : FW_OPAUTH_WINDOW;
    next->taken = ahead >= FW_OPAUTH_WINDOW ? 1U : (w->taken << ahead) | 1U;
    next->newest = seq;
    next->any = true;
    return FW_OPAUTH_TAKEN;
  }
  const uint64_t behind = (uint64_t)w->newest - (uint64_t)seq;
  if (behind >= FW_OPAUTH_WINDOW) {
    return FW_OPAUTH_OLD;
  }
  const uint64_t bit = (uint64_t)1U << behind;
  if (w->taken & bit) {
    return FW_OPAUTH_REPLAY;
  }
  next->taken = w->taken | bit;
  return FW_OPAUTH_TAKEN;
}

// Checks 2-5 of fw/opauth.h for a decoded message; moves the window when taken.
static fw_opauth_verdict_t authenticate(fw_opauth_t* a, fw_opauth_channel_t ch, const uint8_t* key_id,
                                        const uint8_t* session, int64_t seq, const uint8_t* mac,
                                        const uint8_t* expected_mac) {
  if (!a->have_key || memcmp(key_id, a->key_id, FW_OPAUTH_KEY_ID_BYTES) != 0) {
    return FW_OPAUTH_KEY;
  }
  if (CRYPTO_memcmp(mac, expected_mac, FW_OPAUTH_MAC_BYTES) != 0) {
    return FW_OPAUTH_MAC;
  }
  if (memcmp(session, a->nonce, FW_OPAUTH_NONCE_BYTES) != 0) {
    return FW_OPAUTH_SESSION;
  }
  fw_opauth_window_t next;
  const fw_opauth_verdict_t v = window_check(&a->window[ch], seq, &next);
  if (v == FW_OPAUTH_TAKEN) {
    a->window[ch] = next;
  }
  return v;
}

static fw_opauth_verdict_t counted(fw_opauth_t* a, fw_opauth_channel_t ch, fw_opauth_verdict_t v) {
  __atomic_fetch_add(&a->count[ch][v], 1U, __ATOMIC_RELAXED);
  return v;
}

// LCM's decoders take int sizes: anything larger than an int is no message of ours anyway.
static int size_int(size_t size) { return size > (size_t)MAX_ENCODED ? MAX_ENCODED + 1 : (int)size; }

fw_opauth_verdict_t fw_opauth_take_teleop(fw_opauth_t* a, const void* data, size_t size, b21r_teleop_t* out) {
  const int n = size_int(size);
  b21r_teleop_t m;
  if (data == NULL || b21r_teleop_t_decode(data, 0, n, &m) != n) {
    b21r_teleop_v1_t old;
    const bool is_old = data != NULL && b21r_teleop_v1_t_decode(data, 0, n, &old) == n;
    return counted(a, FW_OPAUTH_TELEOP, is_old ? FW_OPAUTH_UNAUTHENTICATED : FW_OPAUTH_MALFORMED);
  }
  uint8_t expected[FW_OPAUTH_MAC_BYTES];
  mac_of(a->key, k_teleop, data, size, expected);
  const fw_opauth_verdict_t v = authenticate(a, FW_OPAUTH_TELEOP, m.key_id, m.session, m.seq, m.mac, expected);
  if (v == FW_OPAUTH_TAKEN) {
    *out = m;
  }
  return counted(a, FW_OPAUTH_TELEOP, v);
}

fw_opauth_verdict_t fw_opauth_take_command(fw_opauth_t* a, const void* data, size_t size, b21r_command_t* out) {
  const int n = size_int(size);
  b21r_command_t m;
  if (data == NULL || b21r_command_t_decode(data, 0, n, &m) != n) {
    b21r_command_v1_t old;
    const bool is_old = data != NULL && b21r_command_v1_t_decode(data, 0, n, &old) == n;
    return counted(a, FW_OPAUTH_COMMAND, is_old ? FW_OPAUTH_UNAUTHENTICATED : FW_OPAUTH_MALFORMED);
  }
  uint8_t expected[FW_OPAUTH_MAC_BYTES];
  mac_of(a->key, k_command, data, size, expected);
  const fw_opauth_verdict_t v = authenticate(a, FW_OPAUTH_COMMAND, m.key_id, m.session, m.seq, m.mac, expected);
  if (v == FW_OPAUTH_TAKEN) {
    *out = m;
  }
  return counted(a, FW_OPAUTH_COMMAND, v);
}

void fw_opauth_session(const fw_opauth_t* a, int64_t utime, b21r_session_t* out) {
  memset(out, 0, sizeof *out);
  out->utime = utime;
  out->started_us = a->started_us;
  memcpy(out->nonce, a->nonce, sizeof out->nonce);
  if (a->have_key) {
    memcpy(out->key_id, a->key_id, sizeof out->key_id);
    MESSAGE_MAC(b21r_session_t, k_session, a->key, out, out->mac);
  }
}

void fw_opauth_sign_teleop(const uint8_t key[FW_OPAUTH_KEY_BYTES], b21r_teleop_t* m) {
  uint8_t mac[FW_OPAUTH_MAC_BYTES];
  MESSAGE_MAC(b21r_teleop_t, k_teleop, key, m, mac);
  memcpy(m->mac, mac, sizeof mac);
}

void fw_opauth_sign_command(const uint8_t key[FW_OPAUTH_KEY_BYTES], b21r_command_t* m) {
  uint8_t mac[FW_OPAUTH_MAC_BYTES];
  MESSAGE_MAC(b21r_command_t, k_command, key, m, mac);
  memcpy(m->mac, mac, sizeof mac);
}

bool fw_opauth_session_valid(const uint8_t key[FW_OPAUTH_KEY_BYTES], const b21r_session_t* s) {
  uint8_t expected[FW_OPAUTH_MAC_BYTES];
  MESSAGE_MAC(b21r_session_t, k_session, key, s, expected);
  return CRYPTO_memcmp(expected, s->mac, sizeof expected) == 0;
}

fw_opauth_counters_t fw_opauth_counters(const fw_opauth_t* a) {
  fw_opauth_counters_t c;
  memset(&c, 0, sizeof c);
  if (a == NULL) {
    return c;
  }
  for (int ch = 0; ch < (int)FW_OPAUTH_CHANNEL_COUNT; ++ch) {
    for (int v = 0; v < (int)FW_OPAUTH_VERDICT_COUNT; ++v) {
      const uint64_t n = __atomic_load_n(&a->count[ch][v], __ATOMIC_RELAXED);
      c.by_verdict[v] += n;
      if (v == FW_OPAUTH_TAKEN) {
        c.taken[ch] += n;
      } else {
        c.refused[ch] += n;
      }
    }
  }
  return c;
}

const char* fw_opauth_verdict_name(fw_opauth_verdict_t v) {
  static const char* const names[FW_OPAUTH_VERDICT_COUNT] = {
      "taken", "malformed", "unauthenticated", "another key", "wrong mac", "another session", "replay", "old seq"};
  return (unsigned)v < FW_OPAUTH_VERDICT_COUNT ? names[v] : "unknown";
}

// ---- the key file ---------------------------------------------------------------------------

static int hex_value(char c) {
  if (c >= '0' && c <= '9') {
    return c - '0';
  }
  if (c >= 'a' && c <= 'f') {
    return c - 'a' + 10;
  }
  if (c >= 'A' && c <= 'F') {
    return c - 'A' + 10;
  }
  return -1;
}

#define KEY_HINT "create one with: tools/b21r_key.py create %s (docs/robot.md, \"Network and security\")"

int fw_opauth_load_key(const char* path, uint8_t key[FW_OPAUTH_KEY_BYTES], char* err, size_t err_cap) {
  const int fd = open(path, O_RDONLY | O_CLOEXEC | O_NOCTTY);
  if (fd < 0) {
    const int e = errno;
    if (e == ENOENT) {
      fw_errfmt(err, err_cap, "operator_key_file %s: no such file; " KEY_HINT, path, path);
    } else {
      fw_errfmt(err, err_cap,
                "operator_key_file %s: %s (the controller runs as uid %u; the key must be readable by it)", path,
                strerror(e), (unsigned)geteuid());
    }
    return -1;
  }
  struct stat st;
  char text[160];
  ssize_t n = -1;
  int rc = -1;
  if (fstat(fd, &st) != 0) {
    fw_errfmt(err, err_cap, "operator_key_file %s: %s", path, strerror(errno));
  } else if (!S_ISREG(st.st_mode)) {
    fw_errfmt(err, err_cap, "operator_key_file %s: not a regular file; " KEY_HINT, path, path);
  } else if (st.st_uid != geteuid() && st.st_uid != 0) {
    fw_errfmt(err, err_cap,
              "operator_key_file %s belongs to uid %u: the key must belong to the user that runs the controller "
              "(uid %u) or to root: chown %u %s",
              path, (unsigned)st.st_uid, (unsigned)geteuid(), (unsigned)geteuid(), path);
  } else if ((st.st_mode & 077) != 0) {
    // As ssh with its private keys: a key others may read is no secret, one others may write is
    // not the owner's.
    fw_errfmt(err, err_cap,
              "operator_key_file %s has mode %04o: group or others may access it, so the key is not secret; "
              "chmod 600 %s (and make a new key if others may have read it)",
              path, (unsigned)(st.st_mode & 07777), path);
  } else if ((n = read(fd, text, sizeof text - 1)) < 0) {
    fw_errfmt(err, err_cap, "operator_key_file %s: %s", path, strerror(errno));
  } else {
    size_t len = (size_t)n;
    while (len > 0 && (text[len - 1] == '\n' || text[len - 1] == '\r')) {
      --len;
    }
    uint8_t k[FW_OPAUTH_KEY_BYTES];
    bool ok = len == 2 * FW_OPAUTH_KEY_BYTES;
    for (size_t i = 0; ok && i < FW_OPAUTH_KEY_BYTES; ++i) {
      const int hi = hex_value(text[2 * i]);
      const int lo = hex_value(text[2 * i + 1]);
      ok = hi >= 0 && lo >= 0;
      k[i] = (uint8_t)(ok ? hi * 16 + lo : 0);
    }
    if (!ok) {
      fw_errfmt(err, err_cap,
                "operator_key_file %s: expected %u hexadecimal digits (a %u-byte key) and a newline; " KEY_HINT, path,
                2 * FW_OPAUTH_KEY_BYTES, FW_OPAUTH_KEY_BYTES, path);
    } else {
      memcpy(key, k, sizeof k);
      rc = 0;
    }
    OPENSSL_cleanse(k, sizeof k);
  }
  OPENSSL_cleanse(text, sizeof text);
  (void)close(fd);
  return rc;
}
