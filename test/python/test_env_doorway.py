# SPDX-License-Identifier: MIT
"""B21rDoorway-v0: the doorway task's environment, which comes from its declaration in lib/tasks
with no Python code of its own, on both back-ends: Gymnasium's env_checker, the example driver and
the reference from the evaluation poses, and the reward and termination at the goal, on a
collision and at the step limit.
"""
import sys
import unittest

import gymnasium
import numpy as np
from gymnasium.utils.env_checker import check_env

import b21r
import b21r_learn
from b21r_learn import _core
from b21r_learn.envs import ENV_IDS

BACKENDS = ("ode", "kinematic")


def make(backend, **kwargs):
    return gymnasium.make("B21rDoorway-v0", backend=backend, **kwargs)


def drive(env, driver, options, seed=1):
    """One episode with the driver's actions; returns (rewards, final info, terminated, truncated)."""
    env.reset(seed=seed, options=options)
    driver.begin_run(seed)
    rewards = []
    while True:
        a = env.unwrapped.driver_action(driver)
        _, r, term, trunc, info = env.step(np.array([a], dtype=np.float32))
        rewards.append(r)
        if term or trunc:
            return rewards, info, term, trunc


class Doorway(unittest.TestCase):
    def test_registered_from_the_declaration(self):
        # The id comes from the registry (lib/tasks), and the messages name the task byte.
        tasks = {t["name"]: t for t in _core.tasks()}
        self.assertEqual(tasks["doorway"]["env_id"], "B21rDoorway-v0")
        self.assertEqual(ENV_IDS["doorway"], "B21rDoorway-v0")
        self.assertIn("B21rDoorway-v0", gymnasium.registry)
        self.assertEqual(len(tasks["doorway"]["state_names"]), 4)
        for name, t in tasks.items():
            self.assertEqual(getattr(b21r.experience_t, "TASK_" + name.upper()), t["id"])

    def test_env_checker_passes(self):
        for backend in BACKENDS:
            with self.subTest(backend=backend):
                env = make(backend, render_mode="rgb_array")
                check_env(env.unwrapped, skip_render_check=False)
                env.close()

    def test_example_driver_reaches_the_goal_from_most_poses(self):
        # The sloppy example at its nominal gain: most poses end at the goal with +1 (terminated),
        # the others on a jamb with -1 (terminated); every step before the last is rewarded 0. The
        # reference reaches the goal from every pose, in fewer steps where both do.
        for backend in BACKENDS:
            with self.subTest(backend=backend):
                env = make(backend)
                example = b21r_learn.Driver("proportional", "doorway", gain=1.5)
                reference = b21r_learn.Driver("optimal", "doorway")
                ends, faster = {"goal": 0, "collision": 0}, 0
                for i in range(10):
                    opts = {"start": "eval", "eval_index": i}
                    rewards, info, term, trunc = drive(env, example, opts)
                    self.assertTrue(term)
                    self.assertFalse(trunc)
                    self.assertIn(info["reason"], ends)
                    ends[info["reason"]] += 1
                    self.assertEqual(rewards[-1], 1.0 if info["reason"] == "goal" else -1.0)
                    self.assertTrue(all(r == 0.0 for r in rewards[:-1]))
                    truth = env.unwrapped.core.truth()
                    if info["reason"] == "goal":
                        gx, gy, gr = env.unwrapped.core.world()["goal"]
                        self.assertLessEqual(np.hypot(truth["pose"][0] - gx, truth["pose"][1] - gy), gr + 0.05)
                    else:
                        self.assertTrue(truth["collided"])
                    ref_rewards, ref_info, ref_term, _ = drive(env, reference, opts)
                    self.assertEqual(ref_info["reason"], "goal")
                    self.assertTrue(ref_term)
                    self.assertEqual(sum(ref_rewards), 1.0)
                    if info["reason"] == "goal" and ref_info["steps"] < info["steps"]:
                        faster += 1
                print("%s: example at gain 1.5 from the 10 poses: %s; the reference faster from %d of its %d goals" %
                      (backend, ends, faster, ends["goal"]))
                self.assertGreaterEqual(ends["goal"], 7)
                self.assertGreaterEqual(faster, ends["goal"] // 2)

    def test_collision_goal_and_step_limit(self):
        for backend in BACKENDS:
            with self.subTest(backend=backend):
                # Straight at the wall beside the door: -1 and the end, at the wall.
                env = make(backend)
                env.reset(seed=2, options={"pose": (-1.0, 1.5, 0.0)})
                for _ in range(100):
                    _, r, term, trunc, info = env.step(np.zeros(1, dtype=np.float32))
                    if term or trunc:
                        break
                self.assertTrue(term)
                self.assertEqual((r, info["reason"]), (-1.0, "collision"))
                x = env.unwrapped.core.truth()["pose"][0]
                self.assertGreater(x, -0.05 - 0.26 - 0.1)  # the robot's edge at the wall's face
                # Through the middle of the door from just before it: +1 at the goal.
                env.reset(seed=2, options={"pose": (-0.6, 0.0, 0.0)})
                total, steps = 0.0, 0
                while True:
                    _, r, term, trunc, info = env.step(np.zeros(1, dtype=np.float32))
                    total += r
                    steps += 1
                    if term or trunc:
                        break
                self.assertTrue(term)
                self.assertEqual((total, info["reason"]), (1.0, "goal"))
                self.assertLess(steps, 60)
                # The step limit: truncated, not terminated, reward 0.
                short = make(backend, spec={"step_limit": 5})
                short.reset(seed=2, options={"start": "eval", "eval_index": 0})
                for _ in range(5):
                    _, r, term, trunc, info = short.step(np.zeros(1, dtype=np.float32))
                self.assertEqual((term, trunc, r, info["reason"]), (False, True, 0.0, "step_limit"))

    def test_settings_by_name(self):
        # The declaration's parameters are the environment's settings: with the goal moved off the
        # door's line, a wider door lets the robot drive straight through to it where the default
        # door stops it at the wall.
        for backend in BACKENDS:
            for width, reason in ((1.0, "collision"), (2.0, "goal")):
                env = make(backend, spec={"door_width_m": width, "goal_y_m": 0.6})
                self.assertEqual(env.unwrapped.task_spec["door_width_m"], width)
                env.reset(seed=0, options={"pose": (-1.5, 0.6, 0.0)})
                while True:
                    _, _, term, trunc, info = env.step(np.zeros(1, dtype=np.float32))
                    if term or trunc:
                        break
                self.assertEqual(info["reason"], reason, (backend, width))


def main():
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
