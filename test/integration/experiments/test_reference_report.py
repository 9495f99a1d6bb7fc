#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.reference_report: the report's reference-learner table is computed from the
result files, whichever exist (fixture files written here, with known answers):
- training steps to within 1 % / 3 % of the optimal controller and staying there: the first
  evaluation from which every later one is within (an evaluation that leaves the band restarts
  the count), a seed whose final evaluation is outside censored ("> budget") and counted;
- the median over seeds of those steps, of the training episodes ending on a wall and of the final
  evaluation (failures at the step limit), with the order-statistics 95 % interval from 6 seeds;
- the product's learner gets its row from a learn result (training steps of both phases per
  evaluation block, collisions among its training runs), and a "not run yet" row where its
  result files are missing: the greedy policy from fig4_corridor_examples and ablation_teachers'
  gentle-teacher variant, the actor (policy = actor) from actor_corridor's two variants, both
  policies from the sloppy human's examples (corridor_human_10m's two variants), each row from its
  own variant's files;
- `report --section reference_learners` replaces only its own section of an existing report (the
  rest kept, the prose between its markers kept, no duplicate on a second run) and draws the
  learning-curve figure; the full report has the section too.
Skipped (exit 77) when the sweep's packages are not installed in build/venv.
usage: test_reference_report.py"""
import json
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
VENV_PY = os.path.join(REPO, "build", "venv", "bin", "python3")
TOOL = os.path.join(REPO, "tools", "b21r_experiments.py")
FORMAT = "b21r-experiment-result/1"
OPTIMAL = [138, 138, 138, 142, 142, 131, 131, 142, 142, 129]  # mean 137.3: 1 % band <= 138.673, 3 % <= 141.419
LIMIT = 1000


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def poses(mean):
    """10 evaluation runs whose mean (failures at the limit) is `mean`; 1000 = every run failed."""
    if mean >= LIMIT:
        return [LIMIT] * 10, [False] * 10
    total = int(round(mean * 10))
    steps = [total // 10] * 10
    steps[0] += total - sum(steps)
    return steps, [True] * 10


def reference_result(algorithm, seed, curve, walls):
    """curve: [(training steps, mean steps)], walls: training episodes on a wall by each evaluation."""
    evals = []
    for (t, m), w in zip(curve, walls):
        s, ok = poses(m)
        evals.append({"steps": s, "success": ok, "mean_all": sum(s) / 10, "successes": sum(ok), "training_steps": t,
                      "training_episodes": w + t // 500, "wall_episodes": w, "wall_time_s": 0.0})
    return {"format": FORMAT, "experiment": "ref_fixture", "title": "fixture", "kind": "reference",
            "variant": "reference.algorithm=%s" % algorithm, "variant_index": 0 if algorithm == "sac" else 1,
            "seed": seed, "task": "corridor", "dt_s": 0.1, "step_limit": LIMIT, "eval_starts": 10,
            "reference": {"algorithm": algorithm, "library": "stable-baselines3", "env_id": "B21rCorridor-v0",
                          "backend": "kinematic", "hyperparameters": {"learning_rate": 0.0003}, "versions": {},
                          "train_steps": curve[-1][0], "eval_every_steps": 1000,
                          "optimal": {"steps": OPTIMAL, "success": [True] * 10, "mean_all": 137.3, "successes": 10},
                          "evaluations": evals, "episodes": [], "wall_time_s": 1.0}}


GREEDY_FIG4 = "product: greedy policy (HEDGER), proportional examples"
GREEDY_GENTLE = "product: greedy policy (HEDGER), gentle teacher"
ACTOR_FIG4 = "product: actor on HEDGER's values (policy = actor), proportional examples"
ACTOR_GENTLE = "product: actor on HEDGER's values (policy = actor), gentle teacher"
GREEDY_HUMAN = "product: greedy policy (HEDGER), sloppy human"
ACTOR_HUMAN = "product: actor on HEDGER's values (policy = actor), sloppy human"


def learn_result(seed, experiment="fig4_corridor_examples", variant="", means=(300.0, 150.0, 138.0), walls=1):
    """A product learn result: 3 blocks (mean steps `means`) after 5, 10, 15 training runs of 140
    steps (`walls` of them, 0 or 1, on a wall)."""
    runs = [{"run_id": i, "kind": "train", "phase": 1 if i < 10 else 2, "training_index": i, "steps": 140,
             "outcome": "collision" if i == 2 and walls else "goal"} for i in range(15)]
    blocks = []
    for b, m in enumerate(means):
        s, ok = poses(m)
        blocks.append({"block": b, "training_runs": 5 * (b + 1), "phase": 1, "steps": s, "success": ok,
                       "training_steps": 700 * (b + 1)})
    return {"format": FORMAT, "experiment": experiment, "kind": "learn", "variant": variant, "variant_index": 0,
            "seed": seed, "task": "corridor", "dt_s": 0.1, "step_limit": LIMIT, "eval_starts": 10,
            "learning": {"blocks": blocks, "runs": runs, "totals": {"training_steps": 2100}},
            "references": {"optimal": {"steps": OPTIMAL, "success": [True] * 10}}}


def write(out, r):
    var = (r["variant"] or "default").replace("/", "_")
    d = os.path.join(out, "results", r["experiment"], var)
    os.makedirs(d, exist_ok=True)
    with open(os.path.join(d, "seed-%d.json" % r["seed"]), "w") as f:
        json.dump(r, f)


def section(text):
    a = text.find("<!-- section:reference_learners -->")
    b = text.find("<!-- /section:reference_learners -->")
    if a < 0 or b < a:
        fail("no reference_learners section in the report:\n" + text[-3000:])
    return text[a:b]


def row(text, label):
    for line in section(text).splitlines():
        if line.startswith("| " + label):
            return [c.strip() for c in line.strip("|").split("|")]
    fail("no row '%s' in the table:\n%s" % (label, section(text)))


def main():
    probe = subprocess.run([VENV_PY, "-c", "import scipy, matplotlib"], capture_output=True)
    if probe.returncode != 0:
        print("SKIP: SciPy is not installed in build/venv (tools/b21r_experiments.py installs it on first use)")
        return 77
    with tempfile.TemporaryDirectory(prefix="b21r-refrep-") as d:
        confs = os.path.join(d, "configs")
        os.makedirs(confs)
        with open(os.path.join(confs, "ref_fixture.conf"), "w") as f:
            f.write("experiment.kind = reference\nexperiment.vary = reference.algorithm=sac|ppo\n")
        out = os.path.join(d, "out")
        # SAC, 6 seeds; steps to within 1 % and staying: 4000, censored, 1000, 2000, 3000, 2000.
        sac = [
            [(0, 1000), (1000, 300), (2000, 138), (3000, 139), (4000, 137.5)],      # 1 %: 4000 (139 leaves); 3 %: 2000
            [(0, 1000), (1000, 138), (2000, 138), (3000, 138), (4000, 170)],        # censored for both
            [(0, 1000), (1000, 137.3), (2000, 138), (3000, 138.6), (4000, 137.3)],  # 1000; 1000
            [(0, 1000), (1000, 500), (2000, 138.5), (3000, 138), (4000, 138)],      # 2000; 2000
            [(0, 1000), (1000, 141), (2000, 141), (3000, 138), (4000, 138)],        # 3000; 1000
            [(0, 1000), (1000, 145), (2000, 138), (3000, 138), (4000, 138)],        # 2000; 2000
        ]
        walls = [[0, 30, 60, 70, 70], [0, 5, 5, 5, 9], [0, 40, 40, 40, 40], [0, 10, 20, 30, 40], [0, 1, 2, 3, 4],
                 [0, 0, 0, 0, 0]]
        for seed, (c, w) in enumerate(zip(sac, walls), 1):
            write(out, reference_result("sac", seed, c, w))
        for seed in (1, 2):
            write(out, reference_result("ppo", seed, [(0, 1000), (2048, 400), (4096, 137.3)], [0, 20, 20]))
        report = os.path.join(d, "docs", "RESULTS.md")
        os.makedirs(os.path.dirname(report))
        with open(report, "w") as f:
            f.write("# Results\n\n## Before\n\nkept above\n\n## Ablations\n\nkept below\n")
        cmd = [VENV_PY, TOOL, "figures", "report", "--section", "reference_learners", "--configs", confs, "--out", out,
               "--report", report]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        if p.returncode != 0:
            fail("report --section failed: %s" % (p.stdout + p.stderr)[-3000:])
        with open(report) as f:
            text = f.read()
        print(section(text))
        if "kept above" not in text or "kept below" not in text or text.find("section:reference_learners") > text.find(
                "## Ablations"):
            fail("the rest of the report was not kept, or the section is not before the ablations")
        r = row(text, "SAC")
        # learner, back-end, seeds, budget, to 1 %, to 3 %, walls (seeds with any), walls until 1 %, final, 10/10
        # 6 values: 1000, 2000, 2000, 3000, 4000, inf -> median (2000 + 3000) / 2 = 2500; interval ranks 1 and 6.
        want_1 = "2,500 [1,000, > budget] (1)"
        if r[4] != want_1:
            fail("SAC steps to within 1 %%: %r, expected %r" % (r[4], want_1))
        # 3 %: 2000, inf, 1000, 2000, 1000, 2000 -> sorted 1000 1000 2000 2000 2000 inf: median 2000.
        if r[5] != "2,000 [1,000, > budget] (1)":
            fail("SAC steps to within 3 %%: %r" % r[5])
        # walls in all: 70, 9, 40, 40, 4, 0 -> sorted 0 4 9 40 40 70: median 24.5 -> "24" or "25" at 0 digits
        if not r[6].startswith("24") or "[0, 70]" not in r[6] or not r[6].endswith("(5)"):
            fail("SAC training episodes on a wall: %r" % r[6])
        # walls until within 1 %: 70, inf, 40, 20, 3, 0 -> sorted 0 3 20 40 70 inf: median 30.
        if r[7] != "30 [0, > budget]":
            fail("SAC walls until within 1 %%: %r" % r[7])
        # final: 137.5, 170, 137.3, 138, 138, 138 -> median 138.0, interval [137.3, 170.0]
        if r[8] != "138.0 [137.3, 170.0]" or r[9] != "6 of 6 seeds" or r[2] != "6" or r[3] != "4,000":
            fail("SAC final evaluation / seeds / budget: %r" % r)
        r = row(text, "PPO")
        if r[4] != "4,096 (0)" or r[2] != "2":
            fail("PPO (2 seeds: a median without an interval): %r" % r)
        for label in (GREEDY_FIG4, GREEDY_GENTLE, ACTOR_FIG4, ACTOR_GENTLE, GREEDY_HUMAN, ACTOR_HUMAN):
            r = row(text, label)
            if "not run yet" not in r[3]:
                fail("a missing product result is not marked 'not run yet': %r" % r)
        if "run actor_corridor` (variant `example_gain_range=0.25,0.35`)" not in row(text, ACTOR_GENTLE)[3]:
            fail("the actor's missing row does not name its experiment and variant: %r" % row(text, ACTOR_GENTLE))
        png = os.path.join(d, "docs", "figures", "ref_fixture.png")
        if not os.path.exists(png) or "ref_fixture.png" not in section(text):
            fail("the learning-curve figure was not drawn or not linked")

        # The product's learner from its learn results; prose kept; no second section.
        for seed in (1, 2, 3):
            write(out, learn_result(seed))
        # The actor's gentle-teacher variant (two seeds, a different curve), and a Fig. 4 variant of the
        # same experiment that must not be read for it.
        for seed in (1, 2):
            write(out, learn_result(seed, "actor_corridor", "example_gain_range=0.25,0.35", (139.0, 138.5, 138.2),
                                    walls=0))
        write(out, learn_result(1, "actor_corridor", "example_gain_range=0.5,2", (1000.0, 1000.0, 1000.0)))
        # The human's examples: the actor's variant of corridor_human_10m only (the greedy one missing).
        for seed in (1, 2, 3):
            write(out, learn_result(seed, "corridor_human_10m", "policy=actor", (150.0, 141.0, 140.0), walls=0))
        text = text.replace("_(Prose to be written", "Kept prose. _(Prose to be written", 1)
        with open(report, "w") as f:
            f.write(text)
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        if p.returncode != 0:
            fail("report --section (second run) failed: %s" % (p.stdout + p.stderr)[-3000:])
        with open(report) as f:
            text = f.read()
        if text.count("<!-- section:reference_learners -->") != 1 or "Kept prose." not in text:
            fail("a second run duplicated the section or lost its prose")
        r = row(text, GREEDY_FIG4)
        # blocks 300, 150, 138 after 700, 1400, 2100 training steps: within 1 % and 3 % from 2100; 1 run on a wall
        if r[1] != "ode" or r[2] != "3" or r[3] != "2,100" or r[4] != "2,100 (0)" or r[5] != "2,100 (0)" or \
                r[6] != "1 (3)" or r[7] != "1" or r[8] != "138.0":
            fail("the product's row from its learn results: %r" % r)
        if "not run yet" not in row(text, GREEDY_GENTLE)[3]:
            fail("the gentle teacher's missing results are not marked")
        if "run corridor_human_10m` (variant `policy=greedy`)" not in row(text, GREEDY_HUMAN)[3]:
            fail("the greedy policy's missing human row does not name its experiment and variant: %r" %
                 row(text, GREEDY_HUMAN))
        r = row(text, ACTOR_HUMAN)
        # blocks 150, 141, 140 after 700, 1400, 2100: never within 1 % (censored), 3 % (<= 141.419) from 1400
        if r[2] != "3" or r[4] != "> budget (3)" or r[5] != "1,400 (0)" or r[8] != "140.0" or r[9] != "3 of 3 seeds":
            fail("the actor's human row from its own variant's results: %r" % r)
        r = row(text, ACTOR_GENTLE)
        # blocks 139.0, 138.5, 138.2 after 700, 1400, 2100: within 1 % (<= 138.673) from 1400, 3 % from 700; no wall
        if r[2] != "2" or r[4] != "1,400 (0)" or r[5] != "700 (0)" or r[6] != "0 (0)" or r[8] != "138.2" or \
                r[9] != "2 of 2 seeds":
            fail("the actor's gentle-teacher row from its own variant's results: %r" % r)
        r = row(text, ACTOR_FIG4)
        if r[2] != "1" or r[4] != "> budget (1)" or r[8] != "1000.0" or r[9] != "0 of 1 seeds":
            fail("the actor's Fig. 4 row from its own variant's results: %r" % r)

        # The full report has the section too (reference results and the actor's), and draws no figure of
        # the actor's experiment alone (its curves are in the section's figure).
        out2 = os.path.join(d, "out2")
        for seed, (c, w) in enumerate(zip(sac, walls), 1):
            write(out2, reference_result("sac", seed, c, w))
        for seed in (1, 2):
            write(out2, learn_result(seed, "actor_corridor", "example_gain_range=0.25,0.35", (139.0, 138.5, 138.2),
                                     walls=0))
        full = os.path.join(d, "full", "RESULTS.md")
        p = subprocess.run([VENV_PY, TOOL, "report", "--configs", confs, "--out", out2, "--report", full],
                           capture_output=True, text=True, timeout=300)
        if p.returncode != 0:
            fail("the full report failed: %s" % (p.stdout + p.stderr)[-3000:])
        with open(full) as f:
            text = f.read()
        if row(text, "SAC")[4] != want_1 or row(text, ACTOR_GENTLE)[4] != "1,400 (0)":
            fail("the full report's table differs from the section's")
        figs = os.listdir(os.path.join(d, "full", "figures"))
        if "ref_fixture.png" not in figs or any(f.startswith("actor_corridor") for f in figs):
            fail("the full report's figures: %r (the reference figure, and none of actor_corridor alone)" % figs)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
