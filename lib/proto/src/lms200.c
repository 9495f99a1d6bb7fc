// SPDX-License-Identifier: MIT
// SICK LMS200 telegrams: CRC16, request and reply encoders, the streaming decoder, typed parsers.
#include <proto/lms200.h>

#include "bytes.h"

#include <math.h>
#include <string.h>

uint16_t lms_crc16(const uint8_t* data, size_t len) {
  // SICK's own CRC (not a textbook CRC-16): the previous byte is folded into the high half.
  uint16_t crc = 0;
  uint8_t prev = 0;
  for (size_t i = 0; i < len; ++i) {
    const uint8_t cur = data[i];
    if ((crc & 0x8000U) != 0U) {
      crc = (uint16_t)(((unsigned)(crc & 0x7FFFU) << 1) ^ 0x8005U);
    } else {
      crc = (uint16_t)((unsigned)crc << 1);
    }
    crc = (uint16_t)(crc ^ ((unsigned)cur | ((unsigned)prev << 8)));
    prev = cur;
  }
  return crc;
}

// ---------------------------------------------------------------------------------------------
// Encoders

size_t lms_encode_telegram(uint8_t* buf, size_t cap, uint8_t adr, uint8_t cmd, const uint8_t* data,
                           size_t n, bool has_status, uint8_t status) {
  const size_t len_field = 1U + n + (has_status ? 1U : 0U);
  const size_t total = 4U + len_field + 2U;
  if (buf == NULL || (data == NULL && n > 0U) || len_field > LMS_MAX_LEN || cap < total) {
    return 0;
  }
  buf[0] = LMS_STX;
  buf[1] = adr;
  proto_put_le16(&buf[2], (uint16_t)len_field);
  buf[4] = cmd;
  if (n > 0U) {
    memcpy(&buf[5], data, n);
  }
  if (has_status) {
    buf[5U + n] = status;
  }
  proto_put_le16(&buf[4U + len_field], lms_crc16(buf, 4U + len_field));
  return total;
}

static size_t encode_request(uint8_t* buf, size_t cap, uint8_t cmd, const uint8_t* data, size_t n) {
  return lms_encode_telegram(buf, cap, LMS_ADR_DEVICE, cmd, data, n, false, 0);
}

static size_t encode_reply(uint8_t* buf, size_t cap, uint8_t cmd, const uint8_t* data, size_t n,
                           uint8_t status) {
  return lms_encode_telegram(buf, cap, LMS_ADR_HOST, cmd, data, n, true, status);
}

size_t lms_encode_mode(uint8_t* buf, size_t cap, uint8_t mode) {
  return encode_request(buf, cap, LMS_CMD_MODE, &mode, 1);
}

size_t lms_encode_start_stream(uint8_t* buf, size_t cap) {
  return lms_encode_mode(buf, cap, LMS_MODE_STREAM);
}

size_t lms_encode_stop_stream(uint8_t* buf, size_t cap) {
  return lms_encode_mode(buf, cap, LMS_MODE_STOP_STREAM);
}

size_t lms_encode_installation_mode(uint8_t* buf, size_t cap, const char* password) {
  uint8_t data[1U + LMS_PASSWORD_BYTES];
  data[0] = LMS_MODE_INSTALLATION;
  memcpy(&data[1], password != NULL ? password : LMS_DEFAULT_PASSWORD, LMS_PASSWORD_BYTES);
  return encode_request(buf, cap, LMS_CMD_MODE, data, sizeof data);
}

uint8_t lms_baud_mode(uint32_t baud) {
  switch (baud) {
    case 9600U:
      return LMS_MODE_BAUD_9600;
    case 19200U:
      return LMS_MODE_BAUD_19200;
    case 38400U:
      return LMS_MODE_BAUD_38400;
    case 500000U:
      return LMS_MODE_BAUD_500K;
    default:
      return 0xFFU;
  }
}

uint32_t lms_mode_baud(uint8_t mode) {
  switch (mode) {
    case LMS_MODE_BAUD_9600:
      return 9600U;
    case LMS_MODE_BAUD_19200:
      return 19200U;
    case LMS_MODE_BAUD_38400:
      return 38400U;
    case LMS_MODE_BAUD_500K:
      return 500000U;
    default:
      return 0;
  }
}

