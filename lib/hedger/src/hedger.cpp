// SPDX-License-Identifier: MIT
// HEDGER C API (skeleton: config, storage, status strings; learning is being implemented).
#include "hedger/hedger.h"

#include <cmath>
#include <cstdlib>
#include <cstring>

extern "C" {

hedger_config_t hedger_config_default(void) {
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
  c.ridge = 1e-6;
  c.alpha = 0.2;
  c.gamma = 0.99;
  for (double& s : c.input_scale) s = 1.0;
  c.default_value = 0.0;
  c.seed = 1;
  c.greedy_coarse_actions = 9;
  c.greedy_refine_iters = 6;
  c.ivh_mode = HEDGER_IVH_UNWEIGHTED;
  c.merge_radius = 0.02;
  c.evict_candidates = 8;
  c.fresh_capacity = 256;
  c.rebuild_work_per_update = 0;
  c.run_capacity = 0;
  c.replay = 0;
  return c;
}

hedger_status_t hedger_config_validate(const hedger_config_t* cfg) { return cfg ? HEDGER_OK : HEDGER_ERR_INVALID_ARG; }
size_t hedger_storage_size(const hedger_config_t*) { return 0; }
hedger_status_t hedger_init(hedger_t**, void*, size_t, const hedger_config_t*) { return HEDGER_ERR_INVALID_ARG; }
hedger_status_t hedger_create(hedger_t**, const hedger_config_t*) { return HEDGER_ERR_INVALID_ARG; }
void hedger_destroy(hedger_t*) {}
const hedger_config_t* hedger_get_config(const hedger_t*) { return nullptr; }
hedger_status_t hedger_predict(hedger_t*, const double*, double, hedger_prediction_t*) { return HEDGER_ERR_INVALID_ARG; }
hedger_status_t hedger_predict_ex(hedger_t*, const double*, double, hedger_prediction_t*, uint32_t*, double*, uint32_t) {
  return HEDGER_ERR_INVALID_ARG;
}
hedger_status_t hedger_greedy(hedger_t*, const double*, double*, double*, hedger_kind_t*) { return HEDGER_ERR_INVALID_ARG; }
hedger_status_t hedger_update(hedger_t*, const double*, double, double, const double*, int, hedger_update_info_t*) {
  return HEDGER_ERR_INVALID_ARG;
}
hedger_status_t hedger_end_run(hedger_t*, uint32_t*) { return HEDGER_ERR_INVALID_ARG; }
hedger_status_t hedger_insert(hedger_t*, const double*, double, double, uint32_t, hedger_store_op_t*) {
  return HEDGER_ERR_INVALID_ARG;
}
uint32_t hedger_size(const hedger_t*) { return 0; }
hedger_status_t hedger_get_point(const hedger_t*, uint32_t, hedger_point_t*) { return HEDGER_ERR_INVALID_ARG; }
const hedger_counters_t* hedger_counters(const hedger_t*) { return nullptr; }
size_t hedger_serialized_size(const hedger_t*) { return 0; }
size_t hedger_serialized_max_size(const hedger_config_t*) { return 0; }
hedger_status_t hedger_save(const hedger_t*, void*, size_t, size_t*) { return HEDGER_ERR_INVALID_ARG; }
hedger_status_t hedger_load(hedger_t*, const void*, size_t) { return HEDGER_ERR_INVALID_ARG; }
const char* hedger_status_str(hedger_status_t) { return "unknown status"; }
const char* hedger_kind_str(hedger_kind_t) { return "unknown"; }

}  // extern "C"
