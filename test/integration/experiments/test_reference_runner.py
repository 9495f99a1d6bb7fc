#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.reference_runner: a reference learner (b21r_exp.reference, Stable-Baselines3) runs
through the sweep like the other experiments:
- a short SAC run (300 training steps on B21rCorridor-v0, kinematic model, an evaluation every 100)
  writes one result file with the fields the report uses: an evaluation before training and after
  every 100 training steps, each with its training steps, the training episodes so far and those
  that ended on a wall (the training episodes' own record agrees), 10 runs from the evaluation
  poses with failures at the step limit; the optimal controller from the same poses (137.3 steps on
  the kinematic model); the hyperparameters in force (SAC's defaults) and the packages' versions;
  the identity of the program that made it;
- the same seed gives the same result (deterministic), a second sweep skips the finished task;
- an experiment file with a misspelt key or a bad value is refused with file:line; one marked
  experiment.on_request is skipped unless named.
Skipped (exit 77) when the sweep's packages (Ray, Stable-Baselines3, PyTorch) are not installed
in build/venv: tools/b21r_experiments.py installs them on first use; CI's set-up does not.
usage: test_reference_runner.py B21R_EXPERIMENT"""
import glob
import json
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
VENV_PY = os.path.join(REPO, "build", "venv", "bin", "python3")
TOOL = os.path.join(REPO, "tools", "b21r_experiments.py")
CONF = """experiment.kind = reference
experiment.seeds = 1
experiment.vary = reference.algorithm=sac
reference.env = B21rCorridor-v0
reference.backend = kinematic
reference.train_steps_sac = 300
reference.eval_every_steps = 100
"""


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def module(*args):
    env = dict(os.environ, PYTHONPATH=os.path.join(REPO, "tools"), OMP_NUM_THREADS="1")
    return subprocess.run([VENV_PY, "-m", "b21r_exp.reference", *args], capture_output=True, text=True, env=env,
                          timeout=300)


def main():
    exe = sys.argv[1]
    probe = subprocess.run([VENV_PY, "-c", "import ray, scipy, stable_baselines3, torch, b21r_learn"],
                           capture_output=True)
    if probe.returncode != 0:
        print("SKIP: Ray, Stable-Baselines3 or PyTorch is not installed in build/venv "
              "(tools/b21r_experiments.py installs them on first use)")
        return 77
    with tempfile.TemporaryDirectory(prefix="b21r-ref-") as d:
        confs = os.path.join(d, "configs")
        os.makedirs(confs)
        conf = os.path.join(confs, "tiny_sac.conf")
        with open(conf, "w") as f:
            f.write(CONF)
        with open(os.path.join(confs, "later.conf"), "w") as f:
            f.write(CONF + "experiment.on_request = true\n")
        bad = os.path.join(d, "bad.conf")
        with open(bad, "w") as f:
            f.write("experiment.kind = reference\nreference.algoritm = sac\n")
        p = module("--config", bad, "--plan")
        if p.returncode != 2 or "bad.conf:2" not in p.stderr or "reference.algoritm" not in p.stderr:
            fail("a misspelt key was not refused with file:line (%d): %s" % (p.returncode, p.stderr))
        with open(bad, "w") as f:
            f.write("experiment.kind = reference\nexperiment.vary = reference.algorithm=sac|a2c\n")
        p = module("--config", bad, "--plan")
        if p.returncode != 2 or "bad.conf:2" not in p.stderr or "'a2c'" not in p.stderr:
            fail("a bad variant was not refused with file:line (%d): %s" % (p.returncode, p.stderr))

        out = os.path.join(d, "out")
        cmd = [VENV_PY, TOOL, "run", "--configs", confs, "--runner", exe, "--out", out, "--num-cpus", "1"]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        text = p.stdout + p.stderr
        print(text[-2000:])
        if p.returncode != 0 or "skipping later: it runs only when named" not in text:
            fail("the sweep failed or ran the on-request experiment unnamed (%d)" % p.returncode)
        files = sorted(glob.glob(os.path.join(out, "results", "*", "*", "seed-*.json")))
        want = os.path.join(out, "results", "tiny_sac", "reference.algorithm=sac", "seed-1.json")
        if files != [want]:
            fail("expected the one result %s, got %s" % (want, files))
        with open(want) as f:
            r = json.load(f)
        R = r["reference"]
        if r["format"] != "b21r-experiment-result/1" or r["kind"] != "reference" or r["seed"] != 1 or \
                r["task"] != "corridor" or r["step_limit"] != 1000 or not r.get("build", "").startswith("ref-"):
            fail("result header: %s" % {k: v for k, v in r.items() if k != "reference"})
        if R["algorithm"] != "sac" or R["backend"] != "kinematic" or R["train_steps"] != 300:
            fail("learner, back-end or training steps: %s %s %s" % (R["algorithm"], R["backend"], R["train_steps"]))
        h = R["hyperparameters"]
        if h.get("learning_rate") != 0.0003 or h.get("batch_size") != 256 or h.get("learning_starts") != 100 or \
                h.get("gamma") != 0.99 or h.get("ent_coef") != "auto":
            fail("not SAC's default hyperparameters: %s" % h)
        if not R["versions"].get("stable_baselines3") or not R["versions"].get("torch"):
            fail("package versions missing: %s" % R["versions"])
        opt = R["optimal"]
        if abs(sum(opt["steps"]) / 10.0 - 137.3) > 1e-9 or opt["successes"] != 10:
            fail("the optimal controller from the 10 poses: %s" % opt)
        evals = R["evaluations"]
        if [e["training_steps"] for e in evals] != [0, 100, 200, 300]:
            fail("evaluations at training steps %s, expected 0, 100, 200, 300" % [e["training_steps"] for e in evals])
        ends = []  # cumulative training steps at the end of each training episode
        for x in R["episodes"]:
            ends.append((ends[-1] if ends else 0) + x["steps"])
            if x["reason"] not in ("goal", "collision", "step_limit"):
                fail("an episode's reason: %s" % x)
        for e in evals:
            done = [x for x, t in zip(R["episodes"], ends) if t <= e["training_steps"]]
            if e["training_episodes"] != len(done) or \
                    e["wall_episodes"] != sum(1 for x in done if x["reason"] == "collision"):
                fail("evaluation at %d: %d episodes (%d on a wall), the episodes say %d (%d)" % (
                    e["training_steps"], e["training_episodes"], e["wall_episodes"], len(done),
                    sum(1 for x in done if x["reason"] == "collision")))
            if len(e["steps"]) != 10 or e["successes"] != sum(e["success"]) or \
                    abs(e["mean_all"] - sum(e["steps"]) / 10.0) > 1e-9 or \
                    any(s != 1000 for s, ok in zip(e["steps"], e["success"]) if not ok):
                fail("an evaluation's runs (failures at the step limit 1000): %s" % e)
        if evals[-1]["wall_episodes"] == 0:
            fail("no training episode of an untrained SAC ended on a wall in 300 steps: is info['reason'] read?")

        # Deterministic: the same seed again, by hand, gives the same evaluations and episodes.
        again = os.path.join(d, "again.json")
        p = module("--config", conf, "--seed", "1", "--variant", "reference.algorithm=sac", "--out", again)
        if p.returncode != 0:
            fail("by hand: %s" % p.stderr[-2000:])
        with open(again) as f:
            R2 = json.load(f)["reference"]

        def strip(x):
            return [{k: v for k, v in e.items() if k != "wall_time_s"} for e in x["evaluations"]]

        if strip(R2) != strip(R) or R2["episodes"] != R["episodes"]:
            fail("the same seed gave another result")
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if "1 tasks, 1 finished already by this build" not in p.stdout:
            fail("a second sweep did not skip the finished task: %s" % p.stdout[-1500:])
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
