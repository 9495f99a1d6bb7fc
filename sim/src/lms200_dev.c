// SPDX-License-Identifier: MIT
// The emulated SICK LMS200: request handling, scans with noise and error codes, pacing.
#include "sim/lms200_dev.h"

#include <math.h>
#include <proto/lms200.h>
#include <stdlib.h>
#include <string.h>
#include <rng/rng.h>

#include "byteq.h"

static const double k_pi = 3.14159265358979323846;
#define LMS_SWEEP_HZ 75.0  // mirror revolutions per second
#define LMS_TYPE_STRING "LMS200;30106"

struct sim_lms {
  sim_lms_config_t cfg;
  sim_lms_scan_fn scan_fn;
  void* user;
  lms_decoder_t dec;
  sim_byteq_t out;
  rng_t rng;
  uint32_t baud;
  uint16_t width_deg;
  uint16_t res_cdeg;
  lms_config_t config;
  bool streaming;
  bool installation;
  double silent_until_s;
  double stuck_until_s;   // scans repeat the last measured distances until then (a frozen sensor)
  size_t raw_n;           // beams in raw[] from the last measured scan (0 = none yet)
  double sweep_origin_s;  // the mirror's phase: sweeps end at origin + k * sweep period
  double next_sweep_s;    // earliest time the next streamed scan may be taken (paced)
  sim_lms_counters_t counters;
  double ranges[LMS_MAX_SCAN_VALUES];
  uint16_t raw[LMS_MAX_SCAN_VALUES];
  uint8_t tx[LMS_MAX_TELEGRAM_BYTES + 8U];
};

void sim_lms_config_default(sim_lms_config_t* cfg) {
  cfg->width_deg = 180;
  cfg->res_cdeg = 100;
  cfg->unit_mm = 1;
  cfg->power_up_baud = 9600;
  cfg->noise_sigma_m = 0.005;
  cfg->max_range_m = 30.0;
  cfg->error_code_prob = 0.0;
  cfg->paced = false;
  cfg->seed = 1;
}

static void power_up(sim_lms_t* d) {
  d->baud = d->cfg.power_up_baud;
  d->width_deg = d->cfg.width_deg;
  d->res_cdeg = d->cfg.res_cdeg;
  memset(&d->config, 0, sizeof(d->config));
  d->config.measuring_mode = 0;  // 8 m / 80 m, 13-bit distances
  d->config.unit = d->cfg.unit_mm ? LMS_UNIT_MM : LMS_UNIT_CM;
  d->streaming = false;
  d->installation = false;
}

sim_lms_t* sim_lms_create(const sim_lms_config_t* cfg, sim_lms_scan_fn scan_fn, void* user) {
  if (cfg == NULL || scan_fn == NULL || !lms_variant_valid(cfg->width_deg, cfg->res_cdeg) ||
      lms_baud_mode(cfg->power_up_baud) == 0xFFU || !isfinite(cfg->noise_sigma_m) ||
      cfg->noise_sigma_m < 0.0 || !(cfg->max_range_m > 0.0) || !isfinite(cfg->max_range_m) ||
      !(cfg->error_code_prob >= 0.0 && cfg->error_code_prob <= 1.0)) {
    return NULL;
  }
  sim_lms_t* d = calloc(1, sizeof(*d));
  if (d == NULL) {
    return NULL;
  }
  d->cfg = *cfg;
  d->scan_fn = scan_fn;
  d->user = user;
  (void)lms_decoder_init(&d->dec, LMS_ROLE_DEVICE, 0);
  sim_byteq_init(&d->out);
  rng_seed(&d->rng, cfg->seed);
  power_up(d);
  return d;
}

void sim_lms_destroy(sim_lms_t* d) { free(d); }

void sim_lms_reseed(sim_lms_t* d, uint64_t seed) { rng_seed(&d->rng, seed); }

static void queue(sim_lms_t* d, const uint8_t* bytes, size_t n, double t_s) {
  if (n == 0) {
    return;
  }
  if (!sim_byteq_push(&d->out, bytes, n, t_s, d->baud)) {
    ++d->counters.queue_overflows;
  }
}

static void send_ack(sim_lms_t* d, double t_s) {
  const uint8_t ack = LMS_ACK;
  queue(d, &ack, 1, t_s);
}

static void send_nak(sim_lms_t* d, double t_s) {
  const uint8_t nak = LMS_NAK;
  queue(d, &nak, 1, t_s);
  ++d->counters.naks;
}

size_t sim_lms_beams(const sim_lms_t* d, double* angle_min_rad, double* increment_rad) {
  const double res_rad = (double)d->res_cdeg * 0.01 * k_pi / 180.0;
  const size_t n = (size_t)(d->width_deg * 100U / d->res_cdeg) + 1U;
  if (angle_min_rad != NULL) {
    *angle_min_rad = -0.5 * (double)d->width_deg * k_pi / 180.0;
  }
  if (increment_rad != NULL) {
    *increment_rad = res_rad;
  }
  return n;
}

