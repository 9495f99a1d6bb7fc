#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.report_doorway: `tools/b21r_experiments.py report --section doorway` regenerates the
doorway's section of an existing report from the result files and keeps every other line:
- two seeds of the doorway experiment on a short schedule (b21r-experiment, its own file);
- the section goes in before "Learning without examples" when the report has none, between its
  markers, with its figure, the claims (the learner against the example policy and the reference
  from the same poses), the comparators' table and how the runs ended;
- run again, it replaces the section in place and keeps the people's prose inside it;
- the whole report (no --section) holds the same section.
Skipped (exit 77) when the sweep's packages are not installed in build/venv (as experiments.sweep).
usage: test_report_doorway.py B21R_EXPERIMENT"""
import os
import subprocess
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
VENV_PY = os.path.join(REPO, "build", "venv", "bin", "python3")
TOOL = os.path.join(REPO, "tools", "b21r_experiments.py")
CONFIGS = os.path.join(REPO, "tools", "experiments")
SHORT = ["--set", "phase_one_runs=3", "--set", "phase_two_runs=3", "--set", "eval_every_runs=3",
         "--set", "eval_starts=2"]
BEFORE = "# Results\n\nIntro.\n\n## Obstacle avoidance (Figs. 7-10)\n\nObstacles.\n\n"
AFTER = "## Learning without examples: the corridor (Fig. 6)\n\nFig. 6.\n\n## All claims at a glance\n\nEnd.\n"


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


def report(out, path, *extra):
    p = subprocess.run([VENV_PY, TOOL, "report", "--configs", CONFIGS, "--out", out, "--report", path, *extra],
                       capture_output=True, text=True, timeout=600)
    if p.returncode != 0:
        fail("report %s: exit %d\n%s" % (" ".join(extra), p.returncode, (p.stdout + p.stderr)[-3000:]))
    with open(path) as f:
        return f.read()


def main():
    exe = sys.argv[1]
    probe = subprocess.run([VENV_PY, "-c", "import ray, scipy"], capture_output=True)
    if probe.returncode != 0:
        print("SKIP: Ray/SciPy are not installed in build/venv (tools/b21r_experiments.py installs them on first use)")
        return 77
    with tempfile.TemporaryDirectory(prefix="b21r-report-") as d:
        out = os.path.join(d, "out")
        for seed in (1, 2):
            res = os.path.join(out, "results", "doorway", "default", "seed-%d.json" % seed)
            os.makedirs(os.path.dirname(res), exist_ok=True)
            p = subprocess.run([exe, "--config", os.path.join(CONFIGS, "doorway.conf"), "--seed", str(seed), "--out", res,
                                *SHORT], capture_output=True, text=True, timeout=600)
            if p.returncode != 0:
                fail("b21r-experiment seed %d: %s" % (seed, p.stderr[-2000:]))
        path = os.path.join(d, "docs", "RESULTS.md")
        os.makedirs(os.path.dirname(path))
        with open(path, "w") as f:
            f.write(BEFORE + AFTER)
        text = report(out, path, "--section", "doorway")
        start, end = "<!-- section:doorway -->\n", "<!-- /section:doorway -->\n"
        if text.count(start) != 1 or text.count(end) != 1:
            fail("the section's markers are not there once:\n%s" % text)
        head, rest = text.split(start)
        section, tail = rest.split(end)
        if not head.startswith(BEFORE) or tail.lstrip("\n") != AFTER:
            fail("the other lines were not kept (before %r, after %r)" % (head[:200], tail[:200]))
        for want in ("## Doorway passing", "seeds 1-2", "the claim (the issue's", "example policy at its nominal gain",
                     "reference (\"optimal\") controller", "| learned policy, final block |", "How the runs ended",
                     "phase-one training runs (the example policy) goal", "figures/doorway.png",
                     "<!-- prose:doorway -->"):
            if want not in section:
                fail("the section lacks %r:\n%s" % (want, section))
        if not os.path.exists(os.path.join(d, "docs", "figures", "doorway.png")):
            fail("no figure docs/figures/doorway.png")
        # People's prose survives; the section is replaced in place, not added again.
        mine = text.replace(section[section.index("<!-- prose:doorway -->"):section.index("<!-- /prose:doorway -->")],
                            "<!-- prose:doorway -->\nWhat the numbers mean.\n")
        with open(path, "w") as f:
            f.write(mine)
        again = report(out, path, "--section", "doorway")
        if again.count(start) != 1 or "What the numbers mean." not in again or not again.startswith(BEFORE):
            fail("the section was not replaced in place with its prose kept:\n%s" % again)
        whole = report(out, path)
        if whole.count(start) != 1 or "What the numbers mean." not in whole or "## Doorway passing" not in whole:
            fail("the whole report lacks the doorway's section")
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
