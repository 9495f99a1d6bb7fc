// SPDX-License-Identifier: MIT
// HEDGER's per-dimension algorithms behind one table: the core is templated on the input
// dimension D (state + action, 2..HEDGER_MAX_STATE_DIM + 1) so every Eigen object is fixed-size
// and allocation-free. Each D is compiled in its own translation unit (dim.cpp.in, generated once
// per D by CMake) and reached through dim_ops(d): the eight instantiations are most of the
// library's build cost, and separate units let a build spread them over every core. The
// factorisations they share are compiled once, in linalg.cpp (see linalg.hpp).
#ifndef HEDGER_DIMS_HPP
#define HEDGER_DIMS_HPP

#include <cstddef>
#include <cstdint>

#include "hedger/hedger.h"

namespace hg {

struct GreedyResult;
struct Judgement;

/// The entry points of one D. Every pointer is non-null; arguments are checked (non-null,
/// finite) by the C API before a call. Cost and memory are those of the core functions named.
struct DimOps {
  /// hg::predict_x on the scaled (state, action); copies up to `cap` neighbour slots/weights
  /// into `slots`/`weights` when non-null.
  void (*predict)(hedger_t& h, const double* state, double action, hedger_prediction_t& out, uint32_t* slots,
                  double* weights, uint32_t cap) noexcept;
  /// hg::greedy_at.
  void (*greedy)(hedger_t& h, const double* state, GreedyResult& out) noexcept;
  /// hg::greedy_at with a judgement of judge.action.
  void (*judge)(hedger_t& h, const double* state, GreedyResult& out, Judgement& judge) noexcept;
  /// hg::update.
  void (*update)(hedger_t& h, const double* s, double a, double r, const double* sn, int terminal,
                 hedger_update_info_t& info) noexcept;
  /// hg::learn.
  void (*learn)(hedger_t& h, const double* s, double a, double r, const double* sn, int terminal, double q_next,
                hedger_update_info_t& info) noexcept;
  /// hg::replay_step: the updates done.
  uint32_t (*replay_step)(hedger_t& h, uint32_t max_updates) noexcept;
  /// hg::insert.
  hedger_store_op_t (*insert)(hedger_t& h, const double* s, double a, double q, uint8_t flags) noexcept;
  /// hg::rebuild_now.
  void (*rebuild)(hedger_t& h) noexcept;
  /// Bytes of one replay record (hg::ReplayRecord<D>, cfg.replay_cache), a multiple of its alignment.
  size_t replay_record_bytes;
  /// Constructs n replay records at mem (aligned to HEDGER_STORAGE_ALIGN), none valid. O(n).
  void (*replay_cache_init)(void* mem, uint32_t n) noexcept;
};

/// The table of input dimension d (2..9; anything else gets 9's, as the store was laid out).
const DimOps& dim_ops(uint32_t d) noexcept;

}  // namespace hg

#endif  // HEDGER_DIMS_HPP