static uint16_t range_to_raw(sim_lms_t* d, double range_m) {
  const unsigned bits = 13;
  if (d->cfg.error_code_prob > 0.0 && rng_uniform(&d->rng) < d->cfg.error_code_prob) {
    return lms_beam_status_raw(rng_uniform(&d->rng) < 0.5 ? LMS_BEAM_DAZZLED
                                                                : LMS_BEAM_SNR_LOW,
                               bits);
  }
  if (!isfinite(range_m) || range_m > d->cfg.max_range_m) {
    return lms_beam_status_raw(LMS_BEAM_NO_ECHO, bits);
  }
  double r = range_m;
  if (d->cfg.noise_sigma_m > 0.0) {
    r += d->cfg.noise_sigma_m * rng_normal(&d->rng);
  }
  if (r < 0.0) {
    r = 0.0;
  }
  const double lsb_m = d->config.unit == LMS_UNIT_MM ? 0.001 : 0.01;
  const double max_valid_m = (double)((1U << bits) - 10U) * lsb_m;
  if (r > max_valid_m + 0.5 * lsb_m) {
    return lms_beam_status_raw(LMS_BEAM_OVER_MAX, bits);
  }
  return lms_range_to_raw((float)r, d->config.unit, bits);
}

static void queue_scan(sim_lms_t* d, double t_s) {
  double angle_min, inc;
  const size_t n = sim_lms_beams(d, &angle_min, &inc);
  // A frozen sensor (its measurement stage hangs, the interface still sends) repeats the last
  // distances bit for bit; the scan index, a counter of the interface, keeps counting.
  if (!(t_s < d->stuck_until_s) || d->raw_n != n) {
    d->scan_fn(d->user, angle_min, inc, n, d->ranges);
    for (size_t i = 0; i < n; ++i) {
      d->raw[i] = range_to_raw(d, d->ranges[i]);
    }
    d->raw_n = n;
  } else {
    ++d->counters.repeated_scans;
  }
  const uint8_t scan_index = (uint8_t)(d->counters.scans & 0xFFU);
  const bool with_index = (d->config.availability & 0x01U) != 0U;
  const size_t len = lms_encode_scan_reply(d->tx, sizeof(d->tx), d->raw, n, d->config.unit, 0,
                                           with_index ? &scan_index : NULL, 0);
  queue(d, d->tx, len, t_s);
  ++d->counters.scans;
}

// A scan at 0.5° interleaves two mirror turns, at 0.25° four.
static double sweep_period_s(const sim_lms_t* d) {
  const double sweeps = d->res_cdeg >= 100U ? 1.0 : (d->res_cdeg >= 50U ? 2.0 : 4.0);
  return sweeps / LMS_SWEEP_HZ;
}

static void reply_mode(sim_lms_t* d, lms_mode_result_t r, double t_s) {
  send_ack(d, t_s);
  queue(d, d->tx, lms_encode_mode_reply(d->tx, sizeof(d->tx), r, 0), t_s);
}

