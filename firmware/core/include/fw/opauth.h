// SPDX-License-Identifier: MIT
/// fw/opauth.h — Authenticated operator messages: the controller's side of B21R_SESSION,
/// B21R_TELEOP and B21R_COMMAND (docs/robot.md, "Network and security").
///
/// The controller and the operator tools share an operator key: 32 random bytes, written as 64
/// hexadecimal digits in a file only its owner may read (tools/b21r_key.py creates one). At every
/// start the controller draws a random 16-byte session nonce and announces it on B21R_SESSION
/// with the key's id, signed. Each operator message carries the key id, that nonce, a sequence
/// number and an HMAC-SHA256 (RFC 2104 over SHA-256, from OpenSSL's libcrypto) keyed with the
/// operator key over the channel's name, a zero byte and the message's LCM encoding with the
/// mac field all zero (the encoding starts with the type's fingerprint, so the type is bound
/// too). The controller takes a message only when, checked in this order:
///   1. it decodes as the channel's type and is exactly that long, else MALFORMED (UNAUTHENTICATED
///      when it is the older unauthenticated type, teleop_v1_t / command_v1_t);
///   2. its key_id is the controller's key's, else KEY (also every message when the controller
///      has no key);
///   3. its mac verifies (compared in constant time), else MAC;
///   4. its session is the current nonce, else SESSION (an authentic message of an earlier start:
///      a replay across a restart, or a tool that has not seen the new session yet);
///   5. its seq is newer than the newest taken on its channel, or one of the FW_OPAUTH_WINDOW - 1
///      below it not taken yet (reordering), else REPLAY (taken already) or OLD (below the window).
/// A refused message changes nothing, the window included: a forged seq of 2^63 - 1 cannot lock
/// the operator out. Each check counts its refusals, per channel.
///
/// Memory: the caller owns fw_opauth_t (about 0.25 kB); no allocation of its own (OpenSSL's HMAC
/// allocates a context per call: never call it from the tick). Cost per message: one LCM decode
/// and one HMAC-SHA256 over less than 200 bytes (signing: one encode and one HMAC).
/// Thread-safety: one thread takes messages (the LCM receive thread); the counters are updated and
/// read with atomic operations (GCC/Clang __atomic builtins, so that the header stays plain C and
/// C++), so any thread may read them (fw_opauth_counters: the tick puts them on B21R_STATUS).
#ifndef FW_OPAUTH_H
#define FW_OPAUTH_H

#include <b21r/b21r_command_t.h>
#include <b21r/b21r_session_t.h>
#include <b21r/b21r_teleop_t.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define FW_OPAUTH_KEY_BYTES 32U     ///< operator key [bytes]; its file holds twice as many hex digits
#define FW_OPAUTH_KEY_ID_BYTES 8U   ///< key id: the first bytes of SHA-256(key)
#define FW_OPAUTH_NONCE_BYTES 16U   ///< session nonce, random per start of the controller
#define FW_OPAUTH_MAC_BYTES 32U     ///< HMAC-SHA256
#define FW_OPAUTH_WINDOW 64U        ///< seq window: the newest taken and the 63 below it

/// What became of one message. Every value but FW_OPAUTH_TAKEN is a refusal.
typedef enum fw_opauth_verdict {
  FW_OPAUTH_TAKEN = 0,          ///< authentic, this session, fresh: hand it to the loop
  FW_OPAUTH_MALFORMED = 1,      ///< not the channel's type, or not exactly its size
  FW_OPAUTH_UNAUTHENTICATED = 2,///< the unauthenticated type of older tools
  FW_OPAUTH_KEY = 3,            ///< another key id, or the controller has no operator key
  FW_OPAUTH_MAC = 4,            ///< the mac does not verify: forged or altered
  FW_OPAUTH_SESSION = 5,        ///< authentic, for another session
  FW_OPAUTH_REPLAY = 6,         ///< authentic, this session, its seq taken already
  FW_OPAUTH_OLD = 7,            ///< authentic, this session, its seq below the window
  FW_OPAUTH_VERDICT_COUNT = 8
} fw_opauth_verdict_t;

/// The two operator channels, each with a seq window of its own.
typedef enum fw_opauth_channel {
  FW_OPAUTH_TELEOP = 0,   ///< B21R_TELEOP
  FW_OPAUTH_COMMAND = 1,  ///< B21R_COMMAND
  FW_OPAUTH_CHANNEL_COUNT = 2
} fw_opauth_channel_t;

/// The seq window of one channel (anti-replay, as IPsec's: RFC 4303, 3.4.3).
typedef struct fw_opauth_window {
  bool any;         ///< a message has been taken on this channel
  int64_t newest;   ///< the newest seq taken
  uint64_t taken;   ///< bit i set: seq newest - i taken (bit 0 is newest)
} fw_opauth_window_t;

