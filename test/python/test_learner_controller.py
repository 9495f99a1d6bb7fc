# SPDX-License-Identifier: MIT
"""b21r_learn.Learner reproduces the controller's learning on the product's own environments.

Claim checked: Learner.from_controller_config on B21rCorridor-v0 / B21rObstacles-v0 (ODE back-end)
with an experiment file and the same --set overrides gives exactly the evaluation blocks of
b21r-experiment (the controller's loop against the in-process emulator) for the same seed, and
every run alike: its steps, outcome and who drove each step (example, greedy, exploration,
advisor), and every step's experience as the controller publishes it (the learner's state, the
executed action, reward, next state, terminal, and Q(s, a) before the update). No tolerance: both
compute every number with the same C code (lib/learn, lib/hedger, lib/tasks, the emulator) from
the same inputs, and the environment equals the controller's run
step for step (test_env_equivalence.py). Schedules are shortened (5 + 5 runs for the corridor's
Fig. 4 set-up, 10 + 5 for the obstacle task's Figs. 9-10 set-up, with the simulated person's
examples and collisions) to keep the test short; the full schedules match too (seed 1: every block
of fig4_corridor_examples, final 10/10 at 140.2 steps).

Also checked: read_experience_log of b21r-experiment's --experience-log gives the transitions the
controller learned in phase one, and a Learner that learns phase one from them ends phase one with
the very learned state (HEDGER's saved bytes) of one that drove phase one itself.

Usage: test_learner_controller.py <b21r-experiment> <repository root> <work dir> [--quick]
"""
import json
import pathlib
import subprocess
import sys
import unittest

import numpy as np

import b21r_learn
from b21r_learn import Learner, read_experience_log

EXPERIMENT = None
REPO = None
WORK = None
QUICK = "--quick" in sys.argv  # a sanitized build: ten times slower, the obstacle case is left out

# (name, experiment file, seed, overrides)
CASES = {
    "corridor": ("fig4_corridor_examples.conf", 3, {"phase_one_runs": 5, "phase_two_runs": 5}),
    "obstacles": ("fig9_10_obstacles.conf", 2, {"phase_one_runs": 10, "phase_two_runs": 5}),
}


def controller_session(name, conf, seed, overrides, log=False):
    WORK.mkdir(parents=True, exist_ok=True)
    out = WORK / (name + ".json")
    cmd = [str(EXPERIMENT), "--config", str(REPO / "tools" / "experiments" / conf), "--set", "experiment.references=",
           "--seed", str(seed), "--out", str(out)]
    for k, v in overrides.items():
        cmd += ["--set", "%s=%s" % (k, v)]
    if log:
        cmd += ["--experience-log", str(WORK / (name + ".lcmlog"))]
    subprocess.run(cmd, check=True)
    return json.loads(out.read_text())["learning"]


def learner_session(conf, seed, overrides, **kwargs):
    settings = dict(overrides, seed=seed)
    learner = Learner.from_controller_config(settings=settings, config_file=REPO / "tools" / "experiments" / conf,
                                             **kwargs)
    learner.run()
    return learner


