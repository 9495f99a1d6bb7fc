// SPDX-License-Identifier: MIT
/// proto/lms200.h — SICK LMS200 telegram codec: CRC16, host and device encoders, streaming decoder.
///
/// Wire format (protocols.md B.2), all multi-byte fields little-endian:
/// `STX(0x02) ADR LEN(u16) CMD DATA... [STATUS] CRC16(u16)`. LEN counts CMD..last data byte and,
/// in replies (ADR 0x80), the trailing STATUS byte. The CRC covers STX..the byte before the CRC.
/// Before a reply telegram the LMS sends a single ACK byte 0x06 (NAK 0x15 when refused).
///
/// Both sides are here: the host (controller) encodes requests and decodes replies; the device
/// (emulator) decodes requests and encodes replies. The decoder's role picks which.
///
/// Memory: lms_decoder_t holds one telegram buffer (LMS_MAX_TELEGRAM_BYTES); lms_scan_t holds
/// LMS_MAX_SCAN_VALUES beams (about 4 kB). No allocation anywhere.
#ifndef PROTO_LMS200_H
#define PROTO_LMS200_H

#include <proto/common.h>

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/// @name Framing constants
/// @{
#define LMS_STX 0x02U         ///< Start of every telegram.
#define LMS_ACK 0x06U         ///< Single byte the LMS sends before accepting a request.
#define LMS_NAK 0x15U         ///< Single byte the LMS sends when it refuses a request.
#define LMS_ADR_DEVICE 0x00U  ///< ADR of requests (host -> LMS, default LMS address).
#define LMS_ADR_HOST 0x80U    ///< ADR of replies (LMS -> host).
/// Largest LEN the decoder accepts (CMD + data [+ STATUS]). The biggest telegram the LMS200
/// sends is a 0xB0 scan with 401 values: 1 + 2 + 802 + 1 (scan index) + 1 (status) = 807.
#define LMS_MAX_LEN 812U
/// Largest whole telegram (STX, ADR, LEN, body, CRC): the decoder's buffer size.
#define LMS_MAX_TELEGRAM_BYTES (4U + LMS_MAX_LEN + 2U)
/// Most beams in one scan (100° at 0.25°). Scans announcing more are refused (PROTO_ERR_CAPACITY).
#define LMS_MAX_SCAN_VALUES 401U
/// @}

/// @name Command and reply codes (reply = request + 0x80; protocols.md B.4)
/// @{
#define LMS_CMD_RESET 0x10U          ///< Initialisation and reset; reply 0x91.
#define LMS_CMD_MODE 0x20U           ///< Change operating mode; reply 0xA0.
#define LMS_CMD_VALUES 0x30U         ///< Request measured values; reply 0xB0.
#define LMS_CMD_STATUS 0x31U         ///< Status; reply 0xB1.
#define LMS_CMD_TYPE 0x3AU           ///< Type string; reply 0xBA.
#define LMS_CMD_VARIANT 0x3BU        ///< Change variant (width, resolution); reply 0xBB.
#define LMS_CMD_CONFIG_READ 0x74U    ///< Read configuration; reply 0xF4.
#define LMS_CMD_CONFIG_WRITE 0x77U   ///< Write configuration (installation mode); reply 0xF7.
#define LMS_REPLY_RESET 0x91U
#define LMS_REPLY_MODE 0xA0U
#define LMS_REPLY_VALUES 0xB0U
#define LMS_REPLY_STATUS 0xB1U
#define LMS_REPLY_TYPE 0xBAU
#define LMS_REPLY_VARIANT 0xBBU
#define LMS_REPLY_CONFIG_READ 0xF4U
#define LMS_REPLY_CONFIG_WRITE 0xF7U
#define LMS_REPLY_NAK 0x92U          ///< "Negative acknowledge" reply telegram.
/// @}

