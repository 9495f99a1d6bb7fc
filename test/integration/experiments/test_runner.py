#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.runner: b21r-experiment's contract with the sweep and with people.
- a bad key or value in an experiment file is refused with the file, the line and the key;
- --plan lists seeds x variants; an experiment needing controller keys this build lacks says so
  in its plan and is refused (exit 3) when run;
- an exploration study writes a complete result (no temporary file left) and is a function of
  its seed (same seed: same runs; another seed: other runs);
- corridor_length_m reaches the task and the emulator's world: the optimal controller needs
  about (15 - 10) m / 0.6 m/s = 83 more steps in the 15 m corridor than in the 10 m one;
- a reference example@GAIN evaluates the example policy at that gain: example@1.25 (the middle of
  the corridor's range 0.5-2) drives exactly as the plain example reference, example@0.5 (the
  gentlest) needs more steps; a misspelt, duplicated (also as another spelling of one gain),
  out-of-range or too long reference is refused by name;
- example_gain_range replaces the example policy's gain range: at 0.5,0.5 the phase-one runs and
  the plain example reference (the middle of the range) drive at gain 0.5 (the same steps as
  example@0.5; more training steps than at 2,2 from the same starts); the task's own range 0.5,2
  changes nothing (the draw is rescaled, so the same runs bit for bit); at 1,2 the plain example
  drives as example@1.5, in the obstacle task at 0.8,0.8 as example@0.8; a reversed range is
  refused, also as one variant of experiment.vary, before anything runs;
- steps are control ticks with decisions held over two ticks too: the training and evaluation
  totals, each block's training steps and the steps by source add up the runs' steps.