class LearnerEqualsController(unittest.TestCase):
    def check_case(self, name):
        conf, seed, overrides = CASES[name]
        ref = controller_session(name, conf, seed, overrides, log=True)
        learner = learner_session(conf, seed, overrides, record_experiences=True)
        self.assertEqual(len(learner.blocks), len(ref["blocks"]))
        for mine, theirs in zip(learner.blocks, ref["blocks"]):
            where = "%s block %d" % (name, theirs["block"])
            for key in ("block", "training_runs", "phase", "steps", "success", "successes"):
                self.assertEqual(mine[key], theirs[key], where + ": " + key)
            self.assertEqual(mine["store_fill"], theirs["store_fill"], where + ": store fill")
        self.assertEqual(len(learner.runs), len(ref["runs"]))
        outcomes = {"goal": "goal", "terminal": "collision", "step_limit": "step_limit"}
        for mine, theirs in zip(learner.runs, ref["runs"]):
            where = "%s run %d" % (name, theirs["run_id"])
            self.assertEqual(mine["run_id"], theirs["run_id"], where)
            self.assertEqual(mine["kind"] == "eval", theirs["kind"] == "eval", where + ": kind")
            self.assertEqual(mine["steps"], theirs["steps"], where + ": steps")
            self.assertEqual(outcomes[mine["outcome"]], theirs["outcome"], where + ": outcome")
            self.assertEqual(mine["sources"], theirs["sources"], where + ": who drove")
            self.assertAlmostEqual(mine["return"], theirs["return"], places=9, msg=where + ": return")
        # Every step: what was learned (or, evaluating, predicted), bit for bit.
        log = read_experience_log(WORK / (name + ".lcmlog"), training_only=False)
        exps = learner.experiences
        self.assertEqual(len(exps), len(log["a"]))
        for key, field in (("s", "s"), ("a", "a"), ("r", "reward"), ("s_next", "s_next"), ("terminal", "terminal"),
                           ("q", "q"), ("source", "source"), ("run", "run_id"), ("step", "step_id"),
                           ("evaluating", "evaluating")):
            mine = np.array([e[field] for e in exps])
            np.testing.assert_array_equal(mine, log[key], err_msg="%s experiences: %s" % (name, key))
        last = learner.blocks[-1]
        print("%s (seed %d, %s): %d blocks, %d runs and %d experiences identical; last block %d/%d, mean %.1f "
              "steps" % (name, seed, conf, len(learner.blocks), len(learner.runs), len(exps), last["successes"],
                         last["n_starts"], last["mean_steps"]))
        return ref

    def test_corridor_blocks_equal_b21r_experiment(self):
        self.check_case("corridor")

    @unittest.skipIf(QUICK, "--quick (a sanitized build): the corridor's case only")
    def test_obstacle_blocks_equal_b21r_experiment(self):
        ref = self.check_case("obstacles")
        self.assertTrue(any(r["outcome"] == "collision" for r in ref["runs"]), "the case has collisions")

    def test_phase_one_from_the_controllers_log(self):
        conf, seed, overrides = CASES["corridor"]
        # A log is replayed step by step: the controller's session decides every tick.
        overrides = dict(overrides, decision_ticks=1)
        controller_session("corridor_log", conf, seed, overrides, log=True)
        log = read_experience_log(WORK / "corridor_log.lcmlog", task_state_dim=3, phase=1)
        self.assertEqual(len(set(log["run"])), overrides["phase_one_runs"])
        phase_one = dict(overrides, phase_two_runs=0)
        driven = learner_session(conf, seed, phase_one)
        from_log = learner_session(conf, seed, phase_one, transitions=log)
        self.assertEqual([r["steps"] for r in from_log.runs if r["from_log"]],
                         [r["steps"] for r in driven.runs if r["kind"] == "training"])
        self.assertEqual(from_log.save(), driven.save(), "the same learned state after phase one")
        # A log of decisions held over two ticks is refused, naming the tool that learns it; so is
        # decision_ticks > 1 with a log.
        held = dict(CASES["corridor"][2], decision_ticks=2)
        controller_session("corridor_log2", conf, seed, held, log=True)
        log2 = read_experience_log(WORK / "corridor_log2.lcmlog", task_state_dim=3, phase=1)
        with self.assertRaisesRegex(ValueError, "b21r-train --set decision_ticks=2"):
            learner_session(conf, seed, dict(held, phase_two_runs=0, decision_ticks=1), transitions=log2)
        with self.assertRaisesRegex(ValueError, "decision_ticks must be 1, not 2"):
            learner_session(conf, seed, dict(held, phase_two_runs=0), transitions=log)

    def test_configuration_errors_name_the_key(self):
        with self.assertRaisesRegex(ValueError, "phase_one_runz"):
            Learner.from_controller_config(settings={"phase_one_runz": 3})
        env = b21r_learn.envs.B21rEnv("corridor", spec={"step_limit": 500})
        with self.assertRaisesRegex(ValueError, "step_limit differ"):
            Learner.from_controller_config(env=env)


def main():
    global EXPERIMENT, REPO, WORK
    args = [a for a in sys.argv[1:] if a != "--quick"]
    if len(args) != 3:
        print(__doc__)
        return 2
    EXPERIMENT, REPO, WORK = (pathlib.Path(a) for a in args)
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
