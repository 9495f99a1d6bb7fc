// SPDX-License-Identifier: MIT
// HEDGER C API: argument checks, storage layout, dimension dispatch, byte format.
#include "hedger/hedger.h"

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <new>

#include "bytes.hpp"
#include "core.hpp"
#include "dims.hpp"

namespace {

using hg::Layout;
using hg::bits_f32;
using hg::crc32;
using hg::crc32_update;
using hg::f32_bits;
using hg::finite_all;
using hg::get_f64;
using hg::get_u32;
using hg::get_u64;
using hg::put_f64;
using hg::put_u32;
using hg::put_u64;
using hg::same_bits;

constexpr size_t kAlign = HEDGER_STORAGE_ALIGN;

size_t align_up(size_t n) { return (n + kAlign - 1) / kAlign * kAlign; }

bool valid_config(const hedger_config_t* c) {
  if (c == nullptr) return false;
  if (c->state_dim < 1 || c->state_dim > HEDGER_MAX_STATE_DIM) return false;
  if (!std::isfinite(c->action_min) || !std::isfinite(c->action_max) || !(c->action_min < c->action_max)) return false;
  if (c->capacity < 1 || c->capacity > HEDGER_MAX_CAPACITY) return false;
  if (c->k_max < 1 || c->k_max > HEDGER_MAX_K || c->k_min < 1 || c->k_min > c->k_max) return false;
  if (!std::isfinite(c->bandwidth) || !(c->bandwidth > 0.0)) return false;
  if (!(c->weight_epsilon > 0.0 && c->weight_epsilon < 1.0)) return false;
  if (!std::isfinite(c->ridge) || !(c->ridge >= 0.0)) return false;
  if (!(c->alpha > 0.0 && c->alpha <= 1.0)) return false;
  if (!(c->gamma >= 0.0 && c->gamma < 1.0)) return false;
  for (uint32_t i = 0; i <= c->state_dim; ++i) {
    if (!std::isfinite(c->input_scale[i]) || !(c->input_scale[i] > 0.0)) return false;
  }
  if (!std::isfinite(c->default_value)) return false;
  if (c->greedy_coarse_actions < 2 || c->greedy_coarse_actions > HEDGER_MAX_COARSE_ACTIONS) return false;
  if (c->greedy_refine_iters > HEDGER_MAX_REFINE_ITERS) return false;
  if (c->ivh_mode != static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED) && c->ivh_mode != static_cast<uint32_t>(HEDGER_IVH_WEIGHTED)) return false;
  if (!std::isfinite(c->merge_radius) || !(c->merge_radius >= 0.0)) return false;
  if (c->evict_candidates < 1 || c->evict_candidates > HEDGER_MAX_EVICT_CANDIDATES) return false;
  if (c->fresh_capacity < 8 || c->fresh_capacity > HEDGER_MAX_FRESH) return false;
  if (c->run_capacity > HEDGER_MAX_RUN) return false;
  if (c->replay > 1 || (c->replay == 1 && c->run_capacity == 0)) return false;
  if (c->replay_passes < 1 || c->replay_passes > HEDGER_MAX_REPLAY_PASSES) return false;
  if (!(c->replay_lambda >= 0.0 && c->replay_lambda <= 1.0)) return false;
  if (!(c->replay_alpha >= 0.0 && c->replay_alpha <= 1.0)) return false;
  if (c->replay_cache > 1) return false;
  if (c->greedy_method != static_cast<uint32_t>(HEDGER_GREEDY_PER_ACTION) &&
      c->greedy_method != static_cast<uint32_t>(HEDGER_GREEDY_STATE_MODEL)) {
    return false;
  }
  if (c->local_model != static_cast<uint32_t>(HEDGER_LOCAL_LWR) && c->local_model != static_cast<uint32_t>(HEDGER_LOCAL_LWA)) {
    return false;
  }
  if (!std::isfinite(c->greedy_pessimism) || !(c->greedy_pessimism >= 0.0)) return false;
  if (!std::isfinite(c->greedy_reach) || !(c->greedy_reach >= 1.0) || c->greedy_reach > 100.0) return false;
  if (!std::isfinite(c->anchor_recency_runs) || !(c->anchor_recency_runs >= 0.0)) return false;
  return true;
}

/// Whether the replay keeps its records' geometry (cfg.replay_cache with a replay to keep it for).
bool replay_cached(const hedger_config_t& c) { return c.replay != 0 && c.replay_cache != 0 && c.run_capacity > 0; }

