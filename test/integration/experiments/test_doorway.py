#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.doorway: the doorway task, added only as a declaration, runs end to end in
b21r-experiment (the controller's loop core and the ODE emulator in one process) from its own
experiment file on a short schedule (4 phase-one runs, 2 phase-two runs, evaluation blocks of 4
poses):
- the result is the doorway's (task, world, the declared 4-value state) and every run ends at the
  goal, on a collision or at the step limit, with the reward that goes with it (+1, -1, 0); the
  example policy drives phase one and the learner phase two;
- the references run from the same evaluation poses: the reference controller reaches the goal
  from every one;
- the same seed gives the same session run for run (determinism), another seed another one.
usage: test_doorway.py B21R_EXPERIMENT CONFIG"""
import json
import os
import subprocess
import sys
import tempfile

SHORT = ["--set", "phase_one_runs=4", "--set", "phase_two_runs=2", "--set", "eval_every_runs=3",
         "--set", "eval_starts=4", "--set", "experiment.references=optimal,example"]
RETURNS = {"goal": 1, "collision": -1, "step_limit": 0}


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def run(exe, config, seed, out):
    p = subprocess.run([exe, "--config", config, "--seed", str(seed), "--out", out, *SHORT], capture_output=True,
                       text=True, timeout=600)
    if p.returncode != 0:
        fail("b21r-experiment seed %d: exit %d\n%s" % (seed, p.returncode, p.stderr[-3000:]))
    with open(out) as f:
        return json.load(f)


def session(r):
    """What must repeat for a seed: runs (without wall times) and evaluation blocks."""
    L = r["learning"]
    return [{k: v for k, v in x.items()} for x in L["runs"]], [
        {k: v for k, v in b.items() if k != "wall_time_s"} for b in L["blocks"]]


def main():
    exe, config = sys.argv[1:3]
    with tempfile.TemporaryDirectory(prefix="b21r-doorway-") as d:
        a = run(exe, config, 1, os.path.join(d, "a.json"))
        if a["task"] != "doorway" or a["controller"]["task"] != "doorway" or a["world"] != "doorway":
            fail("not the doorway's result: task %s, world %s" % (a["task"], a["world"]))
        L = a["learning"]
        train = [x for x in L["runs"] if x["kind"] == "train"]
        evals = [x for x in L["runs"] if x["kind"] == "eval"]
        if len(train) != 6 or [x["phase"] for x in train] != [1, 1, 1, 1, 2, 2]:
            fail("expected 4 phase-one and 2 phase-two training runs: %s" % [(x["phase"], x["outcome"]) for x in train])
        for x in L["runs"]:
            if x["outcome"] not in RETURNS or x["return"] != RETURNS[x["outcome"]]:
                fail("run %d ended %s with return %s" % (x["run_id"], x["outcome"], x["return"]))
        p1 = [x for x in train if x["phase"] == 1]
        if any(x["sources"]["example"] != x["steps"] for x in p1):
            fail("phase one was not driven by the example policy: %s" % [x["sources"] for x in p1])
        p2 = [x for x in train if x["phase"] == 2]
        if any(x["sources"]["example"] != 0 for x in p2):
            fail("phase two was driven by the example policy: %s" % [x["sources"] for x in p2])
        if len(L["blocks"]) != 2 or any(len(b["steps"]) != 4 for b in L["blocks"]) or len(evals) != 8:
            fail("expected two evaluation blocks of 4 poses: %s" % [b["steps"] for b in L["blocks"]])
        refs = a["references"]
        if set(refs) != {"optimal", "example"} or any(len(v["steps"]) != 4 for v in refs.values()):
            fail("references not evaluated from the 4 poses: %s" % refs)
        if refs["optimal"]["successes"] != 4:
            fail("the reference controller should reach the goal from every pose: %s" % refs["optimal"])
        ends = {}
        for x in L["runs"]:
            ends[x["outcome"]] = ends.get(x["outcome"], 0) + 1
        print("seed 1: training runs %s; evaluation blocks %s; reference %s, example %s; all runs end %s" % (
            [x["outcome"] for x in train], [b["steps"] for b in L["blocks"]], refs["optimal"]["steps"],
            refs["example"]["steps"], ends))

        b = run(exe, config, 1, os.path.join(d, "b.json"))
        if session(a) != session(b) or a["references"]["example"]["steps"] != b["references"]["example"]["steps"]:
            fail("the same seed gave another session")
        c = run(exe, config, 2, os.path.join(d, "c.json"))
        if session(a) == session(c):
            fail("another seed gave the same session")
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