size_t lms_encode_baud(uint8_t* buf, size_t cap, uint32_t baud) {
  const uint8_t mode = lms_baud_mode(baud);
  if (mode == 0xFFU) {
    return 0;
  }
  return lms_encode_mode(buf, cap, mode);
}

bool lms_variant_valid(uint16_t width_deg, uint16_t res_cdeg) {
  if (width_deg == 180U) {
    return res_cdeg == 100U || res_cdeg == 50U;
  }
  if (width_deg == 100U) {
    return res_cdeg == 100U || res_cdeg == 50U || res_cdeg == 25U;
  }
  return false;
}

size_t lms_encode_variant(uint8_t* buf, size_t cap, uint16_t width_deg, uint16_t res_cdeg) {
  if (!lms_variant_valid(width_deg, res_cdeg)) {
    return 0;
  }
  uint8_t data[4];
  proto_put_le16(&data[0], width_deg);
  proto_put_le16(&data[2], res_cdeg);
  return encode_request(buf, cap, LMS_CMD_VARIANT, data, sizeof data);
}

size_t lms_encode_status_request(uint8_t* buf, size_t cap) {
  return encode_request(buf, cap, LMS_CMD_STATUS, NULL, 0);
}

size_t lms_encode_type_request(uint8_t* buf, size_t cap) {
  return encode_request(buf, cap, LMS_CMD_TYPE, NULL, 0);
}

size_t lms_encode_values_request(uint8_t* buf, size_t cap) {
  const uint8_t all_values = 0x01U;
  return encode_request(buf, cap, LMS_CMD_VALUES, &all_values, 1);
}

size_t lms_encode_config_request(uint8_t* buf, size_t cap) {
  return encode_request(buf, cap, LMS_CMD_CONFIG_READ, NULL, 0);
}

static void config_to_block(const lms_config_t* cfg, uint8_t block[LMS_CONFIG_BLOCK_BYTES]) {
  memset(block, 0, LMS_CONFIG_BLOCK_BYTES);
  proto_put_le16(&block[0], cfg->blanking);
  block[2] = cfg->stop_threshold;
  block[3] = cfg->peak_threshold;
  block[4] = cfg->availability;
  block[5] = cfg->measuring_mode;
  block[6] = (uint8_t)cfg->unit;
}

static proto_status_t config_from_block(const uint8_t* block, size_t n, lms_config_t* out) {
  if (n < 7U || block[6] > 1U) {
    return PROTO_ERR_FORMAT;
  }
  out->blanking = proto_le16(&block[0]);
  out->stop_threshold = block[2];
  out->peak_threshold = block[3];
  out->availability = block[4];
  out->measuring_mode = block[5];
  out->unit = block[6] == 0U ? LMS_UNIT_CM : LMS_UNIT_MM;
  return PROTO_OK;
}

size_t lms_encode_config_write(uint8_t* buf, size_t cap, const lms_config_t* cfg) {
  if (cfg == NULL || (cfg->unit != LMS_UNIT_CM && cfg->unit != LMS_UNIT_MM)) {
    return 0;
  }
  uint8_t block[LMS_CONFIG_BLOCK_BYTES];
  config_to_block(cfg, block);
  return encode_request(buf, cap, LMS_CMD_CONFIG_WRITE, block, sizeof block);
}

size_t lms_encode_scan_reply(uint8_t* buf, size_t cap, const uint16_t* raw, size_t n,
                             lms_unit_t unit, uint8_t partial_index, const uint8_t* scan_index,
                             uint8_t status) {
  if (raw == NULL || n == 0U || n > LMS_MAX_SCAN_VALUES || partial_index > 3U ||
      (unit != LMS_UNIT_CM && unit != LMS_UNIT_MM)) {
    return 0;
  }
  const size_t n_data = 2U + 2U * n + (scan_index != NULL ? 1U : 0U);
  const size_t total = 4U + 1U + n_data + 1U + 2U;
  if (buf == NULL || cap < total) {
    return 0;
  }
  // Built in place (the data block is up to 805 bytes: no stack copy).
  buf[0] = LMS_STX;
  buf[1] = LMS_ADR_HOST;
  proto_put_le16(&buf[2], (uint16_t)(n_data + 2U));
  buf[4] = LMS_REPLY_VALUES;
  const uint16_t count_word =
      (uint16_t)(n | ((unsigned)partial_index << 11) | ((unsigned)unit << 14));
  proto_put_le16(&buf[5], count_word);
  for (size_t i = 0; i < n; ++i) {
    proto_put_le16(&buf[7U + 2U * i], raw[i]);
  }
  if (scan_index != NULL) {
    buf[7U + 2U * n] = *scan_index;
  }
  buf[5U + n_data] = status;
  proto_put_le16(&buf[6U + n_data], lms_crc16(buf, 6U + n_data));
  return total;
}

