#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_experiments: reproduce the paper's experiments (Smart & Kaelbling, ICRA 2002) in the
emulator, over many seeds, and regenerate the figures and docs/RESULTS.md.

Commands (default: all):
  run      build b21r-experiment (host-release preset) and run the sweep of the chosen
           experiments (tools/experiments/<name>.conf; default: every one) as Ray tasks, one
           result file per (experiment, variant, seed) under OUT/results; finished tasks are
           skipped (run again to resume; --rerun to redo)
  figures  the paper-style figures (PNG, with captions) from the result files
  report   docs/RESULTS.md: our numbers next to the paper's claims, every yes/no from a test
           (--section doorway, reference_learners or explore_study: only that section and its
           figures, the rest of the report kept, for when the other experiments' results are not
           at hand)
  merge    one JSON per experiment with all its results (OUT/merged)
  all      run, merge, figures, report
On first use it installs the sweep's Python packages (tools/requirements-experiments.txt: Ray,
SciPy) into build/venv, and Stable-Baselines3 and PyTorch (tools/requirements-reference.txt) the
first time a reference learner runs. Ray runs on this machine with all its cores unless --num-cpus or a
cluster --address is given; it is shut down when the command ends.
Examples:
  tools/b21r_experiments.py                                    # everything, 10 seeds each
  tools/b21r_experiments.py run fig4_corridor_examples --seeds 3
  tools/b21r_experiments.py run 'explore_*'                   # every file the pattern matches
  tools/b21r_experiments.py figures report
  tools/b21r_experiments.py run report doorway --section doorway   # the doorway task, 10 seeds, its section
  tools/b21r_experiments.py run reference_learners --num-cpus 1   # SAC and PPO from scratch
  tools/b21r_experiments.py run report 'explore_*' --section explore_study   # the sensitivity study, its section
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure(need_types=False)

import argparse
import glob
import hashlib
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = b21r_bootstrap.REPO
CONFIGS = REPO / "tools" / "experiments"
REQUIREMENTS = REPO / "tools" / "requirements-experiments.txt"
REFERENCE_REQUIREMENTS = REPO / "tools" / "requirements-reference.txt"
PRESET = "host-release"


def say(msg):
    print("experiments: %s" % msg, flush=True)


def ensure_packages(requirements=REQUIREMENTS, what="the sweep's Python packages"):
    """Installs a requirements file into the venv when it changed since its last install (a stamp
    per file in the venv)."""
    stamp = b21r_bootstrap.VENV / (".%s.sha256" % requirements.stem)
    want = hashlib.sha256(requirements.read_bytes()).hexdigest()
    if stamp.exists() and stamp.read_text().strip() == want:
        return
    say("installing %s (%s) into %s" % (what, requirements.name, b21r_bootstrap.VENV))
    subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                           "-r", str(requirements)])
    stamp.write_text(want + "\n")


def ensure_runner(jobs, python_module=False):
    """Configures (once) and builds b21r-experiment in the host-release preset (and, with
    python_module, the environments' Python module the reference learners use); returns its path."""
    build = REPO / "build" / PRESET
    log = REPO / "build" / "experiments-build.log"
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        if not (build / "build.ninja").exists():
            say("configuring the %s preset" % PRESET)
            if subprocess.call(["cmake", "--preset", PRESET], cwd=REPO, stdout=f, stderr=subprocess.STDOUT) != 0:
                sys.exit("experiments: configuring failed (log: %s)" % log)
        targets = ["b21r_experiment"] + (["b21r_learn_core"] if python_module else [])
        say("building %s (%s preset, -j%d)" % (", ".join(targets), PRESET, jobs))
        if subprocess.call(["cmake", "--build", "--preset", PRESET, "-j", str(jobs), "--target"] + targets,
                           cwd=REPO, stdout=f, stderr=subprocess.STDOUT) != 0:
            sys.exit("experiments: building b21r-experiment failed (log: %s)" % log)
    return str(build / "bin" / "b21r-experiment")


