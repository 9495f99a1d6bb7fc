# SPDX-License-Identifier: MIT
"""b21r_learn.Hedger against the hand-computed cases of the C tests (test/unit/hedger), plus the
binding's own contract: settings as keyword arguments with the C defaults, Python exceptions with
the C error text, NumPy arrays in and out (caller buffers written in place), save/load.
"""
import math
import sys
import unittest

import numpy as np

import b21r_learn
from b21r_learn import Hedger, HedgerError

LWA, LWR, UNKNOWN = 1, 2, 0
STORE_INSERTED, STORE_MERGED = 1, 2


def hand_config(**overrides):
    """test_hedger_update.c: 1-D state; actions {-1, 0, 1}, no refinement; h = 1, alpha = gamma = 0.5."""
    cfg = dict(state_dim=1, capacity=16, k_min=1, k_max=4, bandwidth=1.0, weight_epsilon=0.01, alpha=0.5,
               gamma=0.5, greedy_coarse_actions=3, greedy_refine_iters=0, merge_radius=0.01)
    cfg.update(overrides)
    return cfg


def lin(s, a):
    """test_hedger_predict.c: q(s, a) = 1 + 2 s0 - 3 s1 + 0.5 a."""
    return 1.0 + 2.0 * s[0] - 3.0 * s[1] + 0.5 * a


def make_linear():
    h = Hedger(state_dim=2, capacity=2000, k_min=4, k_max=32, bandwidth=0.3, ridge=0.0, gamma=0.9, merge_radius=0.0)
    for i in range(11):
        for j in range(11):
            for k in range(9):
                s = np.array([0.1 * i, 0.1 * j])
                a = -1.0 + 0.25 * k
                h.insert(s, a, lin(s, a))
    h.observe_reward(-1.0)
    h.observe_reward(1.0)
    return h


S0 = np.zeros(1)