static void handle_request(sim_lms_t* d, const lms_telegram_t* t, double t_s) {
  lms_request_t req;
  if (lms_parse_request(t, &req) != PROTO_OK) {
    send_nak(d, t_s);
    return;
  }
  switch (req.kind) {
    case LMS_REQ_RESET:
      power_up(d);
      send_ack(d, t_s);
      queue(d, d->tx,
            lms_encode_telegram(d->tx, sizeof(d->tx), LMS_ADR_HOST, LMS_REPLY_RESET, NULL, 0, true, 0),
            t_s);
      break;
    case LMS_REQ_MODE:
      if (req.mode == LMS_MODE_STREAM) {
        reply_mode(d, LMS_MODE_OK, t_s);
        d->streaming = true;
        d->installation = false;
        d->sweep_origin_s = t_s;
        d->next_sweep_s = t_s + sweep_period_s(d);
      } else if (req.mode == LMS_MODE_STOP_STREAM) {
        reply_mode(d, LMS_MODE_OK, t_s);
        d->streaming = false;
        d->installation = false;
      } else {
        reply_mode(d, LMS_MODE_NOT_POSSIBLE, t_s);  // other stream modes are not emulated
      }
      break;
    case LMS_REQ_INSTALLATION:
      if (memcmp(req.password, LMS_DEFAULT_PASSWORD, LMS_PASSWORD_BYTES) == 0) {
        reply_mode(d, LMS_MODE_OK, t_s);
        d->installation = true;
        d->streaming = false;
      } else {
        reply_mode(d, LMS_MODE_BAD_PASSWORD, t_s);
      }
      break;
    case LMS_REQ_BAUD:
      // The reply leaves at the old rate (queued before the switch), as on the real sensor.
      reply_mode(d, LMS_MODE_OK, t_s);
      d->baud = req.baud;
      break;
    case LMS_REQ_VALUES:
      send_ack(d, t_s);
      queue_scan(d, t_s);
      break;
    case LMS_REQ_STATUS: {
      lms_device_status_t st;
      memset(&st, 0, sizeof(st));
      memcpy(st.version, "V02.10 ", 8);
      st.operating_mode = d->streaming      ? LMS_MODE_STREAM
                          : d->installation ? LMS_MODE_INSTALLATION
                                            : LMS_MODE_STOP_STREAM;
      st.device_status = 0;
      st.unit = d->config.unit;
      st.width_deg = d->width_deg;
      st.res_cdeg = d->res_cdeg;
      send_ack(d, t_s);
      queue(d, d->tx, lms_encode_status_reply(d->tx, sizeof(d->tx), &st, 0), t_s);
      break;
    }
    case LMS_REQ_TYPE:
      send_ack(d, t_s);
      queue(d, d->tx, lms_encode_type_reply(d->tx, sizeof(d->tx), LMS_TYPE_STRING, 0), t_s);
      break;
    case LMS_REQ_VARIANT: {
      lms_variant_reply_t vr;
      vr.accepted = lms_variant_valid(req.width_deg, req.res_cdeg);
      if (vr.accepted) {
        d->width_deg = req.width_deg;
        d->res_cdeg = req.res_cdeg;
      }
      vr.width_deg = d->width_deg;
      vr.res_cdeg = d->res_cdeg;
      send_ack(d, t_s);
      queue(d, d->tx, lms_encode_variant_reply(d->tx, sizeof(d->tx), &vr, 0), t_s);
      break;
    }
    case LMS_REQ_CONFIG_READ:
      send_ack(d, t_s);
      queue(d, d->tx, lms_encode_config_reply(d->tx, sizeof(d->tx), &d->config, 0), t_s);
      break;
    case LMS_REQ_CONFIG_WRITE: {
      uint8_t accepted = 0;
      if (d->installation && req.config.measuring_mode == 0U &&
          (req.config.unit == LMS_UNIT_MM || req.config.unit == LMS_UNIT_CM)) {
        d->config = req.config;
        accepted = 1;
      }
      send_ack(d, t_s);
      queue(d, d->tx,
            lms_encode_telegram(d->tx, sizeof(d->tx), LMS_ADR_HOST, LMS_REPLY_CONFIG_WRITE,
                                &accepted, 1, true, 0),
            t_s);
      break;
    }
    case LMS_REQ_UNKNOWN:
    default:
      send_nak(d, t_s);
      break;
  }
}

void sim_lms_feed(sim_lms_t* d, const uint8_t* bytes, size_t n, double t_s) {
  while (n > 0) {
    lms_event_t ev;
    const size_t k = lms_decoder_push(&d->dec, bytes, n, &ev);
    bytes += k;
    n -= k;
    if (ev.kind != LMS_EVENT_TELEGRAM) {
      continue;
    }
    ++d->counters.requests;
    if (t_s < d->silent_until_s) {
      ++d->counters.ignored_silent;
      continue;
    }
    handle_request(d, &ev.telegram, t_s);
  }
}

size_t sim_lms_drain(sim_lms_t* d, uint8_t* out, size_t cap, double t_s) {
  return sim_byteq_drain(&d->out, out, cap, t_s, d->cfg.paced);
}

void sim_lms_poll(sim_lms_t* d, double t_s) {
  if (!d->cfg.paced || !d->streaming || t_s < d->next_sweep_s || t_s < d->silent_until_s ||
      !sim_byteq_idle(&d->out, t_s)) {
    return;
  }
  queue_scan(d, t_s);
  // The newest sweep goes out when the line is free; the next one ends on the mirror's phase.
  const double period = sweep_period_s(d);
  d->next_sweep_s = d->sweep_origin_s + (floor((t_s - d->sweep_origin_s) / period) + 1.0) * period;
}

void sim_lms_emit_scan(sim_lms_t* d, double t_s) {
  if (t_s < d->silent_until_s) {
    return;
  }
  queue_scan(d, t_s);
}

bool sim_lms_streaming(const sim_lms_t* d) { return d->streaming; }

uint32_t sim_lms_baud(const sim_lms_t* d) { return d->baud; }

void sim_lms_variant(const sim_lms_t* d, uint16_t* width_deg, uint16_t* res_cdeg) {
  *width_deg = d->width_deg;
  *res_cdeg = d->res_cdeg;
}

void sim_lms_set_silent_until(sim_lms_t* d, double t_s) {
  d->silent_until_s = t_s;
  if (t_s > 0.0) {
    sim_byteq_clear(&d->out);  // a dropped sensor loses what it had not yet sent
  }
}

void sim_lms_set_stuck_until(sim_lms_t* d, double t_s) { d->stuck_until_s = t_s; }

const sim_lms_counters_t* sim_lms_get_counters(const sim_lms_t* d) { return &d->counters; }