/// The storage block: [hedger | store arrays | fresh (pos per slot, slots, points) | 2 × (tree
/// points, ids, nodes) | run | replay records].
Layout make_layout(const hedger_config_t& c) {
  Layout l{};
  const size_t d = c.state_dim + 1u;
  const size_t cap = c.capacity;
  l.max_nodes = hg::kd_max_nodes(c.capacity);
  l.run_stride = 2u * c.state_dim + 3u;
  size_t off = align_up(sizeof(hedger));
  auto take = [&off](size_t bytes) {
    const size_t at = off;
    off = align_up(off + bytes);
    return at;
  };
  l.pts = take(cap * d * sizeof(double));
  l.val = take(cap * sizeof(double));
  l.seq = take(cap * sizeof(uint64_t));
  l.flags = take(cap);
  l.run_tag = take(cap * sizeof(uint32_t));
  l.anchor_w = take(cap * sizeof(float));
  l.fresh_pos = take(cap * sizeof(uint32_t));
  l.fresh_slot = take(static_cast<size_t>(c.fresh_capacity) * sizeof(uint32_t));
  l.fresh_pts = take(static_cast<size_t>(c.fresh_capacity) * d * sizeof(double));
  l.fresh_box = take((c.fresh_capacity + hg::kFreshBlock - 1) / hg::kFreshBlock * 2u * d * sizeof(double));
  for (int t = 0; t < 2; ++t) {
    l.tpts[t] = take(cap * d * sizeof(double));
    l.tids[t] = take(cap * sizeof(uint32_t));
    l.tnodes[t] = take(static_cast<size_t>(l.max_nodes) * sizeof(hg::Node));
  }
  l.run = take(static_cast<size_t>(c.run_capacity) * l.run_stride * sizeof(double));
  l.replay_cache = take(replay_cached(c) ? static_cast<size_t>(c.run_capacity) * hg::dim_ops(static_cast<uint32_t>(d)).replay_record_bytes : 0);
  l.total = off;
  return l;
}

bool live(const hedger_t* h) { return h != nullptr && h->magic == hg::kMagic; }


/// After every call that may change the learned state: gauges, and the generation that
/// hedger_save_step() checks.
void refresh_gauges(hedger_t* h) {
  ++h->generation;
  h->counters.store_fill = h->fill;
  h->counters.store_protected = h->n_protected;
  h->counters.fresh_fill = h->n_fresh;
  h->counters.run_fill = h->run_count;
}

hedger_status_t reject_non_finite(hedger_t* h) {
  ++h->counters.rejected_non_finite;
  return HEDGER_ERR_NON_FINITE;
}

void reset_learned_state(hedger_t* h) {
  for (uint32_t i = 0; i < h->n_fresh; ++i) h->fresh_pos[h->fresh_slot[i]] = hg::kNone;
  h->fill = 0;
  h->n_protected = 0;
  h->seq_counter = 0;
  h->cur_tag = 0;
  h->n_fresh = 0;
  h->active = 0;
  h->building = 0;
  h->run_head = 0;
  h->run_count = 0;
  h->replay_pending = 0;
  h->replay_pass = 0;
  h->replay_k = 0;
  h->r_min = 0.0;
  h->r_max = 0.0;
  h->reward_seen = 0;
}

// ---- Byte format ----------------------------------------------------------------------------
// Little-endian. Offsets: 0 magic "HDGR", 4 u32 version, 8 u64 total length (with CRC), 16 u32
// state_dim, 20 u32 capacity, 24 u32 count, 28 u32 reward_seen, 32 f64 action_min, 40 f64
// action_max, 48 f64 gamma, 56 f64 r_min, 64 f64 r_max, 72 u64 generator state, 80 u32 current
// run tag, 84 u32 reserved (0), 88 f64 input_scale[D], then count × (D f64 scaled coordinates,
// f64 value, u32 flags, u32 run tag, f32 anchor weight), then u32 CRC-32 (IEEE 802.3, reflected
// 0xEDB88320, init and final xor 0xFFFFFFFF) of all preceding bytes. Version 1 (read only): no
// run tag fields (input_scale at 80, records of D f64, f64 value, u32 flags).
constexpr uint8_t kFileMagic[4] = {'H', 'D', 'G', 'R'};

size_t header_fixed(uint32_t version) { return version == 1u ? 80u : 88u; }
size_t record_size(uint32_t d, uint32_t version) { return 8u * d + (version == 1u ? 12u : 20u); }

size_t format_size(uint32_t d, uint32_t count, uint32_t version = HEDGER_FORMAT_VERSION) {
  return header_fixed(version) + 8u * static_cast<size_t>(d) + static_cast<size_t>(count) * record_size(d, version) +
         4u;
}


// ---- Entry points (noexcept: nothing inside throws; the library builds with -fno-exceptions) --

hedger_status_t predict_impl(hedger_t* self, const double* state, double action, hedger_prediction_t* out,
                             uint32_t* slots, double* weights, uint32_t cap) noexcept {
  if (!live(self) || state == nullptr || out == nullptr) return HEDGER_ERR_INVALID_ARG;
  if (!finite_all(state, self->cfg.state_dim) || !std::isfinite(action)) return reject_non_finite(self);
  hg::dim_ops(self->dim).predict(*self, state, action, *out, slots, weights, cap);
  return HEDGER_OK;
}

}  // namespace

