#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.sweep: tools/b21r_experiments.py runs a sweep as Ray tasks (local Ray, 1 CPU) and
- writes one result file per (experiment, variant, seed);
- names a failed task with its error, exits non-zero, and keeps every other task's result;
- resumes: a second run skips the finished tasks and runs only the failed one again;
- never mixes builds: a result made by another build of b21r-experiment is run again;
- merges, draws and reports from the result files;
- runs the experiments a pattern names ('explore_*'), and reports the sensitivity study of
  learning without examples in a section of its own, which --section explore_study regenerates
  alone (before "Ablations" in a report without it; in place, with its prose, in one with it).
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

        # The sensitivity study of learning without examples (explore_* files, run by pattern) gets
        # its section; --section explore_study regenerates that section alone and keeps every other byte.
        with open(os.path.join(confs, "explore_tiny_hold.conf"), "w") as f:
            f.write("experiment.kind = explore_goal\nexperiment.seeds = 2\nexperiment.explore_runs = 3\n"
                    "experiment.explore_time_limit_s = 600\nexperiment.vary = experiment.explore_hold_s=0|1\n"
                    "task = obstacles\n")
        os.remove(broken)
        p = subprocess.run(cmd[:2] + ["explore_*"] + cmd[2:], capture_output=True, text=True, timeout=600)
        if p.returncode != 0 or "4 tasks, 0 finished" not in p.stdout:
            fail("run 'explore_*' should run the 4 tasks of explore_tiny_hold alone: %s" % (p.stdout + p.stderr)[-1500:])
        report = os.path.join(d, "docs", "RESULTS.md")
        before = "# Results\n\nintro. Text between `prose` markers is kept.\n\n## Other\n\nkept as it is\n\n## Ablations\n\nkept too\n"
        with open(report, "w") as f:
            f.write(before)
        p = subprocess.run([VENV_PY, TOOL, "report", "--configs", confs, "--out", out, "--report", report,
                            "--section", "explore_study"], capture_output=True, text=True, timeout=600)
        with open(report) as f:
            after = f.read()
        start, end = "<!-- section:explore_study -->\n", "<!-- /section:explore_study -->\n"
        if p.returncode != 0 or after.count(start) != 1 or after.count(end) != 1:
            fail("report --section explore_study should put the study's section in once: %s\n%s" % (
                (p.stdout + p.stderr)[-1500:], after[:3000]))
        head, rest = after.split(start)
        sec, tail = rest.split(end)
        if "## Learning without examples: which assumptions (sensitivity study)" not in sec or \
                "`explore_tiny_hold` | hold_s=0 |" not in sec or "|  | hold_s=1 |" not in sec or \
                tail.lstrip("\n") != "## Ablations\n\nkept too\n" or head != before[:before.index("## Ablations")]:
            fail("report --section explore_study should put the study's section before Ablations and keep the rest:"
                 "\n%s" % after[:3000])
        # Run again, the section is replaced in place and the people's prose in it is kept.
        mine = after.replace(sec[sec.index("<!-- prose:explore_study -->"):sec.index("<!-- /prose:explore_study -->")],
                             "<!-- prose:explore_study -->\nWhat the numbers mean.\n")
        with open(report, "w") as f:
            f.write(mine)
        p = subprocess.run([VENV_PY, TOOL, "report", "--configs", confs, "--out", out, "--report", report,
                            "--section", "explore_study"], capture_output=True, text=True, timeout=600)
        with open(report) as f:
            again = f.read()
        if p.returncode != 0 or again.count(start) != 1 or "What the numbers mean." not in again or \
                not again.startswith(head):
            fail("report --section explore_study should replace its section in place, prose kept:\n%s" % again[:3000])
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
