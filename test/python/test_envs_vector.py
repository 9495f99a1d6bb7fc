# SPDX-License-Identifier: MIT
"""gymnasium.vector works with both environments and both back-ends, synchronously and in
subprocesses (async), with autoreset, and gives the same numbers both ways: the environments
carry no hidden process-global state.
"""
import sys
import unittest

import gymnasium
import numpy as np

import b21r_learn  # noqa: F401  (registers the environments)
from b21r_learn.envs import ENV_IDS

N_ENVS = 3
N_STEPS = 120


def run(task, backend, mode):
    envs = gymnasium.make_vec(ENV_IDS[task], num_envs=N_ENVS, vectorization_mode=mode,
                              vector_kwargs={"autoreset_mode": gymnasium.vector.AutoresetMode.SAME_STEP},
                              backend=backend, max_episode_steps=50)  # truncations: autoreset is exercised
    try:
        obs, _ = envs.reset(seed=[10, 11, 12])
        rng = np.random.default_rng(0)
        history = [obs]
        ends = 0
        for _ in range(N_STEPS):
            obs, rew, term, trunc, _ = envs.step(rng.uniform(-1, 1, size=(N_ENVS, 1)).astype(np.float32))
            assert obs.shape == (N_ENVS, envs.single_observation_space.shape[0])
            ends += int(np.sum(term | trunc))
            history.append((obs, rew, term, trunc))
        return history, ends
    finally:
        envs.close()


class VectorEnvironments(unittest.TestCase):
    def test_sync_and_async_agree(self):
        for task in ("corridor", "obstacles"):
            for backend in ("ode", "kinematic"):
                with self.subTest(task=task, backend=backend):
                    sync, ends = run(task, backend, "sync")
                    asyn, _ = run(task, backend, "async")
                    self.assertGreater(ends, 0, "some episode ended and was reset automatically")
                    np.testing.assert_array_equal(sync[0], asyn[0])
                    for a, b in zip(sync[1:], asyn[1:]):
                        for x, y in zip(a, b):
                            np.testing.assert_array_equal(x, y)
                    # The three sub-environments got different seeds: different starts.
                    self.assertFalse(np.array_equal(sync[0][0], sync[0][1]))


def main():
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
