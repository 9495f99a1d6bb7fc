#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Learns the corridor task from Python: B21rCorridor-v0 (the emulated B21r by default) and HEDGER,
with the paper's schedule and the controller's learner settings, and prints the evaluation blocks
the way the main job does.

- Phase one (30 runs): the example policy (omega = k * theta, k drawn per run) drives; HEDGER
  learns from every step, and replays each run backwards at its end.
- Phase two (35 runs): the learned policy drives: HEDGER's greedy action where its value comes
  from a local regression (LWR) and beats the example policy's action by 2 % (else the example
  policy's action, the controller's advisor rule), plus N(0, 0.1) exploration on 20 % of steps.
- Every 5 training runs, an evaluation block: the 10 fixed start poses, learning off, the learned
  policy alone (greedy; hold course where nothing is known). Reported: successes out of 10 and
  the mean steps to the goal with its 95 % interval (successful runs), as the controller does.
- Before learning, the two reference policies are evaluated from the same poses: the example
  policy at its nominal gain and the hand-tuned "optimal" controller.

Usage: tools/b21r_learn_corridor.py [--backend ode|kinematic] [--seed N] [--phase-one-runs N]
                                    [--phase-two-runs N] [--eval-every N]
"""
import b21r_bootstrap

b21r_bootstrap.ensure()

import argparse  # noqa: E402
import time  # noqa: E402

import gymnasium  # noqa: E402
import numpy as np  # noqa: E402

import b21r_learn  # noqa: E402

LWR = 2
ADVISOR_MARGIN = 0.02
EXPLORE_PROBABILITY = 0.2
EXPLORE_SIGMA = 0.1
NOMINAL_GAIN = 0.5 * (0.5 + 2.0)  # middle of the example policy's gain range


def learner_state(obs, executed, rotation):
    """The controller's learner state: the task's features (the observation), then, with
    state_rotation (the controller's default), the rotation the base executes: the last command
    sent (0 when a run starts)."""
    return np.append(obs, executed) if rotation else obs


def run_episode(env, options, choose, learner=None, rotation=True):
    """One run: choose(state) gives the rotation command; with a learner, every transition is
    learned and the run replayed at its end. Returns (steps, reached the goal)."""
    obs, _ = env.reset(options=options)
    state = learner_state(obs, 0.0, rotation)
    steps = 0
    while True:
        action = choose(state)
        nxt, reward, terminated, truncated, info = env.step(np.array([action]))
        steps += 1
        nxt_state = learner_state(nxt, info["action"], rotation)
        if learner is not None:
            learner.update(state, info["action"], reward, None if terminated else nxt_state, terminated)
        state = nxt_state
        if terminated or truncated:
            if learner is not None:
                learner.end_run()
            return steps, info["reason"] == "goal"


def evaluate(env, choose_for_run, step_limit, rotation):
    """The 10 evaluation poses; returns (successes, mean steps, 95 % half-width)."""
    steps, successes = [], 0
    for index in range(b21r_learn._core.N_EVAL_STARTS):
        n, goal = run_episode(env, {"start": "eval", "eval_index": index}, choose_for_run(index), rotation=rotation)
        successes += goal
        if goal:
            steps.append(float(n))
    mean, half = b21r_learn.mean_ci95(steps)
    return successes, mean, half


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", choices=("ode", "kinematic"), default="ode")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--phase-one-runs", type=int, default=30)
    ap.add_argument("--phase-two-runs", type=int, default=35)
    ap.add_argument("--eval-every", type=int, default=5)
    args = ap.parse_args()
    t0 = time.time()

    env = gymnasium.make("B21rCorridor-v0", backend=args.backend)
    env.reset(seed=args.seed)
    core = env.unwrapped
    step_limit = core.task_spec["step_limit"]
    rng = np.random.default_rng(args.seed)
    config = b21r_learn.controller_learner_config("corridor")
    config["seed"] = args.seed
    hedger = b21r_learn.Hedger(**config)
    rotation = config["state_dim"] > env.observation_space.shape[0]  # state_rotation
    driver = b21r_learn.Driver("proportional", "corridor")
    print("learn-corridor: B21rCorridor-v0 (%s back-end), seed %d; HEDGER as the controller configures it "
          "(capacity %d, bandwidth %.2f, alpha %.1f, gamma %.2f, replay %s)"
          % (args.backend, args.seed, config["capacity"], config["bandwidth"], config["alpha"], config["gamma"],
             "on" if config["replay"] else "off"))

    # The reference lines: the example policy at its nominal gain, and the "optimal" controller.
    for name, kind in (("example policy (k = %.2f)" % NOMINAL_GAIN, "proportional"), ("optimal controller", "optimal")):
        ref = b21r_learn.Driver(kind, "corridor")

        def ref_for_run(index, ref=ref, kind=kind):
            ref.begin_run(index)
            if kind == "proportional":
                ref.gain = NOMINAL_GAIN
            return lambda obs: core.driver_action(ref)

        ok, mean, half = evaluate(env, ref_for_run, step_limit, rotation)
        print("REFERENCE %-26s %2d/10 reached the goal, mean %.1f +- %.1f steps" % (name, ok, mean, half))

    def learned(obs):
        action, _, _, known = hedger.greedy(obs)
        return action if known else 0.0

    def phase_two(obs):
        advice = core.driver_action(driver)  # the driver runs every step so its state follows the run
        action, value, kind, known = hedger.greedy(obs)
        if known and kind == LWR:
            pa = hedger.predict(obs, advice)
            if pa.kind != 0 and value > pa.value + ADVISOR_MARGIN * abs(pa.value):
                if rng.random() < EXPLORE_PROBABILITY:
                    action += EXPLORE_SIGMA * rng.standard_normal()
                return action
        return advice

    def phase_one(obs):
        return core.driver_action(driver)

    runs = args.phase_one_runs + args.phase_two_runs
    example_steps = []
    for run in range(runs):
        phase = 1 if run < args.phase_one_runs else 2
        driver.begin_run(int(rng.integers(0, 2**63 - 1)))
        steps, goal = run_episode(env, {"start": "training"}, phase_one if phase == 1 else phase_two, learner=hedger,
                                  rotation=rotation)
        if phase == 1 and goal:
            example_steps.append(steps)
        print("run %4d  phase %d  train  %-7s %4d steps  store %d/%d"
              % (run, phase, "goal" if goal else "no goal", steps, len(hedger), config["capacity"]))
        if (run + 1) % args.eval_every == 0:
            ok, mean, half = evaluate(env, lambda index: learned, step_limit, rotation)
            print("EVAL block %2d after %3d training runs (phase %d): %2d/10 reached the goal, mean %.1f +- %.1f steps"
                  % ((run + 1) // args.eval_every - 1, run + 1, phase, ok, mean, half))
            if run + 1 == args.phase_one_runs:
                print("PHASE TWO: the learned policy drives from now on")
    best = min(example_steps) if example_steps else float("nan")
    counters = hedger.counters
    print("learn-corridor: done in %.0f s; best example run %s steps; HEDGER answered %d LWR / %d LWA / %d unknown"
          % (time.time() - t0, best, counters["predictions_lwr"], counters["predictions_lwa"],
             counters["predictions_unknown"]))


if __name__ == "__main__":
    main()