class HandComputedCases(unittest.TestCase):
    def test_update_hand_example_matches_steps(self):
        h = Hedger(**hand_config())
        self.assertEqual(h.insert(S0, 0.0, 1.0), STORE_INSERTED)
        h.insert(S0, 1.0, 3.0)
        e1, e025 = math.exp(-1.0), math.exp(-0.25)
        q_next = (e1 * 1.0 + 3.0) / (e1 + 1.0)  # greedy at s' = 0: a' = 1 (LWA)
        q = (e025 * 1.0 + e025 * 3.0) / (e025 + e025)  # Q(0, 0.5) = 2
        target = 1.0 + 0.5 * q_next
        q_new = q + 0.5 * (target - q)
        p0 = 1.0 + 0.5 * e025 * (q_new - 1.0)
        p1 = 3.0 + 0.5 * e025 * (q_new - 3.0)
        info = h.update(S0, 0.5, 1.0, S0)
        self.assertTrue(info["next_known"])
        self.assertEqual(info["next_action"], 1.0)
        self.assertEqual(info["next_kind"], LWA)
        self.assertAlmostEqual(info["next_value"], q_next, delta=1e-12)
        self.assertAlmostEqual(info["q_next"], q_next, delta=1e-12)
        self.assertEqual(info["kind"], LWA)
        self.assertAlmostEqual(info["q_old"], q, delta=1e-12)
        self.assertAlmostEqual(info["target"], target, delta=1e-12)
        self.assertAlmostEqual(info["q_new"], q_new, delta=1e-12)
        self.assertEqual(info["store_op"], STORE_INSERTED)
        self.assertEqual(info["n_pulled"], 2)
        self.assertEqual(len(h), 3)
        pt = h.get_point(2)
        self.assertEqual((pt["state"][0], pt["action"]), (0.0, 0.5))
        self.assertAlmostEqual(pt["value"], q_new, delta=1e-12)
        self.assertEqual(pt["flags"], b21r_learn.POINT_PROTECTED)
        self.assertAlmostEqual(h.get_point(0)["value"], p0, delta=1e-12)
        self.assertAlmostEqual(h.get_point(1)["value"], p1, delta=1e-12)
        c = h.counters
        self.assertEqual((c["reward_min"], c["reward_max"]), (0.0, 1.0))
        states, actions, values, flags = h.points()
        self.assertEqual(states.shape, (3, 1))
        np.testing.assert_allclose(values, [p0, p1, q_new], atol=1e-12)
        np.testing.assert_array_equal(actions, [0.0, 1.0, 0.5])
        np.testing.assert_array_equal(flags, [0, 0, b21r_learn.POINT_PROTECTED])

    def test_update_terminal_uses_zero_next_value(self):
        h = Hedger(**hand_config())
        h.insert(S0, 0.0, 1.0)
        greedy_before = h.counters["greedy_calls"]
        info = h.update(S0, 0.2, -1.0, None, terminal=True)
        self.assertEqual(h.counters["greedy_calls"], greedy_before)
        self.assertFalse(info["next_known"])
        self.assertEqual(info["next_kind"], UNKNOWN)
        self.assertEqual(info["q_next"], 0.0)
        self.assertAlmostEqual(info["q_old"], 1.0, delta=1e-15)
        self.assertEqual(info["target"], -1.0)
        self.assertAlmostEqual(info["q_new"], 0.0, delta=1e-15)
        self.assertEqual(h.get_point(1)["flags"], b21r_learn.POINT_PROTECTED)
        self.assertAlmostEqual(h.get_point(0)["value"], 1.0 - 0.5 * math.exp(-0.04), delta=1e-12)
        self.assertEqual(h.counters["reward_min"], -1.0)
        self.assertEqual(h.counters["store_protected"], 1)

    def test_update_unknown_everywhere_uses_default(self):
        h = Hedger(**hand_config(default_value=0.5))
        info = h.update(S0, 0.0, 0.0, np.array([0.1]))
        self.assertFalse(info["next_known"])
        self.assertEqual(info["next_action"], 0.0)
        self.assertEqual(info["q_next"], 0.5)
        self.assertEqual(info["kind"], UNKNOWN)
        self.assertEqual(info["q_old"], 0.5)
        self.assertAlmostEqual(info["q_new"], 0.375, delta=1e-15)
        self.assertEqual(info["n_pulled"], 0)
        self.assertEqual(len(h), 1)

    def test_update_close_point_merged(self):
        h = Hedger(**hand_config())
        h.insert(S0, 0.0, 1.0)
        self.assertEqual(h.insert(np.array([0.005]), 0.0, 3.0, b21r_learn.POINT_PROTECTED), STORE_MERGED)
        self.assertEqual(len(h), 1)
        pt = h.get_point(0)
        self.assertAlmostEqual(pt["value"], 1.0 + math.exp(-0.005 * 0.005) * 2.0, delta=1e-12)
        self.assertEqual(pt["flags"], b21r_learn.POINT_PROTECTED)
        self.assertEqual(h.counters["merges"], 1)

    def test_greedy_unknown_never_beats_known(self):
        h = Hedger(**hand_config(default_value=100.0, greedy_coarse_actions=5))
        h.insert(S0, 1.0, -5.0)
        self.assertEqual(h.greedy(S0), (-1.0, -5.0, LWA, True))  # all known, ties -> smallest action
        h = Hedger(**hand_config(default_value=100.0, greedy_coarse_actions=5, bandwidth=0.25))
        h.insert(S0, 1.0, -5.0)
        self.assertEqual(h.greedy(S0), (0.5, -5.0, LWA, True))

    def test_greedy_all_unknown_distinct_status(self):
        h = Hedger(**hand_config(action_min=-0.5, action_max=1.5, default_value=2.0))
        self.assertEqual(h.greedy(np.array([3.0])), (0.5, 2.0, UNKNOWN, False))
        self.assertEqual(h.counters["greedy_all_unknown"], 1)

    def test_end_run_replay_propagates_reward(self):
        h = Hedger(**hand_config(run_capacity=8, replay=1, gamma=0.9, bandwidth=0.1))
        for t in range(3):
            h.update(np.array([float(t)]), 0.0, 0.0, np.array([t + 1.0]))
        h.update(np.array([3.0]), 0.0, 1.0, None, terminal=True)
        self.assertEqual(h.counters["run_fill"], 4)
        self.assertEqual(h.end_run(), 4)
        self.assertEqual(h.counters["replayed_updates"], 4)
        p = h.predict(np.array([2.0]), 0.0)
        self.assertNotEqual(p.kind, UNKNOWN)
        self.assertGreater(p.value, 0.0)

    def test_predict_linear_data_lwr_exact(self):
        h = make_linear()
        rng = np.random.default_rng(42)
        for _ in range(200):
            s = rng.uniform(0.1, 0.9, size=2)
            a = float(rng.uniform(-0.8, 0.8))
            p = h.predict(s, a)
            self.assertEqual(p.kind, LWR)
            self.assertEqual(p.fallback, 0)
            self.assertTrue(4 <= p.n_neighbours <= 32)
            self.assertAlmostEqual(p.value, lin(s, a), delta=1e-9)
        self.assertEqual(h.counters["predictions_lwr"], 200)

    def test_predict_fewer_than_kmin_unknown(self):
        h = Hedger(state_dim=2, capacity=2000, k_min=4, k_max=32, bandwidth=0.3, ridge=0.0, gamma=0.9,
                   merge_radius=0.0, default_value=-7.5)
        s = np.zeros(2)
        p = h.predict(s, 0.0)
        self.assertEqual((p.kind, p.value, p.n_neighbours), (UNKNOWN, -7.5, 0))
        for i in range(3):
            h.insert(np.array([0.05 * i, 0.0]), 0.0, 1.0)
        p = h.predict(s, 0.0)
        self.assertEqual((p.kind, p.n_neighbours), (UNKNOWN, 3))
        h.insert(np.array([0.0, 0.05]), 0.0, 1.0)
        p = h.predict(s, 0.0)
        self.assertEqual(p.n_neighbours, 4)
        self.assertNotEqual(p.kind, UNKNOWN)
        p = h.predict(np.array([5.0, 5.0]), 0.0)
        self.assertEqual((p.kind, p.n_neighbours), (UNKNOWN, 0))
        self.assertEqual(h.counters["predictions_unknown"], 3)

    def test_predict_ex_neighbours_sorted_weights_gaussian(self):
        h = make_linear()
        s = np.array([0.52, 0.47])
        p, slots, w = h.predict_ex(s, 0.1)
        self.assertEqual(p.n_neighbours, 32)
        self.assertEqual((len(slots), len(w)), (32, 32))
        for i in range(32):
            pt = h.get_point(int(slots[i]))
            d2 = float(np.sum((pt["state"] - s) ** 2) + (pt["action"] - 0.1) ** 2)
            self.assertAlmostEqual(w[i], math.exp(-d2 / 0.09), delta=1e-12)
            if i > 0:
                self.assertLessEqual(w[i], w[i - 1])
        # Into the caller's arrays, in place (a smaller buffer takes the nearest ones).
        slots_buf = np.zeros(8, dtype=np.uint32)
        w_buf = np.zeros(8)
        p2, rs, rw = h.predict_ex(s, 0.1, slots=slots_buf, weights=w_buf)
        self.assertIs(rs, slots_buf)
        self.assertIs(rw, w_buf)
        np.testing.assert_array_equal(slots_buf, slots[:8])
        np.testing.assert_array_equal(w_buf, w[:8])
        self.assertEqual(p2.value, p.value)


