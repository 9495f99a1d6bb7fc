# SPDX-License-Identifier: MIT
"""Sweeps: every (experiment, variant, seed) of the chosen configs is one Ray task that runs
b21r-experiment and hands its result file's content back; the driver writes it atomically to
<out>/results/... . Finished tasks (a valid result file made by this very build of b21r-experiment:
each result records the SHA-256 of the program that made it) are skipped, so an interrupted sweep
is resumed by running the same command again, a result of an older build is run again instead of
being mixed with new ones, and result folders of several machines can be merged by copying them
together. A failed task is reported by name with its error; the others go on
and keep their results.

An experiment file with `experiment.kind = reference` (b21r_exp.reference: Stable-Baselines3
learners on the Gymnasium environments) is planned and run by that Python module instead of
b21r-experiment, in the same tasks, result layout and resume rules; its results record the
identity of that module, the packages' versions and the compiled environment instead.

Ray: `ray.init()` on this machine by default (all cores; --num-cpus to limit), or the cluster at
--address (every node needs this checkout at the same path and a build of b21r-experiment)."""
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass

from b21r_exp import reference, results


@dataclass(frozen=True)
class Task:
    experiment: str
    config: str
    variant: str
    seed: int

    def label(self):
        return "%s%s seed %d" % (self.experiment, " [%s]" % self.variant if self.variant else "", self.seed)


def plan(exe, config, seeds=None, named=True):
    """The experiment's plan from b21r-experiment --plan (b21r_exp.reference for a reference
    experiment): dict with name, kind, title, seeds, variants, and 'unavailable' (a reason) when
    this build cannot run it or when it runs only on request and was not named (named=False)."""
    if reference.is_reference(config):
        try:
            d = reference.plan(config)
        except reference.ConfigError as e:
            raise RuntimeError(str(e)) from None
        if d.pop("on_request") and not named:
            d["unavailable"] = "it runs only when named (tools/b21r_experiments.py run %s)" % d["name"]
    else:
        p = subprocess.run([exe, "--config", config, "--plan"], capture_output=True, text=True)
        if p.returncode != 0:
            raise RuntimeError("%s: %s" % (config, p.stderr.strip()))
        d = json.loads(p.stdout)
    if seeds is not None:
        d["seeds"] = list(range(d["seeds"][0], d["seeds"][0] + seeds))
    d["config"] = os.path.abspath(config)
    return d


