# SPDX-License-Identifier: MIT
"""The Python environment computes the same numbers as the controller.

Claim checked: with the emulator seeded alike, an episode of B21rCorridor-v0 / B21rObstacles-v0
(ODE back-end) started at the controller's start pose and given the controller's actions yields,
step by step, bit-identical observations, executed (clamped) actions, rewards and terminations as
the controller's own run: the unmodified controller loop (fw_loop) in lockstep with the emulator
linked in-process (controller_trace), driven through its joystick input by a noisy policy (with
bursts that hit the acceleration clamp). Scenarios: corridor runs that reach the goal, corridor
runs cut by a step limit of 40, obstacle runs (goal or collision). Several consecutive runs per
scenario check that a reset reproduces the controller's sequence between runs.

Also checked: the controller's checkpoint payload loads into the Python Hedger configured with
controller_learner_config(), and gives the same predictions as the C library loaded from it.

Usage: test_env_equivalence.py <controller_trace> <sim/worlds dir> <work dir>
"""
import json
import pathlib
import subprocess
import sys
import unittest

import numpy as np

import b21r_learn  # noqa: F401  (registers the environments)
import gymnasium

TRACE = None
WORLDS = None
WORK = None

# (name, task, world file, seed, runs, max_steps_per_run)
SCENARIOS = [
    ("corridor_goal", "corridor", "corridor10.world", 7, 4, 0),
    ("corridor_step_limit", "corridor", "corridor10.world", 11, 3, 40),
    ("obstacles", "obstacles", "obstacle1.world", 4, 4, 0),
]


def controller_runs(name, task, world, seed, runs, max_steps):
    WORK.mkdir(parents=True, exist_ok=True)
    out = WORK / (name + ".json")
    ckpt = WORK / (name + ".ckpt")
    subprocess.run([str(TRACE), str(WORLDS / world), task, str(seed), str(runs), str(max_steps), str(out),
                    str(ckpt)], check=True)
    return json.loads(out.read_text())


class EnvironmentEqualsController(unittest.TestCase):
    def check_scenario(self, name, task, world, seed, runs, max_steps):
        trace = controller_runs(name, task, world, seed, runs, max_steps)
        self.assertGreaterEqual(len(trace["runs"]), 2 if trace["collided"] else runs,
                                "the controller produced too few runs to compare")
        spec = {"step_limit": max_steps} if max_steps > 0 else {}
        env = gymnasium.make(b21r_learn.envs.ENV_IDS[task], backend="ode", spec=spec)
        compared = 0
        for k, run in enumerate(trace["runs"]):
            steps = run["steps"]
            obs, _ = env.reset(seed=seed if k == 0 else None, options={"pose": tuple(run["start"])})
            for i, st in enumerate(steps):
                where = "%s run %d step %d" % (name, k, i)
                np.testing.assert_array_equal(obs, np.array(st["s"]), err_msg=where + ": state")
                obs, reward, terminated, truncated, info = env.step(np.array([st["raw"]], dtype=np.float64))
                self.assertEqual(info["action"], st["a"], where + ": executed action")
                np.testing.assert_array_equal(obs, np.array(st["s_next"]), err_msg=where + ": next state")
                self.assertEqual(reward, st["r"], where + ": reward")
                self.assertEqual(terminated, st["terminal"], where + ": terminal")
                last = i == len(steps) - 1
                self.assertEqual(terminated or truncated, last, where + ": end of the run")
                compared += 1
            if max_steps > 0 and not steps[-1]["terminal"]:
                self.assertEqual(len(steps), max_steps)
                self.assertTrue(truncated, "%s run %d: the step limit truncates" % (name, k))
        env.close()
        print("%s: %d runs, %d steps identical (%s)" % (name, len(trace["runs"]), compared,
                                                         "ends with a collision" if trace["collided"] else "no collision"))
        return trace

    def check_checkpoint(self, trace, task):
        # The controller's checkpoint payload in the Python Hedger: same predictions as the C side.
        # The payload is HEDGER's bytes, then the actor's section (its size in the progress section).
        meta, payload = b21r_learn.read_checkpoint(trace["checkpoint"])
        progress = b21r_learn.read_checkpoint_progress(meta)
        values = payload[:len(payload) - progress["actor_bytes"]]
        self.assertEqual(progress["policy"] == "actor", progress["actor_bytes"] > 0)
        h = b21r_learn.Hedger(**b21r_learn.controller_learner_config(task, {"decision_ticks": 1}))  # the trace's
        h.load(payload)
        self.assertEqual(len(h), trace["store_fill"])
        self.assertEqual(h.save(), values, "save() writes the controller's HEDGER bytes again")
        rotation = h.config["state_dim"] > len(trace["runs"][0]["steps"][0]["s"])  # state_rotation
        for run in trace["runs"]:
            executed = 0.0  # the learner's state ends with the last command sent, 0 at a run's start
            for st in run["steps"]:
                learner_s = np.append(st["s"], executed) if rotation else np.array(st["s"])
                np.testing.assert_array_equal(learner_s, np.array(st["learner_s"]))
                executed = st["a"]
                p = h.predict(learner_s, st["a"])
                self.assertEqual(p.value, st["q"])
                self.assertEqual(p.kind, st["q_kind"])

    def test_corridor_goal_runs(self):
        trace = self.check_scenario(*SCENARIOS[0])
        self.assertTrue(any(run["steps"][-1]["r"] > 0 for run in trace["runs"]), "some run reaches the goal")
        self.check_checkpoint(trace, "corridor")

    def test_corridor_step_limit_runs(self):
        trace = self.check_scenario(*SCENARIOS[1])
        self.assertTrue(all(not run["steps"][-1]["terminal"] for run in trace["runs"]))

    def test_obstacle_runs(self):
        trace = self.check_scenario(*SCENARIOS[2])
        self.check_checkpoint(trace, "obstacles")


def main():
    global TRACE, WORLDS, WORK
    if len(sys.argv) != 4:
        print(__doc__)
        return 2
    TRACE, WORLDS, WORK = (pathlib.Path(a) for a in sys.argv[1:4])
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
