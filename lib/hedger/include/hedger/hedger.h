// SPDX-License-Identifier: MIT
/// hedger/hedger.h — HEDGER: fixed-memory Q-value function approximation for one continuous action.
///
/// Q(s, a) is a memory of points x_i = (s_i, a_i) with values q_i (Smart & Kaelbling, ICML 2000;
/// ICRA 2002 section III; design: shared/design/hedger.md). Each query fits a fresh local model:
/// locally weighted regression (LWR), guarded by the independent-variable-hull (IVH) test and by
/// value bounds derived from the rewards seen, falling back to locally weighted averaging (LWA),
/// which never extrapolates. With fewer than k_min usable neighbours the answer is "unknown".
///
/// Coordinates. Raw inputs (state in the caller's units, action in the actuator's units, e.g.
/// rad/s) are divided per dimension by cfg.input_scale[] ("one scaled unit = input_scale raw
/// units"; a good choice is each dimension's range). Every distance, the bandwidth and the merge
/// radius are in these scaled units. Index 0..state_dim-1 is the state, index state_dim the action.
///
/// Memory. Everything lives in one block provided by the caller (hedger_storage_size(),
/// hedger_init()) or allocated once by hedger_create(). After init no function allocates;
/// predict / greedy / update run in bounded time. Footprint (hedger_storage_size() is exact):
///   per stored point  (24 D + 45) bytes + about 64 / 16 · 2 bytes of tree nodes
///                     (store: coordinates 8D, value 8, sequence 8, flags 1, fresh index 4,
///                      run tag 4, anchor weight 4; two kd-trees: coordinates 8D + id 4 each)
///   per fresh entry   8 D + 4 bytes;  per run record (2 state_dim + 3) · 8 bytes, and with
///                     replay_cache the geometry its replay keeps: 4,016 bytes at D = 4, 4,864 at
///                     D = 5, 10,096 at D = 9 (two searches' neighbours, factorisations, inverses);
///                     + ~1 KiB.
/// D = 4 (3-D state + action): 147 bytes per stored point measured at 20k points. The firmware's
/// corridor learner (D = 5, run_capacity 1,008) keeps 4.9 MB of replay records.
///
/// Choices (hedger.md leaves them open; measured on the mountain-car test and the benchmark):
/// - Bandwidth: fixed h in scaled units, not tied to the neighbourhood, so "unknown" means
///   "nothing within h·sqrt(ln(1/weight_epsilon))" everywhere and a far query is never answered
///   from distant points. h sets the resolution: too coarse aliases states whose best actions
///   differ (mountain car at h = 0.06: the greedy policy settles in a loop and the aliased
///   neighbourhood's values collapse for every action, 1/10 starts reached); too fine leaves
///   queries unknown and needs a larger store (capacity grows like h^-D). h = 0.03 learned.
/// - IVH design matrix: unweighted rows [x_i, 1] (Cook's hull of the neighbourhood), the
///   default: 8/8 seeds learned the mountain car vs 5/8 with the weighted variant.
/// - Ridge: on the slopes only (never shrinks the intercept = the prediction). A small ridge
///   damps the slope noise that LWR turns into optimistic values at untried actions:
///   mountain car 21/24 seeds at λ = 1e-3 vs 19/24 at 1e-6, 16/24 at 1e-4, 14/24 at 1e-2.
/// - Store rule (bounded memory), applied to every new point:
///   1. merge into the nearest stored point if closer than merge_radius;
///   2. else insert while there is room;
///   3. else (full) compare the new point with evict_candidates slots drawn by the seeded
///      generator (unprotected ones first): redundancy = distance to the k_min-th nearest
///      other stored point; the most redundant candidate is evicted and replaced, unless the
///      new point is more redundant itself, then it is merged into its nearest.
///   A merge of an update applies the Q-learning step to the point it is merged into
///   (q_j += α (target − q_j), state aggregation); a merge of hedger_insert() moves q_j toward q
///   by the kernel weight between them. Points of transitions with r != 0 or terminal are
///   protected: evicted only when every candidate drawn is protected (counted).
///   Measured: a stream 90 % inside one small cluster leaves about k_min points there (it
///   stays known) and the rest of the store covers the sparse region; with the nearest-
///   neighbour distance as redundancy the cluster was thinned to one point (unknown). Mountain
///   car learns at capacity >= 1500 (21/24 seeds), 1000 → 13/24, 750 → 0/24 at h = 0.03
///   (13/24 with h = 0.04): small stores need a coarser kernel.
/// - Replay: optional backward replay of each finished run (cfg.replay) propagates a sparse
///   final reward along the whole run at once: mountain car 21/24 seeds with replay vs 10/24
///   without. Passes and target (cfg.replay_passes, cfg.replay_lambda): one pass of the Q-learning
///   target leaves values tracking visit counts (corridor: Q 0.43 where the return is 2.8); many
///   passes of it overshoot (5.8: the max over noisy values, amplified by 1/(1-gamma)); many passes
///   of the run's own return converge (within 5 %) but a crash late in a run then writes 0 into
///   every state it passed. The lambda-return with lambda = 0.9 (an effective horizon of ten steps
///   of the run, then the learned value) over 20 passes learned the corridor best (6 seeds x 65
///   runs: 10/10 in every phase-two block; lambda = 0 and 0.8 failed runs, 1.0 more failures).
///   The replay's own step (cfg.replay_alpha) lets fewer passes move a value as far: 3 passes of
///   0.7741 (1 − 0.7741 = 0.8^(20/3)) with the controller's k_max at 48 learned as 20 passes of
///   α = 0.2 with k_max 64 did on held-out seeds for 0.56 of b21r-train's instructions; the
///   controller's defaults since (docs/LEARNING.md). Mountain car (the Learner's example, 30 seeds)
///   pays a little: every final goal on 28 seeds against 30.
/// - Greedy method (cfg.greedy_method; the library's defaults are HEDGER_GREEDY_PER_ACTION,
///   greedy_pessimism 0, greedy_reach 1; the firmware sets the state model and the rest below).
///   HEDGER_GREEDY_PER_ACTION: one prediction per candidate action, each with its own
///   neighbourhood. The bias each carries from the states around the query is larger than the
///   effect of one action at 10 Hz: on the corridor the greedy policy followed that noise (a gain
///   of 0.15 where the examples use 0.5-2) and got worse with more data.
///   HEDGER_GREEDY_STATE_MODEL: one model at the state (linear in the state, concave quadratic in
///   the action) judges every candidate, pessimistically: value - κ standard errors of the
///   action's effect, measured from the neighbours' own policy at the state (the anchor; κ =
///   cfg.greedy_pessimism). κ = 4: 0, 1, 2 gave collisions in evaluation, 3 and 4 none, 10 a
///   policy that only repeated its data. Where the state has too few neighbours, a second
///   attempt with a kernel greedy_reach times wider.
///   The controller's defaults (learn_learner_config() from its configuration; chosen on seeds
///   11-20, confirmed on seeds 1-10; paired differences in steps of 0.1 s, negative = shorter):
///   * the executed rotation (rad/s, scale 1 rad/s) as the last state entry (state_rotation):
///     the acceleration limit, 0.29 rad/s per tick, ties the next rotation to the last command.
///     Fig. 4 after phase one +1.3 ± 0.4 vs the example policy (was +2.0), failed phase-two
///     runs 9 → 0; seeds 1-10, failed runs: Fig. 5 2 against 9, obstacles 10 against 41. At
///     0.25 rad/s (the action's scale) the human-driven corridor lost (final block 274.7 ± 26.1
///     against 243.5 ± 4.3; 252.3 ± 7.0 at 1 rad/s).
///   * the corridor's target angle at 0.125 rad per scaled unit (was 0.5) with k_max 64 (was 32; 48 now):
///     an off-axis start is judged by runs that started at a similar heading. Fig. 4 -0.8 ± 0.2,
///     Fig. 5 -4.6 ± 4.2; seeds 1-10: Fig. 4 -0.6 ± 0.3, obstacles -14.8 ± 19.2, Fig. 5
///     +6.7 ± 20.5 (not significant). Cost: tick p50 74 us against 59, max 576 us against 412
///     (20k points), and early learning (Fig. 4 after 5 runs, seeds 1-10: 5.2/10 poses against
///     9.9/10).
///   * greedy_reach 8 for the corridor, 3 for the obstacles: with the fine angle an early state's
///     neighbourhood is often empty; the wide attempt answers from runs at other headings. Fig. 4
///     after 5 runs -284.7 ± 87.5 against reach 3, final 0.0 ± 0.1; tick cost unchanged.
///     Obstacles: reach 8 final +4.2 ± 12.6 and 26 failed phase-two runs against 10: they keep 3.
///   What it learns: with code examples on the corridor the greedy policy is an imitation of the
///   examples (κ = 100 leaves only the anchor and gives the same policy; seeds 1-10, before the
///   firmware's pairs: Fig. 4 final -0.2 ± 0.2): one tick's action changes the return by about 0.3
///   step, far below the fit's standard error. Taught by one consistent teacher it reproduces it.
///   docs/LEARNING.md records every alternative measured (lower pessimism, more data and
///   neighbours, exploration, held decisions, planning on the values, advantage weighting, one
///   teacher or a mixture, the obstacle task's gap) and the diagnosis behind these choices.
/// - Run tags and anchor weights (hedger_set_run_tag, hedger_weight_run, cfg.anchor_recency_runs):
///   a caller that ranks whole runs can weigh their points in the anchor (and the action range
///   tilted with it); the value fits do not see the weights. A faster run's points weigh
///   2 / (1 + e^(-d/tau)), the slower run's 2 minus that, a run not yet ranked 0 (a neighbourhood
///   of such points falls back to the kernel weights: counted in anchor_unweighted); runs fade with
///   e^(-age / anchor_recency_runs run tags). The controller does not use them (every weight 1):
///   the run ranking that did was removed with the controller's ranked pairs, whose terms were the
///   reference law's coordinates (docs/LEARNING.md). Cost: 8 bytes per stored point; one O(fill)
///   pass per weighted run, between runs.
/// - kd-tree: static median-split tree in a fixed node pool, leaf size 16; new points go to a
///   small linearly scanned fresh buffer; a shadow tree is rebuilt in fixed work slices across
///   updates and swapped in (see hedger_counters_t::max_rebuild_work). Neighbour sets are
///   ordered by (distance, slot), so results never depend on the tree's shape or the timing.
///   A search for the k nearest is bounded from the start by the previous search of its kind
///   (its k neighbours, re-measured from the new query: the k nearest lie within the farthest of
///   them), so it visits far fewer nodes and finds the same points.
/// - Replay cache (cfg.replay_cache): the backward replay's later passes reuse each record's
///   geometry (see hedger_end_run()).
///
/// Determinism. Results are a pure function of (config, call sequence): no clocks, no global
/// state, an explicitly seeded generator, and neighbour sets ordered by (distance, slot) so that
/// the internal kd-tree layout never changes a result. Same binary + same calls = bit-identical
/// outputs and saved bytes.
///
/// Threads. An instance is not thread-safe; use one instance per thread or lock around it.
/// Distinct instances share nothing.
///
/// Errors. Functions return hedger_status_t: 0 = OK, 1 = an outcome the caller must handle (no
/// known action), >= 2 errors. A failed call leaves the learned state unchanged (only the
/// monotonic fault counters move).
///
/// Typical tick (phase two):
/// @code
///   hedger_update_info_t info;
///   hedger_update(h, s_prev, a_prev, r, s, terminal, &info);   // learns; greedy at s done once
///   double a = (info.next_status == HEDGER_OK) ? info.next_action : fallback_action;
///   a = explore(a);                                            // caller's seeded exploration
/// @endcode
#ifndef HEDGER_HEDGER_H
#define HEDGER_HEDGER_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
/// C++ callers see every function as noexcept: no exception ever crosses the C boundary.
#define HEDGER_NOEXCEPT noexcept
extern "C" {
#else
#define HEDGER_NOEXCEPT
#endif

/// Largest state dimension (compile-time ceiling; the runtime value is cfg.state_dim).
#define HEDGER_MAX_STATE_DIM 8U
/// Largest input dimension D = state_dim + 1 (state + action).
#define HEDGER_MAX_INPUT_DIM (HEDGER_MAX_STATE_DIM + 1U)
/// Largest neighbourhood (ceiling of cfg.k_max).
#define HEDGER_MAX_K 64U
/// Largest number of evenly spaced actions of the coarse greedy scan.
#define HEDGER_MAX_COARSE_ACTIONS 64U
/// Largest number of refinement evaluations of the greedy search.
#define HEDGER_MAX_REFINE_ITERS 32U
/// Largest eviction candidate set.
#define HEDGER_MAX_EVICT_CANDIDATES 32U
/// Largest sample store (ceiling of cfg.capacity).
#define HEDGER_MAX_CAPACITY (1U << 24)
/// Largest fresh-point buffer (ceiling of cfg.fresh_capacity).
#define HEDGER_MAX_FRESH 4096U
/// Largest run buffer for backward replay (ceiling of cfg.run_capacity).
#define HEDGER_MAX_RUN 65536U
/// Largest number of backward passes of one replay (ceiling of cfg.replay_passes).
#define HEDGER_MAX_REPLAY_PASSES 64U
/// Alignment (bytes) the storage given to hedger_init() must have.
#define HEDGER_STORAGE_ALIGN 64U
/// Version of the byte format written by hedger_save(). hedger_load() reads it and version 1
/// (before run tags: its points load with tag 0 and anchor weight 1).
#define HEDGER_FORMAT_VERSION 2U

/// Result codes. 0 is success; 1 is an outcome, not an error; >= 2 are errors.
typedef enum hedger_status {
  HEDGER_OK = 0,
  /// hedger_greedy() / hedger_update_info_t::next_status: every candidate action's value is
  /// unknown (fewer than k_min neighbours). The outputs hold the action-range midpoint and
  /// cfg.default_value; the caller decides (phase one: the example policy; phase two: the
  /// advisor or a default action).
  HEDGER_NO_KNOWN_ACTION = 1,
  HEDGER_ERR_INVALID_ARG = 2,      ///< NULL pointer, bad config field, or value outside its documented range.
  HEDGER_ERR_NON_FINITE = 3,       ///< An input was NaN or infinite; nothing was stored or changed.
  HEDGER_ERR_CAPACITY = 4,         ///< A caller buffer or storage block is too small; nothing was written.
  HEDGER_ERR_ALIGNMENT = 5,        ///< Storage not aligned to HEDGER_STORAGE_ALIGN.
  HEDGER_ERR_NO_MEMORY = 6,        ///< hedger_create() only: its one allocation failed.
  HEDGER_ERR_FORMAT = 7,           ///< hedger_load(): not a HEDGER buffer (bad magic) or inconsistent contents.
  HEDGER_ERR_VERSION = 8,          ///< hedger_load(): written by another format version.
  HEDGER_ERR_TRUNCATED = 9,        ///< hedger_load(): the buffer is shorter than the length it declares.
  HEDGER_ERR_CHECKSUM = 10,        ///< hedger_load(): CRC-32 mismatch (corrupted bytes).
  HEDGER_ERR_CONFIG_MISMATCH = 11, ///< hedger_load(): saved under an incompatible config (see hedger_load()).
  HEDGER_ERR_CHANGED = 12,         ///< hedger_save_step(): the learned state changed since hedger_save_begin().
} hedger_status_t;

/// How a value was obtained.
typedef enum hedger_kind {
  HEDGER_KIND_UNKNOWN = 0, ///< fewer than k_min usable neighbours: value = cfg.default_value
  HEDGER_KIND_LWA = 1,     ///< locally weighted average (outside hull, implausible or singular LWR)
  HEDGER_KIND_LWR = 2,     ///< locally weighted ridge regression, inside the hull and within bounds
} hedger_kind_t;

/// Why LWR fell back to LWA (HEDGER_FALLBACK_NONE for LWR and for unknown).
typedef enum hedger_fallback {
  HEDGER_FALLBACK_NONE = 0,        ///< LWR, unknown, or LWA by configuration (HEDGER_LOCAL_LWA)
  HEDGER_FALLBACK_HULL = 1,        ///< query outside the independent-variable hull
  HEDGER_FALLBACK_IMPLAUSIBLE = 2, ///< LWR value outside [Q_min, Q_max]
  /// The local regression is singular: the usable neighbours do not span every input dimension
  /// (fewer than D+1 of them, or λmin <= 1e-12 λmax for the eigenvalues of their centred scatter
  /// matrix Σ (x_i − m)(x_i − m)^T in scaled units, i.e. a spread ratio of 1e-6 between the
  /// thinnest and the widest direction; e.g. all on one hyperplane, or all with the same action),
  /// or a factorisation of the normal equations failed. Rank-deficient neighbourhoods always
  /// land here, whatever the ridge.
  HEDGER_FALLBACK_SINGULAR = 3,
} hedger_fallback_t;

/// Weighting of the design matrix of the IVH test (hedger.md step 4 "(choice)").
typedef enum hedger_ivh_mode {
  /// Rows [x_i, 1]: Cook's hull of the neighbourhood points (every usable neighbour counts equally).
  HEDGER_IVH_UNWEIGHTED = 0,
  /// Rows sqrt(w_i)[x_i, 1]: the ellipsoid of the points the regression weights; a query is
  /// compared with the largest weighted leverage h_ii = w_i x_i^T (X^T W X)^-1 x_i (stricter).
  HEDGER_IVH_WEIGHTED = 1,
} hedger_ivh_mode_t;

/// Greedy method (hedger_config_t::greedy_method): how hedger_greedy() and the update's max over
/// actions judge candidate actions.
typedef enum hedger_greedy_method {
  /// Every candidate action is a full prediction (hedger_predict) with its own neighbourhood;
  /// regressions rank above averages, averages above unknown, then by value − κ · std_error.
  HEDGER_GREEDY_PER_ACTION = 0,
  /// One local model at the state: the k_max points nearest to the state (action ignored), a
  /// regression linear in the state and quadratic in the action; candidates inside its hull and
  /// within [Q_min, Q_max] are ranked by value − κ · standard error. Falls back to PER_ACTION
  /// where the model cannot be formed (see hedger_counters_t::greedy_state_model).
  HEDGER_GREEDY_STATE_MODEL = 1,
} hedger_greedy_method_t;

/// Local model of a prediction (hedger_config_t::local_model).
typedef enum hedger_local_model {
  /// LWR guarded by the hull and plausibility tests, falling back to LWA (hedger.md steps 4–7).
  HEDGER_LOCAL_LWR = 0,
  /// Every known prediction is the locally weighted average Σ w_i q_i / Σ w_i (kind LWA,
  /// fallback NONE): the averager alone (Gordon), the learner ablation's "LWA only". The greedy
  /// search is then per action whatever greedy_method says (the state model is a regression).
  HEDGER_LOCAL_LWA = 1,
} hedger_local_model_t;

/// What the store did with the new point of an update / insert.
typedef enum hedger_store_op {
  HEDGER_STORE_NONE = 0,     ///< nothing stored (error, or the call stores nothing)
  HEDGER_STORE_INSERTED = 1, ///< into a free slot
  HEDGER_STORE_MERGED = 2,   ///< folded into its nearest neighbour (closer than merge_radius, or the
                             ///< most redundant point when the store is full)
  HEDGER_STORE_REPLACED = 3, ///< the store was full: the most redundant candidate was evicted
} hedger_store_op_t;

/// Flags of a stored point (hedger_point_t::flags, hedger_insert()).
#define HEDGER_POINT_PROTECTED 0x01U ///< carries a non-zero reward or a terminal transition: evicted last

/// Configuration. Start from hedger_config_default() and change what you need. Fixed at init.
/// Units: "scaled" = raw / input_scale (see the file comment).
typedef struct hedger_config {
  uint32_t state_dim;    ///< state dimension, 1..HEDGER_MAX_STATE_DIM. Default 3.
  double action_min;     ///< action lower bound (caller units, e.g. rad/s), finite. Default -1.
  double action_max;     ///< action upper bound, finite, > action_min. Default 1.
  uint32_t capacity;     ///< stored points, 1..HEDGER_MAX_CAPACITY; memory is linear in it. Default 8192.
  uint32_t k_min;        ///< fewer usable neighbours than this → unknown; 1..k_max. Default 3.
  uint32_t k_max;        ///< neighbourhood ceiling, 1..HEDGER_MAX_K. Default 16.
  double bandwidth;      ///< Gaussian kernel width h (scaled units), w = exp(-d^2/h^2), > 0; the
                         ///< resolution of the value function (see "Choices"). Default 0.2.
  double weight_epsilon; ///< neighbours with kernel weight below this are not used, (0, 1). With the
                         ///< fixed h this is a radius h*sqrt(ln(1/eps)). Default 0.01 (2.15 h).
  double ridge;          ///< ridge λ added to the slope terms (not the intercept) of X^T W X, >= 0,
                         ///< in units of kernel weight × scaled distance^2. Default 1e-3.
  double alpha;          ///< learning rate α, (0, 1]. Default 0.2.
  double gamma;          ///< discount γ, [0, 1). Default 0.99.
  double input_scale[HEDGER_MAX_INPUT_DIM]; ///< raw→scaled divisor per dimension, finite > 0;
                         ///< [0..state_dim-1] state, [state_dim] action; the rest ignored. Default 1.
  double default_value;  ///< value of unknown queries, finite. Default 0.
  uint64_t seed;         ///< seed of the eviction-candidate generator (any value). Default 1.
  uint32_t greedy_coarse_actions; ///< M evenly spaced actions scanned by greedy, 2..HEDGER_MAX_COARSE_ACTIONS. Default 9.
  uint32_t greedy_refine_iters;   ///< golden-section evaluations around the best coarse action,
                                  ///< 0..HEDGER_MAX_REFINE_ITERS. Default 6.
  uint32_t ivh_mode;              ///< IVH design-matrix weighting, a hedger_ivh_mode_t value (stored as
                                  ///< uint32_t so that any value a C caller writes is checkable).
                                  ///< Default HEDGER_IVH_UNWEIGHTED.
  double merge_radius;   ///< a new point closer than this (scaled) to its nearest stored point is
                         ///< merged into it instead of stored, >= 0. Default 0.02.
  uint32_t evict_candidates; ///< candidates examined per eviction, 1..HEDGER_MAX_EVICT_CANDIDATES. Default 8.
  uint32_t fresh_capacity;   ///< fresh-point buffer (points not yet in the kd-tree, scanned linearly),
                             ///< 8..HEDGER_MAX_FRESH. A rebuild of the tree starts when about twice
                             ///< the square root of its work units wait there (350 at 1k stored
                             ///< points, 2,000 at 20k: rebuilding less often as it costs more,
                             ///< against the longer scan of every query), kept within
                             ///< [fresh_capacity/16, fresh_capacity/2]. Queries skip blocks of 32
                             ///< fresh points whose bounding box lies beyond their bound. Larger =
                             ///< rarer rebuilds and smaller rebuild slices, longer scans. Measured
                             ///< (callgrind, b21r-train on a corridor session, 9k points at its
                             ///< end): 512 with rebuilds at 128 points spent 566 M instructions
                             ///< rebuilding, 4096 with the trigger 85 M. Default 4096.
  uint32_t rebuild_work_per_update; ///< kd-tree rebuild work units per update (1 unit ≈ one point
                             ///< visited in one pass, about 50 instructions); 0 = automatic (a
                             ///< rebuild of a full store finishes within fresh_capacity/2 updates,
                             ///< before the fresh buffer can fill). Default 0.
  uint32_t run_capacity; ///< run buffer length (experiences) for backward replay, 0..HEDGER_MAX_RUN.
                         ///< 0 disables the buffer. Default 0.
  uint32_t replay;       ///< 1: hedger_end_run() replays the recorded run backwards (newest first)
                         ///< through the training update; 0: it only clears the buffer. Default 0.
  uint32_t replay_passes;///< backward passes over the run per replay, 1..HEDGER_MAX_REPLAY_PASSES.
                         ///< Default 1.
  double replay_lambda;  ///< target of the replay, [0, 1]: the λ-return
                         ///< T_t = r_t + γ ((1 − λ) max_a Q(s_{t+1}, a) + λ T_{t+1}); 0 = the
                         ///< Q-learning target, 1 = the return of the run as driven. Default 0.
  double replay_alpha;   ///< learning rate of the replay's updates, [0, 1]; 0 = alpha. Fewer passes
                         ///< with a larger step move a value about as far as many small ones
                         ///< (N passes of α_r ≈ M of α when 1 − α_r = (1 − α)^(M/N)) for N/M of the
                         ///< replay's updates. Default 0.
  uint32_t replay_cache; ///< 1: the replay keeps, per record of the run, the geometry of its two
                         ///< local models (the neighbours found, the factorised normal equations,
                         ///< the hull tests) and, while no stored point has moved, repeats only
                         ///< what depends on the values (see hedger_end_run()); the results are
                         ///< bit-identical to 0, which recomputes everything. Memory: run_capacity ×
                         ///< hedger_replay_record_bytes(). Ignored without replay. Default 1.
  uint32_t greedy_method;///< a hedger_greedy_method_t value. Default HEDGER_GREEDY_PER_ACTION.
  double greedy_pessimism; ///< κ >= 0: the greedy search ranks known actions by value − κ ·
                         ///< standard error of the regression. Default 0.
  double greedy_reach;   ///< HEDGER_GREEDY_STATE_MODEL, >= 1: where the state has too few
                         ///< neighbours within the kernel's radius, the model is formed once more
                         ///< with bandwidth and radius × greedy_reach (its value is then the
                         ///< neighbours' average, kind LWA); 1 = no second attempt. Default 1.
  uint32_t local_model;  ///< a hedger_local_model_t value. Not part of a save (values stay valid
                         ///< under either model). Default HEDGER_LOCAL_LWR.
  double anchor_recency_runs; ///< HEDGER_GREEDY_STATE_MODEL, >= 0 [run tags]: in the
                         ///< neighbours' policy (the anchor) a point stored `age` run tags before
                         ///< the current one (hedger_set_run_tag) has its weight multiplied by
                         ///< e^(−age / anchor_recency_runs), so older runs fade from the
                         ///< imitation (not from the value fits); 0 = no fading. Default 0.
} hedger_config_t;

/// One prediction.
typedef struct hedger_prediction {
  double value;              ///< Q estimate (reward units); cfg.default_value when unknown
  hedger_kind_t kind;        ///< how it was obtained
  hedger_fallback_t fallback;///< why LWR was not used (LWA only)
  uint32_t n_neighbours;     ///< usable neighbours (weight >= weight_epsilon, at most k_max)
  double std_error;          ///< LWR: standard error of the value (weighted residual variance
                             ///< propagated through the fit); 0 for LWA and unknown
} hedger_prediction_t;

/// What hedger_update() did.
typedef struct hedger_update_info {
  /// Greedy result at s_next, computed once before learning, for reuse as the next action.
  /// HEDGER_OK: next_action is the best known action; HEDGER_NO_KNOWN_ACTION: all unknown (or
  /// the transition was terminal, then next_kind = UNKNOWN and nothing was searched).
  hedger_status_t next_status;
  double next_action;        ///< greedy action at s_next (action units), in [action_min, action_max]
  double next_value;         ///< Q(s_next, next_action); default_value when unknown
  hedger_kind_t next_kind;   ///< how next_value was obtained
  double q_next;             ///< q' used in the target: 0 if terminal, else next_value
  double q_old;              ///< Q(s, a) before the update
  hedger_kind_t kind;        ///< how q_old was obtained
  double target;             ///< r + γ q'
  double q_new;              ///< q_old + α (target − q_old): the value stored for (s, a)
  uint32_t n_pulled;         ///< neighbours of (s, a) pulled toward q_new
  hedger_store_op_t store_op;///< what the store did with (s, a)
} hedger_update_info_t;

/// Monotonic counters (never decrease, never reset, not restored by hedger_load()), plus gauges
/// marked "gauge".
typedef struct hedger_counters_s {
  uint64_t predictions_lwr;     ///< predictions answered by LWR (including those inside greedy/update)
  uint64_t predictions_lwa;     ///< ... by LWA
  uint64_t predictions_unknown; ///< ... unknown
  uint64_t fallback_hull;       ///< LWA because outside the IVH
  uint64_t fallback_implausible;///< LWA because the LWR value was outside [Q_min, Q_max]
  uint64_t fallback_singular;   ///< LWA because the normal equations were singular
  uint64_t greedy_calls;        ///< greedy searches (hedger_greedy and inside hedger_update)
  uint64_t greedy_all_unknown;  ///< ... that found no known action
  uint64_t greedy_state_model;  ///< ... answered by the state model (HEDGER_GREEDY_STATE_MODEL)
  uint64_t greedy_reached;      ///< ... of which with the widened kernel (greedy_reach)
  /// state-model searches whose neighbours all weighed (nearly) 0 in the anchor (hedger_weight_run,
  /// anchor_recency_runs), so that the anchor used the plain kernel weights
  uint64_t anchor_unweighted;
  uint64_t updates;             ///< successful training updates (including replayed ones)
  uint64_t replayed_updates;    ///< updates performed by backward replay
  /// searches (greedy and prediction) of replayed updates that took their geometry from the
  /// replay's record (cfg.replay_cache): neither the neighbours nor the factorisations recomputed
  uint64_t replay_reused;
  uint64_t run_overflows;       ///< experiences dropped from a full run buffer (the oldest go first)
  uint64_t inserts;             ///< points stored into a free slot
  uint64_t merges;              ///< points folded into a close neighbour
  uint64_t evictions;           ///< points evicted from a full store
  uint64_t protected_evictions; ///< ... of which were protected (only if every candidate was)
  uint64_t rebuilds;            ///< kd-tree rebuilds completed (swapped in)
  uint64_t forced_rebuild_work; ///< work units done outside the per-update budget (fresh buffer full)
  uint64_t rejected_non_finite; ///< calls refused because an input was NaN or infinite
  uint64_t loads;               ///< successful hedger_load() calls
  uint32_t max_rebuild_work;    ///< largest rebuild work done within one call (units)
  uint32_t store_fill;          ///< gauge: stored points (<= capacity)
  uint32_t store_protected;     ///< gauge: stored points with HEDGER_POINT_PROTECTED
  uint32_t fresh_fill;          ///< gauge: entries in the fresh buffer
  uint32_t run_fill;            ///< gauge: experiences in the run buffer
  double reward_min;            ///< gauge: smallest reward seen (0 before any)
  double reward_max;            ///< gauge: largest reward seen (0 before any)
} hedger_counters_t;

/// One stored point, in raw (unscaled) units (hedger_get_point()).
typedef struct hedger_point {
  double state[HEDGER_MAX_STATE_DIM]; ///< first state_dim entries valid
  double action;
  double value;
  uint32_t flags;                     ///< HEDGER_POINT_* bits
  uint32_t run_tag;                   ///< the run tag current when the point was stored
  double anchor_weight;               ///< its weight in the neighbours' policy (hedger_weight_run)
} hedger_point_t;

/// Opaque instance. Internals are C++/Eigen.
typedef struct hedger hedger_t;

/// The default configuration (values documented per field). O(1).
hedger_config_t hedger_config_default(void) HEDGER_NOEXCEPT;

/// Checks every field of cfg. Returns HEDGER_OK or HEDGER_ERR_INVALID_ARG. O(state_dim).
hedger_status_t hedger_config_validate(const hedger_config_t* cfg) HEDGER_NOEXCEPT;

/// Bytes of storage hedger_init() needs for cfg (aligned to HEDGER_STORAGE_ALIGN), or 0 if cfg is
/// invalid. Linear in capacity, fresh_capacity and run_capacity. O(log capacity), no allocation.
size_t hedger_storage_size(const hedger_config_t* cfg) HEDGER_NOEXCEPT;

/// Placement-initialises an instance into storage (caller-owned; must outlive the instance and be
/// aligned to HEDGER_STORAGE_ALIGN). *out receives the handle (it points into storage). The store
/// starts empty, rewards seen = none. O(capacity) (clears the store), no allocation.
/// Errors: INVALID_ARG (NULL or invalid cfg), ALIGNMENT, CAPACITY (storage_size too small).
hedger_status_t hedger_init(hedger_t** out, void* storage, size_t storage_size, const hedger_config_t* cfg) HEDGER_NOEXCEPT;

/// Convenience: allocates hedger_storage_size(cfg) bytes once (aligned) and initialises them.
/// Release with hedger_destroy(). Errors: as hedger_init(), plus NO_MEMORY.
hedger_status_t hedger_create(hedger_t** out, const hedger_config_t* cfg) HEDGER_NOEXCEPT;

/// Frees an instance made by hedger_create() (NULL is a no-op). Never call it on an instance made
/// by hedger_init(): that storage belongs to the caller, who just stops using it.
void hedger_destroy(hedger_t* self) HEDGER_NOEXCEPT;

/// The config the instance was initialised with (never NULL for a valid self).
const hedger_config_t* hedger_get_config(const hedger_t* self) HEDGER_NOEXCEPT;

/// Q(state, action). state: state_dim raw values; action: raw. *out receives value, kind,
/// fallback and neighbour count. Cost O(log n + k_max·D + fresh·D + k_max·D^2 + D^3) with
/// n = stored points, D = state_dim + 1; no allocation. Counts the prediction.
/// Errors: INVALID_ARG (NULL), NON_FINITE (then *out is untouched).
hedger_status_t hedger_predict(hedger_t* self, const double* state, double action, hedger_prediction_t* out) HEDGER_NOEXCEPT;

/// As hedger_predict(), and also writes the usable neighbours, nearest first (ties: lower slot),
/// into caller buffers of capacity cap: slots[] (store slot, 0..fill-1, see hedger_get_point()) and
/// weights[] (kernel weights in (0, 1]). Either buffer may be NULL. If cap < out->n_neighbours
/// only the first cap are written. Same cost as hedger_predict().
hedger_status_t hedger_predict_ex(hedger_t* self, const double* state, double action, hedger_prediction_t* out,
                                  uint32_t* slots, double* weights, uint32_t cap) HEDGER_NOEXCEPT;

/// Greedy action at state: scans greedy_coarse_actions evenly spaced actions over
/// [action_min, action_max] (both ends included), then golden-section refines around the best
/// known one within its neighbouring grid interval (greedy_refine_iters evaluations). Unknown
/// values never beat known ones; ties go to the smaller action (earlier evaluation).
/// Returns HEDGER_OK with the best action/value/kind, or HEDGER_NO_KNOWN_ACTION (action =
/// midpoint, value = default_value, kind = UNKNOWN). Any output pointer may be NULL except none
/// are required. Cost: (M + R) predictions, no allocation. Errors: INVALID_ARG, NON_FINITE.
hedger_status_t hedger_greedy(hedger_t* self, const double* state, double* action, double* value,
                              hedger_kind_t* kind) HEDGER_NOEXCEPT;

/// A given action judged against the greedy action by the same state model (a policy other than
/// the greedy one, e.g. an actor, guarded by the values): the greedy search of hedger_greedy()
/// (outputs, status and counters identical), and where its answer came from a state model
/// (cfg.greedy_method HEDGER_GREEDY_STATE_MODEL, at either reach), judged = 1 with
/// - action_lo, action_hi: the actions the data hold at the state (raw; the neighbours' policy
///   at the state plus the range of their residuals, the range the greedy search keeps to);
/// - kept_action: the given action clamped into [action_lo, action_hi];
/// - gap, gap_se: Q(greedy action) − Q(kept_action) by that model (reward units; >= 0 up to
///   the pessimism's choice, since the greedy ranks by value − κ·SE) and its standard error (of
///   the difference: the state part cancels).
/// Where no state model answers (too few neighbours, per-action search, or no known action),
/// judged = 0, kept_action = action, gap = gap_se = 0. Cost: as hedger_greedy() plus O(1).
/// Errors: INVALID_ARG (NULL), NON_FINITE (state or action).
typedef struct hedger_judgement {
  double greedy_action;     ///< as hedger_greedy()'s action
  double greedy_value;      ///< as hedger_greedy()'s value
  hedger_kind_t greedy_kind;///< as hedger_greedy()'s kind
  int judged;               ///< 1: the fields below come from the state model; 0: not judged
  double action_lo;         ///< smallest action the data hold at the state (raw)
  double action_hi;         ///< largest action the data hold at the state (raw)
  double kept_action;       ///< the given action clamped into [action_lo, action_hi] (raw)
  double gap;               ///< Q(greedy action) − Q(kept_action) (reward units)
  double gap_se;            ///< standard error of gap, >= 0
} hedger_judgement_t;

hedger_status_t hedger_judge(hedger_t* self, const double* state, double action, hedger_judgement_t* out) HEDGER_NOEXCEPT;

/// One training update with experience (s, a, r, s_next, terminal) (hedger.md steps 1–6):
/// 1. q' = 0 if terminal, else greedy value at s_next (default_value if all unknown);
/// 2. q = Q(s, a) with neighbourhood K and kernel weights κ;
/// 3. q_new = q + α (r + γ q' − q);
/// 4. store (s, a) with q_new (merge / insert / evict, see the source for the rule);
/// 5. pull each neighbour in K: q_i ← q_i + α κ_i (q_new − q_i);
/// 6. r_min, r_max ← min/max with r (they bound plausible values: Q_min = min(r_min,0)/(1−γ),
///    Q_max = max(r_max,0)/(1−γ)).
/// Points of transitions with r != 0 or terminal are protected from eviction. With a run buffer,
/// the experience is also recorded for hedger_end_run(). info (may be NULL) receives the greedy
/// result at s_next for reuse as the next action, and what was stored.
/// s_next is ignored (may be NULL) when terminal != 0. Cost: greedy (M + R predictions) + one
/// prediction + eviction (evict_candidates nearest-neighbour queries when full) + at most
/// rebuild_work_per_update rebuild units; no allocation. Errors: INVALID_ARG, NON_FINITE (nothing
/// changed).
hedger_status_t hedger_update(hedger_t* self, const double* state, double action, double reward,
                              const double* state_next, int terminal, hedger_update_info_t* info) HEDGER_NOEXCEPT;

/// The training update split in two, so that a controller can send its command between them:
/// hedger_greedy() at s_next (the next action and q'), then hedger_learn() with that q'. The pair
/// gives bit-identical results to hedger_update() (which is greedy at s_next, then the same
/// steps 2–6), provided nothing else changes the instance in between. q_next is ignored when
/// terminal != 0 (q' = 0); otherwise pass the greedy value (cfg.default_value when it found no
/// known action). info (may be NULL) receives steps 2–6 (next_* fields: q_next as given, status
/// HEDGER_OK). Cost: one prediction, the store step and the pull; no allocation.
/// Errors: INVALID_ARG, NON_FINITE (nothing changed).
hedger_status_t hedger_learn(hedger_t* self, const double* state, double action, double reward, const double* state_next,
                             int terminal, double q_next, hedger_update_info_t* info) HEDGER_NOEXCEPT;

/// Ends the current run. With cfg.replay = 1, replays the recorded experiences through the
/// training update, cfg.replay_passes backward passes (newest first) with the λ-return target of
/// cfg.replay_lambda (propagates a sparse final reward back along the whole run at once); then
/// clears the run buffer. *replayed (may be NULL) receives the number of replayed updates.
/// Cost: replay_passes × run_fill updates, no allocation: between runs, never inside a tick (use
/// hedger_end_run_begin / hedger_end_run_step to spread it over ticks). With cfg.replay_cache
/// (the default) each record keeps the geometry of its two searches (the neighbours, the
/// factorised normal equations, the hull tests): the first pass forms it, and the later passes,
/// while no stored point has moved (no insertion or eviction, run tag or anchor weight changed
/// meanwhile), repeat only the parts that depend on the values, with bit-identical results
/// (b21r-train on a corridor session with 20 passes: 5.6 times fewer instructions per learned
/// experience).
hedger_status_t hedger_end_run(hedger_t* self, uint32_t* replayed) HEDGER_NOEXCEPT;

/// Sliced hedger_end_run(): begin freezes the recorded run and returns (in *pending, may be
/// NULL) the updates its replay takes (0 without replay: the run buffer is simply cleared); each
/// hedger_end_run_step() call performs updates worth at most max_updates full updates (at least
/// one when max_updates >= 1) and returns how many updates remain in *remaining (may be NULL).
/// An update whose searches reuse their record's geometry (cfg.replay_cache) counts an eighth of
/// one that forms it (measured: about a fifteenth of its instructions), and three eighths in a
/// full store, where its store step evicts (measured: about a quarter), or while the kd-tree is
/// being rebuilt or due to be (each update advances the rebuild whether or not it reuses), so a
/// step never costs
/// more than max_updates updates without the cache, and the passes after the first go about
/// eight times faster (in a full store, where every eviction moves a point, most updates form
/// their geometry again). The results are bit-identical to hedger_end_run(), however the work is
/// sliced. Until the replay is finished the run buffer records nothing new; a hedger_update()
/// meanwhile first finishes the replay (unbounded), so state is never torn.
/// Cost of a step: at most max_updates full updates. O(1) for begin.
hedger_status_t hedger_end_run_begin(hedger_t* self, uint32_t* pending) HEDGER_NOEXCEPT;
hedger_status_t hedger_end_run_step(hedger_t* self, uint32_t max_updates, uint32_t* remaining) HEDGER_NOEXCEPT;

/// Run tags and anchor weights: ranking whole runs. Every stored point carries the run tag that
/// was current when it was stored (merges keep the tag of the point merged into) and an anchor
/// weight, 1 when stored. The weight multiplies the point's kernel weight in the neighbours'
/// policy of HEDGER_GREEDY_STATE_MODEL (the anchor of the greedy search, a locally linear
/// imitation of the stored actions, and the action range tilted with it). Weights are relative
/// within a neighbourhood; where every neighbour weighs (nearly) 0 the kernel weights are used.
/// The value model is fitted without them, but the value of the action the greedy search picks
/// enters the learning targets, so the values follow the steered policy. A caller that can rank
/// its runs (two runs from one start, say, by their measured returns) weights the better run's
/// points up and the worse run's down, and the imitation moves toward the better run. Both are
/// saved (format version 2).
///
/// hedger_set_run_tag: points stored from now on carry `tag`, and `tag` is the current run for
/// cfg.anchor_recency_runs. Tags must not decrease (INVALID_ARG). O(1).
hedger_status_t hedger_set_run_tag(hedger_t* self, uint32_t tag) HEDGER_NOEXCEPT;

/// The current run tag (0 for an invalid instance): after a load, the tag the saved instance had.
/// O(1).
uint32_t hedger_run_tag(const hedger_t* self) HEDGER_NOEXCEPT;

/// Sets the anchor weight of every stored point tagged `tag` to `weight` (finite, [0, 16]);
/// *points (may be NULL) receives how many. Counts as a change of the learned state (a sliced
/// save under way must start again). O(fill): between runs, never before a tick's command.
/// Errors: INVALID_ARG.
hedger_status_t hedger_weight_run(hedger_t* self, uint32_t tag, double weight, uint32_t* points) HEDGER_NOEXCEPT;

/// Stores a point directly with value q (seeding, tests, offline tools), through the same
/// merge/evict rule as an update; no neighbour is pulled. flags: HEDGER_POINT_* bits. op (may be
/// NULL) receives what the store did. O(evict_candidates · log n), no allocation.
/// Errors: INVALID_ARG, NON_FINITE.
hedger_status_t hedger_insert(hedger_t* self, const double* state, double action, double q, uint32_t flags,
                              hedger_store_op_t* op) HEDGER_NOEXCEPT;

/// Records r as a reward seen (step 6 of the update alone): widens [r_min, r_max] and thus the
/// plausible value range. For seeding with hedger_insert() and for tests. O(1).
/// Errors: INVALID_ARG, NON_FINITE.
hedger_status_t hedger_observe_reward(hedger_t* self, double reward) HEDGER_NOEXCEPT;

/// Stored points (<= capacity). Slots 0..fill-1 are all occupied. O(1).
uint32_t hedger_size(const hedger_t* self) HEDGER_NOEXCEPT;

/// Reads stored point `slot` (0..hedger_size()-1) in raw units (scaled × input_scale, so within
/// rounding of what was given). Errors: INVALID_ARG. O(D).
hedger_status_t hedger_get_point(const hedger_t* self, uint32_t slot, hedger_point_t* out) HEDGER_NOEXCEPT;

/// Counters (monotonic) and gauges; the pointer stays valid for the instance's life. O(1).
const hedger_counters_t* hedger_counters(const hedger_t* self) HEDGER_NOEXCEPT;

/// Exact bytes hedger_save() writes for the current state. O(1).
size_t hedger_serialized_size(const hedger_t* self) HEDGER_NOEXCEPT;

/// Largest hedger_serialized_size() any instance with cfg can reach (a full store), or 0 if cfg
/// is invalid: size a save buffer once with it. O(1).
size_t hedger_serialized_max_size(const hedger_config_t* cfg) HEDGER_NOEXCEPT;

/// Writes the learned state (config, stored points with values, flags, run tags and anchor weights,
/// the current run tag, rewards seen, the eviction generator's state) into buf: little-endian,
/// versioned (HEDGER_FORMAT_VERSION), CRC-32 (IEEE 802.3) over all preceding bytes at the end.
/// *written (may be NULL) receives the byte count. The run buffer and counters are not saved.
/// O(n·D), no allocation, no file I/O (write the bytes atomically yourself: write, fsync, rename).
/// Errors: INVALID_ARG, CAPACITY (size < hedger_serialized_size(); nothing written).
hedger_status_t hedger_save(const hedger_t* self, void* buf, size_t size, size_t* written) HEDGER_NOEXCEPT;

/// Position of a sliced save (hedger_save_begin / hedger_save_step). Caller-owned plain data.
typedef struct hedger_save_cursor {
  uint8_t* buf;          ///< the caller's buffer
  size_t size;           ///< bytes the complete save takes
  size_t offset;         ///< bytes written so far
  uint32_t next_point;   ///< next stored point to write
  uint32_t crc;          ///< CRC-32 register over the bytes written
  uint64_t generation;   ///< the instance's state the save belongs to
  int done;              ///< 1 once the CRC is written
} hedger_save_cursor_t;

/// hedger_save() in slices, so that serialising a large store never costs one tick more than a
/// bounded amount: begin writes the header (O(D)) and checks the capacity (CAPACITY as
/// hedger_save()); every step writes at most max_points stored points (O(max_points · D)) and,
/// after the last one, the CRC, then sets cursor->done and *written (may be NULL; 0 until done)
/// to the byte count. The bytes are identical to hedger_save()'s. The instance must not change
/// in between: a step after any update, learn, replay, insert, load or observe_reward returns
/// HEDGER_ERR_CHANGED and the save must start again.
hedger_status_t hedger_save_begin(const hedger_t* self, void* buf, size_t size, hedger_save_cursor_t* cursor)
    HEDGER_NOEXCEPT;
hedger_status_t hedger_save_step(const hedger_t* self, hedger_save_cursor_t* cursor, uint32_t max_points,
                                 size_t* written) HEDGER_NOEXCEPT;

/// Replaces the learned state with the one in buf (from hedger_save(), format version 2 or 1).
/// Checks, in order: magic (FORMAT), version (VERSION), declared length vs size (TRUNCATED), CRC-32
/// (CHECKSUM), config compatibility (CONFIG_MISMATCH: state_dim, action bounds, input scales, gamma
/// must be equal bit for bit, and the saved points must fit cfg.capacity), then contents (FORMAT:
/// non-finite or out-of-range fields). Any failure leaves the instance unchanged. On success the
/// run buffer is cleared and the kd-tree rebuilt at once: O(n log n), no allocation; not for inside
/// a tick. Bytes after the declared length are ignored.
hedger_status_t hedger_load(hedger_t* self, const void* buf, size_t size) HEDGER_NOEXCEPT;

/// What a saved learned state was written for (hedger_saved_config()): the fields hedger_load()
/// checks against the instance's config. Plain data.
typedef struct hedger_saved {
  uint32_t state_dim;  ///< state dimension
  uint32_t count;      ///< stored points (cfg.capacity must be at least this)
  double action_min;   ///< action bounds, as in hedger_config_t
  double action_max;
  double gamma;        ///< discount per learned transition
  /// Raw units per scaled unit of each input (the state's dimensions, then the action) as the
  /// points were stored; entries past state_dim + 1 (or past HEDGER_MAX_INPUT_DIM) are 0.
  double input_scale[HEDGER_MAX_INPUT_DIM];
} hedger_saved_t;

/// Reads what buf (from hedger_save()) was written for, so that a caller refused with
/// CONFIG_MISMATCH can say which setting differs. Checks as hedger_load() does up to the CRC-32
/// (FORMAT, VERSION, TRUNCATED, CHECKSUM) and that the input scales are inside (FORMAT), then
/// fills *out. No instance needed; O(size), no allocation.
hedger_status_t hedger_saved_config(const void* buf, size_t size, hedger_saved_t* out) HEDGER_NOEXCEPT;

/// A constant English description of a status ("ok", "invalid argument", ...). Never NULL.
const char* hedger_status_str(hedger_status_t status) HEDGER_NOEXCEPT;

/// A constant name of a kind: "unknown", "lwa", "lwr". Never NULL.
const char* hedger_kind_str(hedger_kind_t kind) HEDGER_NOEXCEPT;

#ifdef __cplusplus
}
#endif

#endif  // HEDGER_HEDGER_H
