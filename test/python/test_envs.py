# SPDX-License-Identifier: MIT
"""B21rCorridor-v0 and B21rObstacles-v0, both back-ends: Gymnasium's env_checker, determinism,
a random agent, start options, errors, rendering, and how closely the back-ends agree.
"""
import math
import sys
import unittest

import gymnasium
import numpy as np
from gymnasium.utils.env_checker import check_env

import b21r_learn
from b21r_learn.envs import ENV_IDS

CASES = [(task, backend) for task in ("corridor", "obstacles") for backend in ("ode", "kinematic")]
REWARDS = {"corridor": {0.0, 10.0}, "obstacles": {-1.0, 0.0, 1.0}}


def make(task, backend, **kwargs):
    return gymnasium.make(ENV_IDS[task], backend=backend, **kwargs)


def rollout(env, seed, n_steps, action_seed):
    """Random actions from a seeded generator; resets when an episode ends. Returns the history."""
    rng = np.random.default_rng(action_seed)
    obs, _ = env.reset(seed=seed)
    out = [obs.copy()]
    for _ in range(n_steps):
        obs, r, term, trunc, info = env.step(rng.uniform(-1.0, 1.0, size=1).astype(np.float32))
        out.append((obs.copy(), r, term, trunc, info["action"]))
        if term or trunc:
            obs, _ = env.reset()
            out.append(obs.copy())
    return out


