#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.human_claims: the paper's Fig. 5 experiment, the corridor taught by the simulated
sloppy human (tools/experiments/fig5_corridor_human.conf: 15 human runs, the paper's 35 phase-two
runs), seeds 1-10 (two sessions at a time). Each session evaluates the human driver, the proportional example
policy at its nominal gain and the optimal controller from the same 10 poses as the learned
policy; failed runs count at the step limit; comparisons are paired by seed (Student-t 0.95
quantile, 9 degrees of freedom: 1.833).

Claims, each printed with its numbers; ASSERTED ones fail the test when they do not hold:
  beats_human     after phase two the learned policy is significantly better than the human
                  driver from the same poses (the paper's claim; measured -85.8 ± 25.5 steps)
  reaches         every phase-two evaluation block of every seed reaches all 10 poses
  falls           the final block is significantly shorter than the first phase-two block
  beats_examples  the final block is significantly shorter than the proportional example
                  policy's from the same poses
  near_optimal    the final block is not significantly longer than the optimal controller's
                  (falls, beats_examples and near_optimal: not met, measured below)
usage: test_human_claims.py B21R_EXPERIMENT FIG5_CORRIDOR_HUMAN_CONFIG"""
import sys

from paired_stats import T95_ONE_SIDED_DF9, mean, paired, report, run_sessions

SEEDS = list(range(1, 11))
# The greedy policy on HEDGER's values (decisions every 2 ticks, the default) beats the sloppy
# human and reaches every pose in every phase-two block, but beats neither the proportional policy
# nor the optimal controller, and phase two does not shorten it: measured over these 10 seeds,
# final minus proportional +7.2 ± 2.0 steps, minus optimal +8.5 ± 2.0, phase two's fall -0.3 ±
# 1.7. Those three are printed with their numbers (FAILS) and not asserted until the learner that
# meets them (issue 40) is in place.
ASSERTED = {"beats_human": True, "reaches": True, "falls": False, "beats_examples": False,
            "near_optimal": False}


def main():
    exe, conf = sys.argv[1:3]
    try:
        rs = run_sessions(exe, conf, [(s, []) for s in SEEDS], "b21r-human-claims-")
    except RuntimeError as e:
        print("FAIL:", e)
        return 1
    final, first_two, human, example, optimal = [], [], [], [], []
    all_reached = True
    for s, r in zip(SEEDS, rs):
        L = r["learning"]
        two = [b for b in L["blocks"] if b["phase"] == 2]
        final.append(mean(L["blocks"][-1]["steps"]))
        first_two.append(mean(two[0]["steps"]))
        all_reached = all_reached and all(b["successes"] == 10 for b in two)
        refs = r["references"]
        human.append(mean(refs["human"]["steps"]))
        example.append(mean(refs["example"]["steps"]))
        optimal.append(mean(refs["optimal"]["steps"]))
        totals = L["totals"]
        print("seed %2d: final %.1f (first phase-two block %.1f; human %.1f, proportional %.1f, optimal %.1f); "
              "phase-two steps by source %s" %
              (s, final[-1], first_two[-1], human[-1], example[-1], optimal[-1], totals["phase_two_steps_by_source"]))
    results = {}
    m, t, h = paired(final, human)
    results["beats_human"] = (t < -T95_ONE_SIDED_DF9, "final block minus the human driver: %+.2f ± %.2f steps, "
                                    "t = %.2f" % (m, h, t))
    results["reaches"] = (all_reached, "every phase-two evaluation block reaches 10/10 in every seed")
    m, t, h = paired(final, first_two)
    results["falls"] = (t < -T95_ONE_SIDED_DF9, "final minus first phase-two block: %+.2f ± %.2f steps, t = %.2f"
                        % (m, h, t))
    m, t, h = paired(final, example)
    results["beats_examples"] = (t < -T95_ONE_SIDED_DF9, "final block minus the proportional policy: %+.2f ± %.2f "
                                    "steps, t = %.2f" % (m, h, t))
    m, t, h = paired(final, optimal)
    results["near_optimal"] = (t <= T95_ONE_SIDED_DF9, "final block minus the optimal controller: %+.2f ± %.2f steps, "
                               "t = %.2f" % (m, h, t))
    return report(results, ASSERTED)


if __name__ == "__main__":
    sys.exit(main())
