#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.sweep: tools/b21r_experiments.py runs a sweep as Ray tasks (local Ray, 1 CPU) and
- writes one result file per (experiment, variant, seed);
- names a failed task with its error, exits non-zero, and keeps every other task's result;
- resumes: a second run skips the finished tasks and runs only the failed one again;
- never mixes builds: a result made by another build of b21r-experiment is run again;
- merges, draws and reports from the result files.
Skipped (exit 77) when the sweep's packages (tools/requirements-experiments.txt) are not installed
in build/venv: tools/b21r_experiments.py installs them on first use; CI's set-up does not.
usage: test_sweep.py B21R_EXPERIMENT"""
import glob
import json
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
VENV_PY = os.path.join(REPO, "build", "venv", "bin", "python3")
TOOL = os.path.join(REPO, "tools", "b21r_experiments.py")


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def main():
    exe = sys.argv[1]
    probe = subprocess.run([VENV_PY, "-c", "import ray, scipy"], capture_output=True)
    if probe.returncode != 0:
        print("SKIP: Ray/SciPy are not installed in build/venv (tools/b21r_experiments.py installs them on first use)")
        return 77
    with tempfile.TemporaryDirectory(prefix="b21r-sweep-") as d:
        confs = os.path.join(d, "configs")
        os.makedirs(confs)
        with open(os.path.join(confs, "tiny_goal.conf"), "w") as f:
            f.write("experiment.kind = explore_goal\nexperiment.seeds = 2\nexperiment.explore_runs = 3\n"
                    "experiment.explore_time_limit_s = 600\nexperiment.vary = experiment.explore_start_distance_m=1|2\n"
                    "task = obstacles\n")
        broken = os.path.join(confs, "broken.conf")
        with open(broken, "w") as f:  # valid to plan, fails when run: the world file does not exist
            f.write("experiment.seeds = 1\nexperiment.world = missing.world\nphase_one_runs = 1\nphase_two_runs = 0\n")
        out = os.path.join(d, "out")
        cmd = [VENV_PY, TOOL, "run", "--configs", confs, "--runner", exe, "--out", out, "--num-cpus", "1"]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        text = p.stdout + p.stderr
        print(text[-3000:])
        if p.returncode == 0 or "FAILED broken seed 1" not in text or "missing.world" not in text:
            fail("the failed task was not named with its error and a non-zero exit status (%d)" % p.returncode)
        done = sorted(glob.glob(os.path.join(out, "results", "*", "*", "seed-*.json")))
        if len(done) != 4 or any("broken" in x for x in done):
            fail("expected the 4 results of tiny_goal, got %s" % done)
        if "[5/5]" not in text or "elapsed" not in text or "left" not in text:
            fail("no progress lines (done/total, elapsed, estimate)")
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        if "5 tasks, 4 finished already by this build" not in p.stdout or ", 1 to run" not in p.stdout:
            fail("a second run did not resume (skip the finished tasks): %s" % p.stdout[-1500:])
        with open(done[0]) as f:
            r = json.load(f)
        build = r.get("build")
        r["build"] = "0" * 16  # as if an older program had made it
        with open(done[0], "w") as f:
            json.dump(r, f)
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        with open(done[0]) as f:
            again = json.load(f).get("build")
        if "(1 of them made by another build: run again)" not in p.stdout or not build or again != build:
            fail("a result of another build was not run again (build %s -> %s): %s" % (build, again, p.stdout[-1500:]))
        p = subprocess.run([VENV_PY, TOOL, "merge", "figures", "report", "--configs", confs, "--out", out,
                            "--report", os.path.join(d, "docs", "RESULTS.md")], capture_output=True, text=True,
                           timeout=600)
        if p.returncode != 0 or not os.path.exists(os.path.join(out, "merged", "tiny_goal.json")):
            fail("merge/figures/report failed: %s" % (p.stdout + p.stderr)[-2000:])
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
