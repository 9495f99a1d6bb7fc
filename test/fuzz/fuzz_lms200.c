// SPDX-License-Identifier: MIT
// libFuzzer target: the LMS200 streaming decoder in both roles and every typed parser.
// The first input byte picks the chunk size, so splits vary with the input.
#include <proto/lms200.h>

#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

static lms_decoder_t g_dec;
static lms_scan_t g_scan;

static void check(int ok) {
  if (!ok) {
    abort();
  }
}

static void run_role(lms_role_t role, const uint8_t* data, size_t size, size_t chunk) {
  check(lms_decoder_init(&g_dec, role, 0) == PROTO_OK);
  size_t off = 0;
  while (off < size) {
    const size_t c = size - off < chunk ? size - off : chunk;
    const uint8_t* p = data + off;
    size_t left = c;
    while (left > 0) {
      lms_event_t ev;
      const size_t k = lms_decoder_push(&g_dec, p, left, &ev);
      check(k <= left);
      check(k > 0 || ev.kind != LMS_EVENT_NONE);  // progress or an event: never stuck
      p += k;
      left -= k;
      if (ev.kind != LMS_EVENT_TELEGRAM) {
        continue;
      }
      const lms_telegram_t* t = &ev.telegram;
      check(t->data_len <= LMS_MAX_LEN);
      if (role == LMS_ROLE_HOST) {
        if (lms_parse_scan(t, 13, &g_scan) == PROTO_OK) {
          check(g_scan.count >= 1 && g_scan.count <= LMS_MAX_SCAN_VALUES);
          for (unsigned i = 0; i < g_scan.count; ++i) {
            check(g_scan.range_m[i] >= 0.0f && g_scan.range_m[i] <= g_scan.max_range_m);
          }
        }
        (void)lms_parse_scan(t, 15, &g_scan);
        lms_mode_result_t mr;
        (void)lms_parse_mode_reply(t, &mr);
        lms_variant_reply_t vr;
        (void)lms_parse_variant_reply(t, &vr);
        lms_device_status_t st;
        (void)lms_parse_status_reply(t, &st);
        char type[LMS_TYPE_MAX_CHARS + 1];
        (void)lms_parse_type_reply(t, type, sizeof type);
        lms_config_t cfg;
        (void)lms_parse_config_reply(t, &cfg);
      } else {
        lms_request_t req;
        (void)lms_parse_request(t, &req);
      }
    }
    off += c;
  }
  check(g_dec.counters.bytes_in == size);
  check(g_dec.counters.bytes_dropped <= size);
  lms_decoder_reset(&g_dec);
}

int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) {
    return 0;
  }
  const size_t chunk = (size_t)(data[0] % 17U) + 1U;
  run_role(LMS_ROLE_HOST, data + 1, size - 1, chunk);
  run_role(LMS_ROLE_DEVICE, data + 1, size - 1, chunk);
  return 0;
}