/// @name Mode bytes of LMS_CMD_MODE
/// @{
#define LMS_MODE_INSTALLATION 0x00U   ///< Followed by the 8-character password.
#define LMS_MODE_STREAM 0x24U         ///< Stream all measured values continuously.
#define LMS_MODE_STOP_STREAM 0x25U    ///< Values on request only.
#define LMS_MODE_BAUD_38400 0x40U
#define LMS_MODE_BAUD_19200 0x41U
#define LMS_MODE_BAUD_9600 0x42U
#define LMS_MODE_BAUD_500K 0x48U
/// Default installation-mode password of the LMS2xx.
#define LMS_DEFAULT_PASSWORD "SICK_LMS"
#define LMS_PASSWORD_BYTES 8U
/// @}

/// @name Sizes of the fixed reply blocks this codec writes and reads
/// @{
/// Status (0xB1) data bytes after the reply code, excluding STATUS. Byte offsets are counted
/// with the reply code as byte 0, as Player does: width at 107..108, resolution at 109..110.
#define LMS_STATUS_BLOCK_BYTES 152U
/// Configuration (0xF4) data bytes after the reply code, excluding STATUS.
#define LMS_CONFIG_BLOCK_BYTES 32U
/// Longest type string (0xBA) this codec writes or returns, excluding the terminating NUL.
#define LMS_TYPE_MAX_CHARS 32U
/// @}

// ---------------------------------------------------------------------------------------------
// CRC

/// SICK CRC16 (protocols.md B.3): polynomial 0x8005, init 0, no reflection, no final XOR, with
/// the previous byte folded into the high half of each step. Covers `len` bytes from STX up to
/// (not including) the CRC. Transmitted low byte first. O(len), no memory.
/// @param data bytes, may be NULL only when len is 0.
uint16_t lms_crc16(const uint8_t* data, size_t len);

// ---------------------------------------------------------------------------------------------
// Generic telegram encoder (both sides)

/// Writes STX, adr, LEN, cmd, data[0..n), optional status, CRC. LEN = 1 + n (+1 with status).
/// @param has_status true for replies (the STATUS byte is counted in LEN), false for requests.
/// @return bytes written (6 + n + has_status), or 0 if buf is NULL, data is NULL with n > 0,
///         LEN would exceed LMS_MAX_LEN, or cap is too small. O(n).
size_t lms_encode_telegram(uint8_t* buf, size_t cap, uint8_t adr, uint8_t cmd, const uint8_t* data,
                           size_t n, bool has_status, uint8_t status);

// ---------------------------------------------------------------------------------------------
// Host -> device request encoders. All return bytes written or 0 (see lms_encode_telegram).

/// Mode change 0x20 with a one-byte mode (stream 0x24, stop 0x25, baud codes...). 8 bytes.
size_t lms_encode_mode(uint8_t* buf, size_t cap, uint8_t mode);
/// Start streaming all values (`20 24`). 8 bytes.
size_t lms_encode_start_stream(uint8_t* buf, size_t cap);
/// Stop streaming (`20 25`). 8 bytes.
size_t lms_encode_stop_stream(uint8_t* buf, size_t cap);
/// Installation mode (`20 00` + 8 password characters). 16 bytes.
/// @param password exactly LMS_PASSWORD_BYTES characters (need not be NUL-terminated); NULL = "SICK_LMS".
size_t lms_encode_installation_mode(uint8_t* buf, size_t cap, const char* password);
/// Baud change. 8 bytes.
/// @param baud 9600, 19200, 38400 or 500000; anything else returns 0.
size_t lms_encode_baud(uint8_t* buf, size_t cap, uint32_t baud);
/// Mode byte for a baud rate (0x42/0x41/0x40/0x48), or 0xFF for an unsupported rate. O(1).
uint8_t lms_baud_mode(uint32_t baud);
/// Baud rate of a baud mode byte, or 0 if the byte is not a baud mode. O(1).
uint32_t lms_mode_baud(uint8_t mode);
/// Variant change 0x3B: width u16 + resolution u16. 11 bytes.
/// @param width_deg 180 or 100. @param res_cdeg 100, 50 or 25 (0.01°); 25 only with width 100.
/// Any other combination returns 0 (lms_variant_valid()).
size_t lms_encode_variant(uint8_t* buf, size_t cap, uint16_t width_deg, uint16_t res_cdeg);
/// True for the five variants the LMS200 supports (180/1°, 180/0.5°, 100/1°, 100/0.5°, 100/0.25°).
bool lms_variant_valid(uint16_t width_deg, uint16_t res_cdeg);
/// Status request 0x31. 7 bytes.
size_t lms_encode_status_request(uint8_t* buf, size_t cap);
/// Type request 0x3A. 7 bytes.
size_t lms_encode_type_request(uint8_t* buf, size_t cap);
/// Request measured values once, 0x30 with sub-mode 0x01 (all values). 8 bytes.
size_t lms_encode_values_request(uint8_t* buf, size_t cap);
/// Configuration read 0x74. 7 bytes.
size_t lms_encode_config_request(uint8_t* buf, size_t cap);