size_t lms_encode_mode_reply(uint8_t* buf, size_t cap, lms_mode_result_t result, uint8_t status) {
  const uint8_t r = (uint8_t)result;
  return encode_reply(buf, cap, LMS_REPLY_MODE, &r, 1, status);
}

size_t lms_encode_variant_reply(uint8_t* buf, size_t cap, const lms_variant_reply_t* reply,
                                uint8_t status) {
  if (reply == NULL) {
    return 0;
  }
  uint8_t data[5];
  data[0] = reply->accepted ? 1U : 0U;
  proto_put_le16(&data[1], reply->width_deg);
  proto_put_le16(&data[3], reply->res_cdeg);
  return encode_reply(buf, cap, LMS_REPLY_VARIANT, data, sizeof data, status);
}

// Offsets in the status block, counted from the first data byte (reply code = byte 0 in
// Player's numbering, so block[i] is Player's byte i + 1).
enum {
  STATUS_VERSION = 0,
  STATUS_OPERATING_MODE = 7,
  STATUS_DEVICE_STATUS = 8,
  STATUS_WIDTH = 106,
  STATUS_RES = 108,
  STATUS_UNIT = 121,
};

size_t lms_encode_status_reply(uint8_t* buf, size_t cap, const lms_device_status_t* st,
                               uint8_t status) {
  if (st == NULL || (st->unit != LMS_UNIT_CM && st->unit != LMS_UNIT_MM)) {
    return 0;
  }
  uint8_t block[LMS_STATUS_BLOCK_BYTES];
  memset(block, 0, sizeof block);
  for (size_t i = 0; i < 7U && st->version[i] != '\0'; ++i) {
    block[STATUS_VERSION + i] = (uint8_t)st->version[i];
  }
  block[STATUS_OPERATING_MODE] = st->operating_mode;
  block[STATUS_DEVICE_STATUS] = st->device_status;
  proto_put_le16(&block[STATUS_WIDTH], st->width_deg);
  proto_put_le16(&block[STATUS_RES], st->res_cdeg);
  block[STATUS_UNIT] = (uint8_t)st->unit;
  return encode_reply(buf, cap, LMS_REPLY_STATUS, block, sizeof block, status);
}

size_t lms_encode_type_reply(uint8_t* buf, size_t cap, const char* type, uint8_t status) {
  if (type == NULL) {
    return 0;
  }
  const char* end = memchr(type, '\0', LMS_TYPE_MAX_CHARS + 1U);
  const size_t n = end != NULL ? (size_t)(end - type) : LMS_TYPE_MAX_CHARS + 1U;
  if (n == 0U || n > LMS_TYPE_MAX_CHARS) {
    return 0;
  }
  return encode_reply(buf, cap, LMS_REPLY_TYPE, (const uint8_t*)type, n, status);
}

size_t lms_encode_config_reply(uint8_t* buf, size_t cap, const lms_config_t* cfg, uint8_t status) {
  if (cfg == NULL || (cfg->unit != LMS_UNIT_CM && cfg->unit != LMS_UNIT_MM)) {
    return 0;
  }
  uint8_t block[LMS_CONFIG_BLOCK_BYTES];
  config_to_block(cfg, block);
  return encode_reply(buf, cap, LMS_REPLY_CONFIG_READ, block, sizeof block, status);
}

size_t lms_encode_nak_reply(uint8_t* buf, size_t cap, uint8_t status) {
  return encode_reply(buf, cap, LMS_REPLY_NAK, NULL, 0, status);
}

size_t lms_encode_ack(uint8_t* buf, size_t cap, bool ack) {
  if (buf == NULL || cap == 0U) {
    return 0;
  }
  buf[0] = ack ? LMS_ACK : LMS_NAK;
  return 1;
}

static unsigned norm_bits(unsigned distance_bits) {
  return (distance_bits == 14U || distance_bits == 15U) ? distance_bits : 13U;
}

static float lsb_m(lms_unit_t unit) { return unit == LMS_UNIT_MM ? 0.001f : 0.01f; }

