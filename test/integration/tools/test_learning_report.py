#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.learning_report: the main job's claims (tools/b21r_learning_report.py, claims()) decide
each claim from hand-built evaluation blocks as documented: paired over the poses, failures at
the step limit, the best example gain chosen by its mean, phase-two drivers counted per step.
Each case flips one verdict, so a claim that always says yes (or no) fails here."""
import sys

import b21r_learning_report as rep


def block(steps, phase, limit=1000):
    return {"n_starts": len(steps), "steps": list(steps), "phase": phase,
            "successes": sum(1 for s in steps if s < limit)}


def verdicts(blocks, optimal, examples, train):
    return {c.split(":")[0].split(" (")[0]: ok for c, ok, _ in rep.claims(blocks, optimal, examples, train)}


def check(cond, what):
    if not cond:
        print("FAIL:", what)
        sys.exit(1)


def main():
    poses = [130, 135, 140, 145, 150, 131, 136, 141, 146, 151]
    shift = lambda d: [p + d + (i % 3) * 0.5 for i, p in enumerate(poses)]  # noqa: E731 (small paired noise)
    first = block([1000] + shift(10)[1:], 1)
    good_p1 = block(shift(-3), 1)
    final = block(shift(-3), 2)
    optimal = block(shift(-3), 1)
    examples = {"0.5": block(shift(8), 1), "2.0": block(shift(0), 1)}
    learner_run = {"phase": 2, "sources": {"greedy": 90, "exploration": 10}}
    v = verdicts([first, good_p1, final], optimal, examples, [learner_run])
    check(all(v.values()), "every claim should hold for a learner better than every comparator: %s" % v)
    # Worse than the best gain (2.0) by 3 steps on every pose: both example claims fail; gain 0.5
    # (the worse one) must not be the bar.
    v = verdicts([first, block(shift(3), 1), final], optimal, examples, [learner_run])
    check(not any(ok for c, ok in v.items() if "example policy" in c), "worse than the best gain: %s" % v)
    # Final block worse than optimal on every pose: the optimality claim fails, the others not.
    v = verdicts([first, good_p1, block(shift(0), 2)], optimal, examples, [learner_run])
    check(not v["after phase two, not significantly worse than the optimal controller"], "optimality: %s" % v)
    # A failed pose in a phase-two block: "every pose reached" fails.
    v = verdicts([first, good_p1, block([1000] + shift(-3)[1:], 2), final], optimal, examples, [learner_run])
    check(not v["every pose reached in every phase-two block"], "failure in phase two: %s" % v)
    # The advisor drove 10 % of phase two: not driven by the learned policy.
    v = verdicts([first, good_p1, final], optimal, examples,
                 [{"phase": 2, "sources": {"greedy": 90, "advisor": 10}}])
    check(not v["phase two is driven by the learned policy"], "advisor share: %s" % v)
    # A curve that does not fall.
    v = verdicts([good_p1, first, final], optimal, examples, [learner_run])
    check(not v["the curve falls"], "rising curve: %s" % v)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