// ---------------------------------------------------------------------------------------------
// Typed reply contents (shared by device encoders and host parsers)

/// Distance unit of scan values (count word bits 14-15 / config byte 7).
typedef enum lms_unit {
  LMS_UNIT_CM = 0,  ///< 1 cm per LSB (max 81.91 m in the 13-bit modes).
  LMS_UNIT_MM = 1,  ///< 1 mm per LSB (max 8.191 m in the 13-bit modes).
} lms_unit_t;

/// Mode-change reply (0xA0) result byte.
typedef enum lms_mode_result {
  LMS_MODE_OK = 0,              ///< Mode changed.
  LMS_MODE_NOT_POSSIBLE = 1,    ///< Refused (e.g. config write outside installation mode).
  LMS_MODE_BAD_PASSWORD = 2,    ///< Installation-mode password wrong.
  LMS_MODE_FAULT = 3,           ///< Device fault; mode not changed.
} lms_mode_result_t;

/// Variant reply (0xBB) contents.
typedef struct lms_variant_reply {
  bool accepted;       ///< Byte 1: 1 = accepted, 0 = rejected.
  uint16_t width_deg;  ///< Active width after the request (100 or 180).
  uint16_t res_cdeg;   ///< Active resolution, 0.01° (25, 50, 100).
} lms_variant_reply_t;

/// The status (0xB1) fields this project writes and reads; every other byte of the
/// LMS_STATUS_BLOCK_BYTES block is written as 0 and ignored on read.
typedef struct lms_device_status {
  char version[8];        ///< Bytes 1..7: software version, 7 ASCII chars + NUL (e.g. "V02.10 ").
  uint8_t operating_mode; ///< Byte 8: current mode byte (0x24 streaming, 0x25 on request, ...).
  uint8_t device_status;  ///< Byte 9: 0 = OK, nonzero = error.
  lms_unit_t unit;        ///< Byte 122: units of measured values.
  uint16_t width_deg;     ///< Bytes 107..108 (LE): scan width (100 or 180).
  uint16_t res_cdeg;      ///< Bytes 109..110 (LE): resolution in 0.01°.
} lms_device_status_t;

/// The configuration (0xF4/0x77) fields this project writes and reads; other bytes are 0.
typedef struct lms_config {
  uint16_t blanking;        ///< Bytes 1..2 (LE).
  uint8_t stop_threshold;   ///< Byte 3.
  uint8_t peak_threshold;   ///< Byte 4 (sensitivity).
  uint8_t availability;     ///< Byte 5 (bit flags; 0x01 would add the real-time scan index).
  uint8_t measuring_mode;   ///< Byte 6 (0 = 8 m/80 m, fields A, B, dazzle: 13-bit distance).
  lms_unit_t unit;          ///< Byte 7: 0 = cm, 1 = mm.
} lms_config_t;

/// Configuration write 0x77 (needs installation mode): the block of lms_config_t. 39 bytes.
size_t lms_encode_config_write(uint8_t* buf, size_t cap, const lms_config_t* cfg);