namespace hg {

extern const DimOps kDimOps2, kDimOps3, kDimOps4, kDimOps5, kDimOps6, kDimOps7, kDimOps8, kDimOps9;

static_assert(HEDGER_MAX_INPUT_DIM == 9, "one DimOps table per input dimension 2..9");

const DimOps& dim_ops(uint32_t d) noexcept {
  static const DimOps* const kByDim[] = {&kDimOps2, &kDimOps3, &kDimOps4, &kDimOps5,
                                         &kDimOps6, &kDimOps7, &kDimOps8, &kDimOps9};
  return *kByDim[(d >= 2 && d <= 9 ? d : 9) - 2];
}

}  // namespace hg

extern "C" {

hedger_config_t hedger_config_default(void) HEDGER_NOEXCEPT {
  hedger_config_t c;
  std::memset(&c, 0, sizeof c);
  c.state_dim = 3;
  c.action_min = -1.0;
  c.action_max = 1.0;
  c.capacity = 8192;
  c.k_min = 3;
  c.k_max = 16;
  c.bandwidth = 0.2;
  c.weight_epsilon = 0.01;
  c.ridge = 1e-3;
  c.alpha = 0.2;
  c.gamma = 0.99;
  for (double& s : c.input_scale) s = 1.0;
  c.default_value = 0.0;
  c.seed = 1;
  c.greedy_coarse_actions = 9;
  c.greedy_refine_iters = 6;
  c.ivh_mode = static_cast<uint32_t>(HEDGER_IVH_UNWEIGHTED);
  c.merge_radius = 0.02;
  c.evict_candidates = 8;
  c.fresh_capacity = 4096;
  c.rebuild_work_per_update = 0;
  c.run_capacity = 0;
  c.replay = 0;
  c.replay_passes = 1;
  c.replay_lambda = 0.0;
  c.replay_alpha = 0.0;
  c.replay_cache = 1;
  c.greedy_method = static_cast<uint32_t>(HEDGER_GREEDY_PER_ACTION);
  c.greedy_pessimism = 0.0;
  c.greedy_reach = 1.0;
  c.local_model = static_cast<uint32_t>(HEDGER_LOCAL_LWR);
  c.anchor_recency_runs = 0.0;
  return c;
}

hedger_status_t hedger_config_validate(const hedger_config_t* cfg) HEDGER_NOEXCEPT {
  return valid_config(cfg) ? HEDGER_OK : HEDGER_ERR_INVALID_ARG;
}

size_t hedger_storage_size(const hedger_config_t* cfg) HEDGER_NOEXCEPT {
  return valid_config(cfg) ? make_layout(*cfg).total : 0;
}

hedger_status_t hedger_init(hedger_t** out, void* storage, size_t storage_size, const hedger_config_t* cfg)
    HEDGER_NOEXCEPT {
  if (out == nullptr || storage == nullptr || !valid_config(cfg)) return HEDGER_ERR_INVALID_ARG;
  if (reinterpret_cast<uintptr_t>(storage) % kAlign != 0) return HEDGER_ERR_ALIGNMENT;
  const Layout l = make_layout(*cfg);
  if (storage_size < l.total) return HEDGER_ERR_CAPACITY;
  uint8_t* base = static_cast<uint8_t*>(storage);
  std::memset(base, 0, l.total);
  hedger_t* h = new (base) hedger_t;
  std::memset(static_cast<void*>(h), 0, sizeof *h);
  h->cfg = *cfg;
  h->dim = cfg->state_dim + 1;
  h->h2 = cfg->bandwidth * cfg->bandwidth;
  h->r2max = h->h2 * std::log(1.0 / cfg->weight_epsilon);
  h->merge_r2 = cfg->merge_radius * cfg->merge_radius;
  h->fresh_cap = cfg->fresh_capacity;
  if (cfg->rebuild_work_per_update > 0) {
    h->rebuild_budget = cfg->rebuild_work_per_update;
  } else {
    const uint64_t per = cfg->fresh_capacity / 2;
    const uint64_t est = hg::kd_build_work_estimate(cfg->capacity);
    h->rebuild_budget = (est + per - 1) / per;
    if (h->rebuild_budget < 64) h->rebuild_budget = 64;
  }
  h->cap = cfg->capacity;
  h->pts = reinterpret_cast<double*>(base + l.pts);
  h->val = reinterpret_cast<double*>(base + l.val);
  h->seq = reinterpret_cast<uint64_t*>(base + l.seq);
  h->flags = base + l.flags;
  h->run_tag = reinterpret_cast<uint32_t*>(base + l.run_tag);
  h->anchor_w = reinterpret_cast<float*>(base + l.anchor_w);
  h->fresh_pos = reinterpret_cast<uint32_t*>(base + l.fresh_pos);
  std::memset(h->fresh_pos, 0xFF, static_cast<size_t>(cfg->capacity) * sizeof(uint32_t));  // kNone
  h->fresh_slot = reinterpret_cast<uint32_t*>(base + l.fresh_slot);
  h->fresh_pts = reinterpret_cast<double*>(base + l.fresh_pts);
  h->fresh_box = reinterpret_cast<double*>(base + l.fresh_box);
  for (int t = 0; t < 2; ++t) {
    hg::kd_bind(h->tree[t], reinterpret_cast<double*>(base + l.tpts[t]), reinterpret_cast<uint32_t*>(base + l.tids[t]),
                    reinterpret_cast<hg::Node*>(base + l.tnodes[t]), cfg->capacity);
  }
  h->run = reinterpret_cast<double*>(base + l.run);
  h->replay_cache = nullptr;
  if (replay_cached(*cfg)) {
    h->replay_cache = base + l.replay_cache;
    hg::dim_ops(h->dim).replay_cache_init(h->replay_cache, cfg->run_capacity);
  }
  h->run_cap = cfg->run_capacity;
  h->run_stride = l.run_stride;
  h->rng = cfg->seed ^ 0x9E3779B97F4A7C15ull;
  if (h->rng == 0) h->rng = 0x9E3779B97F4A7C15ull;
  reset_learned_state(h);
  h->fresh_start = hg::fresh_trigger(*h);
  refresh_gauges(h);
  h->magic = hg::kMagic;
  *out = h;
  return HEDGER_OK;
}

hedger_status_t hedger_create(hedger_t** out, const hedger_config_t* cfg) HEDGER_NOEXCEPT {
  if (out == nullptr || !valid_config(cfg)) return HEDGER_ERR_INVALID_ARG;
  const size_t n = make_layout(*cfg).total;
  void* mem = std::aligned_alloc(kAlign, n);
  if (mem == nullptr) return HEDGER_ERR_NO_MEMORY;
  const hedger_status_t st = hedger_init(out, mem, n, cfg);
  if (st != HEDGER_OK) {
    std::free(mem);
    return st;
  }
  (*out)->owned = 1;
  return HEDGER_OK;
}

void hedger_destroy(hedger_t* self) HEDGER_NOEXCEPT {
  if (!live(self) || !self->owned) return;
  self->magic = 0;
  std::free(self);
}

const hedger_config_t* hedger_get_config(const hedger_t* self) HEDGER_NOEXCEPT {
  return live(self) ? &self->cfg : nullptr;
}

hedger_status_t hedger_predict(hedger_t* self, const double* state, double action, hedger_prediction_t* out)
    HEDGER_NOEXCEPT {
  return predict_impl(self, state, action, out, nullptr, nullptr, 0);
}

hedger_status_t hedger_predict_ex(hedger_t* self, const double* state, double action, hedger_prediction_t* out,
                                  uint32_t* slots, double* weights, uint32_t cap) HEDGER_NOEXCEPT {
  return predict_impl(self, state, action, out, slots, weights, cap);
}

hedger_status_t hedger_greedy(hedger_t* self, const double* state, double* action, double* value,
                              hedger_kind_t* kind) HEDGER_NOEXCEPT {
  if (!live(self) || state == nullptr) return HEDGER_ERR_INVALID_ARG;
  if (!finite_all(state, self->cfg.state_dim)) return reject_non_finite(self);
  hg::GreedyResult g;
  hg::dim_ops(self->dim).greedy(*self, state, g);
  if (action != nullptr) *action = g.action;
  if (value != nullptr) *value = g.value;
  if (kind != nullptr) *kind = g.kind;
  return g.status;
}

hedger_status_t hedger_judge(hedger_t* self, const double* state, double action, hedger_judgement_t* out)
    HEDGER_NOEXCEPT {
  if (!live(self) || state == nullptr || out == nullptr) return HEDGER_ERR_INVALID_ARG;
  if (!finite_all(state, self->cfg.state_dim) || !std::isfinite(action)) return reject_non_finite(self);
  hg::GreedyResult g;
  hg::Judgement j{};
  j.action = action;
  hg::dim_ops(self->dim).judge(*self, state, g, j);
  out->greedy_action = g.action;
  out->greedy_value = g.value;
  out->greedy_kind = g.kind;
  out->judged = j.judged;
  out->action_lo = j.lo;
  out->action_hi = j.hi;
  out->kept_action = j.kept;
  out->gap = j.gap;
  out->gap_se = j.gap_se;
  return g.status;
}

hedger_status_t hedger_update(hedger_t* self, const double* state, double action, double reward,
                              const double* state_next, int terminal, hedger_update_info_t* info) HEDGER_NOEXCEPT {
  if (!live(self) || state == nullptr || (!terminal && state_next == nullptr)) return HEDGER_ERR_INVALID_ARG;
  const uint32_t sd = self->cfg.state_dim;
  if (!finite_all(state, sd) || !std::isfinite(action) || !std::isfinite(reward) ||
      (!terminal && !finite_all(state_next, sd))) {
    return reject_non_finite(self);
  }
  hedger_update_info_t local;
  hedger_update_info_t& inf = (info != nullptr) ? *info : local;
  hg::dim_ops(self->dim).update(*self, state, action, reward, state_next, terminal ? 1 : 0, inf);
  refresh_gauges(self);
  return HEDGER_OK;
}

hedger_status_t hedger_learn(hedger_t* self, const double* state, double action, double reward, const double* state_next,
                             int terminal, double q_next, hedger_update_info_t* info) HEDGER_NOEXCEPT {
  if (!live(self) || state == nullptr || (!terminal && state_next == nullptr)) return HEDGER_ERR_INVALID_ARG;
  const uint32_t sd = self->cfg.state_dim;
  if (!finite_all(state, sd) || !std::isfinite(action) || !std::isfinite(reward) ||
      (!terminal && (!finite_all(state_next, sd) || !std::isfinite(q_next)))) {
    return reject_non_finite(self);
  }
  hedger_update_info_t local;
  hedger_update_info_t& inf = (info != nullptr) ? *info : local;
  inf = hedger_update_info_t{};
  hg::dim_ops(self->dim).learn(*self, state, action, reward, state_next, terminal ? 1 : 0, q_next, inf);
  refresh_gauges(self);
  return HEDGER_OK;
}

hedger_status_t hedger_end_run_begin(hedger_t* self, uint32_t* pending) HEDGER_NOEXCEPT {
  if (!live(self)) return HEDGER_ERR_INVALID_ARG;
  if (self->replay_pending) {
    (void)hg::dim_ops(self->dim).replay_step(*self, 0xFFFFFFFFu);
  }
  const uint32_t n = hg::replay_begin(*self);
  refresh_gauges(self);
  if (pending != nullptr) *pending = n;
  return HEDGER_OK;
}

hedger_status_t hedger_end_run_step(hedger_t* self, uint32_t max_updates, uint32_t* remaining) HEDGER_NOEXCEPT {
  if (!live(self)) return HEDGER_ERR_INVALID_ARG;
  if (self->replay_pending && max_updates > 0) {
    (void)hg::dim_ops(self->dim).replay_step(*self, max_updates);
  }
  refresh_gauges(self);
  if (remaining != nullptr) {
    *remaining = self->replay_pending
                     ? (self->cfg.replay_passes - self->replay_pass) * self->run_count - self->replay_k
                     : 0u;
  }
  return HEDGER_OK;
}

hedger_status_t hedger_end_run(hedger_t* self, uint32_t* replayed) HEDGER_NOEXCEPT {
  uint32_t n = 0;
  const hedger_status_t st = hedger_end_run_begin(self, &n);
  if (st != HEDGER_OK) return st;
  (void)hedger_end_run_step(self, 0xFFFFFFFFu, nullptr);
  if (replayed != nullptr) *replayed = n;
  return HEDGER_OK;
}

hedger_status_t hedger_insert(hedger_t* self, const double* state, double action, double q, uint32_t flags,
                              hedger_store_op_t* op) HEDGER_NOEXCEPT {
  if (!live(self) || state == nullptr || (flags & ~HEDGER_POINT_PROTECTED) != 0) return HEDGER_ERR_INVALID_ARG;
  if (!finite_all(state, self->cfg.state_dim) || !std::isfinite(action) || !std::isfinite(q)) {
    return reject_non_finite(self);
  }
  const hedger_store_op_t r = hg::dim_ops(self->dim).insert(*self, state, action, q, static_cast<uint8_t>(flags));
  refresh_gauges(self);
  if (op != nullptr) *op = r;
  return HEDGER_OK;
}

hedger_status_t hedger_observe_reward(hedger_t* self, double reward) HEDGER_NOEXCEPT {
  if (!live(self)) return HEDGER_ERR_INVALID_ARG;
  if (!std::isfinite(reward)) return reject_non_finite(self);
  hg::track_reward(*self, reward);
  refresh_gauges(self);
  return HEDGER_OK;
}

uint32_t hedger_size(const hedger_t* self) HEDGER_NOEXCEPT { return live(self) ? self->fill : 0; }

hedger_status_t hedger_get_point(const hedger_t* self, uint32_t slot, hedger_point_t* out) HEDGER_NOEXCEPT {
  if (!live(self) || out == nullptr || slot >= self->fill) return HEDGER_ERR_INVALID_ARG;
  std::memset(out, 0, sizeof *out);
  const uint32_t d = self->dim;
  const double* p = self->pts + static_cast<size_t>(slot) * d;
  for (uint32_t i = 0; i + 1 < d; ++i) out->state[i] = p[i] * self->cfg.input_scale[i];
  out->action = p[d - 1] * self->cfg.input_scale[d - 1];
  out->value = self->val[slot];
  out->flags = self->flags[slot];
  out->run_tag = self->run_tag[slot];
  out->anchor_weight = static_cast<double>(self->anchor_w[slot]);
  return HEDGER_OK;
}

uint32_t hedger_run_tag(const hedger_t* self) HEDGER_NOEXCEPT { return live(self) ? self->cur_tag : 0u; }

hedger_status_t hedger_set_run_tag(hedger_t* self, uint32_t tag) HEDGER_NOEXCEPT {
  if (!live(self) || tag < self->cur_tag) return HEDGER_ERR_INVALID_ARG;
  if (tag != self->cur_tag) ++self->geom_gen;  // the anchor's recency has moved
  self->cur_tag = tag;
  refresh_gauges(self);  // the anchor's recency has moved: a sliced save must start again
  return HEDGER_OK;
}

hedger_status_t hedger_weight_run(hedger_t* self, uint32_t tag, double weight, uint32_t* points) HEDGER_NOEXCEPT {
  if (!live(self) || !std::isfinite(weight) || !(weight >= 0.0) || weight > 16.0) return HEDGER_ERR_INVALID_ARG;
  const float w = static_cast<float>(weight);
  uint32_t n = 0;
  for (uint32_t s = 0; s < self->fill; ++s) {
    if (self->run_tag[s] != tag) continue;
    self->anchor_w[s] = w;
    ++n;
  }
  if (points != nullptr) *points = n;
  ++self->geom_gen;  // anchor weights have changed
  refresh_gauges(self);
  return HEDGER_OK;
}

const hedger_counters_t* hedger_counters(const hedger_t* self) HEDGER_NOEXCEPT {
  return live(self) ? &self->counters : nullptr;
}

size_t hedger_serialized_size(const hedger_t* self) HEDGER_NOEXCEPT {
  return live(self) ? format_size(self->dim, self->fill) : 0;
}

size_t hedger_serialized_max_size(const hedger_config_t* cfg) HEDGER_NOEXCEPT {
  return valid_config(cfg) ? format_size(cfg->state_dim + 1, cfg->capacity) : 0;
}

hedger_status_t hedger_save_begin(const hedger_t* self, void* buf, size_t size, hedger_save_cursor_t* cursor)
    HEDGER_NOEXCEPT {
  if (!live(self) || buf == nullptr || cursor == nullptr) return HEDGER_ERR_INVALID_ARG;
  const uint32_t d = self->dim;
  const size_t total = format_size(d, self->fill);
  if (size < total) return HEDGER_ERR_CAPACITY;
  uint8_t* p = static_cast<uint8_t*>(buf);
  std::memcpy(p, kFileMagic, 4);
  put_u32(p + 4, HEDGER_FORMAT_VERSION);
  put_u64(p + 8, total);
  put_u32(p + 16, self->cfg.state_dim);
  put_u32(p + 20, self->cfg.capacity);
  put_u32(p + 24, self->fill);
  put_u32(p + 28, self->reward_seen);
  put_f64(p + 32, self->cfg.action_min);
  put_f64(p + 40, self->cfg.action_max);
  put_f64(p + 48, self->cfg.gamma);
  put_f64(p + 56, self->r_min);
  put_f64(p + 64, self->r_max);
  put_u64(p + 72, self->rng);
  put_u32(p + 80, self->cur_tag);
  put_u32(p + 84, 0u);
  size_t off = header_fixed(HEDGER_FORMAT_VERSION);
  for (uint32_t i = 0; i < d; ++i, off += 8) put_f64(p + off, self->cfg.input_scale[i]);
  cursor->buf = p;
  cursor->size = total;
  cursor->offset = off;
  cursor->next_point = 0;
  cursor->crc = crc32_update(0xFFFFFFFFu, p, off);
  cursor->generation = self->generation;
  cursor->done = 0;
  return HEDGER_OK;
}

hedger_status_t hedger_save_step(const hedger_t* self, hedger_save_cursor_t* cursor, uint32_t max_points,
                                 size_t* written) HEDGER_NOEXCEPT {
  if (!live(self) || cursor == nullptr || cursor->buf == nullptr) return HEDGER_ERR_INVALID_ARG;
  if (cursor->done) {
    if (written != nullptr) *written = cursor->size;
    return HEDGER_OK;
  }
  if (cursor->generation != self->generation) return HEDGER_ERR_CHANGED;
  const uint32_t d = self->dim;
  uint8_t* p = cursor->buf;
  size_t off = cursor->offset;
  const size_t start = off;
  uint32_t s = cursor->next_point;
  const uint32_t end = (self->fill - s) > max_points ? s + max_points : self->fill;
  for (; s < end; ++s) {
    const double* x = self->pts + static_cast<size_t>(s) * d;
    for (uint32_t i = 0; i < d; ++i, off += 8) put_f64(p + off, x[i]);
    put_f64(p + off, self->val[s]);
    off += 8;
    put_u32(p + off, self->flags[s]);
    off += 4;
    put_u32(p + off, self->run_tag[s]);
    off += 4;
    put_u32(p + off, f32_bits(self->anchor_w[s]));
    off += 4;
  }
  cursor->crc = crc32_update(cursor->crc, p + start, off - start);
  cursor->offset = off;
  cursor->next_point = s;
  if (s == self->fill) {
    put_u32(p + off, cursor->crc ^ 0xFFFFFFFFu);
    cursor->done = 1;
    if (written != nullptr) *written = cursor->size;
  } else if (written != nullptr) {
    *written = 0;
  }
  return HEDGER_OK;
}

hedger_status_t hedger_save(const hedger_t* self, void* buf, size_t size, size_t* written) HEDGER_NOEXCEPT {
  hedger_save_cursor_t c;
  const hedger_status_t st = hedger_save_begin(self, buf, size, &c);
  if (st != HEDGER_OK) return st;
  return hedger_save_step(self, &c, 0xFFFFFFFFu, written);
}

namespace {

// The checks of a saved buffer before its contents are read: magic first (on what is there), then
// version, then the declared length, then the CRC-32. On success *version and *total are set.
hedger_status_t check_saved(const uint8_t* p, size_t size, uint32_t* version, size_t* total) {
  const size_t nm = size < 4 ? size : 4;
  if (std::memcmp(p, kFileMagic, nm) != 0) return HEDGER_ERR_FORMAT;
  if (size < 8) return HEDGER_ERR_TRUNCATED;
  const uint32_t v = get_u32(p + 4);
  if (v != HEDGER_FORMAT_VERSION && v != 1u) return HEDGER_ERR_VERSION;
  if (size < 16) return HEDGER_ERR_TRUNCATED;
  const uint64_t t = get_u64(p + 8);
  if (t < header_fixed(v) + 8u + 4u) return HEDGER_ERR_FORMAT;
  if (t > size) return HEDGER_ERR_TRUNCATED;
  const size_t n = static_cast<size_t>(t);
  if (get_u32(p + n - 4) != crc32(p, n - 4)) return HEDGER_ERR_CHECKSUM;
  *version = v;
  *total = n;
  return HEDGER_OK;
}

}  // namespace

hedger_status_t hedger_saved_config(const void* buf, size_t size, hedger_saved_t* out) HEDGER_NOEXCEPT {
  if (buf == nullptr || out == nullptr) return HEDGER_ERR_INVALID_ARG;
  const uint8_t* p = static_cast<const uint8_t*>(buf);
  uint32_t version = 0;
  size_t n = 0;
  const hedger_status_t st = check_saved(p, size, &version, &n);
  if (st != HEDGER_OK) return st;
  const uint64_t d = static_cast<uint64_t>(get_u32(p + 16)) + 1u;
  const size_t head = header_fixed(version);
  if (n < head + 8u * d + 4u) return HEDGER_ERR_FORMAT;  // the input scales must be inside, as for hedger_load()
  out->state_dim = get_u32(p + 16);
  out->count = get_u32(p + 24);
  out->action_min = get_f64(p + 32);
  out->action_max = get_f64(p + 40);
  out->gamma = get_f64(p + 48);
  for (uint32_t i = 0; i < HEDGER_MAX_INPUT_DIM; ++i) out->input_scale[i] = i < d ? get_f64(p + head + 8u * i) : 0.0;
  return HEDGER_OK;
}

hedger_status_t hedger_load(hedger_t* self, const void* buf, size_t size) HEDGER_NOEXCEPT {
  if (!live(self) || buf == nullptr) return HEDGER_ERR_INVALID_ARG;
  const uint8_t* p = static_cast<const uint8_t*>(buf);
  uint32_t version = 0;
  size_t n = 0;
  const hedger_status_t checked = check_saved(p, size, &version, &n);
  if (checked != HEDGER_OK) return checked;
  const uint64_t total = n;
  const size_t head = header_fixed(version);
  // Compatibility with this instance's config.
  const uint32_t sd = get_u32(p + 16);
  const uint32_t count = get_u32(p + 24);
  if (sd != self->cfg.state_dim) return HEDGER_ERR_CONFIG_MISMATCH;
  const uint32_t d = sd + 1;
  if (total < head + 8u * d + 4u) return HEDGER_ERR_FORMAT;  // the input scales must be inside
  if (!same_bits(get_f64(p + 32), self->cfg.action_min) || !same_bits(get_f64(p + 40), self->cfg.action_max) ||
      !same_bits(get_f64(p + 48), self->cfg.gamma)) {
    return HEDGER_ERR_CONFIG_MISMATCH;
  }
  for (uint32_t i = 0; i < d; ++i) {
    if (!same_bits(get_f64(p + head + 8u * i), self->cfg.input_scale[i])) return HEDGER_ERR_CONFIG_MISMATCH;
  }
  if (count > self->cfg.capacity) return HEDGER_ERR_CONFIG_MISMATCH;
  // Contents.
  if (total != format_size(d, count, version)) return HEDGER_ERR_FORMAT;
  const uint32_t seen = get_u32(p + 28);
  const double rmin = get_f64(p + 56), rmax = get_f64(p + 64);
  const uint64_t rng = get_u64(p + 72);
  if (seen > 1 || !std::isfinite(rmin) || !std::isfinite(rmax) || rmin > rmax || rng == 0) return HEDGER_ERR_FORMAT;
  const bool tagged = version != 1u;
  const uint32_t cur_tag = tagged ? get_u32(p + 80) : 0u;
  if (tagged && get_u32(p + 84) != 0u) return HEDGER_ERR_FORMAT;
  const size_t rec = record_size(d, version);
  const size_t first = head + 8u * d;
  for (uint32_t s = 0; s < count; ++s) {
    const uint8_t* r = p + first + s * rec;
    for (uint32_t i = 0; i <= d; ++i) {
      if (!std::isfinite(get_f64(r + 8u * i))) return HEDGER_ERR_FORMAT;
    }
    if ((get_u32(r + 8u * d + 8u) & ~HEDGER_POINT_PROTECTED) != 0) return HEDGER_ERR_FORMAT;
    if (tagged) {
      const float w = bits_f32(get_u32(r + 8u * d + 16u));
      if (get_u32(r + 8u * d + 12u) > cur_tag || !std::isfinite(w) || !(w >= 0.0f) || w > 16.0f) {
        return HEDGER_ERR_FORMAT;
      }
    }
  }
  // Valid: replace the learned state.
  reset_learned_state(self);
  uint32_t prot = 0;
  for (uint32_t s = 0; s < count; ++s) {
    const uint8_t* r = p + first + s * rec;
    double* x = self->pts + static_cast<size_t>(s) * d;
    for (uint32_t i = 0; i < d; ++i) x[i] = get_f64(r + 8u * i);
    self->val[s] = get_f64(r + 8u * d);
    self->flags[s] = static_cast<uint8_t>(get_u32(r + 8u * d + 8u));
    self->run_tag[s] = tagged ? get_u32(r + 8u * d + 12u) : 0u;
    self->anchor_w[s] = tagged ? bits_f32(get_u32(r + 8u * d + 16u)) : 1.0f;
    self->seq[s] = 1;
    prot += self->flags[s] & HEDGER_POINT_PROTECTED;
  }
  self->fill = count;
  self->n_protected = prot;
  self->seq_counter = 1;
  self->cur_tag = cur_tag;
  self->reward_seen = seen;
  self->r_min = rmin;
  self->r_max = rmax;
  self->counters.reward_min = rmin < 0.0 ? rmin : 0.0;
  self->counters.reward_max = rmax > 0.0 ? rmax : 0.0;
  self->rng = rng;
  hg::dim_ops(self->dim).rebuild(*self);
  ++self->counters.loads;
  refresh_gauges(self);
  return HEDGER_OK;
}

const char* hedger_status_str(hedger_status_t status) HEDGER_NOEXCEPT {
  switch (status) {
    case HEDGER_OK:
      return "ok";
    case HEDGER_NO_KNOWN_ACTION:
      return "no known action (every candidate action's value is unknown)";
    case HEDGER_ERR_INVALID_ARG:
      return "invalid argument (NULL pointer or value out of range)";
    case HEDGER_ERR_NON_FINITE:
      return "non-finite input (NaN or infinity) refused";
    case HEDGER_ERR_CAPACITY:
      return "buffer or storage too small";
    case HEDGER_ERR_ALIGNMENT:
      return "storage not aligned to HEDGER_STORAGE_ALIGN";
    case HEDGER_ERR_NO_MEMORY:
      return "out of memory";
    case HEDGER_ERR_FORMAT:
      return "not a HEDGER state buffer, or inconsistent contents";
    case HEDGER_ERR_VERSION:
      return "unsupported HEDGER format version";
    case HEDGER_ERR_TRUNCATED:
      return "HEDGER state buffer truncated";
    case HEDGER_ERR_CHECKSUM:
      return "HEDGER state buffer corrupted (CRC-32 mismatch)";
    case HEDGER_ERR_CONFIG_MISMATCH:
      return "HEDGER state saved under an incompatible config";
    case HEDGER_ERR_CHANGED:
      return "the learned state changed during a sliced save (start it again)";
  }
  return "unknown status";
}

const char* hedger_kind_str(hedger_kind_t kind) HEDGER_NOEXCEPT {
  switch (kind) {
    case HEDGER_KIND_UNKNOWN:
      return "unknown";
    case HEDGER_KIND_LWA:
      return "lwa";
    case HEDGER_KIND_LWR:
      return "lwr";
  }
  return "invalid";
}

}  // extern "C"