def build_id(exe):
    """The identity of a b21r-experiment build: the first 16 hex digits of its SHA-256."""
    h = hashlib.sha256()
    with open(exe, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def tasks_of(p):
    """The plan's tasks, seed by seed (every variant of seed 1, then of seed 2, ...): a sweep on few
    CPUs has paired results of every variant early, and a stopped one leaves whole seeds."""
    return [Task(p["name"], p["config"], v, s) for s in p["seeds"] for v in p["variants"]]


def command_of(exe, p):
    """The program that runs the plan's tasks (a list): b21r-experiment, or this interpreter
    with b21r_exp.reference for a reference experiment."""
    return [sys.executable, "-m", "b21r_exp.reference"] if p["kind"] == reference.KIND else [exe]


def run_one(command, task, build):
    """Runs one task in a scratch folder; returns (ok, result text or error text, wall seconds).
    command: the program (a list, or the path of b21r-experiment). The result records `build`
    (the identity of that program)."""
    t0 = time.time()
    with tempfile.TemporaryDirectory(prefix="b21r-exp-") as d:
        out = os.path.join(d, "result.json")
        cmd = ([command] if isinstance(command, str) else list(command)) + [
            "--config", task.config, "--seed", str(task.seed), "--out", out]
        if task.variant:
            cmd += ["--variant", task.variant]
        # One thread per task (the reference learners' torch; numerical libraries).
        env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
        p = subprocess.run(cmd, capture_output=True, text=True, env=env)
        if p.returncode != 0:
            return False, "exit status %d: %s" % (p.returncode, p.stderr.strip()[-2000:]), time.time() - t0
        with open(out) as f:
            d = json.load(f)
        d["build"] = build
        return True, json.dumps(d, indent=1), time.time() - t0


def write_atomic(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def fmt_s(s):
    s = int(round(s))
    return "%d:%02d:%02d" % (s // 3600, s % 3600 // 60, s % 60) if s >= 3600 else "%d:%02d" % (s // 60, s % 60)


def run(exe, plans, out, address=None, num_cpus=None, rerun=False, log=print):
    """Runs every task of the plans not finished yet. Returns the list of (task, error) that failed."""
    all_tasks = [t for p in plans for t in tasks_of(p)]
    kinds = {p["name"]: p["kind"] for p in plans}
    builds = {}
    for k in sorted(set(kinds.values())):
        builds[k] = reference.build_id() if k == reference.KIND else build_id(exe)
    commands = {p["name"]: command_of(exe, p) for p in plans}

    def build_of(t):
        return builds[kinds[t.experiment]]

    done_before = {t: results.read_result(results.result_path(out, t.experiment, t.variant, t.seed)) for t in all_tasks}
    stale = [t for t, r in done_before.items() if r is not None and r.get("build") != build_of(t)]
    todo = [t for t in all_tasks if rerun or done_before[t] is None or t in stale]
    log("sweep: %d tasks, %d finished already by this build (%s), %d to run%s" % (
        len(all_tasks), len(all_tasks) - len(todo), ", ".join(sorted(set(builds.values()))), len(todo),
        " (%d of them made by another build: run again)" % len(stale) if stale and not rerun else ""))
    if not todo:
        return []
    import ray  # installed on first use by b21r_experiments.py

    if address:
        ray.init(address=address, log_to_driver=False)
    else:
        ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
    failed = []
    try:
        remote = ray.remote(num_cpus=1)(run_one)
        log("sweep: Ray with %d CPUs (%s)" % (int(ray.cluster_resources().get("CPU", 0)),
                                              "cluster at %s" % address if address else "this machine"))
        pending = {remote.remote(commands[t.experiment], t, build_of(t)): t for t in todo}
        t0 = time.time()
        done = 0
        task_seconds = 0.0
        last_note = t0
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1, timeout=10.0)
            now = time.time()
            for ref in ready:
                task = pending.pop(ref)
                done += 1
                try:
                    ok, text, secs = ray.get(ref)
                except Exception as exc:  # a worker died: the task failed, the sweep goes on
                    ok, text, secs = False, "Ray: %s" % exc, 0.0
                task_seconds += secs
                if ok:
                    write_atomic(results.result_path(out, task.experiment, task.variant, task.seed), text)
                else:
                    failed.append((task, text))
                    log("sweep: FAILED %s: %s" % (task.label(), text))
                elapsed = now - t0
                eta = elapsed / done * (len(todo) - done)
                log("sweep: [%d/%d] %s %s in %.0f s; elapsed %s, about %s left" % (
                    done, len(todo), "done" if ok else "FAILED", task.label(), secs, fmt_s(elapsed), fmt_s(eta)))
            if not ready and now - last_note > 30:
                log("sweep: [%d/%d] running; elapsed %s" % (done, len(todo), fmt_s(now - t0)))
                last_note = now
        wall = time.time() - t0
        log("sweep: %d tasks in %s (%.0f task-seconds), %d failed" % (len(todo), fmt_s(wall), task_seconds,
                                                                     len(failed)))
        # The report quotes the measured runtimes from here.
        os.makedirs(out, exist_ok=True)
        with open(os.path.join(out, "sweeps.jsonl"), "a") as f:
            f.write(json.dumps({"when": time.strftime("%Y-%m-%d %H:%M:%S"), "experiments": sorted({t.experiment for t in todo}),
                                "tasks": len(todo), "failed": len(failed), "wall_s": wall,
                                "task_seconds": task_seconds, "cpus": int(ray.cluster_resources().get("CPU", 0)),
                                "address": address or "local"}) + "\n")
    finally:
        ray.shutdown()
    return failed


def merge(out, configs_dir=None):
    """One file per experiment with every result (<out>/merged/<experiment>.json)."""
    data = results.load(out, configs_dir)
    paths = []
    for exp, variants in data.items():
        path = os.path.join(out, "merged", exp + ".json")
        write_atomic(path, json.dumps({"experiment": exp, "variants": variants}, indent=None))
        paths.append(path)
    return paths


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use tools/b21r_experiments.py")