// ---------------------------------------------------------------------------------------------
// Device -> host reply encoders (the emulator). Return bytes written or 0.

/// Scan reply 0xB0. Count word = n | partial_index << 11 | unit << 14.
/// @param raw n raw 16-bit values as sent (distance bits plus flag bits; see lms_range_to_raw()).
/// @param n 1..LMS_MAX_SCAN_VALUES. @param partial_index 0..3.
/// @param scan_index NULL, or a real-time scan index byte to append before STATUS.
/// @return 2n + 10 (+1 with scan_index) bytes, or 0. O(n).
size_t lms_encode_scan_reply(uint8_t* buf, size_t cap, const uint16_t* raw, size_t n,
                             lms_unit_t unit, uint8_t partial_index, const uint8_t* scan_index,
                             uint8_t status);
/// Mode reply 0xA0 with one result byte. 9 bytes.
size_t lms_encode_mode_reply(uint8_t* buf, size_t cap, lms_mode_result_t result, uint8_t status);
/// Variant reply 0xBB: accepted u8, width u16, resolution u16. 13 bytes.
size_t lms_encode_variant_reply(uint8_t* buf, size_t cap, const lms_variant_reply_t* reply,
                                uint8_t status);
/// Status reply 0xB1 (LMS_STATUS_BLOCK_BYTES data bytes). 160 bytes.
size_t lms_encode_status_reply(uint8_t* buf, size_t cap, const lms_device_status_t* st,
                               uint8_t status);
/// Type reply 0xBA with the ASCII string (no NUL on the wire).
/// @param type NUL-terminated, 1..LMS_TYPE_MAX_CHARS characters (e.g. "LMS200;30106").
size_t lms_encode_type_reply(uint8_t* buf, size_t cap, const char* type, uint8_t status);
/// Configuration reply 0xF4 (LMS_CONFIG_BLOCK_BYTES data bytes). 40 bytes.
size_t lms_encode_config_reply(uint8_t* buf, size_t cap, const lms_config_t* cfg, uint8_t status);
/// Negative-acknowledge reply telegram 0x92 (no data). 8 bytes.
size_t lms_encode_nak_reply(uint8_t* buf, size_t cap, uint8_t status);
/// The single ACK (0x06) or NAK (0x15) byte the LMS sends before a reply or instead of one.
/// @return 1, or 0 if buf is NULL or cap is 0.
size_t lms_encode_ack(uint8_t* buf, size_t cap, bool ack);

/// Converts a range to the raw value the LMS would send (13/14/15-bit distance, no flag bits).
/// Ranges that are not finite, negative, or beyond the largest valid distance become the
/// "no echo" code (all distance bits set); the largest valid distance is (2^bits - 10) LSB
/// because the top 9 codes are error codes. Rounds to the nearest LSB. O(1).
/// @param distance_bits 13, 14 or 15; anything else is treated as 13.
uint16_t lms_range_to_raw(float range_m, lms_unit_t unit, unsigned distance_bits);

// ---------------------------------------------------------------------------------------------
// Streaming decoder

/// Which side decodes: sets the expected ADR and whether replies carry STATUS and ACK/NAK bytes.
typedef enum lms_role {
  LMS_ROLE_HOST = 0,  ///< Controller: decodes LMS replies (ADR 0x80, STATUS byte, ACK/NAK bytes).
  LMS_ROLE_DEVICE,    ///< Emulator: decodes host requests (ADR 0x00, no STATUS, no ACK/NAK).
} lms_role_t;

