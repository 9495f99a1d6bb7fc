# SPDX-License-Identifier: MIT
"""Environment steps per second, single process, for both tasks and both back-ends, through
gymnasium.make (with Gymnasium's default wrappers) and on the raw environment (env.unwrapped).

Rates are steps per second of the process's own CPU time (time.process_time) and of wall time.
On a machine shared by several jobs the wall rate falls with the load (this benchmark prints the
load average); the CPU-time rate is what one unshared core delivers, and the targets are checked
against it: kinematic >= 100,000 steps/s, ODE with the 181-beam laser >= 5,000 steps/s (checked on
the corridor task, whose laser features are the costlier; obstacles are printed too). Exits 1
when a target is missed.

Usage: bench_envs.py [seconds per case, default 3]
"""
import os
import sys
import time

import gymnasium
import numpy as np

import b21r_learn  # noqa: F401  (registers the environments)
from b21r_learn.envs import ENV_IDS

TARGETS = {"kinematic": 100_000.0, "ode": 5_000.0}


def steps_per_second(env, seconds):
    """Random actions (drawn beforehand), resets at episode ends. Returns (CPU-time rate, wall
    rate), each the best of three timed blocks."""
    actions = np.random.default_rng(0).uniform(-1.0, 1.0, size=(4096, 1)).astype(np.float32)
    env.reset(seed=1)
    best_cpu = best_wall = 0.0
    for _ in range(3):
        n, w0, c0 = 0, time.perf_counter(), time.process_time()
        deadline = w0 + seconds / 3.0
        while True:
            for k in range(512):
                _, _, term, trunc, _ = env.step(actions[(n + k) & 4095])
                if term or trunc:
                    env.reset()
            n += 512
            now = time.perf_counter()
            if now >= deadline:
                break
        cpu = time.process_time() - c0
        best_cpu = max(best_cpu, n / cpu if cpu > 0 else 0.0)
        best_wall = max(best_wall, n / (now - w0))
    return best_cpu, best_wall


def main():
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 3.0
    print("python.bench: load average %.2f %.2f %.2f on %d CPUs" % (os.getloadavg() + (os.cpu_count(),)))
    missed = []
    for backend in ("kinematic", "ode"):
        for task in ("corridor", "obstacles"):
            made = gymnasium.make(ENV_IDS[task], backend=backend)
            cpu, wall = steps_per_second(made, seconds)
            raw_cpu, raw_wall = steps_per_second(made.unwrapped, seconds)
            made.close()
            target = TARGETS[backend]
            checked = backend == "kinematic" or task == "corridor"
            ok = cpu >= target
            if checked and not ok:
                missed.append("%s/%s" % (task, backend))
            print("python.bench %-9s %-9s gymnasium.make: %8.0f steps/CPU-s (%8.0f wall)  raw env: %8.0f (%8.0f)"
                  "  target >= %.0f: %s" % (task, backend, cpu, wall, raw_cpu, raw_wall, target,
                                            ("met" if ok else "MISSED") if checked else "not checked"))
            sys.stdout.flush()
    if missed:
        print("python.bench: targets missed: %s" % ", ".join(missed))
        return 1
    print("python.bench: targets met")
    return 0


if __name__ == "__main__":
    sys.exit(main())