usage: test_runner.py B21R_EXPERIMENT CONFIG_DIR"""
import json
import os
import subprocess
import sys
import tempfile


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def run(exe, *args):
    return subprocess.run([exe, *args], capture_output=True, text=True)


def main():
    exe, configs = sys.argv[1:3]
    with tempfile.TemporaryDirectory(prefix="b21r-runner-") as d:
        bad = os.path.join(d, "bad.conf")
        with open(bad, "w") as f:
            f.write("task = corridor\nexperiment.seeds = 10\nhedger_capacity = lots\n")
        p = run(exe, "--config", bad, "--plan")
        if p.returncode != 2 or "bad.conf:3" not in p.stderr or "hedger_capacity" not in p.stderr:
            fail("a bad value was not refused with file:line and key (%d): %s" % (p.returncode, p.stderr))
        with open(bad, "w") as f:
            f.write("experiment.vary = hedger_capacity=500|-3\n")
        p = run(exe, "--config", bad, "--plan")
        if p.returncode != 2 or "'-3'" not in p.stderr:
            fail("a bad variant value was not refused (%d): %s" % (p.returncode, p.stderr))
        with open(bad, "w") as f:
            f.write("experiment.sedes = 3\n")
        p = run(exe, "--config", bad, "--plan")
        if p.returncode != 2 or "unknown key 'experiment.sedes'" not in p.stderr:
            fail("an unknown experiment key was not refused (%d): %s" % (p.returncode, p.stderr))

        p = run(exe, "--config", os.path.join(configs, "ablation_capacity.conf"), "--plan")
        plan = json.loads(p.stdout)
        if plan["seeds"] != list(range(1, 11)) or plan["variants"] != [
                "hedger_capacity=20000", "hedger_capacity=2000", "hedger_capacity=500"]:
            fail("unexpected plan: %s" % plan)
        learner = os.path.join(configs, "ablation_learner.conf")
        plan = json.loads(run(exe, "--config", learner, "--plan").stdout)
        if "unavailable" in plan:
            p = run(exe, "--config", learner, "--seed", "1", "--out", os.path.join(d, "x.json"))
            if p.returncode != 3 or "learner" not in p.stderr:
                fail("an unavailable experiment was not refused with exit 3 (%d): %s" % (p.returncode, p.stderr))
        elif plan["variants"] != ["learner=hedger", "learner=lwa", "learner=tabular"]:
            fail("unexpected ablation_learner plan: %s" % plan)
        # (experiments.learner_variants runs the available learners end to end.)
        with open(bad, "w") as f:
            f.write("experiment.requires = no_such_key\ntask = corridor\nexperiment.seeds = 2\n")
        missing = json.loads(run(exe, "--config", bad, "--plan").stdout)
        p = run(exe, "--config", bad, "--seed", "1", "--out", os.path.join(d, "x.json"))
        if "no_such_key" not in missing.get("unavailable", "") or p.returncode != 3 or "no_such_key" not in p.stderr:
            fail("an experiment needing a missing key was not refused with exit 3 (%d): %s %s" % (
                p.returncode, missing, p.stderr))
        print("ablation_learner: %s" % plan.get("unavailable", "available"))

        goal = os.path.join(configs, "table1_explore_goal.conf")
        outs = []
        for name, seed in (("a", 4), ("b", 4), ("c", 5)):
            out = os.path.join(d, name + ".json")
            p = run(exe, "--config", goal, "--seed", str(seed), "--variant", "experiment.explore_start_distance_m=2",
                    "--set", "experiment.explore_runs=8", "--set", "experiment.explore_time_limit_s=3600", "--out", out)
            if p.returncode != 0:
                fail("explore_goal run failed: %s" % p.stderr)
            if os.path.exists(out + ".tmp"):
                fail("temporary result file left behind")
            with open(out) as f:
                r = json.load(f)
            if r["format"] != "b21r-experiment-result/1" or len(r["explore"]["runs"]) != 8 or r["seed"] != seed:
                fail("incomplete result: %s" % r)
            if r["explore"]["start_distance_m"] != 2 or r["controller"]["task"] != "obstacles":
                fail("the variant or the controller settings are not recorded: %s" % r["explore"])
            outs.append(r["explore"]["runs"])
        if outs[0] != outs[1]:
            fail("the same seed gave different runs")
        if outs[0] == outs[2]:
            fail("another seed gave the same runs")
        steps = {}
        for length in (10, 15):
            out = os.path.join(d, "len%d.json" % length)
            p = run(exe, "--config", os.path.join(configs, "fig4_corridor_examples.conf"), "--seed", "1", "--out", out,
                    "--set", "corridor_length_m=%d" % length, "--set", "experiment.references=optimal",
                    "--set", "phase_one_runs=1", "--set", "phase_two_runs=0", "--set", "eval_starts=1")
            if p.returncode != 0:
                fail("corridor %d m: %s" % (length, p.stderr))
            with open(out) as f:
                r = json.load(f)
            ref = r["references"]["optimal"]
            if ref["successes"] != 1 or r["world"] != "corridor%d" % length:
                fail("corridor %d m: optimal did not reach the goal in world %s" % (length, r["world"]))
            steps[length] = ref["steps"][0]
        print("optimal controller: %d steps in 10 m, %d steps in 15 m" % (steps[10], steps[15]))

        for refs, wrong in (("optimal,exampel", "'exampel' is none"),
                            ("example@2,example@2", "'example@2' and 'example@2' are the same"),
                            ("example@2,example@2.0", "'example@2' and 'example@2.0' are the same"),
                            ("optimal,example@0", "'example@0' is none"), ("optimal,example@2x", "'example@2x' is none"),
                            ("optimal,example@2e0", "'example@2e0' is none"), ("optimal,example@+2", "'example@+2' is none"),
                            ("optimal,example@nan", "'example@nan' is none"),
                            ("optimal,example@0.1234567", "at most 15 characters")):
            p = run(exe, "--config", os.path.join(configs, "fig4_corridor_examples.conf"), "--plan",
                    "--set", "experiment.references=" + refs)
            if p.returncode != 2 or wrong not in p.stderr:
                fail("references %s were not refused naming %s (%d): %s" % (refs, wrong, p.returncode, p.stderr))
        out = os.path.join(d, "gains.json")
        p = run(exe, "--config", os.path.join(configs, "fig4_corridor_examples.conf"), "--seed", "1", "--out", out,
                "--set", "experiment.references=example,example@1.25,example@0.5",
                "--set", "phase_one_runs=1", "--set", "phase_two_runs=0", "--set", "eval_starts=4")
        if p.returncode != 0:
            fail("example@GAIN references: %s" % p.stderr)
        with open(out) as f:
            refs = json.load(f)["references"]
        if set(refs) != {"example", "example@1.25", "example@0.5"}:
            fail("references missing from the result: %s" % sorted(refs))
        if refs["example@1.25"]["steps"] != refs["example"]["steps"]:
            fail("example@1.25 should drive as the nominal example: %s vs %s" % (
                refs["example@1.25"]["steps"], refs["example"]["steps"]))
        if not sum(refs["example@0.5"]["steps"]) > sum(refs["example"]["steps"]):
            fail("the gentlest gain should need more steps: %s vs %s" % (
                refs["example@0.5"]["steps"], refs["example"]["steps"]))
        print("example policy from 4 poses: nominal gain %d steps, gain 0.5 %d steps" % (
            sum(refs["example"]["steps"]), sum(refs["example@0.5"]["steps"])))
        ranged = {}
        for conf, rng, refs_set in (("fig4_corridor_examples", "0.5,0.5", "example,example@0.5"),
                                    ("fig4_corridor_examples", "2,2", "example"),
                                    ("fig4_corridor_examples", "", "example"),
                                    ("fig4_corridor_examples", "0.5,2", "example"),
                                    ("fig4_corridor_examples", "1,2", "example,example@1.5"),
                                    ("fig9_10_obstacles", "0.8,0.8", "example,example@0.8")):
            out = os.path.join(d, "range.json")
            p = run(exe, "--config", os.path.join(configs, conf + ".conf"), "--seed", "1", "--out", out,
                    "--set", "experiment.references=" + refs_set, "--set", "example_gain_range=" + rng,
                    "--set", "phase_one_driver=example", "--set", "phase_one_runs=2", "--set", "phase_two_runs=0",
                    "--set", "eval_starts=2", "--set", "eval_every_runs=2")
            if p.returncode != 0:
                fail("%s with example_gain_range=%s: %s" % (conf, rng, p.stderr))
            with open(out) as f:
                ranged[(conf, rng)] = json.load(f)
        for conf, rng, gain in (("fig4_corridor_examples", "0.5,0.5", "0.5"), ("fig4_corridor_examples", "1,2", "1.5"),
                                ("fig9_10_obstacles", "0.8,0.8", "0.8")):
            refs = ranged[(conf, rng)]["references"]
            if refs["example"]["steps"] != refs["example@" + gain]["steps"]:
                fail("%s with example_gain_range=%s: the plain example should drive at gain %s: %s vs %s" % (
                    conf, rng, gain, refs["example"]["steps"], refs["example@" + gain]["steps"]))
        blocks = {rng: ranged[("fig4_corridor_examples", rng)]["learning"]["blocks"] for rng in ("", "0.5,2")}
        if blocks["0.5,2"] != blocks[""]:
            fail("example_gain_range=0.5,2 (the task's own range) changed the learning session")
        train = {rng: ranged[("fig4_corridor_examples", rng)]["learning"]["blocks"][0]["training_steps"]
                 for rng in ("0.5,0.5", "2,2")}
        if not train["0.5,0.5"] > train["2,2"]:
            fail("phase-one runs at gain 0.5 should need more steps than at gain 2: %s" % train)
        print("two phase-one runs: %d steps at gain 0.5, %d at gain 2" % (train["0.5,0.5"], train["2,2"]))
        for args in (("--set", "example_gain_range=2,1"),
                     ("--set", "experiment.vary=example_gain_range=0.5,2|2,1")):
            p = run(exe, "--config", os.path.join(configs, "fig4_corridor_examples.conf"), "--plan", *args)
            if p.returncode != 2 or '"2,1"' not in p.stderr or "lowest first" not in p.stderr:
                fail("a reversed example_gain_range (%s) was not refused (%d): %s" % (args[1], p.returncode, p.stderr))
        if not 70 <= steps[15] - steps[10] <= 100:
            fail("the 15 m corridor should take about 83 more steps than the 10 m one")

        # Steps are control ticks at any decision spacing: with decision_ticks = 2 one experience
        # covers two ticks, and the totals, each block's training steps and the steps by source
        # still add up the runs' own steps (the reference learners' table compares them with
        # environment steps).
        goal_returns, optimal = {}, {}
        for ticks in (1, 2):
            out = os.path.join(d, "ticks%d.json" % ticks)
            p = run(exe, "--config", os.path.join(configs, "fig4_corridor_examples.conf"), "--seed", "1", "--out", out,
                    "--set", "decision_ticks=%d" % ticks, "--set", "experiment.references=optimal",
                    "--set", "phase_one_runs=3", "--set", "phase_two_runs=2", "--set", "eval_starts=2",
                    "--set", "eval_every_runs=2")
            if p.returncode != 0:
                fail("decision_ticks = %d: %s" % (ticks, p.stderr))
            with open(out) as f:
                L = json.load(f)["learning"]
            train = sorted((x for x in L["runs"] if x["kind"] == "train"), key=lambda x: x["training_index"])
            driven = sum(x["steps"] for x in train)
            evals = sum(x["steps"] for x in L["runs"] if x["kind"] == "eval")
            by_source = sum(sum(L["totals"][k].values()) for k in ("phase_one_steps_by_source",
                                                                   "phase_two_steps_by_source"))
            if (L["totals"]["training_steps"], by_source, L["totals"]["eval_steps"]) != (driven, driven, evals):
                fail("decision_ticks = %d: training steps %d, by source %d, evaluation steps %d; the runs drove %d "
                     "and %d" % (ticks, L["totals"]["training_steps"], by_source, L["totals"]["eval_steps"],
                                 driven, evals))
            for b in L["blocks"]:
                if b["training_steps"] != sum(x["steps"] for x in train[: b["training_runs"]]):
                    fail("decision_ticks = %d: the block after %d runs counts %d training steps, its runs drove %d" % (
                        ticks, b["training_runs"], b["training_steps"],
                        sum(x["steps"] for x in train[: b["training_runs"]])))
            # A run's return is its rewards summed undiscounted (the corridor pays only at the goal),
            # not its decisions' rewards, which are discounted within each decision.
            goal_returns[ticks] = sorted({x["return"] for x in L["runs"] if x["outcome"] == "goal"})
            with open(out) as f:
                optimal[ticks] = json.load(f)["references"]["optimal"]["steps"]
            print("decision_ticks %d: %d training steps, %d evaluation steps, as the runs drove; returns of the runs "
                  "that reached the goal %s" % (ticks, driven, evals, goal_returns[ticks]))
        if len(goal_returns[1]) != 1 or goal_returns[2] != goal_returns[1]:
            fail("a run that reached the goal returns the goal's reward at any decision spacing: %s" % goal_returns)
        # The optimal controller, every variant's yardstick, decides every tick whatever the learner's setting.
        if optimal[1] != optimal[2]:
            fail("the optimal controller's evaluation moved with decision_ticks: %s against %s" % (optimal[2], optimal[1]))
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
