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
///   per stored point  (24 D + 37) bytes + about 64 / 16 · 2 bytes of tree nodes
///                     (store: coordinates 8D, value 8, sequence 8, flags 1, fresh index 4;
///                      two kd-trees: coordinates 8D + id 4 each)
///   per fresh entry   8 D + 4 bytes;  per run record (2 state_dim + 3) · 8 bytes;  + ~1 KiB.
/// D = 4 (3-D state + action): 139 bytes per stored point measured at 20k points.
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
/// - Greedy method (cfg.greedy_method): with one prediction per candidate action
///   (HEDGER_GREEDY_PER_ACTION) every candidate has its own neighbourhood, and the bias each of
///   them carries from the states around the query is larger than the effect of one action at
///   10 Hz: on the corridor the greedy policy followed that noise (a gain of 0.15 where the
///   examples use 0.5-2) and got worse with more data. HEDGER_GREEDY_STATE_MODEL fits one model
///   at the state (linear in the state, concave quadratic in the action) and judges every
///   candidate on it, pessimistically (cfg.greedy_pessimism = 4 standard errors of the action's
///   effect, measured from the neighbours' own policy at the state): 0, 1, 2 gave collisions in
///   evaluation, 3 and 4 none, 10 a policy that only repeated its data. Corridor, 6 seeds: the
///   learned policy after the 30 example runs 140.1 +- 0.5 steps, after phase two 140.1 +- 0.5,
///   against 146.2 / 139.7 / 138.5 / 138.4 for the example policy at gains 0.5 / 1 / 1.5 / 2 and
///   137.3 for the hand-tuned optimal controller from the same ten poses.
///   Why the learned policy does not beat its teachers (Fig. 4 schedule; seed 11 traced, seeds
///   11-20 swept): the greedy policy is an imitation of the average example. Least squares of the
///   executed rotation on (target angle θ, lateral offset d): phase-one training data 0.89 θ +
///   0.00 d (gains 0.5-2 with the clamp at 1 rad/s, plus dither); learned policy after phase one
///   0.82 θ + 0.03 d, after phase two 0.32 θ + 0.13 d; the optimal controller 1.54 θ - 1.09 d.
///   Steps are lost at the off-axis starts (pose (1.5, 0, 0.9): first second at |ω| 0.3-0.6 where
///   optimal and the examples command 1.0; 138 steps vs 132 example, 131 optimal) and in centring
///   (the robot settles 0.3 m off the centre line at 0.52 m/s instead of 0.6). One tick's action
///   changes the return by about 0.3 step (estimate: 6 steps over the 20 ticks of that turn;
///   value 0.0075 at γ^T = 0.25), far below the standard
///   error of the local fit, so value − 4 SE stays at the neighbours' policy. Measured on seeds
///   11-20 (baseline: last phase-one block 140.7 ± 0.6, +1.9 ± 0.6 vs the example policy, 11
///   failed phase-two evaluation runs): pessimism 2 → 150.8 (failures, 20 in phase two);
///   phase-one dither and phase-two exploration held 1 s at σ 0.3 (explore_hold_s also holds the
///   phase-one dither) → 169.4, 29 failures; no phase-one dither → 490 (the state model cannot
///   be formed without action spread); an advantage-weighted anchor (neighbours weighted by
///   exp(A / τ σ_A), A = value above a fit on the state alone; branch learn2-advantage, not
///   merged) τ = 1 → final block 141.1 ± 0.7 (+2.3 ± 0.7 vs examples, 0 phase-two failures),
///   τ = 0.3 → 143.1. Nor do (same seeds, last phase-one block minus the example policy; baseline
///   +2.0 ± 0.6): k_max 64 +2.4 ± 0.8, bandwidth 0.35 +10.6 ± 19.4 (failures), pessimism 3
///   +2.9 ± 0.9, and a squared term
///   per state dimension in the state model (so that the value's curvature across the
///   neighbourhood, about γ^(steps) over ±2.5 m of corridor, is not counted as noise in the
///   action's standard error; not merged) +1.9 ± 0.6, with pessimism 2 +12.6 ± 19.0 and 0
///   +52.9 ± 59.4 (collisions). The imitation is not the state model's misfit. None beats the
///   examples. Where the steps are lost (seeds 11-20, last phase-one block minus the example policy
///   at its nominal gain, per evaluation pose, state = end distance, lateral fraction, target
///   angle): +0.3 to +0.7 ± 0.6 steps from each of the five poses with |θ| <= 0.45 rad, +2.0 to
///   +5.1 (± 1.0 to 3.7) from each of the five with |θ| 0.7-0.9: the learned policy equals its
///   teachers near the axis and loses to them only where a run starts far off it. There the data
///   is thin (seed 11: 129 of 4,208 phase-one steps have |θ| > 0.5, 45 of them the first three ticks
///   of a run, while the rotation still ramps up at the acceleration limit, 0.29 rad/s per tick, a
///   rotation the 3-D state does not show), and the greedy turns more gently than the example
///   (pose (9.0, 0.7, 0.7): 0.29, 0.35, 0.47, 0.44, 0.40 rad/s, 0.5-0.65 θ, mostly LWA values).
///   The executed rotation as a last state entry (controller key state_rotation, the default: the
///   last command sent, which the acceleration limit ties the next rotation to; scale 1 rad/s).
///   Chosen on seeds 11-20: Fig. 4 last phase-one block +1.3 ± 0.4 steps vs the example policy (was
///   +2.0), final block 140.4 ± 0.3 and no failed phase-two evaluation run (was 158.0 ± 25.9, 9
///   failed phase-two runs); at scale 0.25 (the action's) +0.8 ± 0.4 after phase one but the
///   human-driven corridor (Fig. 5) lost: final block 274.7 ± 26.1 against 243.5 ± 4.3 (252.3 ± 7.0
///   at scale 1); obstacles 17 failed phase-two runs against 26. Confirmed on seeds 1-10 (the
///   ablations in docs/RESULTS.md, paired with the same seeds): Fig. 4 final block 0.5 ± 0.5 steps
///   shorter (+1.1 ± 0.4 vs the examples, +2.6 ± 0.4 vs optimal), Fig. 5 final block 240.7 ± 6.0
///   against 255.5 ± 24.6 with 2 failed phase-two runs against 9, obstacles 10 failed phase-two
///   runs against 41 at an equal final block. Pessimism 8 on top (seeds 11-20, scale 0.25) helped
///   Fig. 4 (+0.7 / +0.9) and cost Fig. 5 (280.1, 30 failed runs) and the obstacles (174.4 against
///   137.8). The off-axis deficit stays (the poses heading 0.7-0.9 rad off still lose up to 2.3
///   steps each): the first ticks of such a run are seen in only three phase-one runs per pose.
///   A finer target-angle scale keeps those neighbourhoods to runs that started at similar
///   headings (seeds 11-20, final block against the default 0.5 rad, paired): Fig. 4 -0.4 ± 0.2
///   steps at 0.25, -0.8 ± 0.2 at 0.125, -0.6 ± 0.5 at 0.0625 (10 failed phase-two runs: too few
///   neighbours); but Fig. 5 (the noisier human examples) +6.8 ± 18.0 at 0.25 and +13.4 ± 35.3 at
///   0.125 with 11 failed phase-two runs against 5. Confirmed for Fig. 4 on seeds 1-10
///   (ablation_angle_scale: -0.4 ± 0.4, +0.7 ± 0.3 vs the examples); the default stayed 0.5.
///   With a larger neighbourhood the finer angle keeps Fig. 5 (seeds 11-20, final block against
///   k_max 32 and 0.5 rad, paired; failed phase-two runs of 700 in brackets): k_max 64 (the
///   ceiling) and 0.125 rad: Fig. 4 -0.8 ± 0.2 (0), Fig. 5 -4.6 ± 4.2 (2 against 5; after phase
///   one -17.5 ± 6.8); k_max 64 alone: Fig. 4 +0.2 ± 0.4, Fig. 5 -10.7 ± 5.6 (1), obstacles
///   -16.4 ± 13.3 (10 against 17). Both are the defaults now (controller keys hedger_k_max and
///   the corridor's scales in learning.c). Confirmed on seeds 1-10: Fig. 4 -0.6 ± 0.3 (+0.5 ± 0.2
///   vs the examples, +2.0 ± 0.2 vs optimal, 0 failed runs against 1), obstacles -14.8 ± 19.2 (5
///   against 10), Fig. 5 after phase one -18.5 ± 4.6 but final block +6.7 ± 20.5, not significant
///   (one seed failed 2 runs late in phase two; 3 against 2). Cost per tick (firmware.bench, 20k
///   points, tick compute): p50 74 us against 59, max 576 us against 412. The price is early
///   learning: with few runs a state's fine neighbourhood is often empty (Fig. 4, seeds 1-10,
///   after 5 runs 5.2/10 poses against 9.9/10 at 0.5 rad). A wider second attempt for the
///   corridor (greedy_reach 8 instead of 3; the controller's task default) recovers most of it,
///   seeds 11-20, paired against reach 3: Fig. 4 after 5 runs -284.7 ± 87.5 steps, after 10 runs
///   -155.8 ± 56.9, final block 0.0 ± 0.1; Fig. 5 after 5 runs -137.7 ± 68.6, final +9.8 ± 17.1
///   (5 failed phase-two runs against 2). Greedy_reach 5: Fig. 4 365.2 after 5 runs. Obstacles
///   keep 3 (reach 8 there: final +4.2 ± 12.6, 26 failed runs against 10; reach 5: 3 failed).
///   Seeds 1-10 (docs/RESULTS.md): Fig. 4 after 5 runs 262.3 against 553.5, final +0.2 ± 0.2;
///   Fig. 5 final -7.4 ± 17.5 (1 failed run against 3); tick cost unchanged (firmware.bench).
///   With these defaults the Fig. 4 policy is a fixed point that no exploration or search setting
///   moves (seeds 11-20, final block minus the defaults', paired, 0-1 failed phase-two runs each):
///   example dither σ 0.15 / 0.5 rad/s -0.2 ± 0.2 / -0.1 ± 0.3; pessimism 3 / 6 +0.2 ± 0.2 /
///   -0.2 ± 0.2; exploration σ 0.3 -0.1 ± 0.2; exploration probability 0.5 +0.1 ± 0.2; replay
///   lambda 1 -0.1 ± 0.2; 17 coarse greedy actions 0.0 ± 0.1; 100 phase-two runs instead of 35
///   -0.1 ± 0.2 (the last phase-one block and the final block agree within 0.2 step in every one).
///   Phase two re-learns its own actions: one tick's effect on the return stays below the fit's
///   error, so value - 4 SE keeps the action the neighbours took. Holding each greedy decision for
///   3 ticks (learning still per tick; not merged) made it worse: after phase one +0.5 ± 0.3 steps
///   (the coarser evaluation policy), final +1.2 ± 0.4, and with the exploration offset held as
///   long +10.1 ± 19.5 (1 failed run). Learned as one transition as well (every driver decides
///   every N ticks, the learner sees (s, a, discounted reward sum, s after N ticks) with gamma^N;
///   not merged): final -0.4 ± 0.2 steps against the defaults at N = 3 and N = 5, still +0.4 vs
///   the per-tick example policy and +1.9 vs optimal, and again no change from the last phase-one
///   block to the final one. Exploration of whole-run policy parameters in phase two instead (each
///   training run adds g θ + c (lateral fraction - 0.5) to the greedy action, g and c drawn once
///   per run; not merged): σ_g = σ_c = 0.5 final +51.6 ± 42.9 (24 failed phase-two runs),
///   σ_g = 0.25 +34.6 ± 43.3 (12), σ_c = 1 +52.2 ± 51.5 (29): the greedy policy takes up the
///   perturbed runs' actions as its neighbours' policy.
///   Noise or bias? (seeds 11-20, paired with the defaults; scratch builds, not merged.) The stored
///   values are noisy: at the off-axis start states (seed 11, end of phase two) the state model's
///   weighted residual standard deviation is 0.2-0.7 in value (values about 2.5, one step about
///   0.025, so 8-28 steps), and neighbours from one run share an offset of up to 0.4. Yet the
///   imitation is not a noise floor. Standard errors that treat each run as one observation (a
///   sandwich summed per run) changed nothing: final block +0.0 ± 0.2 / +0.1 ± 0.3 / +1.0 ± 0.7
///   steps at pessimism 4 / 2 / 1. Three times the example data (90 phase-one runs) +0.1 ± 0.3
///   after phase one (also with lambda 1), and 128 / 256 neighbours for the state model (final)
///   +0.0 ± 0.1 / +0.1 ± 0.1. With that data and 256 neighbours, lowering the pessimism to 1 / 0
///   gave 9 / 18 failed evaluation runs after phase one (lambda 1: 14 / 27): at the off-axis starts
///   the wide second attempt (greedy_reach) fits a negative action slope (across its neighbourhood
///   the large turns happen in the worse states), so the greedy turned away from the target and the
///   target angle grew from 0.85 to 1.5 rad. Taking the neighbours' policy (the anchor) in the wide
///   attempt instead removed every failure (0 at pessimism 0; at the default 4 it changes nothing,
///   0.0 ± 0.2), but the value-ranked choice of the first attempt still lost to the imitation after
///   phase one, from every one of the ten poses: pessimism 1 +1.2 ± 0.3, 0 +2.4 ± 1.0, 0 with the
///   run's return as the target (lambda 1) +3.5 ± 1.2, lambda 0 +2.2 ± 0.9, without the executed
///   rotation in the state +3.4 ± 1.0. Limiting each choice to ±0.1 rad/s around the anchor at
///   pessimism 0 (with the default data): after phase one +0.3 ± 0.4, final +0.8 ± 0.4, worse run
///   by run in phase two (±0.05: -0.3 ± 0.2 / -0.1 ± 0.2). The more the greedy trusts the fitted
///   action effect, the worse the policy, with three times the data as well: the action effect is
///   misjudged, not merely uncertain, and the pessimism is what keeps the policy at its teachers'
///   level. Dropping the executed rotation from the anchor's regression in the wide attempt: final
///   +0.3 ± 0.2. A controlled test makes the misjudgement plain: phase-one gains drawn from
///   {0.5, 2} only (two teachers, 146.1 and 138.4 steps from the ten poses), 90 runs. The default
///   greedy lands between them after phase one (141.9 ± 0.9: -4.2 ± 0.9 against the worse teacher,
///   +3.5 ± 0.9 against the better); ranked by value alone (pessimism 0, 256 neighbours, the anchor
///   in the wide attempt) it is worse than the worse teacher, 150.2 ± 2.2 (+4.0 ± 2.1), also with
///   the run's return as the target (lambda 1: 149.1 ± 2.3) and without the executed rotation in
///   the state (151.5 ± 2.4); the per-action search failed 45 of 100 runs. Nor are the pulls and
///   merges the cause (without both: 157.0 ± 19.1 after phase one, 1 failed run). Near the data the
///   fitted direction is right on average: a step of at most 0.03 rad/s from the anchor, ranked by
///   value alone, beat the default greedy in the same test (140.8 ± 0.5, -1.1 ± 0.9) and, by
///   little, with the default data (after phase one -0.3 ± 0.2, final -0.2 ± 0.1; with 100
///   phase-two runs final -0.2 ± 0.2, phase two flat), while 0.1 rad/s lost (+2.3 ± 0.7). What
///   loses is the size of the step: a choice far from the neighbours' policy leads into states the
///   data does not cover, where the model's action effect no longer holds, and a step small enough
///   to stay inside gains a fraction of a step per run at best. Lead: a greedy whose step is
///   bounded by the data's coverage of the states it leads to, checked against the one-tick effects
///   measured by rollouts in the lockstep emulator.
///   Planning on the values instead of the action slope does not help either (seeds 11-20, final
///   block against the defaults, paired; scratch build, not merged). With the robot's known
///   kinematics (the odometry model with both acceleration limits and the task's speed rule; one
///   tick predicted within about 0.01 rad of the measured target angle) each of 21 rotations, held
///   for H ticks, was rolled forward from the state and ranked by γ^H times the greedy value at the
///   predicted state: H = 5 / 8 / 12 gave +36.9 ± 42.9 / +6.2 ± 3.1 / +4.5 ± 1.7 steps (27 / 1 / 0
///   failed evaluation runs after phase one); ranked by the state model's value at the neighbours'
///   policy there (H = 8) +27.2 ± 42.2 (11 failed); ranked by the value gradient of one state model
///   fitted at the state itself (seed 11) the choice jumps between the action bounds and reaches
///   0-2 of 10 poses. The learned values do not hold the few-step differences between states that
///   such a comparison needs. Seed 11 after phase one, greedy value against the return each
///   evaluation run then obtained, in steps: 0.6 low on average, standard deviation 7.8 over all
///   ticks; 1.7-3.6 along the runs from the five poses with |θ| <= 0.45 rad and 5.5-15 from the
///   five with |θ| 0.7-0.9, whose start values are up to 46 steps low (1.57 against a return of
///   2.50). The stored values at the first ticks of the training runs are the worst (one run's
///   first eight: 0.69 rising to 1.55, where the return changes by 1 % per tick): their targets (a
///   tenth of each step's lambda-return is the greedy value at the next state) and the pulls of
///   neighbouring updates lean on the local prediction, an extrapolation at the edge of the data.
///   With the run's return as the replay target (lambda 1) the errors shrink to a standard
///   deviation of 3.4 steps (1.5-1.9 along the runs near the axis, at most 15 steps at a start),
///   yet the planned choice is still worse: H = 8 +16.8 ± 13.7 (6 failed runs after phase one), at
///   the neighbours' policy +71.4 ± 70.0; with H = 1 the ranking follows the executed-rotation
///   entry of the predicted state (its effect on the value is fitted from data in which the
///   rotation follows the heading) and flips between ±1 rad/s near the axis. So the action's effect
///   cannot be read from the values' dependence on the state either: the rotation entry carries the
///   same confounding, and at the edge of the data the values themselves are off. With both
///   remedies (lambda 1, no rotation entry; H = 8) and a recovery check (a candidate is dropped
///   when the base, turning toward the target point from the predicted state, would still touch a
///   wall) phase two does move for the first time: final block -0.8 ± 0.5 steps against the
///   defaults (138.8, level with the example policy, +1.5 ± 0.4 vs optimal; 0 failed phase-two
///   evaluation runs), but after phase one it is 17.9 ± 12.3 steps slower (157.5: on the teachers'
///   data the plan leaves the states they visited); overriding the imitation only for a predicted
///   gain of 3 steps -0.4 ± 0.7 / +14.4 ± 10.2, H = 12 +0.3 ± 0.6 / +12.4 ± 10.1, the 3-step
///   override with the default lambda and rotation entry -0.4 ± 0.3 / +14.1 ± 12.3 (final / after
///   phase one). Without the exploration and dither segments (explore_probability 0, both phases)
///   the MC returns are less noisy and the plan after phase one is 139.3 ± 0.2 (+0.5 ± 0.2 vs the
///   example policy), but phase two then drifts (final 139.9 ± 1.0); 100 phase-two runs stay at
///   138.8-140.0 per block. Neither claim is reached this way. Nor by imitating the better
///   neighbours with the more accurate values: the advantage-weighted anchor (weights exp(A / τ
///   σ_A), A = value above a fit on the state alone) with lambda 1 after phase one / final: τ = 1
///   -0.2 ± 0.2 / -0.1 ± 0.2, τ = 0.5 -0.1 ± 0.1 / -0.0 ± 0.4, τ = 0.2 +17.6 ± 26.1 (2 failed runs)
///   / +0.3 ± 0.5; without the rotation entry (against the same without weights) τ = 0.5
///   -0.3 ± 0.5 / +0.1 ± 0.5. Judging each candidate where the base settles (after the H ticks it
///   turns toward the target point until aligned; the value is read there, in well-covered states)
///   keeps the plan safe after phase one but no better: lambda 1 without the rotation entry
///   +0.1 ± 0.5 after phase one, -0.4 ± 0.6 final; with the defaults +0.6 ± 0.9 / -0.0 ± 0.6. Each
///   variant ranks by values of the policies that produced the data, and those that stay safe land
///   within a step of the imitation: about half a step better than the average training run
///   (140.1 steps), short of the example policy at its best gain (138.4). Lead: values within a
///   step at the off-axis starts (lambda 1 halves their error) before any ranking by value can beat
///   the imitation.
///   Values or imitation? At a pessimism of 100 or 1000 no value difference outweighs the penalty
///   and the greedy is the anchor alone (the neighbours' policy: a locally linear imitation of the
///   stored actions). Seeds 11-20, against the default 4: Fig. 4 after phase one -0.1 ± 0.2 steps,
///   final -0.1 ± 0.2 (both settings): the corridor policy with code examples is an imitation, and
///   phase two an imitation of its own driving. Fig. 5 (human examples) after phase one
///   +1.6 ± 25.2, final +5.4 ± 24.7 with 17 failed phase-two evaluation runs against 5; obstacles
///   final +30.9 ± 13.3 (26 failed runs against 10). Seeds 1-10 (docs/RESULTS.md,
///   ablation_imitation*): Fig. 4 -0.2 ± 0.2, Fig. 5 +16.9 ± 17.3, obstacles +47.3 ± 22.9. So the
///   values carry the obstacle task and add reliability with the erratic human, and the Fig. 4
///   fixed point is the imitation's. One run shows how the imitation falls short of its teachers
///   (seed 11, first phase-two block, the centre-line pose heading 0.9 rad off): the rotation peaks
///   at 0.69 rad/s where the examples turn at 1, the effective gain falls from 0.8 to 0.4 within
///   two seconds, and the robot stays more than 0.1 m off the centre line for about 7 s (137 steps,
///   the example 132). Not a copycat effect of the rotation entry (a gently turning robot finding
///   the gentle gains' runs as neighbours): the anchor from neighbours chosen without it +0.2 ± 0.2
///   final, the commanded instead of the executed rotation stored (the examples' full turns at the
///   starts imitated, not the acceleration ramp) +0.0 ± 0.2 (-0.1 ± 0.3 at pessimism 100); the
///   imitation copies a mixture of gains and lands near the average run. Decisions held for a
///   second (every driver decides every 10 ticks, one transition per decision with gamma^10;
///   scratch build, not merged) imitate better: after phase one 138.8 ± 0.2, final 138.5 ± 0.3
///   (-1.2 ± 0.3 against the defaults, level with the example at gain 2, +1.2 ± 0.3 vs optimal),
///   but 579 steps after 5 runs against 227; at pessimism 100 the same (138.4), 15 ticks 139.2, 20
///   ticks 147.2. Lower pessimism loses at every decision period (final against pessimism 4,
///   pessimism 2 / 1 / 0): 10 ticks +0.3 / +3.7 / +43.4 (0 / 1 / 37 failed runs), 5 ticks +0.2 /
///   +10.6 / +107.2 (0 / 2 / 57): a larger action effect per decision does not make the values rank
///   actions better than the imitation does. Measuring the default's choices against the anchor is
///   what tells value learning from imitation; a claim of learning beyond the examples needs that
///   ablation.
///   One teacher or a mixture? (docs/RESULTS.md, ablation_teachers: the example gains drawn from
///   0.5-2, 0.5-0.75, 1.75-2 or 0.25-0.35, the same poses and noise; seeds 1-10, final block
///   against the example policy at the middle of each range.) Taught by the best quarter the policy
///   matches its teacher (138.4 ± 0.1, +0.1 ± 0.1); taught by the mixture it is 1.0 ± 0.3 behind
///   gain 2; taught by the gentlest quarter it stays at that teacher (143.6 against 143.1) and
///   6.2 ± 0.5 steps behind the optimal controller; taught by gains 0.25-0.35 (160.8 steps, 17 %
///   above optimal) it is worse than the teacher (0.6 poses per seed missed; the successful runs
///   160.9 ± 1.3). The learner reproduces a consistent teacher and does not improve on it. Seeds
///   11-20, scratch builds, not merged: lower pessimism is worse with the gentle teachers too (2 →
///   +0.8 ± 0.6, 1 → +1.6 ± 0.8). Ranking whole runs instead of single actions: each stored point's
///   weight in the anchor's regression exp(A / (0.5 σ_A)), A = its run's discounted return minus a
///   local linear fit of the other runs' returns on their start states, moved the mixture's policy
///   -0.5 ± 0.2 steps (139.1); weights from the true gains (known to no robot) -0.7 ± 0.2 (138.9),
///   against 138.3 with all 30 runs from the best quarter: the better third of 30 mixed runs is too
///   little data to imitate as well as 30 consistent runs. Bounded steps off the anchor (0.03-0.1
///   rad/s, ranked by value at pessimism 0) compounded across phase-two runs by weighting recent
///   points in the anchor (exp(-age / 1000-2000 points)) drifted the wrong way: +0.7 to +1.1 steps.
///   Advantage learning (each target lowered by β times the state model's action gap at s, V(s) −
///   Q(s, a), so that the gaps grow by 1/(1 − β); gentle teachers, seeds 11-20): β = 0.5 / 0.9
///   final -0.2 ± 0.2 / -0.1 ± 0.4; at pessimism 2 / 1 +8.0 ± 19.7 / -0.9 ± 1.2 against the same
///   pessimism without it, still behind the default. Dither and exploration held for 1 s / 0.5 s
///   (explore_hold_s; same set-up): +24.1 ± 25.2 / +10.7 ± 19.1 (15 / 1 failed phase-two runs).
///   The obstacle task's gap to optimal (final block, successful runs 118.8 against 97.4 on seeds
///   1-10) is not a setting: seeds 11-30, final block against the defaults (123.2 ± 4.4 steps with
///   failures at the limit, 13 failed phase-two evaluation runs of 1,400), paired: exploration σ
///   0.3 rad/s +1.5 ± 7.1 (22), exploration probability 0.4 +7.1 ± 14.9 (16), lambda 1 +3.9 ± 7.8
///   (22), lambda 0.5 +2.1 ± 11.3 (15), pessimism 3 / 6 +9.0 ± 8.3 (35) / +6.1 ± 8.8 (17),
///   bandwidth 0.18 +7.7 ± 11.3 (32); seeds 11-20: all input scales 0.5 +2.7 ± 11.4, pessimism 2 /
///   8 +2.6 ± 17.1 / +12.7 ± 12.8. Where the steps go (seeds 11-20, final block against the optimal
///   controller per pose): a median of 18 steps per run on the way round the obstacle (a wider
///   berth and heading swings), and one run in ten that loses 30-80 steps or fails (the one traced
///   had just missed the goal and circled back to it).
/// - kd-tree: static median-split tree in a fixed node pool, leaf size 16; new points go to a
///   small linearly scanned fresh buffer; a shadow tree is rebuilt in fixed work slices across
///   updates and swapped in (see hedger_counters_t::max_rebuild_work). Neighbour sets are
///   ordered by (distance, slot), so results never depend on the tree's shape or the timing.
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
/// Version of the byte format written by hedger_save(). hedger_load() accepts only this version.
#define HEDGER_FORMAT_VERSION 1U

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
                             ///< 8..HEDGER_MAX_FRESH. Larger = smaller rebuild slices but longer
                             ///< scans. Measured tick p50 at 20k / 50k points: 128 → 213 / 449 us,
                             ///< 256 → 137 / 270, 512 → 107 / 186, 1024 → 100 / 147 (but 1k points:
                             ///< 44 → 52 us). Default 512.
  uint32_t rebuild_work_per_update; ///< kd-tree rebuild work units per update (1 unit ≈ one point
                             ///< visited in one pass); 0 = automatic (a rebuild of a full store
                             ///< finishes within fresh_capacity/2 updates). Default 0.
  uint32_t run_capacity; ///< run buffer length (experiences) for backward replay, 0..HEDGER_MAX_RUN.
                         ///< 0 disables the buffer. Default 0.
  uint32_t replay;       ///< 1: hedger_end_run() replays the recorded run backwards (newest first)
                         ///< through the training update; 0: it only clears the buffer. Default 0.
  uint32_t replay_passes;///< backward passes over the run per replay, 1..HEDGER_MAX_REPLAY_PASSES.
                         ///< Default 1.
  double replay_lambda;  ///< target of the replay, [0, 1]: the λ-return
                         ///< T_t = r_t + γ ((1 − λ) max_a Q(s_{t+1}, a) + λ T_{t+1}); 0 = the
                         ///< Q-learning target, 1 = the return of the run as driven. Default 0.
  uint32_t greedy_method;///< a hedger_greedy_method_t value. Default HEDGER_GREEDY_PER_ACTION.
  double greedy_pessimism; ///< κ >= 0: the greedy search ranks known actions by value − κ ·
                         ///< standard error of the regression. Default 0.
  double greedy_reach;   ///< HEDGER_GREEDY_STATE_MODEL, >= 1: where the state has too few
                         ///< neighbours within the kernel's radius, the model is formed once more
                         ///< with bandwidth and radius × greedy_reach (its value is then the
                         ///< neighbours' average, kind LWA); 1 = no second attempt. Default 1.
  uint32_t local_model;  ///< a hedger_local_model_t value. Not part of a save (values stay valid
                         ///< under either model). Default HEDGER_LOCAL_LWR.
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
  uint64_t updates;             ///< successful training updates (including replayed ones)
  uint64_t replayed_updates;    ///< updates performed by backward replay
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
/// hedger_end_run_begin / hedger_end_run_step to spread it over ticks).
hedger_status_t hedger_end_run(hedger_t* self, uint32_t* replayed) HEDGER_NOEXCEPT;

