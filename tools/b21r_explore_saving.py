#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_explore_saving: what phase one saved this session, measured. Reads a learning session's
summary (summary.json of b21r_learning_report.py) and a random-exploration result of the same task
and seed (b21r-experiment with tools/experiments/explore_corridor_product.conf: random rotation
within the action range every control period, the task's speed policy, the controller's training
starts and step limit, the base's acceleration limits), and adds to the summary (summary.txt and
summary.json, key "without_examples") the time random exploration needs to find its first reward
against the session's training time:
  - in the emulator, where the robot is put back at once after a run;
  - on the robot, where an operator puts it back after every run (--reposition-s each, both sides).
The saving is random exploration's mean time to the first reward minus the session's training time
(95 % interval over the exploration's runs): positive when the examples finish the whole training
before random actions would find the first reward (the paper's argument, Fig. 6), negative when
random actions find it sooner (then the examples save no time by this measure).
usage: b21r_explore_saving.py --explore RESULT.json --summary-dir DIR [--reposition-s 30]"""
import argparse
import json
import math
import os
import sys


def t975(df):
    """The 0.975 quantile of Student's t with df degrees of freedom (df >= 1): the Cornish-Fisher
    expansion around the normal quantile, within 2e-4 of the exact value from df = 10 on (the
    saving is measured over hundreds of runs; the sweeps use scipy)."""
    z = 1.959963984540054
    return (z + (z ** 3 + z) / (4 * df) + (5 * z ** 5 + 16 * z ** 3 + 3 * z) / (96 * df ** 2) +
            (3 * z ** 7 + 19 * z ** 5 + 17 * z ** 3 - 15 * z) / (384 * df ** 3))


def mean_ci(values):
    n = len(values)
    m = sum(values) / n
    if n < 2:
        return m, math.nan
    sd = math.sqrt(sum((v - m) ** 2 for v in values) / (n - 1))
    return m, t975(n - 1) * sd / math.sqrt(n)


def measure(explore, summary, reposition_s):
    """The numbers the summary states (hours)."""
    ex = explore["explore"]
    runs = ex["runs"]
    dt = ex["dt_s"]
    train = summary["training_runs_by_driver"]
    session_h = sum(r["steps"] for r in train) * dt / 3600.0
    reached = [r for r in runs if r["success"]]
    out = {"runs": len(runs), "reached": len(reached), "time_limit_h": ex["time_limit_s"] / 3600.0,
           "model": ex.get("model", "kinematic"), "omega_max_radps": ex["omega_max_radps"],
           "start": ex.get("start", "paper"), "accel_limits": ex["accel_limits"], "seed": explore["seed"],
           "session_training_runs": len(train), "session_training_h": session_h, "reposition_s": reposition_s}
    for where, rep in (("emulator", 0.0), ("robot", reposition_s)):
        # Every attempt after the first needs the robot put back (the runner charged nothing for it).
        times = [(r["time_s"] + (r["episodes"] - 1) * rep) / 3600.0 for r in runs]
        m, hw = mean_ci(times)
        sess = session_h + len(train) * rep / 3600.0
        out[where] = {"first_reward_h": m, "first_reward_ci95_h": hw,
                      "first_reward_median_h": sorted(times)[(len(times) - 1) // 2],
                      "attempts_mean": sum(r["episodes"] for r in runs) / len(runs),
                      "session_training_h": sess, "saving_h": m - sess, "saving_ci95_h": hw}
    return out


def text(w):
    lines = ["without examples (random exploration, measured for this task and seed: rotation uniform in "
             "[-%g, %g] rad/s every control period, the task's speed policy, the controller's %s starts and step "
             "limit, %s model%s; %d runs, %d reached the first reward within %.0f h):" % (
                 w["omega_max_radps"], w["omega_max_radps"], w["start"], w["model"],
                 " with the base's acceleration limits" if w["accel_limits"] else "", w["runs"], w["reached"],
                 w["time_limit_h"])]
    for where, how in (("emulator", "in the emulator (the robot is put back at once)"),
                       ("robot", "on the robot (an operator puts it back after every run, %.0f s each)" %
                        w["reposition_s"])):
        x = w[where]
        s, hw = x["saving_h"], x["saving_ci95_h"]
        if s - hw > 0:
            verdict = "phase one saves %.3f +- %.3f h" % (s, hw)
        elif s + hw < 0:
            verdict = ("phase one saves no time by this measure: random actions find the first reward %.3f +- %.3f h "
                       "before the training with examples ends" % (-s, hw))
        else:
            verdict = "no significant saving (%+.3f +- %.3f h)" % (s, hw)
        lines.append("  %s: the first reward after %.3f +- %.3f h (median %.3f h, %.1f attempts) against this "
                     "session's %.3f h of training (%d runs): %s" % (
                         how, x["first_reward_h"], x["first_reward_ci95_h"], x["first_reward_median_h"],
                         x["attempts_mean"], x["session_training_h"], w["session_training_runs"], verdict))
    lines.append("  (the paper's Fig. 6 argument: the first reward alone outlasting the whole training; why its hours "
                 "are minutes here, and what the examples buy the learner besides: docs/RESULTS.md, \"Learning "
                 "without examples: which assumptions\")")
    return lines


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--explore", required=True, help="b21r-experiment result of the exploration (JSON)")
    ap.add_argument("--summary-dir", required=True, help="folder with summary.json and summary.txt (updated)")
    ap.add_argument("--reposition-s", type=float, default=30.0,
                    help="robot time an operator needs to put the robot back after a run [s] (default 30)")
    args = ap.parse_args()
    with open(args.explore) as f:
        explore = json.load(f)
    js = os.path.join(args.summary_dir, "summary.json")
    with open(js) as f:
        summary = json.load(f)
    if explore.get("kind") != "explore_corridor" or "explore" not in explore:
        sys.exit("b21r_explore_saving: %s is not a result of an explore_corridor experiment" % args.explore)
    if len(explore["explore"]["runs"]) < 11:
        sys.exit("b21r_explore_saving: %s has %d runs; the interval needs at least 11 (experiment.explore_runs)" % (
            args.explore, len(explore["explore"]["runs"])))
    w = measure(explore, summary, args.reposition_s)
    summary["without_examples"] = w
    tmp = js + ".tmp"
    with open(tmp, "w") as f:
        json.dump(summary, f, indent=2)
    os.replace(tmp, js)
    lines = text(w)
    with open(os.path.join(args.summary_dir, "summary.txt"), "a") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