/// Counters of an lms_decoder_t. Never decrease (wrap after 2^64).
typedef struct lms_decoder_counters {
  uint64_t bytes_in;           ///< Every byte consumed.
  uint64_t telegrams_ok;       ///< Telegrams with valid header, length and CRC (events emitted).
  uint64_t acks;               ///< ACK bytes outside telegrams (host role).
  uint64_t naks;               ///< NAK bytes outside telegrams (host role).
  uint64_t bytes_garbage;      ///< Bytes skipped while hunting for STX (not ACK/NAK, not a start).
  uint64_t bad_address;        ///< Candidate starts dropped: ADR not the role's address.
  uint64_t bad_length;         ///< Candidate starts dropped: LEN 0, too short for STATUS, or > max_len.
  uint64_t bad_crc;            ///< Complete telegrams dropped for a CRC mismatch.
  uint64_t bytes_dropped;      ///< Bytes discarded in total (garbage + bytes of dropped candidates).
} lms_decoder_counters_t;

/// One decoded telegram. `data` points into the decoder's buffer and stays valid only until the
/// next call to lms_decoder_push() or lms_decoder_reset() on the same decoder.
typedef struct lms_telegram {
  uint8_t adr;          ///< 0x80 (host role) or 0x00 (device role).
  uint8_t cmd;          ///< Request or reply code.
  const uint8_t* data;  ///< Bytes after CMD, excluding STATUS and CRC (NULL when data_len is 0).
  uint16_t data_len;    ///< LEN - 1 (requests) or LEN - 2 (replies).
  bool has_status;      ///< True in the host role.
  uint8_t status;       ///< STATUS byte of a reply, 0 for requests.
} lms_telegram_t;

/// What one lms_decoder_push() call produced.
typedef enum lms_event_kind {
  LMS_EVENT_NONE = 0,   ///< All given bytes consumed, nothing complete yet.
  LMS_EVENT_ACK,        ///< An ACK byte (host role).
  LMS_EVENT_NAK,        ///< A NAK byte (host role).
  LMS_EVENT_TELEGRAM,   ///< A valid telegram, in lms_event_t::telegram.
} lms_event_kind_t;

typedef struct lms_event {
  lms_event_kind_t kind;
  lms_telegram_t telegram;  ///< Valid for LMS_EVENT_TELEGRAM only.
} lms_event_t;

/// Decoder state. Fields are read-only for callers except through the functions below; read
/// `counters` directly. Size is fixed (about 850 bytes).
typedef struct lms_decoder {
  lms_role_t role;
  uint16_t max_len;                 ///< Largest accepted LEN (<= LMS_MAX_LEN).
  uint16_t fill;                    ///< Bytes held in buf.
  uint16_t pending;                 ///< Bytes of an emitted telegram to discard on the next push.
  uint8_t buf[LMS_MAX_TELEGRAM_BYTES];
  lms_decoder_counters_t counters;
} lms_decoder_t;

/// Initialises (or re-initialises, zeroing counters) a decoder. O(1).
/// @param max_len largest LEN to accept, 1..LMS_MAX_LEN; 0 means LMS_MAX_LEN. A tighter bound
///        resynchronises faster after a false STX.
/// @return PROTO_OK, or PROTO_ERR_INVALID_ARG (dec NULL, bad role or max_len), dec unchanged.
proto_status_t lms_decoder_init(lms_decoder_t* dec, lms_role_t role, uint16_t max_len);

/// Drops any partial telegram (e.g. after a baud change); counters keep their values, the
/// dropped bytes are counted in bytes_dropped. O(1).
void lms_decoder_reset(lms_decoder_t* dec);

/// Feeds bytes. Consumes bytes until one event completes or all `len` bytes are used, and
/// returns how many it consumed (<= len; 0 only when len is 0). The caller loops:
/// @code
///   while (len > 0) { size_t k = lms_decoder_push(&dec, p, len, &ev); p += k; len -= k;
///                     if (ev.kind != LMS_EVENT_NONE) handle(&ev); }
/// @endcode
/// After a false start (bad ADR, LEN or CRC) the decoder rescans the bytes it already holds, so
/// a telegram that begins inside a corrupt one is still found (an 0x06/0x15 byte among those
/// rescanned bytes is then reported as ACK/NAK: harmless, the host waits for reply telegrams). Worst case O(len + LMS_MAX_LEN)
/// per call amortised over the stream; no allocation.
/// @param ev always written (kind NONE when nothing completed). Must not be NULL.
size_t lms_decoder_push(lms_decoder_t* dec, const uint8_t* bytes, size_t len, lms_event_t* ev);

