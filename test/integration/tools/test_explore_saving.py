#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.explore_saving: the main job's "without examples" lines (tools/b21r_explore_saving.py)
from a hand-built exploration result and session summary: the first reward's mean and interval,
the restarts charged on the robot, the session's training on the same terms, and the saving's
sign: random exploration slower than the whole training is a saving, faster is none.
usage: test_explore_saving.py (PYTHONPATH holds tools/)"""
import json
import math
import os
import subprocess
import sys
import tempfile

import b21r_explore_saving as sav

TOOL = os.path.join(os.path.dirname(sav.__file__), "b21r_explore_saving.py")


def check(cond, what):
    if not cond:
        print("FAIL:", what)
        sys.exit(1)


def explore(times_s, episodes):
    return {"kind": "explore_corridor", "seed": 7,
            "explore": {"dt_s": 0.1, "time_limit_s": 604800, "omega_max_radps": 1, "accel_limits": True,
                        "model": "kinematic", "start": "training",
                        "runs": [{"success": True, "time_s": t, "episodes": e, "driving_s": t}
                                 for t, e in zip(times_s, episodes)]}}


def main():
    # 65 training runs of 140 steps: 9100 steps x 0.1 s = 0.2528 h.
    summary = {"training_runs_by_driver": [{"steps": 140}] * 65}
    times = [360.0 + 60.0 * i for i in range(12)]  # 0.1 h .. 0.283 h, mean 0.1917 h
    w = sav.measure(explore(times, [3] * 12), summary, 30.0)
    sd = math.sqrt(sum((t / 3600 - 0.19166667) ** 2 for t in times) / 11)
    check(abs(w["emulator"]["first_reward_h"] - 0.19166667) < 1e-6, "mean first reward: %s" % w["emulator"])
    check(abs(w["emulator"]["first_reward_ci95_h"] - 2.200985 * sd / math.sqrt(12)) < 1e-3,
          "interval (t 0.975, 11 df = 2.201): %s" % w["emulator"])
    check(abs(w["session_training_h"] - 0.25277778) < 1e-6, "session training: %s" % w["session_training_h"])
    check(abs(w["emulator"]["saving_h"] - (0.19166667 - 0.25277778)) < 1e-6, "saving: %s" % w["emulator"])
    # On the robot: 2 restarts x 30 s more per run, 65 runs x 30 s more for the session.
    check(abs(w["robot"]["first_reward_h"] - (0.19166667 + 60 / 3600)) < 1e-6, "robot: %s" % w["robot"])
    check(abs(w["robot"]["session_training_h"] - (0.25277778 + 65 * 30 / 3600)) < 1e-6, "robot: %s" % w["robot"])
    text = "\n".join(sav.text(w))
    check(text.count("saves no time by this measure") == 2 and "phase one saves 0" not in text, text)
    slow = sav.measure(explore([t * 100 for t in times], [40] * 12), summary, 30.0)
    text = "\n".join(sav.text(slow))
    check(slow["emulator"]["saving_h"] > 18 and text.count("phase one saves ") == 2 and "no time" not in text, text)

    with tempfile.TemporaryDirectory(prefix="b21r-saving-") as d:
        with open(os.path.join(d, "summary.json"), "w") as f:
            json.dump(summary, f)
        with open(os.path.join(d, "summary.txt"), "w") as f:
            f.write("claims ...\n")
        with open(os.path.join(d, "x.json"), "w") as f:
            json.dump(explore(times, [3] * 12), f)
        p = subprocess.run([sys.executable, TOOL, "--explore", os.path.join(d, "x.json"), "--summary-dir", d],
                           capture_output=True, text=True)
        check(p.returncode == 0, p.stderr)
        with open(os.path.join(d, "summary.json")) as f:
            check(json.load(f)["without_examples"]["runs"] == 12, "summary.json has no without_examples")
        with open(os.path.join(d, "summary.txt")) as f:
            lines = f.read().splitlines()
        check(lines[0] == "claims ..." and lines[1].startswith("without examples"), "summary.txt: %s" % lines[:2])
        with open(os.path.join(d, "x.json"), "w") as f:
            json.dump(explore(times[:5], [3] * 5), f)
        p = subprocess.run([sys.executable, TOOL, "--explore", os.path.join(d, "x.json"), "--summary-dir", d],
                           capture_output=True, text=True)
        check(p.returncode != 0 and "at least 11" in p.stderr, "too few runs accepted: %s" % p.stderr)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