/// Sliced hedger_end_run(): begin freezes the recorded run and returns (in *pending, may be
/// NULL) the updates its replay takes (0 without replay: the run buffer is simply cleared); each
/// hedger_end_run_step() call performs at most max_updates of them and returns how many remain
/// in *remaining (may be NULL). The results are bit-identical to hedger_end_run(), however the
/// work is sliced. Until the replay is finished the run buffer records nothing new; a
/// hedger_update() meanwhile first finishes the replay (unbounded), so state is never torn.
/// Cost of a step: at most max_updates updates. O(1) for begin.
hedger_status_t hedger_end_run_begin(hedger_t* self, uint32_t* pending) HEDGER_NOEXCEPT;
hedger_status_t hedger_end_run_step(hedger_t* self, uint32_t max_updates, uint32_t* remaining) HEDGER_NOEXCEPT;

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

/// Writes the learned state (config, stored points with values and flags, rewards seen, the
/// eviction generator's state) into buf: little-endian, versioned (HEDGER_FORMAT_VERSION),
/// CRC-32 (IEEE 802.3) over all preceding bytes at the end. *written (may be NULL) receives the
/// byte count. The run buffer and counters are not saved. O(n·D), no allocation, no file I/O
/// (write the bytes atomically yourself: write, fsync, rename).
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

/// Replaces the learned state with the one in buf (from hedger_save()). Checks, in order: magic
/// (FORMAT), version (VERSION), declared length vs size (TRUNCATED), CRC-32 (CHECKSUM), config
/// compatibility (CONFIG_MISMATCH: state_dim, action bounds, input scales, gamma must be equal
/// bit for bit, and the saved points must fit cfg.capacity), then contents (FORMAT: non-finite or
/// out-of-range fields). Any failure leaves the instance unchanged. On success the run buffer is
/// cleared and the kd-tree rebuilt at once: O(n log n), no allocation; not for inside a tick.
/// Bytes after the declared length are ignored.
hedger_status_t hedger_load(hedger_t* self, const void* buf, size_t size) HEDGER_NOEXCEPT;

/// A constant English description of a status ("ok", "invalid argument", ...). Never NULL.
const char* hedger_status_str(hedger_status_t status) HEDGER_NOEXCEPT;

/// A constant name of a kind: "unknown", "lwa", "lwr". Never NULL.
const char* hedger_kind_str(hedger_kind_t kind) HEDGER_NOEXCEPT;

#ifdef __cplusplus
}
#endif

#endif  // HEDGER_HEDGER_H
