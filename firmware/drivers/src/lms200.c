// SPDX-License-Identifier: MIT
// LMS200 host driver: the connect / baud switch / variant / streaming state machine.
#include <drivers/lms200.h>

#include <errno.h>
#include <string.h>

// Connect probes: the power-up rate first, then the target (the LMS keeps its rate across a
// controller restart), then the rest.
static const uint32_t k_probe_rates[] = {9600U, 0U /* target */, 38400U, 500000U, 19200U};
#define PROBE_COUNT (sizeof k_probe_rates / sizeof k_probe_rates[0])
// Bytes read per drv_lms_step() at most: a few scans even at 500 kBd.
#define READ_BUDGET_BYTES 65536U

void drv_lms_config_default(drv_lms_config_t* cfg) {
  if (cfg == NULL) {
    return;
  }
  memset(cfg, 0, sizeof *cfg);
  cfg->target_baud = 38400U;
  cfg->width_deg = 180U;
  cfg->res_cdeg = 100U;
  cfg->unit = -1;
  cfg->distance_bits = 13U;
  memcpy(cfg->password, LMS_DEFAULT_PASSWORD, LMS_PASSWORD_BYTES + 1U);
  cfg->reply_timeout_us = 1000000U;
  cfg->mode_timeout_us = 3000000U;
  cfg->stream_timeout_us = 1000000U;
  cfg->max_retries = 2U;
}

static uint32_t probe_rate(const drv_lms_t* drv, unsigned i) {
  return k_probe_rates[i] == 0U ? drv->config.target_baud : k_probe_rates[i];
}

// 500 kBd needs spacing between bytes (sicktoolbox: 55 µs); slower rates need none.
static void apply_rate(drv_lms_t* drv, uint32_t baud) {
  if (drv->port->baud != baud) {
    (void)drv_serial_set_baud(drv->port, baud);
  }
  drv_serial_set_pacing(drv->port, 0, 0, baud == 500000U ? DRV_SERIAL_LMS_500K_BYTE_GAP_US : 0U);
  drv->line_baud = baud;
}

static void enter(drv_lms_t* drv, drv_lms_state_t s) {
  drv->state = s;
  drv->waiting = false;
  drv->retries = 0;
}

int drv_lms_init(drv_lms_t* drv, drv_serial_t* port, const drv_lms_config_t* cfg) {
  if (drv == NULL || port == NULL || cfg == NULL || lms_baud_mode(cfg->target_baud) == 0xFFU ||
      !lms_variant_valid(cfg->width_deg, cfg->res_cdeg) || cfg->unit < -1 || cfg->unit > 1 ||
      (cfg->distance_bits != 13U && cfg->distance_bits != 14U && cfg->distance_bits != 15U) ||
      cfg->reply_timeout_us == 0U || cfg->mode_timeout_us == 0U || cfg->stream_timeout_us == 0U) {
    return -EINVAL;
  }
  memset(drv, 0, sizeof *drv);
  drv->config = *cfg;
  drv->config.password[LMS_PASSWORD_BYTES] = '\0';
  drv->port = port;
  (void)lms_decoder_init(&drv->decoder, LMS_ROLE_HOST, 0);
  enter(drv, DRV_LMS_CONNECT);
  drv->probe_index = 0;
  return 0;
}

void drv_lms_restart(drv_lms_t* drv) {
  if (drv == NULL) {
    return;
  }
  drv->counters.restarts++;
  lms_decoder_reset(&drv->decoder);
  enter(drv, DRV_LMS_CONNECT);
  // Try the rate in use first: after a glitch the LMS is most likely still there.
  drv->probe_index = 0;
  for (unsigned i = 0; i < PROBE_COUNT; ++i) {
    if (probe_rate(drv, i) == drv->line_baud) {
      drv->probe_index = (uint8_t)i;
      break;
    }
  }
}

const char* drv_lms_state_name(drv_lms_state_t state) {
  switch (state) {
    case DRV_LMS_CONNECT:
      return "connect";
    case DRV_LMS_BAUD:
      return "baud";
    case DRV_LMS_TYPE:
      return "type";
    case DRV_LMS_INSTALL:
      return "install";
    case DRV_LMS_VARIANT:
      return "variant";
    case DRV_LMS_CONFIG_READ:
      return "config_read";
    case DRV_LMS_CONFIG_WRITE:
      return "config_write";
    case DRV_LMS_START:
      return "start";
    case DRV_LMS_STREAMING:
      return "streaming";
  }
  return "unknown";
}

static int send_bytes(drv_lms_t* drv, const uint8_t* buf, size_t n) {
  if (n == 0U) {
    return -EINVAL;
  }
  const int rc = drv_serial_write(drv->port, buf, n, 200);
  if (rc != 0) {
    drv->counters.io_errors++;
  }
  return rc;
}

