#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""experiments.explore_study: the assumptions the sensitivity study of learning without examples
varies (experiment.explore_*, tools/experiments/explore_*.conf) do what their keys say.
- The paper's two studies with their defaults give the runs the runner gave before these keys
  existed (Fig. 6 at 1 rad/s, seed 3; Table I from 2 m, seed 4: recorded from that runner).
- collision = stay without a step limit: one attempt per run, the robot meets the walls and still
  reaches the end of the corridor; restart: several attempts.
- restart_s charges exactly (attempts - 1) x restart_s of robot time and changes nothing else
  (the same seeds drive the same attempts).
- hold_s: a random translation held for a whole run (one draw) reaches a goal 0.2 m in front of
  the robot's disc only when the draw is positive (about half the runs); drawn every period it is
  a recurrent random walk that reaches it in most runs.
- random = translation: the robot no longer drives at the task's 0.3 m/s (every success after the
  straight drive's 2.4 s in some runs); random = rotation keeps that speed.
- the arena's walls with restart: collisions end attempts (the open plane has none).
- the ODE back-end reaches the corridor's end, is a function of its seed, and differs from the
  kinematic model; it refuses assumptions it cannot model (stay, a random translation).
- a bad value of a choice key is refused naming the key and its choices.
usage: test_explore_study.py B21R_EXPERIMENT CONFIG_DIR"""
import json
import os
import subprocess
import sys
import tempfile


def fail(msg):
    print("FAIL: " + msg)
    sys.exit(1)


class Runner:
    def __init__(self, exe, configs, d):
        self.exe, self.configs, self.d, self.n = exe, configs, d, 0

    def runs(self, conf, seed, **keys):
        """The runs of one result (list of dicts) with experiment.explore_<key>=value overrides."""
        self.n += 1
        out = os.path.join(self.d, "r%d.json" % self.n)
        cmd = [self.exe, "--config", os.path.join(self.configs, conf + ".conf"), "--seed", str(seed), "--out", out]
        for k, v in keys.items():
            cmd += ["--set", "experiment.explore_%s=%s" % (k, v)]
        p = subprocess.run(cmd, capture_output=True, text=True)
        if p.returncode != 0:
            fail("%s: %s" % (" ".join(cmd), p.stderr))
        with open(out) as f:
            r = json.load(f)
        self.last = r["explore"]
        return r["explore"]["runs"]


def main():
    exe, configs = sys.argv[1:3]
    with tempfile.TemporaryDirectory(prefix="b21r-explore-") as d:
        rr = Runner(exe, configs, d)
        key = lambda runs: [(x["success"], x["time_s"], x["episodes"]) for x in runs]  # noqa: E731
        got = key(rr.runs("fig6_explore_corridor", 3, omega_max_radps=1, runs=4))
        if got != [(True, 314.8, 87), (True, 194.2, 56), (True, 51.8, 9), (True, 42.9, 10)]:
            fail("Fig. 6's defaults no longer give the runs they gave: %s" % got)
        got = key(rr.runs("table1_explore_goal", 4, start_distance_m=2, runs=6, time_limit_s=7200))
        if got != [(True, 5.9, 1), (True, 6.3, 1), (False, 7200, 1), (True, 5.7, 1), (True, 6.3, 1), (True, 6.4, 1)]:
            fail("Table I's defaults no longer give the runs they gave: %s" % got)

        stay = rr.runs("fig6_explore_corridor", 1, omega_max_radps=1, runs=5, collision="stay", attempt_steps=0)
        restart = rr.runs("fig6_explore_corridor", 1, omega_max_radps=1, runs=5)
        if not all(x["success"] and x["episodes"] == 1 for x in stay) or sum(x["contacts"] for x in stay) == 0:
            fail("stay without a step limit: one attempt per run, walls met, the end reached: %s" % stay)
        if max(x["episodes"] for x in restart) < 2:
            fail("restart: collisions should end attempts: %s" % restart)
        print("corridor, 5 runs: stay %s wall contacts in 1 attempt each; restart %s attempts" % (
            [x["contacts"] for x in stay], [x["episodes"] for x in restart]))

        free = rr.runs("fig6_explore_corridor", 3, omega_max_radps=1, runs=4)
        paid = rr.runs("fig6_explore_corridor", 3, omega_max_radps=1, runs=4, restart_s=30)
        for a, b in zip(free, paid):
            if (a["episodes"], a["driving_s"], a["success"]) != (b["episodes"], b["driving_s"], b["success"]) or \
                    abs(b["time_s"] - b["driving_s"] - 30 * (b["episodes"] - 1)) > 1e-6:
                fail("restart_s = 30 should add 30 s per restart and nothing else: %s vs %s" % (a, b))

        once = rr.runs("table1_explore_goal", 2, start_distance_m=0.5, runs=20, time_limit_s=999, random="translation",
                       hold_s=1000)
        every = rr.runs("table1_explore_goal", 2, start_distance_m=0.5, runs=20, time_limit_s=999, random="translation")
        k_once, k_every = sum(x["success"] for x in once), sum(x["success"] for x in every)
        if not (4 <= k_once <= 15 and k_every >= 16):
            fail("a translation held for the whole run should reach the goal about half the time (%d/20), drawn "
                 "every period most of the time (%d/20)" % (k_once, k_every))
        print("goal from 0.5 m, random translation: %d/20 with one draw per run, %d/20 drawn every period" % (
            k_once, k_every))
        rot = rr.runs("table1_explore_goal", 2, start_distance_m=1, runs=10, time_limit_s=7200)
        trans = rr.runs("table1_explore_goal", 2, start_distance_m=1, runs=10, time_limit_s=7200, random="translation")
        if not all(x["time_s"] < 5 for x in rot if x["success"]) or \
                max(x["time_s"] for x in trans if x["success"]) < 60 or rr.last["translation"] != "normal":
            fail("random = translation should replace the task's speed: rotation %s, translation %s" % (rot, trans))

        walls = rr.runs("table1_explore_goal", 1, runs=10, time_limit_s=3600, arena_walls="true")
        plane = rr.runs("table1_explore_goal", 1, runs=10, time_limit_s=3600)
        if sum(x["contacts"] for x in walls) == 0 or max(x["episodes"] for x in walls) < 2 or \
                any(x["contacts"] or x["episodes"] != 1 for x in plane):
            fail("the arena's walls should end attempts, the open plane none: %s vs %s" % (walls, plane))

        ode = rr.runs("fig6_explore_corridor", 1, omega_max_radps=1, runs=2, model="ode")
        if rr.last["model"] != "ode" or not all(x["success"] for x in ode):
            fail("the ODE back-end should reach the corridor's end: %s" % ode)
        if rr.runs("fig6_explore_corridor", 1, omega_max_radps=1, runs=2, model="ode") != ode:
            fail("the ODE back-end should be a function of its seed")
        if rr.runs("fig6_explore_corridor", 1, omega_max_radps=1, runs=2, accel_limits="true") == ode:
            fail("the ODE back-end gave the kinematic model's runs")
        print("corridor on the ODE emulator, 2 runs: %s" % [(x["time_s"], x["episodes"]) for x in ode])

        for keys, words in ((("model=ode", "collision=stay"), ("explore_model = ode", "explore_collision = restart")),
                            (("model=ode", "random=both"), ("explore_model = ode", "explore_random = rotation")),
                            (("collision=bounce",), ("experiment.explore_collision", "one of restart, stay"))):
            cmd = [exe, "--config", os.path.join(configs, "fig6_explore_corridor.conf"), "--plan"]
            for k in keys:
                cmd += ["--set", "experiment.explore_" + k]
            p = subprocess.run(cmd, capture_output=True, text=True)
            if p.returncode != 2 or not all(w in p.stderr for w in words):
                fail("%s should be refused naming %s (%d): %s" % (keys, words, p.returncode, p.stderr))
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