uint16_t lms_range_to_raw(float range_m, lms_unit_t unit, unsigned distance_bits) {
  const unsigned bits = norm_bits(distance_bits);
  const unsigned no_echo = (1U << bits) - 1U;
  const unsigned max_valid = (1U << bits) - 10U;
  if (!isfinite(range_m) || range_m < 0.0f) {
    return (uint16_t)no_echo;
  }
  const float lsb = lsb_m(unit);
  const float counts = range_m / lsb;
  if (counts > (float)max_valid + 0.5f) {
    return (uint16_t)no_echo;
  }
  long v = lroundf(counts);
  if (v > (long)max_valid) {
    v = (long)max_valid;
  }
  return (uint16_t)v;
}

// ---------------------------------------------------------------------------------------------
// Streaming decoder

proto_status_t lms_decoder_init(lms_decoder_t* dec, lms_role_t role, uint16_t max_len) {
  if (dec == NULL || (role != LMS_ROLE_HOST && role != LMS_ROLE_DEVICE) || max_len > LMS_MAX_LEN) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (role == LMS_ROLE_HOST && max_len == 1U) {
    return PROTO_ERR_INVALID_ARG;  // a reply needs at least CMD and STATUS
  }
  memset(dec, 0, sizeof *dec);
  dec->role = role;
  dec->max_len = max_len == 0U ? (uint16_t)LMS_MAX_LEN : max_len;
  return PROTO_OK;
}

static void drop_front(lms_decoder_t* dec, size_t n) {
  memmove(dec->buf, dec->buf + n, dec->fill - n);
  dec->fill = (uint16_t)(dec->fill - n);
}

void lms_decoder_reset(lms_decoder_t* dec) {
  if (dec == NULL) {
    return;
  }
  if (dec->pending > 0U) {
    drop_front(dec, dec->pending);
    dec->pending = 0;
  }
  dec->counters.bytes_dropped += dec->fill;
  dec->fill = 0;
}

typedef enum scan_result { SCAN_NEED_MORE, SCAN_DROPPED, SCAN_EVENT } scan_result_t;

// Looks at the bytes held: emits at most one event from the front of the buffer, or drops
// bytes that cannot start a telegram, or asks for more.
static scan_result_t scan_buffer(lms_decoder_t* dec, lms_event_t* ev) {
  const bool host = dec->role == LMS_ROLE_HOST;
  if (dec->fill == 0U) {
    return SCAN_NEED_MORE;
  }
  const uint8_t b0 = dec->buf[0];
  if (b0 != LMS_STX) {
    if (host && (b0 == LMS_ACK || b0 == LMS_NAK)) {
      ev->kind = b0 == LMS_ACK ? LMS_EVENT_ACK : LMS_EVENT_NAK;
      if (b0 == LMS_ACK) {
        dec->counters.acks++;
      } else {
        dec->counters.naks++;
      }
      dec->pending = 1;
      return SCAN_EVENT;
    }
    // Skip the whole run of bytes that cannot start anything.
    size_t n = 1;
    while (n < dec->fill && dec->buf[n] != LMS_STX &&
           !(host && (dec->buf[n] == LMS_ACK || dec->buf[n] == LMS_NAK))) {
      ++n;
    }
    dec->counters.bytes_garbage += n;
    dec->counters.bytes_dropped += n;
    drop_front(dec, n);
    return SCAN_DROPPED;
  }
  if (dec->fill < 2U) {
    return SCAN_NEED_MORE;
  }
  const uint8_t want_adr = host ? LMS_ADR_HOST : LMS_ADR_DEVICE;
  if (dec->buf[1] != want_adr) {
    dec->counters.bad_address++;
    dec->counters.bytes_dropped++;
    drop_front(dec, 1);
    return SCAN_DROPPED;
  }
  if (dec->fill < 4U) {
    return SCAN_NEED_MORE;
  }
  const uint16_t len = proto_le16(&dec->buf[2]);
  const uint16_t min_len = host ? 2U : 1U;
  if (len < min_len || len > dec->max_len) {
    dec->counters.bad_length++;
    dec->counters.bytes_dropped++;
    drop_front(dec, 1);
    return SCAN_DROPPED;
  }
  const size_t total = 4U + (size_t)len + 2U;
  if (dec->fill < total) {
    return SCAN_NEED_MORE;
  }
  const uint16_t crc = lms_crc16(dec->buf, 4U + (size_t)len);
  if (crc != proto_le16(&dec->buf[4U + len])) {
    // The STX was false (or the telegram corrupt): rescan from the next byte, so a real
    // telegram that started inside this candidate is still found.
    dec->counters.bad_crc++;
    dec->counters.bytes_dropped++;
    drop_front(dec, 1);
    return SCAN_DROPPED;
  }
  lms_telegram_t* t = &ev->telegram;
  t->adr = dec->buf[1];
  t->cmd = dec->buf[4];
  t->data_len = (uint16_t)(len - min_len);
  t->data = t->data_len > 0U ? &dec->buf[5] : NULL;
  t->has_status = host;
  t->status = host ? dec->buf[4U + len - 1U] : 0U;
  ev->kind = LMS_EVENT_TELEGRAM;
  dec->counters.telegrams_ok++;
  dec->pending = (uint16_t)total;
  return SCAN_EVENT;
}