int drv_lms_stop_stream(drv_lms_t* drv) {
  if (drv == NULL || drv->port == NULL) {
    return -EINVAL;
  }
  uint8_t buf[16];
  return send_bytes(drv, buf, lms_encode_stop_stream(buf, sizeof buf));
}

// Sends the request of the current state and arms its timeout.
static void send_request(drv_lms_t* drv, uint64_t now_us) {
  uint8_t buf[64];
  size_t n = 0;
  uint32_t timeout = drv->config.reply_timeout_us;
  switch (drv->state) {
    case DRV_LMS_CONNECT:
      apply_rate(drv, probe_rate(drv, drv->probe_index));
      (void)drv_serial_flush_input(drv->port);
      lms_decoder_reset(&drv->decoder);
      n = lms_encode_stop_stream(buf, sizeof buf);
      timeout = drv->config.mode_timeout_us;
      break;
    case DRV_LMS_BAUD:
      n = lms_encode_baud(buf, sizeof buf, drv->config.target_baud);
      timeout = drv->config.mode_timeout_us;
      break;
    case DRV_LMS_TYPE:
      n = lms_encode_type_request(buf, sizeof buf);
      break;
    case DRV_LMS_INSTALL:
      n = lms_encode_installation_mode(buf, sizeof buf, drv->config.password);
      timeout = drv->config.mode_timeout_us;
      break;
    case DRV_LMS_VARIANT:
      n = lms_encode_variant(buf, sizeof buf, drv->config.width_deg, drv->config.res_cdeg);
      break;
    case DRV_LMS_CONFIG_READ:
      n = lms_encode_config_request(buf, sizeof buf);
      break;
    case DRV_LMS_CONFIG_WRITE: {
      lms_config_t c = drv->device_config;
      c.unit = drv->config.unit == (int)LMS_UNIT_MM ? LMS_UNIT_MM : LMS_UNIT_CM;
      n = lms_encode_config_write(buf, sizeof buf, &c);
      timeout = drv->config.mode_timeout_us;
      break;
    }
    case DRV_LMS_START:
      n = lms_encode_start_stream(buf, sizeof buf);
      timeout = drv->config.mode_timeout_us;
      break;
    case DRV_LMS_STREAMING:
      return;
  }
  (void)send_bytes(drv, buf, n);
  drv->waiting = true;
  drv->deadline_us = now_us + timeout;
}

static void after_connect(drv_lms_t* drv) {
  drv->counters.connects++;
  enter(drv, drv->line_baud == drv->config.target_baud ? DRV_LMS_TYPE : DRV_LMS_BAUD);
}

// A request failed (timeout or NAK): retry, or start over.
static void request_failed(drv_lms_t* drv) {
  drv->waiting = false;
  if (drv->state == DRV_LMS_CONNECT) {
    // Next probe rate, skipping rates already tried in this round (the target is in the list).
    for (unsigned step = 0; step < PROBE_COUNT; ++step) {
      drv->probe_index = (uint8_t)((drv->probe_index + 1U) % PROBE_COUNT);
      bool seen = false;
      for (unsigned i = 0; i < drv->probe_index; ++i) {
        seen = seen || probe_rate(drv, i) == probe_rate(drv, drv->probe_index);
      }
      if (!seen) {
        break;
      }
    }
    return;
  }
  if (drv->retries < drv->config.max_retries) {
    drv->retries++;
    return;
  }
  drv_lms_restart(drv);
}