def config_paths(configs, names):
    """The experiment files of the names given (all when none); a name may be a shell pattern
    ('explore_*', quoted), which stands for every file it matches."""
    if not names:
        return sorted(glob.glob(str(configs / "*.conf")))
    paths = []
    for n in names:
        pattern = n if n.endswith(".conf") else n + ".conf"
        found = sorted(glob.glob(str(configs / pattern))) if any(c in pattern for c in "*?[") else \
            [str(configs / pattern)] if (configs / pattern).exists() else []
        if not found:
            known = ", ".join(sorted(os.path.basename(x)[:-5] for x in glob.glob(str(configs / "*.conf"))))
            sys.exit("experiments: no experiment '%s' (%s has: %s)" % (n, configs, known))
        paths += [p for p in found if p not in paths]
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("words", nargs="*", metavar="COMMAND|EXPERIMENT",
                    help="commands (run, figures, report, merge, all) then experiment names")
    ap.add_argument("--seeds", type=int, help="seeds per experiment (default: each file's experiment.seeds)")
    ap.add_argument("--out", default=str(REPO / "build" / "experiments"), help="results folder (default build/experiments)")
    ap.add_argument("--report", default=str(REPO / "docs" / "RESULTS.md"), help="report file; figures go to its figures/")
    ap.add_argument("--address", help="Ray cluster address (default: a local Ray on this machine)")
    ap.add_argument("--num-cpus", type=int, help="local Ray: CPUs to use (default: all)")
    ap.add_argument("--jobs", type=int, default=2, help="build parallelism (default 2)")
    ap.add_argument("--rerun", action="store_true", help="run finished tasks again")
    ap.add_argument("--configs", default=str(CONFIGS), help="folder of the experiment files (default tools/experiments)")
    ap.add_argument("--runner", help="use this b21r-experiment instead of building the host-release one")
    ap.add_argument("--section", metavar="NAME",
                    help="figures, report: only this section of an existing report (and its figures); an "
                         "unknown name lists them")
    args = ap.parse_args()
    commands = [w for w in args.words if w in ("run", "figures", "report", "merge", "all")]
    names = [w for w in args.words if w not in commands]
    if not commands:
        commands = ["all"]
    if "all" in commands:
        commands = ["run", "merge", "figures", "report"]
    ensure_packages()
    from b21r_exp import figures, reference, report, sweep  # after the packages exist

    # The report's table of sections is the one list of them (its module needs the packages).
    if args.section is not None and args.section not in report.SECTIONS:
        ap.error("--section: one of %s" % ", ".join(sorted(report.SECTIONS)))

    status = 0
    configs = Path(args.configs).resolve()
    if "run" in commands:
        paths = config_paths(configs, names)
        python_module = any(reference.is_reference(c) for c in paths)
        if python_module:  # Stable-Baselines3 and torch: only for the reference learners (about 5 GB)
            ensure_packages(REFERENCE_REQUIREMENTS, "the reference learners' packages")
        exe = os.path.abspath(args.runner) if args.runner else ensure_runner(args.jobs, python_module)
        plans = []
        for c in paths:
            p = sweep.plan(exe, c, args.seeds, named=bool(names))
            if "unavailable" in p:
                say("skipping %s: %s" % (p["name"], p["unavailable"]))
                continue
            plans.append(p)
        os.environ["PYTHONPATH"] = os.pathsep.join([str(REPO / "tools")] + [x for x in os.environ.get("PYTHONPATH", "").split(os.pathsep) if x])
        t0 = time.time()
        failed = sweep.run(exe, plans, args.out, address=args.address, num_cpus=args.num_cpus, rerun=args.rerun,
                           log=lambda m: print(m, flush=True))
        say("sweep finished in %.0f s" % (time.time() - t0))
        if failed:
            say("%d task(s) FAILED (their results are missing; the others are kept):" % len(failed))
            for task, err in failed:
                say("  %s: %s" % (task.label(), err.splitlines()[-1] if err else "?"))
            status = 1
    if "merge" in commands:
        for p in sweep.merge(args.out, str(configs)):
            say("merged: %s" % p)
    fig_dir = os.path.join(os.path.dirname(os.path.abspath(args.report)), "figures")
    if "figures" in commands:
        for p in figures.make_all(args.out, fig_dir, str(configs),
                                  only=report.SECTIONS[args.section]["figures"](str(configs)) if args.section else None):
            say("figure: %s" % p)
    if "report" in commands:
        if args.section:
            if not os.path.exists(args.report):
                sys.exit("experiments: --section needs an existing report (%s); run the report without it" % args.report)
            report.write_section(args.out, fig_dir, args.report, str(configs), args.section)
            say("report: section %s of %s" % (args.section, args.report))
        else:
            report.write(args.out, fig_dir, args.report, str(configs))
            say("report: %s" % args.report)
    return status


if __name__ == "__main__":
    sys.exit(main())
