#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.learner_variants: the learner ablation's three learners run end to end on a short
schedule of its experiment file, and see the same data.
- `--variant learner=hedger|lwa|tabular` each finish with a complete result that records the learner;
- phase one is the same for every learner (the learner does not act in phase-one training runs),
  also across the evaluation blocks inside phase one, whose learner-driven runs differ in length
  and path: each run's sensor noise starts from its run id and the emulator places the robot only
  once the learner is done, so nothing of an evaluation run carries over; equal
  phase_one_data_digest over the same transitions, and the evaluation blocks do differ;
- phase two differs (the learners choose the actions), and the tabular learner stores visited cells.
usage: test_learner_variants.py B21R_EXPERIMENT ABLATION_LEARNER_CONF"""
import json
import os
import subprocess
import sys
import tempfile


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def main():
    exe, conf = sys.argv[1:3]
    results = {}
    with tempfile.TemporaryDirectory(prefix="b21r-learners-") as d:
        for learner in ("hedger", "lwa", "tabular"):
            out = os.path.join(d, learner + ".json")
            p = subprocess.run([exe, "--config", conf, "--seed", "2", "--variant", "learner=" + learner,
                                "--set", "phase_one_runs=6", "--set", "phase_two_runs=2", "--set", "eval_every_runs=2",
                                "--set", "eval_starts=2", "--out", out], capture_output=True, text=True)
            if p.returncode != 0:
                fail("learner=%s: exit %d: %s" % (learner, p.returncode, p.stderr))
            with open(out) as f:
                results[learner] = json.load(f)
    for learner, r in results.items():
        if r["controller"].get("learner") != learner:
            fail("learner=%s not recorded in the result's controller settings: %s" % (learner, r["controller"]))
        lr = r["learning"]
        if lr["totals"]["training_runs"] != 8 or len(lr["blocks"]) != 4:
            fail("learner=%s: incomplete schedule: %s" % (learner, lr["totals"]))
        print("%-8s digest %s over %d transitions; phase two steps by source %s; store %d" % (
            learner, lr["phase_one_data_digest"], lr["phase_one_transitions"],
            lr["totals"]["phase_two_steps_by_source"], lr["totals"]["store_fill"]))
    ref = results["hedger"]["learning"]
    for learner in ("lwa", "tabular"):
        lr = results[learner]["learning"]
        if (lr["phase_one_data_digest"], lr["phase_one_transitions"]) != (
                ref["phase_one_data_digest"], ref["phase_one_transitions"]):
            fail("phase one differs between hedger and %s" % learner)
    if ref["phase_one_transitions"] <= 0:
        fail("no phase-one transitions")
    evals = {k: [x["steps"] for x in v["learning"]["runs"] if x["kind"] == "eval" and x["phase"] == 1]
             for k, v in results.items()}
    if not evals["hedger"] or (evals["hedger"] == evals["lwa"] and evals["hedger"] == evals["tabular"]):
        fail("the phase-one evaluation runs are the same for every learner (%s): the test shows nothing" % evals)
    runs = {k: [x["steps"] for x in v["learning"]["runs"] if x["phase"] == 2] for k, v in results.items()}
    if runs["hedger"] == runs["tabular"] and runs["hedger"] == runs["lwa"]:
        fail("phase two identical for every learner: the learner is not in the loop (%s)" % runs)
    if not 0 < results["tabular"]["learning"]["totals"]["store_fill"] <= 10 ** 3 * 9:
        fail("tabular: visited cells out of range: %s" % results["tabular"]["learning"]["totals"])
    print("ok")


if __name__ == "__main__":
    main()