size_t lms_decoder_push(lms_decoder_t* dec, const uint8_t* bytes, size_t len, lms_event_t* ev) {
  if (ev != NULL) {
    memset(ev, 0, sizeof *ev);
  }
  if (dec == NULL || ev == NULL || (bytes == NULL && len > 0U)) {
    return len;  // nothing can be done; consuming everything keeps callers' loops finite
  }
  if (dec->pending > 0U) {
    drop_front(dec, dec->pending);
    dec->pending = 0;
  }
  size_t used = 0;
  for (;;) {
    const scan_result_t r = scan_buffer(dec, ev);
    if (r == SCAN_EVENT) {
      return used;
    }
    if (r == SCAN_DROPPED) {
      continue;
    }
    if (used == len) {
      return used;
    }
    // SCAN_NEED_MORE guarantees fill < 4 + max_len + 2 <= sizeof buf.
    dec->buf[dec->fill++] = bytes[used++];
    dec->counters.bytes_in++;
  }
}

// ---------------------------------------------------------------------------------------------
// Typed parsers

lms_beam_status_t lms_raw_beam_status(uint16_t raw, unsigned distance_bits) {
  const unsigned bits = norm_bits(distance_bits);
  const unsigned top = (1U << bits) - 1U;
  const unsigned d = (unsigned)raw & top;
  if (d + 8U < top) {
    return LMS_BEAM_OK;
  }
  switch (top - d) {
    case 0:
      return LMS_BEAM_NO_ECHO;
    case 1:
      return LMS_BEAM_DAZZLED;
    case 2:
      return LMS_BEAM_OVERFLOW;
    case 4:
      return LMS_BEAM_SNR_LOW;
    case 5:
      return LMS_BEAM_CHANNEL_ERROR;
    case 8:
      return LMS_BEAM_OVER_MAX;
    default:
      return LMS_BEAM_ERROR_OTHER;
  }
}

uint16_t lms_beam_status_raw(lms_beam_status_t reason, unsigned distance_bits) {
  const unsigned top = (1U << norm_bits(distance_bits)) - 1U;
  unsigned off = 0;
  switch (reason) {
    case LMS_BEAM_OK:
      return 0;
    case LMS_BEAM_NO_ECHO:
      off = 0;
      break;
    case LMS_BEAM_DAZZLED:
      off = 1;
      break;
    case LMS_BEAM_OVERFLOW:
      off = 2;
      break;
    case LMS_BEAM_SNR_LOW:
      off = 4;
      break;
    case LMS_BEAM_CHANNEL_ERROR:
      off = 5;
      break;
    case LMS_BEAM_OVER_MAX:
      off = 8;
      break;
    case LMS_BEAM_ERROR_OTHER:
      off = 3;
      break;
  }
  return (uint16_t)(top - off);
}

const char* lms_beam_status_name(lms_beam_status_t s) {
  switch (s) {
    case LMS_BEAM_OK:
      return "ok";
    case LMS_BEAM_NO_ECHO:
      return "no_echo";
    case LMS_BEAM_DAZZLED:
      return "dazzled";
    case LMS_BEAM_OVERFLOW:
      return "overflow";
    case LMS_BEAM_SNR_LOW:
      return "snr_low";
    case LMS_BEAM_CHANNEL_ERROR:
      return "channel_error";
    case LMS_BEAM_OVER_MAX:
      return "over_max";
    case LMS_BEAM_ERROR_OTHER:
      return "error_other";
  }
  return "unknown";
}