class BindingContract(unittest.TestCase):
    def test_defaults_are_the_c_defaults(self):
        d = Hedger.default_config()
        self.assertEqual(d["state_dim"], 3)
        self.assertEqual((d["action_min"], d["action_max"]), (-1.0, 1.0))
        self.assertEqual((d["capacity"], d["k_min"], d["k_max"]), (8192, 3, 16))
        self.assertEqual((d["bandwidth"], d["alpha"], d["gamma"]), (0.2, 0.2, 0.99))
        self.assertEqual(Hedger().config, d)

    def test_bad_settings_raise_with_the_c_text(self):
        with self.assertRaises(TypeError) as cm:
            Hedger(bandwith=0.1)
        self.assertIn("bandwidth", str(cm.exception))  # lists the known names
        with self.assertRaises(HedgerError) as cm:
            Hedger(k_min=20, k_max=10)
        self.assertIn("invalid argument", str(cm.exception))
        self.assertIsInstance(cm.exception, ValueError)

    def test_non_finite_and_wrong_shapes_refused(self):
        h = Hedger(**hand_config())
        with self.assertRaises(HedgerError) as cm:
            h.update(np.array([math.nan]), 0.0, 0.0, S0)
        self.assertIn("hedger_update", str(cm.exception))
        with self.assertRaises(HedgerError):
            h.predict(S0, math.inf)
        with self.assertRaises(ValueError):
            h.predict(np.zeros(2), 0.0)  # state_dim is 1
        with self.assertRaises(ValueError):
            h.update(S0, 0.0, 0.0, None)  # s' needed unless terminal
        self.assertEqual(h.counters["rejected_non_finite"], 2)
        self.assertEqual(len(h), 0)

    def test_save_load_round_trip_and_errors(self):
        h = make_linear()
        data = h.save()
        self.assertEqual(len(data), h.serialized_size)
        self.assertLessEqual(len(data), h.serialized_max_size)
        g = Hedger(**h.config)
        g.load(data)
        self.assertEqual(len(g), len(h))
        self.assertEqual(g.save(), data)
        s = np.array([0.4, 0.6])
        self.assertEqual(g.predict(s, 0.3).value, h.predict(s, 0.3).value)
        bad = bytearray(data)
        bad[len(bad) // 2] ^= 0xFF
        with self.assertRaises(HedgerError) as cm:
            g.load(bytes(bad))
        self.assertIn("hedger_load", str(cm.exception))
        other = Hedger(**dict(h.config, gamma=0.5))
        with self.assertRaises(HedgerError):
            other.load(data)  # saved under another discount
        self.assertEqual(g.save(), data, "a failed load leaves the state unchanged")

    def test_float32_states_are_converted(self):
        h = make_linear()
        s64 = np.array([0.25, 0.75])
        self.assertEqual(h.predict(s64.astype(np.float32), 0.0).value,
                         h.predict(s64.astype(np.float32).astype(np.float64), 0.0).value)

    def test_controller_learner_config(self):
        # The task's features, then the executed rotation (state_rotation, the default), then the action.
        c = b21r_learn.controller_learner_config("corridor")
        self.assertEqual(c["state_dim"], 4)
        self.assertEqual(c["input_scale"][:5], [1.0, 0.5, 0.125, 1.0, 0.25])
        self.assertEqual((c["k_min"], c["k_max"], c["greedy_reach"]), (6, 48, 8.0))
        c3 = b21r_learn.controller_learner_config("corridor", {"state_rotation": False})
        self.assertEqual(c3["state_dim"], 3)
        self.assertEqual(c3["input_scale"][:4], [1.0, 0.5, 0.125, 0.25])
        # gamma is the discount per learned decision: the task's 0.9 per tick over decision_ticks (2) ticks.
        o = b21r_learn.controller_learner_config("obstacles", {"hedger_capacity": 5000})
        self.assertEqual((o["state_dim"], o["capacity"], o["gamma"], o["greedy_reach"]), (6, 5000, 0.9 ** 2, 3.0))
        o1 = b21r_learn.controller_learner_config("obstacles", {"decision_ticks": 1})
        self.assertEqual(o1["gamma"], 0.9)
        self.assertEqual(b21r_learn.controller_learner_config("corridor", {"hedger_greedy_reach": 2})["greedy_reach"], 2.0)
        with self.assertRaises(ValueError):
            b21r_learn.controller_learner_config("corridor", {"hedger_capacity": -3})
        with self.assertRaises(ValueError):
            b21r_learn.read_checkpoint("/nonexistent/hedger.ckpt")


def main():
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
