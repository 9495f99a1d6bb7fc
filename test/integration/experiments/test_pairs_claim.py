#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.pairs_claim: ranking whole runs moves phase two past the imitation. The Fig. 4
set-up (tools/experiments/ablation_pairs.conf) with 60 phase-two runs, pair_runs off, on (the
ranking moving the learned policy's shift, the default) and on with pair_shift_rate = 0 (the
ranking weighing the runs in the imitation instead), from the same seeds 1-10 (two sessions at a
time): the same start poses and noise. Failed runs count at
the step limit; comparisons are paired by seed; one-sided t-tests at the 95 % level (Student-t
0.95 quantile, 9 degrees of freedom: 1.833).

Claims, each printed with its numbers; ASSERTED ones fail the test when they do not hold:
  phase_one       phase one's pairs (pair_phase_one, from its 11th example run; each step of the
                  shift vetted, pair_shift_vet): the last phase-one block with pair_runs is
                  significantly shorter than without (measured -1.8 ± 0.5 steps, t = -7.65; the
                  claim against the example policy's best gain is experiments.learning_regression's)
  better          the final block with pair_runs is significantly shorter than without
  falls           with pair_runs the final block is significantly shorter than the last phase-one
                  block (the curve falls in phase two; without pairs it stays flat)
  reaches         the final block with pair_runs reaches at least 9.5 of 10 poses on average
  ranked          (the shift variant) phase two was driven by ranked pair runs: every pair of both
                  phases was ranked, and at least
                  95 % of phase-two training steps are the learned policy's (with the pair's
                  perturbation: source exploration, or after a safety correction without it:
                  greedy); the safety filter's recovery law and the advisor drive the rest
  safe            (the shift variant) the safety filter keeps the perturbed runs off the walls: no phase-two training
                  run with pairs ends in a collision (without pairs the greedy policy's own runs
                  hit a wall now and then: printed)
  shift           the shift beats the imitation weights: the final block with the shift is
                  significantly shorter than with pair_shift_rate = 0
  best_gain       the final block with pair_runs is significantly shorter than the example policy at
                  gain 2, the best of its training gains, from the same poses
  near_optimal    ... and not significantly longer than the optimal controller's (the paper's claim
                  for phase two)
  vetoed          pair runs whose perturbation the safety filter corrected (each counts as failed in
                  its pair's ranking; the learned policy drives the rest of the run) and the
                  training time with and without pairs (reported)
usage: test_pairs_claim.py B21R_EXPERIMENT ABLATION_PAIRS_CONFIG"""
import sys

from paired_stats import T95_ONE_SIDED_DF9, mean, paired, report, run_sessions

SEEDS = list(range(1, 11))
PHASE_TWO_RUNS = 60
# ablation_pairs.conf's 30 phase-one runs, paired from the 11th on (pair_phase_one_from_run = 10).
PHASE_ONE_PAIRS = (30 - 10) // 2
ASSERTED = {"phase_one": True, "better": True, "falls": True, "reaches": True, "ranked": True,
            "safe": True, "shift": True, "best_gain": True, "near_optimal": True, "vetoed": False}
# The variants: pair_runs off, on (the default shift), on with the ranking in the imitation weights.
VARIANTS = {"false": [], "true": [], "weights": ["--set", "pair_shift_rate=0"]}


def session_args(variant):
    pairs = "false" if variant == "false" else "true"
    return ["--variant", "pair_runs=" + pairs, *VARIANTS[variant], "--set", "phase_two_runs=%d" % PHASE_TWO_RUNS]


def main():
    exe, conf = sys.argv[1:3]
    jobs = [(s, v) for s in SEEDS for v in VARIANTS]
    try:
        rs = run_sessions(exe, conf, [(s, session_args(v)) for s, v in jobs], "b21r-pairs-")
    except RuntimeError as e:
        print("FAIL:", e)
        return 1
    for (_, v), r in zip(jobs, rs):
        r["variant_name"] = v
    by = {(r["seed"], "pair_runs=" + r["variant_name"]): r for r in rs}
    p1 = {v: [] for v in ("false", "true")}
    final = {v: [] for v in VARIANTS}
    successes, gain2, optimal, ranked_ok = [], [], [], True
    vetoed, overrides, train_s = 0, 0, {"false": 0.0, "true": 0.0}
    missed = {"false": 0, "true": 0}
    collided = {"false": 0, "true": 0}
    for s in SEEDS:
        for v in ("false", "true"):
            blocks = by[(s, "pair_runs=" + v)]["learning"]["blocks"]
            p1[v].append(mean([b for b in blocks if b["phase"] == 1][-1]["steps"]))
            final[v].append(mean(blocks[-1]["steps"]))
        final["weights"].append(mean(by[(s, "pair_runs=weights")]["learning"]["blocks"][-1]["steps"]))
        on = by[(s, "pair_runs=true")]
        for v in ("false", "true"):
            two = [x for x in by[(s, "pair_runs=" + v)]["learning"]["runs"] if x["kind"] == "train" and x["phase"] == 2]
            missed[v] += sum(1 for x in two if x["outcome"] != "goal")
            collided[v] += sum(1 for x in two if x["outcome"] == "collision")
        successes.append(on["learning"]["blocks"][-1]["successes"])
        gain2.append(mean(on["references"]["example@2"]["steps"]))
        optimal.append(mean(on["references"]["optimal"]["steps"]))
        totals = on["learning"]["totals"]
        src = totals["phase_two_steps_by_source"]
        learned = src["exploration"] + src["greedy"]
        ranked_ok = (ranked_ok and totals["pairs_ranked"] == PHASE_ONE_PAIRS + PHASE_TWO_RUNS // 2 and sum(src.values()) > 0
                     and learned >= 0.95 * sum(src.values()))
        vetoed += totals["pair_runs_vetoed"]
        overrides += totals["pair_safety_overrides"]
        for v in ("false", "true"):
            train_s[v] += by[(s, "pair_runs=" + v)]["learning"]["totals"]["training_time_s"]
        print("seed %2d: after phase one %.1f; final without pairs %.1f, with pairs %.1f (%d/10; imitation weights "
              "%.1f); gain 2 %.1f, optimal %.1f; shift %.2f, %.2f; phase-two steps by source %s" %
              (s, p1["true"][-1], final["false"][-1], final["true"][-1], successes[-1], final["weights"][-1],
               gain2[-1], optimal[-1], totals["shift_gain"], totals["shift_centring"], src))
    results = {}
    m, t, h = paired(p1["true"], p1["false"])
    results["phase_one"] = (t < -T95_ONE_SIDED_DF9, "after phase one, with minus without pairs: %+.2f ± %.2f steps, "
                            "t = %.2f" % (m, h, t))
    m, t, h = paired(final["true"], final["false"])
    results["better"] = (t < -T95_ONE_SIDED_DF9, "final block, with minus without pairs: %+.2f ± %.2f steps, t = %.2f"
                         % (m, h, t))
    m, t, h = paired(final["true"], p1["true"])
    results["falls"] = (t < -T95_ONE_SIDED_DF9, "with pairs, final minus after phase one: %+.2f ± %.2f steps, t = %.2f"
                        % (m, h, t))
    ms = mean(successes)
    results["reaches"] = (ms >= 9.5, "final block with pairs: %.1f of 10 poses reached on average" % ms)
    results["ranked"] = (ranked_ok, "every seed ranked %d pairs (%d in phase one), and at least 95 %% of its "
                         "phase-two training steps were the learned policy's (exploration or greedy)" %
                         (PHASE_ONE_PAIRS + PHASE_TWO_RUNS // 2, PHASE_ONE_PAIRS))
    m, t, h = paired(final["true"], final["weights"])
    results["shift"] = (t < -T95_ONE_SIDED_DF9, "final block, the shift minus the imitation weights: %+.2f ± %.2f "
                        "steps, t = %.2f" % (m, h, t))
    m, t, h = paired(final["true"], gain2)
    results["best_gain"] = (t < -T95_ONE_SIDED_DF9, "final with pairs minus example@2: %+.2f ± %.2f steps, t = %.2f"
                            % (m, h, t))
    m, t, h = paired(final["true"], optimal)
    results["near_optimal"] = (t <= T95_ONE_SIDED_DF9, "final with pairs minus optimal: %+.2f ± %.2f steps, t = %.2f"
                               % (m, h, t))
    n2 = len(SEEDS) * PHASE_TWO_RUNS
    results["safe"] = (collided["true"] == 0, "phase-two training runs ending in a collision: with pairs %d of %d "
                       "(without the goal: %d), without pairs %d (%d)" % (collided["true"], n2, missed["true"],
                                                                         collided["false"], missed["false"]))
    pair_runs = n2 + 2 * len(SEEDS) * PHASE_ONE_PAIRS
    results["vetoed"] = (True, "pair runs the safety filter corrected (ranked as failed; both phases): %d of %d "
                         "(%d commands replaced); training time (both phases) with pairs %.2f h, without %.2f h" %
                         (vetoed, pair_runs, overrides, train_s["true"] / 3600.0, train_s["false"] / 3600.0))
    return report(results, ASSERTED)


if __name__ == "__main__":
    sys.exit(main())