class Environments(unittest.TestCase):
    def test_env_checker_passes(self):
        # Gymnasium's checker: spaces, reset/step signatures and types, seeding determinism, render.
        for task, backend in CASES:
            with self.subTest(task=task, backend=backend):
                env = make(task, backend, render_mode="rgb_array")
                check_env(env.unwrapped, skip_render_check=False)
                env.close()

    def test_same_seed_same_actions_identical_episodes(self):
        for task, backend in CASES:
            with self.subTest(task=task, backend=backend):
                a = rollout(make(task, backend), seed=3, n_steps=400, action_seed=9)
                b = rollout(make(task, backend), seed=3, n_steps=400, action_seed=9)
                self.assertEqual(len(a), len(b))
                for x, y in zip(a, b):
                    if isinstance(x, tuple):
                        np.testing.assert_array_equal(x[0], y[0])
                        self.assertEqual(x[1:], y[1:])
                    else:
                        np.testing.assert_array_equal(x, y)
                # Another seed: other training starts (and, on ODE, other sensor noise).
                c = rollout(make(task, backend), seed=4, n_steps=5, action_seed=9)
                self.assertFalse(np.array_equal(a[0], c[0]))

    def test_reseeding_repeats_the_episode_in_one_env(self):
        env = make("corridor", "ode")
        first, _ = env.reset(seed=21)
        steps = [env.step(np.array([0.3], dtype=np.float32))[0] for _ in range(10)]
        again, _ = env.reset(seed=21)
        np.testing.assert_array_equal(first, again)
        for s in steps:
            np.testing.assert_array_equal(s, env.step(np.array([0.3], dtype=np.float32))[0])

    def test_random_agent_smoke(self):
        for task, backend in CASES:
            with self.subTest(task=task, backend=backend):
                env = make(task, backend)
                env.action_space.seed(1)
                env.reset(seed=1)
                episodes, ends = 0, {}
                for _ in range(3000):
                    obs, r, term, trunc, info = env.step(env.action_space.sample())
                    self.assertTrue(env.observation_space.contains(obs), obs)
                    self.assertIn(r, REWARDS[task])
                    self.assertLessEqual(abs(info["action"]), 1.0)
                    self.assertTrue(np.all(np.isfinite(obs)))
                    if term or trunc:
                        episodes += 1
                        ends[info["reason"]] = ends.get(info["reason"], 0) + 1
                        self.assertEqual(term, info["reason"] in ("goal", "collision"))
                        env.reset()
                self.assertGreater(episodes, 3)
                print("%s/%s: 3000 random steps, %d episodes, ends %s" % (task, backend, episodes, ends))

    def test_start_options(self):
        for task, backend in CASES:
            with self.subTest(task=task, backend=backend):
                env = make(task, backend)
                eval_starts = env.unwrapped.task_spec["eval_starts"]
                self.assertEqual(len(eval_starts), 10)
                env.reset(seed=2)
                for i in (0, 7):
                    _, info = env.reset(options={"start": "eval", "eval_index": i})
                    self.assertEqual(info["eval_index"], i)
                    np.testing.assert_allclose(info["start_pose"], eval_starts[i], atol=1e-12)
                # Without an index, the evaluation poses come in turn.
                seen = [env.reset(options={"start": "eval"})[1]["eval_index"] for _ in range(3)]
                self.assertEqual(seen, [0, 1, 2])
                pose = (1.4, 0.1, 0.2) if task == "corridor" else (-3.0, 0.5, 0.1)
                _, info = env.reset(options={"pose": pose})
                np.testing.assert_allclose(info["start_pose"], pose, atol=1e-12)
                np.testing.assert_allclose(env.unwrapped.core.truth()["pose"], pose, atol=1e-9)
                # Training starts: near, but never equal to, an evaluation pose.
                _, info = env.reset(options={"start": "training"})
                self.assertFalse(any(np.allclose(info["start_pose"], e) for e in eval_starts))

    def test_errors_are_python_exceptions(self):
        env = make("corridor", "kinematic")
        env.reset(seed=0)
        with self.assertRaises(ValueError):
            env.reset(options={"pose": (0.0, 0.0, 0.0)})  # inside the start wall
        with self.assertRaises(ValueError):
            env.reset(options={"start": "somewhere"})
        env.reset(options={"start": "eval", "eval_index": 0})
        with self.assertRaises(ValueError):
            env.step(np.array([math.nan]))
        with self.assertRaises(ValueError):
            make("corridor", "abacus")
        with self.assertRaises(TypeError):
            make("corridor", "kinematic", spec={"lenght_m": 5.0})
        # An ended episode needs a reset (the step limit of 3 ends this one).
        short = make("corridor", "kinematic", spec={"step_limit": 3})
        short.reset(seed=0)
        for k in range(3):
            *_, trunc, info = short.step(np.zeros(1))
        self.assertTrue(trunc)
        self.assertEqual(info["reason"], "step_limit")
        with self.assertRaises(RuntimeError):
            short.unwrapped.step(np.zeros(1))

    def test_settings_reach_the_task(self):
        env = make("corridor", "kinematic", spec={"length_m": 20.0, "step_limit": 50},
                   limits={"max_rotation_radps": 0.5})
        s = env.unwrapped.task_spec
        self.assertEqual((s["length_m"], s["step_limit"], s["omega_max_radps"]), (20.0, 50, 0.5))
        self.assertEqual(env.action_space.high[0], np.float32(0.5))
        obs, _ = env.reset(seed=0, options={"start": "eval", "eval_index": 0})
        self.assertEqual(obs[0], 19.0)  # eval pose 0 is at x = 1 m
        _, _, _, _, info = env.step(np.array([1.0]))
        self.assertLessEqual(info["action"], 0.5)

    def test_render_draws_the_scene(self):
        for task, backend in CASES:
            with self.subTest(task=task, backend=backend):
                env = make(task, backend, render_mode="rgb_array")
                env.reset(seed=5, options={"start": "eval", "eval_index": 0})
                img = env.render()
                self.assertEqual(img.dtype, np.uint8)
                self.assertEqual(img.ndim, 3)
                self.assertEqual(img.shape[2], 3)
                colours = {tuple(c) for c in img.reshape(-1, 3)[::7]}
                self.assertIn((90, 90, 90), colours)      # walls
                self.assertIn((235, 120, 110), colours)   # laser rays
                self.assertIn((40, 80, 200), colours)     # robot
                if task == "obstacles":
                    self.assertIn((150, 110, 70), colours)  # the obstacle
        plain = make("corridor", "kinematic")
        plain.reset(seed=0)
        self.assertIsNone(plain.render())  # no render_mode: nothing drawn

    def test_driver_takes_a_gain(self):
        # Driver(kind, task, gain=...) fixes the gain for every run (the obstacle law's too), and
        # the action follows it: the proportional corridor policy is gain x target angle.
        for task in ("corridor", "obstacles"):
            env = make(task, "kinematic")
            obs, _ = env.reset(seed=3, options={"start": "eval", "eval_index": 3})
            actions = []
            for gain in (0.5, 1.0):
                d = b21r_learn.Driver("proportional", task, gain=gain)
                d.begin_run(7)  # a new run keeps the fixed gain
                self.assertEqual(d.gain, gain)
                actions.append(env.unwrapped.driver_action(d))
            if task == "corridor":
                self.assertAlmostEqual(actions[0], 0.5 * obs[2], places=12)
                self.assertAlmostEqual(actions[1], 1.0 * obs[2], places=12)
            self.assertNotEqual(actions[0], actions[1])
        with self.assertRaises(ValueError):
            b21r_learn.Driver("optimal", "corridor", gain=1.0)
        with self.assertRaises(ValueError):
            b21r_learn.Driver("proportional", "corridor", gain=-1.0)

    def test_render_without_pillow_names_the_fix(self):
        # A plain venv without Pillow: rendering fails at construction with the fix in the message.
        import builtins
        real_import = builtins.__import__

        def no_pil(name, *args, **kwargs):
            if name == "PIL" or name.startswith("PIL."):
                raise ImportError("No module named 'PIL'")
            return real_import(name, *args, **kwargs)

        builtins.__import__ = no_pil
        try:
            with self.assertRaises(ImportError) as cm:
                make("corridor", "kinematic", render_mode="rgb_array")
        finally:
            builtins.__import__ = real_import
        self.assertIn("pip install pillow", str(cm.exception))

    def test_backends_agree_on_the_motion(self):
        # The kinematic model steps like the plant; the ODE back-end's commands are quantised to
        # rFLEX counts and its state comes from noisy scans. Same start, same actions: the true
        # poses stay within millimetres, the states within the features' stated accuracy.
        for task in ("corridor", "obstacles"):
            ode, kin = make(task, "ode"), make(task, "kinematic")
            opts = {"start": "eval", "eval_index": 2}
            so, _ = ode.reset(seed=1, options=opts)
            sk, _ = kin.reset(seed=1, options=opts)
            worst_pose, worst_state = 0.0, np.zeros_like(so)
            for k in range(40):
                a = np.array([0.4 * math.sin(0.2 * k)])
                so, *_ = ode.step(a)
                sk, *_ = kin.step(a)
                po = np.array(ode.unwrapped.core.truth()["pose"])
                pk = np.array(kin.unwrapped.core.truth()["pose"])
                worst_pose = max(worst_pose, float(np.hypot(*(po[:2] - pk[:2]))))
                worst_state = np.maximum(worst_state, np.abs(so - sk))
            print("%s: ODE vs kinematic over 40 steps: pose within %.2e m, state within %s" %
                  (task, worst_pose, np.array2string(worst_state, precision=4)))
            self.assertLess(worst_pose, 0.005)
            if task == "corridor":
                self.assertTrue(np.all(worst_state < [0.05, 0.02, 0.05]))
            else:
                # The obstacle stays in view of both (the age, the fifth value, stays 0 in both).
                self.assertTrue(np.all(worst_state < [0.05, 0.05, 0.1, 0.06, 1e-12]))


def main():
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
