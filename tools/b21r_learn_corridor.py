#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Learns the corridor task from Python with the paper's schedule: b21r_learn.Learner (lib/learn,
the learning framework the controller runs) on B21rCorridor-v0, set up from the controller's
configuration exactly as the controller sets up its own learning, and prints the evaluation
blocks the way the main job does.

- Phase one (30 runs): the example policy (omega = k * theta, k drawn per run, with the
  controller's dither) drives; HEDGER learns from every step and replays each run backwards.
- Phase two (35 runs): the learned policy drives (greedy action plus the controller's exploration;
  the example policy advises where the learner knows nothing) and keeps learning.
- Every 5 training runs, an evaluation block: the 10 fixed start poses, learning off, the learned
  policy alone. Reported: successes out of 10 and the mean steps to the goal with its 95 %
  interval (successful runs), as the controller does.
- Before learning, the two reference policies are evaluated from the same poses as the
  controller's evaluate mode does (each on a fresh emulator with the same seed): the example
  policy at its nominal gain and the hand-tuned "optimal" controller.

On the ODE back-end (the default) every block, run and step equals the controller's for the same
configuration and seed: `build/host-release/bin/b21r-experiment --config
tools/experiments/fig4_corridor_examples.conf --seed N` gives the same numbers (checked by
test/python/test_learner_controller.py). --set takes any controller key (b21r-controller
--print-reference-config), e.g. --set hedger_capacity=2000.

Usage: tools/b21r_learn_corridor.py [--backend ode|kinematic] [--seed N] [--phase-one-runs N]
                                    [--phase-two-runs N] [--eval-every N] [--set KEY=VALUE]...
"""
import b21r_bootstrap

b21r_bootstrap.ensure()

import argparse  # noqa: E402
import time  # noqa: E402

from b21r_learn import Learner  # noqa: E402


def block_line(b):
    return "%2d/%d reached the goal, mean %.1f +- %.1f steps" % (b["successes"], b["n_starts"], b["mean_steps"],
                                                                 b["ci95_halfwidth"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backend", choices=("ode", "kinematic"), default="ode")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--phase-one-runs", type=int, default=30)
    ap.add_argument("--phase-two-runs", type=int, default=35)
    ap.add_argument("--eval-every", type=int, default=5)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="a controller configuration key (b21r-controller --print-reference-config)")
    args = ap.parse_args()
    t0 = time.time()

    # The main job's configuration: the controller's defaults (the corridor, 10 m, alpha 0.2,
    # gamma 0.99), the schedule of the arguments, the seed.
    settings = {"task": "corridor", "seed": args.seed, "phase_one_runs": args.phase_one_runs,
                "phase_two_runs": args.phase_two_runs, "eval_every_runs": args.eval_every}
    for kv in args.set:
        key, sep, value = kv.partition("=")
        if not sep:
            ap.error("--set %r: expected KEY=VALUE" % kv)
        settings[key] = value
    learner = Learner.from_controller_config(settings=settings, backend=args.backend)
    cfg = learner.agent.learner_config
    print("learn-corridor: B21rCorridor-v0 (%s back-end), seed %d; lib/learn as the controller configures it "
          "(capacity %d, bandwidth %.2f, alpha %.1f, gamma %.2f, replay %s)"
          % (args.backend, args.seed, cfg["capacity"], cfg["bandwidth"], cfg["alpha"], cfg["gamma"],
             "on" if cfg["replay"] else "off"))

    # The reference lines: the controller's evaluate mode, each on a fresh emulator with the seed.
    for name, policy in (("example policy (nominal gain)", "example"), ("optimal controller", "optimal")):
        ref = Learner.from_controller_config(settings=dict(settings, mode="evaluate", evaluate_policy=policy),
                                             backend=args.backend)
        print("REFERENCE %-30s %s" % (name, block_line(ref.run()[-1])))

    def on_run(run, block):
        kind = "eval" if run["kind"] == "eval" else "train"
        print("run %4d  phase %d  %-5s  %-7s %4d steps  store %d/%d"
              % (run["run_id"], run["phase"], kind, "goal" if run["goal"] else "no goal", run["steps"],
                 run["store_fill"], cfg["capacity"]))
        if block is not None:
            print("EVAL block %2d after %3d training runs (phase %d): %s"
                  % (block["block"], block["training_runs"], block["phase"], block_line(block)))
            if block["phase"] == 1 and learner.agent.schedule()["phase"] == 2:
                print("PHASE TWO: the learned policy drives from now on")

    learner.run(on_run=on_run)
    best = learner.agent.schedule()["best_example_steps"]
    stats = learner.agent.stats()
    print("learn-corridor: done in %.0f s; best example run %s steps; HEDGER answered %d LWR / %d LWA / %d unknown"
          % (time.time() - t0, best if best > 0 else "no", stats["predictions_lwr"], stats["predictions_lwa"],
             stats["predictions_unknown"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