static void handle_telegram(drv_lms_t* drv, const lms_telegram_t* t, uint64_t now_us,
                            lms_scan_t* scan, bool* got_scan) {
  if (t->cmd == LMS_REPLY_VALUES) {
    if (drv->state != DRV_LMS_STREAMING) {
      return;  // streaming left over from before a (re)connect
    }
    if (scan == NULL) {
      return;
    }
    if (lms_parse_scan(t, drv->config.distance_bits, scan) != PROTO_OK) {
      drv->counters.scan_errors++;
      return;
    }
    if (*got_scan) {
      drv->counters.scans_superseded++;
    } else {
      drv->counters.scans++;
    }
    *got_scan = true;
    drv->deadline_us = now_us + drv->config.stream_timeout_us;
    return;
  }
  if (t->cmd == LMS_REPLY_NAK) {
    drv->counters.naks++;
    if (drv->waiting) {
      request_failed(drv);
    }
    return;
  }
  if (!drv->waiting) {
    return;
  }
  lms_mode_result_t mr = LMS_MODE_FAULT;
  switch (drv->state) {
    case DRV_LMS_CONNECT:
      if (t->cmd == LMS_REPLY_MODE) {
        after_connect(drv);
      }
      break;
    case DRV_LMS_BAUD:
      if (t->cmd == LMS_REPLY_MODE) {
        if (lms_parse_mode_reply(t, &mr) == PROTO_OK && mr == LMS_MODE_OK) {
          // The reply came at the old rate; both sides use the new one from now on.
          apply_rate(drv, drv->config.target_baud);
          lms_decoder_reset(&drv->decoder);
          enter(drv, DRV_LMS_TYPE);
        } else {
          request_failed(drv);
        }
      }
      break;
    case DRV_LMS_TYPE:
      if (t->cmd == LMS_REPLY_TYPE) {
        (void)lms_parse_type_reply(t, drv->type, sizeof drv->type);
        enter(drv, DRV_LMS_INSTALL);
      }
      break;
    case DRV_LMS_INSTALL:
      if (t->cmd == LMS_REPLY_MODE) {
        if (lms_parse_mode_reply(t, &mr) == PROTO_OK && mr == LMS_MODE_OK) {
          enter(drv, DRV_LMS_VARIANT);
        } else {
          request_failed(drv);
        }
      }
      break;
    case DRV_LMS_VARIANT:
      if (t->cmd == LMS_REPLY_VARIANT) {
        lms_variant_reply_t vr;
        if (lms_parse_variant_reply(t, &vr) == PROTO_OK && vr.accepted) {
          enter(drv, DRV_LMS_CONFIG_READ);
        } else {
          request_failed(drv);
        }
      }
      break;
    case DRV_LMS_CONFIG_READ:
      if (t->cmd == LMS_REPLY_CONFIG_READ) {
        if (lms_parse_config_reply(t, &drv->device_config) == PROTO_OK) {
          const bool change =
              drv->config.unit >= 0 && (int)drv->device_config.unit != drv->config.unit;
          enter(drv, change ? DRV_LMS_CONFIG_WRITE : DRV_LMS_START);
        } else {
          request_failed(drv);
        }
      }
      break;
    case DRV_LMS_CONFIG_WRITE:
      if (t->cmd == LMS_REPLY_CONFIG_WRITE) {
        drv->device_config.unit = drv->config.unit == (int)LMS_UNIT_MM ? LMS_UNIT_MM : LMS_UNIT_CM;
        enter(drv, DRV_LMS_START);
      }
      break;
    case DRV_LMS_START:
      if (t->cmd == LMS_REPLY_MODE) {
        if (lms_parse_mode_reply(t, &mr) == PROTO_OK && mr == LMS_MODE_OK) {
          enter(drv, DRV_LMS_STREAMING);
          drv->deadline_us = now_us + drv->config.stream_timeout_us;
        } else {
          request_failed(drv);
        }
      }
      break;
    case DRV_LMS_STREAMING:
      break;
  }
}

drv_lms_state_t drv_lms_step(drv_lms_t* drv, uint64_t now_us, lms_scan_t* scan, bool* got_scan) {
  bool dummy = false;
  if (got_scan == NULL) {
    got_scan = &dummy;
  }
  *got_scan = false;
  if (drv == NULL || drv->port == NULL) {
    return DRV_LMS_CONNECT;
  }
  uint8_t buf[1024];
  size_t budget = READ_BUDGET_BYTES;
  while (budget > 0U) {
    const ssize_t n = drv_serial_read(drv->port, buf, sizeof buf < budget ? sizeof buf : budget);
    if (n <= 0) {
      if (n < 0) {
        drv->counters.io_errors++;
      }
      break;
    }
    budget -= (size_t)n;
    const uint8_t* p = buf;
    size_t left = (size_t)n;
    while (left > 0U) {
      lms_event_t ev;
      const size_t k = lms_decoder_push(&drv->decoder, p, left, &ev);
      p += k;
      left -= k;
      if (ev.kind == LMS_EVENT_NAK) {
        drv->counters.naks++;
        if (drv->waiting) {
          request_failed(drv);
        }
      } else if (ev.kind == LMS_EVENT_TELEGRAM) {
        const drv_lms_state_t before = drv->state;
        handle_telegram(drv, &ev.telegram, now_us, scan, got_scan);
        if (drv->state != before && before == DRV_LMS_BAUD) {
          // Bytes after the baud reply were sent at the new rate; the rest of this read is
          // noise at the old one.
          left = 0;
        }
      }
    }
  }
  if (drv->state == DRV_LMS_STREAMING) {
    if (now_us >= drv->deadline_us) {
      drv->counters.timeouts++;
      drv_lms_restart(drv);
    }
  } else if (drv->waiting && now_us >= drv->deadline_us) {
    drv->counters.timeouts++;
    request_failed(drv);
  }
  if (drv->state != DRV_LMS_STREAMING && !drv->waiting) {
    send_request(drv, now_us);
  }
  return drv->state;
}