// ---------------------------------------------------------------------------------------------
// Typed reply parsers (host side)

/// Why a beam has no valid return (raw distance >= 2^bits - 9, e.g. >= 8183; protocols.md B.5).
typedef enum lms_beam_status {
  LMS_BEAM_OK = 0,           ///< Valid distance.
  LMS_BEAM_NO_ECHO,          ///< 8191: measurement not valid (no echo).
  LMS_BEAM_DAZZLED,          ///< 8190: dazzling.
  LMS_BEAM_OVERFLOW,         ///< 8189: operation overflow.
  LMS_BEAM_SNR_LOW,          ///< 8187: signal-to-noise ratio too small.
  LMS_BEAM_CHANNEL_ERROR,    ///< 8186: error reading channel 1.
  LMS_BEAM_OVER_MAX,         ///< 8183: measured value > maximum value.
  LMS_BEAM_ERROR_OTHER,      ///< 8184, 8185, 8188: other codes in the reserved band.
} lms_beam_status_t;

/// One decoded scan. Beam i points at start_angle_rad + i * step_rad (CCW positive, 0 = ahead).
typedef struct lms_scan {
  uint16_t count;            ///< Number of beams N (1..LMS_MAX_SCAN_VALUES).
  lms_unit_t unit;           ///< Unit of the raw distances.
  uint8_t partial_index;     ///< Count word bits 11-12: partial-scan offset index (0..3).
  uint8_t distance_bits;     ///< Distance bits used to decode (13, 14 or 15).
  uint8_t status;            ///< STATUS byte of the telegram.
  bool has_scan_index;       ///< A real-time scan index byte was present.
  uint8_t scan_index;        ///< Its value when present.
  bool geometry_known;       ///< N matched one of the five variants; else angles are 0.
  uint16_t width_deg;        ///< 180 or 100 when geometry_known, else 0.
  uint16_t res_cdeg;         ///< 100, 50 or 25 when geometry_known, else 0.
  float start_angle_rad;     ///< Angle of beam 0 (-pi/2 for 180°, -50° for 100°, plus partial offset).
  float step_rad;            ///< Angle between beams.
  float max_range_m;         ///< Largest valid distance: (2^bits - 10) LSB (81.82 m in cm mode).
  uint16_t no_return_count;  ///< Beams whose status is not LMS_BEAM_OK.
  /// Range in metres. For a beam without a valid return this holds max_range_m and
  /// beam_status[i] says why, so a consumer that ignores the status sees "nothing nearer".
  float range_m[LMS_MAX_SCAN_VALUES];
  uint16_t raw[LMS_MAX_SCAN_VALUES];          ///< Raw values as received (distance + flag bits).
  uint8_t beam_status[LMS_MAX_SCAN_VALUES];   ///< lms_beam_status_t per beam.
} lms_scan_t;

/// Decodes a 0xB0 telegram into a scan. O(N).
/// @param distance_bits 13 (default measuring mode, 8 m/80 m), 14 or 15; 0 means 13.
/// @return PROTO_OK; PROTO_ERR_FORMAT (not 0xB0, LEN inconsistent with N, unit bits 2/3);
///         PROTO_ERR_CAPACITY (N == 0 or N > LMS_MAX_SCAN_VALUES); PROTO_ERR_INVALID_ARG.
///         On failure *out is unchanged (all checks precede the first write).
proto_status_t lms_parse_scan(const lms_telegram_t* t, unsigned distance_bits, lms_scan_t* out);
/// Beam status of a raw value (flag bits above distance_bits are ignored). O(1).
lms_beam_status_t lms_raw_beam_status(uint16_t raw, unsigned distance_bits);
/// Raw code that the LMS sends for a no-return reason (e.g. 8191 for NO_ECHO at 13 bits); the
/// inverse of lms_raw_beam_status(). ERROR_OTHER gives 2^bits - 4 (8188); LMS_BEAM_OK gives 0.
/// O(1).
uint16_t lms_beam_status_raw(lms_beam_status_t reason, unsigned distance_bits);
/// Short name of a beam status ("no_echo", ...), never NULL.
const char* lms_beam_status_name(lms_beam_status_t s);