/// One controller session. Fields are read-only for callers (set by fw_opauth_init).
typedef struct fw_opauth {
  bool have_key;                            ///< false: every message is refused (KEY)
  uint8_t key[FW_OPAUTH_KEY_BYTES];
  uint8_t key_id[FW_OPAUTH_KEY_ID_BYTES];
  uint8_t nonce[FW_OPAUTH_NONCE_BYTES];
  int64_t started_us;                       ///< wall clock of the start [µs since the epoch]
  fw_opauth_window_t window[FW_OPAUTH_CHANNEL_COUNT];
  /// messages by channel and verdict (monotonic; relaxed atomic adds and loads only)
  uint64_t count[FW_OPAUTH_CHANNEL_COUNT][FW_OPAUTH_VERDICT_COUNT];
} fw_opauth_t;

/// Snapshot of the counters.
typedef struct fw_opauth_counters_s {
  uint64_t taken[FW_OPAUTH_CHANNEL_COUNT];    ///< messages handed on, per channel
  uint64_t refused[FW_OPAUTH_CHANNEL_COUNT];  ///< refusals of every reason, per channel
  uint64_t by_verdict[FW_OPAUTH_VERDICT_COUNT]; ///< both channels together (index FW_OPAUTH_TAKEN: taken)
} fw_opauth_counters_t;

/// Starts a session: key (FW_OPAUTH_KEY_BYTES, copied; NULL = no key: every message refused),
/// nonce (FW_OPAUTH_NONCE_BYTES, copied), started_us (announced on B21R_SESSION). Empty windows,
/// zero counters. O(1).
void fw_opauth_init(fw_opauth_t* a, const uint8_t* key, const uint8_t* nonce, int64_t started_us);

/// A fresh session nonce from OpenSSL's CSPRNG (RAND_bytes). Returns 0, or -1 (nonce unchanged)
/// when the generator cannot be seeded.
int fw_opauth_new_nonce(uint8_t nonce[FW_OPAUTH_NONCE_BYTES]);

/// The id of a key: the first FW_OPAUTH_KEY_ID_BYTES of its SHA-256. O(1).
void fw_opauth_key_id(const uint8_t key[FW_OPAUTH_KEY_BYTES], uint8_t id[FW_OPAUTH_KEY_ID_BYTES]);

/// Checks one received B21R_TELEOP (data, size: the LCM payload as received) and, when taken,
/// moves the window and decodes it into *out. Returns the verdict (counted). *out is written only
/// when taken. O(size).
fw_opauth_verdict_t fw_opauth_take_teleop(fw_opauth_t* a, const void* data, size_t size, b21r_teleop_t* out);

/// The same for B21R_COMMAND.
fw_opauth_verdict_t fw_opauth_take_command(fw_opauth_t* a, const void* data, size_t size, b21r_command_t* out);

/// The session announcement (B21R_SESSION) at controller time utime [µs], signed. With no key the
/// message carries zeros for key_id and mac (it is then not published). O(1).
void fw_opauth_session(const fw_opauth_t* a, int64_t utime, b21r_session_t* out);

/// Sets m->mac for key (m's other fields, key_id and session included, as they are): what the
/// operator tools do (tools/b21r_opauth.py), for tests and fuzz targets. O(1).
void fw_opauth_sign_teleop(const uint8_t key[FW_OPAUTH_KEY_BYTES], b21r_teleop_t* m);
void fw_opauth_sign_command(const uint8_t key[FW_OPAUTH_KEY_BYTES], b21r_command_t* m);

/// True when s->mac is right for key (what the operator tools check before taking a session).
bool fw_opauth_session_valid(const uint8_t key[FW_OPAUTH_KEY_BYTES], const b21r_session_t* s);

/// Snapshot of a's counters (relaxed loads; any thread). NULL gives zeros.
fw_opauth_counters_t fw_opauth_counters(const fw_opauth_t* a);

/// A short name of a verdict ("taken", "malformed", ...), for messages.
const char* fw_opauth_verdict_name(fw_opauth_verdict_t v);

/// Reads an operator key file: 64 hexadecimal digits, optionally followed by a newline. Refused
/// with a message in err naming the fix (err_cap bytes, NUL-terminated): a missing or unreadable
/// file, anything but a regular file, a file owned by another user than the effective one or root
/// (chown), a file with any permission for group or others (chmod 600), other content. Returns 0
/// with the key in key, or -1 (key unchanged). Reads at most a few hundred bytes.
int fw_opauth_load_key(const char* path, uint8_t key[FW_OPAUTH_KEY_BYTES], char* err, size_t err_cap);

#ifdef __cplusplus
}
#endif

#endif  // FW_OPAUTH_H