static bool is_reply(const lms_telegram_t* t, uint8_t code) {
  return t != NULL && t->cmd == code && t->has_status && (t->data != NULL || t->data_len == 0U);
}

proto_status_t lms_parse_scan(const lms_telegram_t* t, unsigned distance_bits, lms_scan_t* out) {
  if (t == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_reply(t, LMS_REPLY_VALUES) || t->data_len < 2U) {
    return PROTO_ERR_FORMAT;
  }
  const uint16_t cw = proto_le16(t->data);
  const unsigned n = cw & 0x3FFU;
  const unsigned unit_bits = (unsigned)cw >> 14;
  if (n == 0U || n > LMS_MAX_SCAN_VALUES) {
    return PROTO_ERR_CAPACITY;
  }
  const size_t plain = 2U + 2U * (size_t)n;
  if ((t->data_len != plain && t->data_len != plain + 1U) || unit_bits > 1U) {
    return PROTO_ERR_FORMAT;
  }
  const unsigned bits = norm_bits(distance_bits);
  out->count = (uint16_t)n;
  out->unit = unit_bits == 0U ? LMS_UNIT_CM : LMS_UNIT_MM;
  out->partial_index = (uint8_t)((cw >> 11) & 0x3U);
  out->distance_bits = (uint8_t)bits;
  out->status = t->status;
  out->has_scan_index = t->data_len == plain + 1U;
  out->scan_index = out->has_scan_index ? t->data[plain] : 0U;

  uint16_t width = 0;
  uint16_t res = 0;
  switch (n) {
    case 181:
      width = 180;
      res = 100;
      break;
    case 361:
      width = 180;
      res = 50;
      break;
    case 101:
      width = 100;
      res = 100;
      break;
    case 201:
      width = 100;
      res = 50;
      break;
    case 401:
      width = 100;
      res = 25;
      break;
    default:
      break;
  }
  const float deg = 0.017453292519943295f;
  out->geometry_known = width != 0U;
  out->width_deg = width;
  out->res_cdeg = res;
  if (out->geometry_known) {
    out->start_angle_rad =
        (-0.5f * (float)width + 0.25f * (float)out->partial_index) * deg;
    out->step_rad = 0.01f * (float)res * deg;
  } else {
    out->start_angle_rad = 0.0f;
    out->step_rad = 0.0f;
  }
  const float lsb = lsb_m(out->unit);
  const unsigned mask = (1U << bits) - 1U;
  out->max_range_m = (float)((1U << bits) - 10U) * lsb;
  out->no_return_count = 0;
  for (unsigned i = 0; i < n; ++i) {
    const uint16_t raw = proto_le16(&t->data[2U + 2U * i]);
    const lms_beam_status_t bs = lms_raw_beam_status(raw, bits);
    out->raw[i] = raw;
    out->beam_status[i] = (uint8_t)bs;
    if (bs == LMS_BEAM_OK) {
      out->range_m[i] = (float)((unsigned)raw & mask) * lsb;
    } else {
      out->range_m[i] = out->max_range_m;
      out->no_return_count++;
    }
  }
  return PROTO_OK;
}

proto_status_t lms_parse_mode_reply(const lms_telegram_t* t, lms_mode_result_t* result) {
  if (t == NULL || result == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_reply(t, LMS_REPLY_MODE) || t->data_len < 1U || t->data[0] > 3U) {
    return PROTO_ERR_FORMAT;
  }
  *result = (lms_mode_result_t)t->data[0];
  return PROTO_OK;
}

proto_status_t lms_parse_variant_reply(const lms_telegram_t* t, lms_variant_reply_t* out) {
  if (t == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_reply(t, LMS_REPLY_VARIANT) || t->data_len < 5U) {
    return PROTO_ERR_FORMAT;
  }
  out->accepted = t->data[0] == 1U;
  out->width_deg = proto_le16(&t->data[1]);
  out->res_cdeg = proto_le16(&t->data[3]);
  return PROTO_OK;
}

