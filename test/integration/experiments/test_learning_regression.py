#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.learning_regression: a small version of the paper's Fig. 4 experiment that catches
a change that breaks learning. Corridor, proportional examples, 5 seeds (1-5), 15 phase-one runs,
10 phase-two runs, an evaluation block (10 poses, learning off) every 5 runs. Failures count at
the step limit. Comparisons are paired by seed, one-sided t-tests at the 95 % level (Student-t
0.95 quantile for 4 degrees of freedom: 2.132).

Claims, each printed with its numbers; ASSERTED ones fail the test when they do not hold:
  improves   the learned policy after the 15 phase-one runs is significantly better than after 5
  keeps      phase two does not make it significantly worse (final block vs last phase-one block)
  reaches    the final block reaches the goal from at least 9 of 10 poses on average
  beats_examples  (the paper's Fig. 4 claim; not asserted until the learner of issue 10 lands:
             then set ASSERTED to True) the final block is significantly better than the mean
             example run of the same seed
usage: test_learning_regression.py B21R_EXPERIMENT FIG4_CONFIG"""
import json
import math
import os
import subprocess
import sys
import tempfile

SEEDS = [1, 2, 3, 4, 5]
T95_ONE_SIDED_DF4 = 2.132
SCHEDULE = ["phase_one_runs=15", "phase_two_runs=10", "eval_every_runs=5", "eval_starts=10",
            "experiment.references="]
ASSERTED = {"improves": True, "keeps": True, "reaches": True, "beats_examples": False}


def run(exe, conf, seed, d):
    out = os.path.join(d, "seed-%d.json" % seed)
    cmd = [exe, "--config", conf, "--seed", str(seed), "--out", out]
    for s in SCHEDULE:
        cmd += ["--set", s]
    p = subprocess.run(cmd, capture_output=True, text=True)
    if p.returncode != 0:
        print("FAIL: %s: exit status %d: %s" % (" ".join(cmd), p.returncode, p.stderr))
        sys.exit(1)
    with open(out) as f:
        return json.load(f)


def mean_all(block):
    return sum(block["steps"]) / len(block["steps"])


def one_sided_less(a, b):
    """Paired: is mean(a - b) significantly below 0? Returns (mean difference, t, holds)."""
    d = [x - y for x, y in zip(a, b)]
    n = len(d)
    m = sum(d) / n
    sd = math.sqrt(sum((x - m) ** 2 for x in d) / (n - 1))
    if sd == 0.0:
        return m, -math.inf if m < 0 else math.inf, m < 0
    t = m / (sd / math.sqrt(n))
    return m, t, t < -T95_ONE_SIDED_DF4


def main():
    exe, conf = sys.argv[1:3]
    with tempfile.TemporaryDirectory(prefix="b21r-regression-") as d:
        rs = [run(exe, conf, s, d) for s in SEEDS]
    first, last_p1, final, example, successes = [], [], [], [], []
    for r in rs:
        blocks = r["learning"]["blocks"]
        p1 = [b for b in blocks if b["phase"] == 1]
        if len(blocks) != 5 or len(p1) != 3:
            print("FAIL: seed %d: expected 5 blocks (3 in phase one), got %d (%d)" % (r["seed"], len(blocks), len(p1)))
            return 1
        first.append(mean_all(blocks[0]))
        last_p1.append(mean_all(p1[-1]))
        final.append(mean_all(blocks[-1]))
        successes.append(blocks[-1]["successes"])
        runs = [x for x in r["learning"]["runs"] if x["kind"] == "train" and x["phase"] == 1]
        example.append(sum(x["steps"] if x["outcome"] == "goal" else r["step_limit"] for x in runs) / len(runs))
        print("seed %d: steps after 5 runs %.1f, after phase one %.1f, final %.1f (%d/10), mean example run %.1f" % (
            r["seed"], first[-1], last_p1[-1], final[-1], successes[-1], example[-1]))
    results = {}
    m, t, ok = one_sided_less(last_p1, first)
    results["improves"] = (ok, "after phase one vs after 5 runs: %+.1f steps, t = %.2f" % (m, t))
    m, t, worse = one_sided_less(last_p1, final)  # final significantly worse = last_p1 - final significantly < 0
    results["keeps"] = (not worse, "final vs after phase one: %+.1f steps, t = %.2f (worse if t > %.3f)" % (-m, -t, T95_ONE_SIDED_DF4))
    mean_succ = sum(successes) / len(successes)
    results["reaches"] = (mean_succ >= 9.0, "final block: %.1f of 10 poses reached on average" % mean_succ)
    m, t, ok = one_sided_less(final, example)
    results["beats_examples"] = (ok, "final vs mean example run: %+.1f steps, t = %.2f" % (m, t))
    failed = False
    for name, (ok, text) in results.items():
        status = "holds" if ok else ("FAILS" if ASSERTED[name] else "does not hold (not asserted yet)")
        print("%-15s %s: %s" % (name, status, text))
        failed = failed or (ASSERTED[name] and not ok)
    print("FAIL" if failed else "PASS")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