/// Parses a 0xA0 reply. @return PROTO_OK or PROTO_ERR_FORMAT.
proto_status_t lms_parse_mode_reply(const lms_telegram_t* t, lms_mode_result_t* result);
/// Parses a 0xBB reply (needs >= 5 data bytes). @return PROTO_OK or PROTO_ERR_FORMAT.
proto_status_t lms_parse_variant_reply(const lms_telegram_t* t, lms_variant_reply_t* out);
/// Parses a 0xB1 reply (needs >= 110 data bytes for width and resolution; other fields read
/// when present). @return PROTO_OK or PROTO_ERR_FORMAT.
proto_status_t lms_parse_status_reply(const lms_telegram_t* t, lms_device_status_t* out);
/// Copies the ASCII of a 0xBA reply, NUL-terminated. @return PROTO_OK, PROTO_ERR_FORMAT, or
/// PROTO_ERR_CAPACITY when cap <= data_len (out then holds a truncated string).
proto_status_t lms_parse_type_reply(const lms_telegram_t* t, char* out, size_t cap);
/// Parses a 0xF4 reply (needs >= 7 data bytes). @return PROTO_OK or PROTO_ERR_FORMAT.
proto_status_t lms_parse_config_reply(const lms_telegram_t* t, lms_config_t* out);

// ---------------------------------------------------------------------------------------------
// Typed request parser (device side)

typedef enum lms_request_kind {
  LMS_REQ_UNKNOWN = 0,   ///< Valid telegram with a code this codec does not model (cmd kept).
  LMS_REQ_RESET,         ///< 0x10.
  LMS_REQ_MODE,          ///< 0x20 with any mode other than installation or a baud code.
  LMS_REQ_INSTALLATION,  ///< 0x20 00 + password.
  LMS_REQ_BAUD,          ///< 0x20 with 0x40/0x41/0x42/0x48.
  LMS_REQ_VALUES,        ///< 0x30.
  LMS_REQ_STATUS,        ///< 0x31.
  LMS_REQ_TYPE,          ///< 0x3A.
  LMS_REQ_VARIANT,       ///< 0x3B.
  LMS_REQ_CONFIG_READ,   ///< 0x74.
  LMS_REQ_CONFIG_WRITE,  ///< 0x77.
} lms_request_kind_t;

/// A host request as the device sees it.
typedef struct lms_request {
  lms_request_kind_t kind;
  uint8_t cmd;                              ///< Raw command code.
  uint8_t mode;                             ///< Mode byte (MODE, INSTALLATION, BAUD).
  uint32_t baud;                            ///< BAUD: 9600, 19200, 38400 or 500000.
  char password[LMS_PASSWORD_BYTES + 1];    ///< INSTALLATION: the 8 characters + NUL.
  uint16_t width_deg;                       ///< VARIANT (not validated: see lms_variant_valid()).
  uint16_t res_cdeg;                        ///< VARIANT.
  uint8_t values_mode;                      ///< VALUES: sub-mode byte (0x01 all values), 0 if absent.
  lms_config_t config;                      ///< CONFIG_WRITE.
} lms_request_t;

/// Classifies a request telegram decoded in the device role. O(1).
/// @return PROTO_OK (also for LMS_REQ_UNKNOWN), PROTO_ERR_FORMAT when a known code has too few
///         data bytes (e.g. installation mode without 8 password bytes), PROTO_ERR_INVALID_ARG.
proto_status_t lms_parse_request(const lms_telegram_t* t, lms_request_t* out);

#ifdef __cplusplus
}
#endif

#endif  // PROTO_LMS200_H