proto_status_t lms_parse_status_reply(const lms_telegram_t* t, lms_device_status_t* out) {
  if (t == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_reply(t, LMS_REPLY_STATUS) || t->data_len < STATUS_RES + 2U) {
    return PROTO_ERR_FORMAT;
  }
  memset(out, 0, sizeof *out);
  for (size_t i = 0; i < 7U; ++i) {
    const uint8_t c = t->data[STATUS_VERSION + i];
    out->version[i] = (c >= 0x20U && c < 0x7FU) ? (char)c : '?';
  }
  out->version[7] = '\0';
  out->operating_mode = t->data[STATUS_OPERATING_MODE];
  out->device_status = t->data[STATUS_DEVICE_STATUS];
  out->width_deg = proto_le16(&t->data[STATUS_WIDTH]);
  out->res_cdeg = proto_le16(&t->data[STATUS_RES]);
  out->unit = (t->data_len > STATUS_UNIT && t->data[STATUS_UNIT] == 1U) ? LMS_UNIT_MM : LMS_UNIT_CM;
  return PROTO_OK;
}

proto_status_t lms_parse_type_reply(const lms_telegram_t* t, char* out, size_t cap) {
  if (t == NULL || out == NULL || cap == 0U) {
    return PROTO_ERR_INVALID_ARG;
  }
  out[0] = '\0';
  if (!is_reply(t, LMS_REPLY_TYPE)) {
    return PROTO_ERR_FORMAT;
  }
  size_t n = t->data_len;
  proto_status_t st = PROTO_OK;
  if (n >= cap) {
    n = cap - 1U;
    st = PROTO_ERR_CAPACITY;
  }
  for (size_t i = 0; i < n; ++i) {
    const uint8_t c = t->data[i];
    out[i] = (c >= 0x20U && c < 0x7FU) ? (char)c : '?';
  }
  out[n] = '\0';
  return st;
}

proto_status_t lms_parse_config_reply(const lms_telegram_t* t, lms_config_t* out) {
  if (t == NULL || out == NULL) {
    return PROTO_ERR_INVALID_ARG;
  }
  if (!is_reply(t, LMS_REPLY_CONFIG_READ)) {
    return PROTO_ERR_FORMAT;
  }
  return config_from_block(t->data, t->data_len, out);
}

proto_status_t lms_parse_request(const lms_telegram_t* t, lms_request_t* out) {
  if (t == NULL || out == NULL || (t->data == NULL && t->data_len > 0U)) {
    return PROTO_ERR_INVALID_ARG;
  }
  memset(out, 0, sizeof *out);
  out->cmd = t->cmd;
  const uint8_t* d = t->data;
  const size_t n = t->data_len;
  switch (t->cmd) {
    case LMS_CMD_RESET:
      out->kind = LMS_REQ_RESET;
      return PROTO_OK;
    case LMS_CMD_MODE:
      if (n < 1U) {
        return PROTO_ERR_FORMAT;
      }
      out->mode = d[0];
      if (d[0] == LMS_MODE_INSTALLATION) {
        if (n < 1U + LMS_PASSWORD_BYTES) {
          return PROTO_ERR_FORMAT;
        }
        out->kind = LMS_REQ_INSTALLATION;
        memcpy(out->password, &d[1], LMS_PASSWORD_BYTES);
        out->password[LMS_PASSWORD_BYTES] = '\0';
      } else if (lms_mode_baud(d[0]) != 0U) {
        out->kind = LMS_REQ_BAUD;
        out->baud = lms_mode_baud(d[0]);
      } else {
        out->kind = LMS_REQ_MODE;
      }
      return PROTO_OK;
    case LMS_CMD_VALUES:
      out->kind = LMS_REQ_VALUES;
      out->values_mode = n >= 1U ? d[0] : 0U;
      return PROTO_OK;
    case LMS_CMD_STATUS:
      out->kind = LMS_REQ_STATUS;
      return PROTO_OK;
    case LMS_CMD_TYPE:
      out->kind = LMS_REQ_TYPE;
      return PROTO_OK;
    case LMS_CMD_VARIANT:
      if (n < 4U) {
        return PROTO_ERR_FORMAT;
      }
      out->kind = LMS_REQ_VARIANT;
      out->width_deg = proto_le16(&d[0]);
      out->res_cdeg = proto_le16(&d[2]);
      return PROTO_OK;
    case LMS_CMD_CONFIG_READ:
      out->kind = LMS_REQ_CONFIG_READ;
      return PROTO_OK;
    case LMS_CMD_CONFIG_WRITE:
      if (config_from_block(d, n, &out->config) != PROTO_OK) {
        return PROTO_ERR_FORMAT;
      }
      out->kind = LMS_REQ_CONFIG_WRITE;
      return PROTO_OK;
    default:
      out->kind = LMS_REQ_UNKNOWN;
      return PROTO_OK;
  }
}
