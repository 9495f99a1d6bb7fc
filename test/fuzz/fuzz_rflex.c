// SPDX-License-Identifier: MIT
// libFuzzer target: the rFLEX streaming decoder in both roles (input byte 0 bit 7: the device
// role, else the host role), typed parsers, odometry. Properties: every decoded packet re-encodes
// (stuffed) and decodes back to itself in the host role; the host role never accepts a raw 0x1B
// packet; the packets and counters do not depend on how the stream is cut (bits 0..6 of byte 0
// pick a chunk size; the same stream is decoded again in one piece and compared).
#include <proto/rflex.h>

#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

static rflex_decoder_t g_dec;
static rflex_decoder_t g_check;
static rflex_odometry_t g_odo;
static uint8_t g_buf[RFLEX_MAX_STUFFED_BYTES];

static void check(int ok) {
  if (!ok) {
    abort();
  }
}

static void round_trip(const rflex_packet_t* pk) {
  const size_t n = rflex_encode(g_buf, sizeof g_buf, pk, RFLEX_DEVICE_STUFFED);
  check(n >= RFLEX_PACKET_BYTES(pk->dlen));
  rflex_decoder_init(&g_check);
  rflex_packet_t back;
  bool have = false;
  const size_t k = rflex_decoder_push(&g_check, g_buf, n, &back, &have);
  check(have && k == n);
  check(back.port == pk->port && back.id == pk->id && back.opcode == pk->opcode &&
        back.dlen == pk->dlen && memcmp(back.data, pk->data, pk->dlen) == 0);
}

static void parse_all(const rflex_packet_t* pk) {
  (void)rflex_classify(pk);
  rflex_motor_report_t m;
  if (rflex_parse_motor_report(pk, &m) == PROTO_OK) {
    if (rflex_odom_feed(&g_odo, &m) == PROTO_OK) {
      (void)rflex_odom_update(&g_odo);
      check(isfinite(g_odo.x_m) && isfinite(g_odo.y_m) && isfinite(g_odo.theta_rad));
    }
  }
  rflex_sys_status_t s;
  (void)rflex_parse_sys_status(pk, &s);
  rflex_dio_report_t d;
  if (rflex_parse_dio_report(pk, &d) == PROTO_OK) {
    (void)rflex_dio_bumper_panel(d.address);
  }
  rflex_set_dir_t sd;
  (void)rflex_parse_set_dir(pk, &sd);
  uint32_t a, b, c;
  uint8_t mode;
  (void)rflex_parse_odometry_request(pk, &a, &b);
  (void)rflex_parse_dio_request(pk, &a);
  (void)rflex_parse_sonar_run(pk, &a, &b, &c, &mode);
}

// FNV-1a over the decoded packets, in order.
static uint64_t hash_packet(uint64_t h, const rflex_packet_t* pk) {
  const uint8_t head[4] = {pk->port, pk->id, pk->opcode, pk->dlen};
  for (size_t i = 0; i < 4U + pk->dlen; ++i) {
    h ^= i < 4U ? head[i] : pk->data[i - 4U];
    h *= 1099511628211ULL;
  }
  return h;
}

// Decodes the whole stream in one piece with a fresh decoder of the same role.
static uint64_t decode_whole(const uint8_t* p, size_t left, rflex_role_t role) {
  rflex_decoder_init_role(&g_check, role);
  uint64_t h = 14695981039346656037ULL;
  while (left > 0) {
    rflex_packet_t pk;
    bool have = false;
    const size_t k = rflex_decoder_push(&g_check, p, left, &pk, &have);
    p += k;
    left -= k;
    if (have) {
      h = hash_packet(h, &pk);
    }
  }
  return h;
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) {
    return 0;
  }
  uint64_t h = 14695981039346656037ULL;
  rflex_b21r_params_t params;
  rflex_b21r_params_default(&params);
  check(rflex_odom_init(&g_odo, &params) == PROTO_OK);
  rflex_decoder_init_role(&g_dec, (data[0] & 0x80U) != 0 ? RFLEX_ROLE_DEVICE : RFLEX_ROLE_HOST);
  const size_t chunk = (size_t)((data[0] & 0x7FU) % 23U) + 1U;
  size_t off = 1;
  while (off < size) {
    const size_t c = size - off < chunk ? size - off : chunk;
    const uint8_t* p = data + off;
    size_t left = c;
    while (left > 0) {
      rflex_packet_t pk;
      bool have = false;
      const size_t k = rflex_decoder_push(&g_dec, p, left, &pk, &have);
      check(k <= left);
      check(k > 0 || have);
      p += k;
      left -= k;
      if (have) {
        check(pk.port >= 1 && pk.port <= 6);
        h = hash_packet(h, &pk);
        round_trip(&pk);
        parse_all(&pk);
      }
    }
    off += c;
  }
  check(g_dec.counters.bytes_in == size - 1);
  check(g_dec.counters.bytes_dropped <= size - 1);
  check(g_dec.role == RFLEX_ROLE_DEVICE || g_dec.counters.packets_raw_esc == 0);  // the host de-stuffs only
  check(decode_whole(data + 1, size - 1, (rflex_role_t)g_dec.role) == h);
  check(memcmp(&g_check.counters, &g_dec.counters, sizeof g_dec.counters) == 0);
  // The host encoder's no-raw-ESC rule holds for velocities taken from the input.
  if (size >= 9) {
    int32_t v;
    uint32_t acc;
    memcpy(&v, data + 1, 4);
    memcpy(&acc, data + 5, 4);
    rflex_packet_t pk;
    if (rflex_make_axis_velocity(&pk, (uint8_t)(data[0] & 1U), v, acc, 30000, NULL) == PROTO_OK) {
      check(rflex_encode(g_buf, sizeof g_buf, &pk, RFLEX_HOST_STRICT) == 23);
    }
  }
  return 0;
}
