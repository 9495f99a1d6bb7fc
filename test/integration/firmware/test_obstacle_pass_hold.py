#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.obstacle_pass_hold: the controller's loop holds course past an obstacle, wired end to
end. b21r-experiment (the controller's loop core and the ODE emulator in one process; its
experience log is byte for byte the controller's) runs a short obstacle session of Figs. 9-10
(10 runs of the simulated human, 10 phase-two runs, an evaluation block of 10 poses every 5 runs)
with obstacle_pass_hold_steps = 10 and = 0 from the same seed, and the evaluation runs' experiences
(the learned policy alone, no noise) are read where a near obstacle (in view, within 1.5 m) slips
out of the laser's view:

  held      with the hold, in every such pass the command falls to 0 at the acceleration limit
            (never growing) and stays exactly 0 for the rest of the 10 states or until an
            obstacle is back in view;
  released  with the hold, where the obstacle stays out of view longer, the command moves again
            after the 10 states in at least one pass (the hold ends);
  turns     without the hold (0), most such passes turn at once (the command is not that ramp to
            0): the checks above tell the two apart.

usage: test_obstacle_pass_hold.py B21R_EXPERIMENT EXPERIMENT_CONF REFERENCE_CONF"""
import math
import os
import subprocess
import sys

from b21r_log import read_log

import fwtest

HOLD = 10
SEED = 3
SHORT = ["--set", "phase_one_runs=10", "--set", "phase_two_runs=10", "--set", "eval_every_runs=5"]
NEAR_M = 1.5  # FW_PAIR_OBSTACLE_RANGE_M: "near" as the hold's rule says


def reference_value(path, key):
    with open(path) as f:
        for line in f:
            k, sep, v = line.partition("=")
            if sep and k.strip() == key:
                return float(v.split("#")[0].strip())
    fwtest.fail("%s: no %s" % (path, key))


def session(exe, conf, hold, d):
    log = os.path.join(d, "hold-%d.lcmlog" % hold)
    cmd = [exe, "--config", conf, *SHORT, "--set", "obstacle_pass_hold_steps=%d" % hold, "--seed", str(SEED),
           "--out", os.path.join(d, "hold-%d.json" % hold), "--experience-log", log]
    p = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=600)
    if p.returncode != 0:
        fwtest.fail("%s: exit %d\n%s" % (" ".join(cmd), p.returncode, p.stderr))
    runs = {}
    for _, _, e in read_log(log, channels={"B21R_EXPERIENCE"}):
        if e.evaluating:
            runs.setdefault(e.run_id, []).append(e)
    return [sorted(es, key=lambda e: e.step_id) for es in runs.values()]


def in_view(s):
    return abs(s[2]) <= math.pi / 2  # the obstacle slot's bearing; an empty slot's is pi


def passes(runs):
    """(commands in the hold window, the command one state after it or None) for every state where a
    near obstacle seen at the state before is out of view; the window ends early where an obstacle
    is back in view or the run ends."""
    out = []
    for es in runs:
        for i in range(1, len(es)):
            before, now = es[i - 1].s, es[i].s
            if not (in_view(before) and before[3] < NEAR_M and not in_view(now)):
                continue
            window = []
            for j in range(i, min(i + HOLD, len(es))):
                if in_view(es[j].s):
                    break
                window.append(es[j].action_radps)
            after = None
            if len(window) == HOLD and i + HOLD < len(es) and not in_view(es[i + HOLD].s):
                after = es[i + HOLD].action_radps
            out.append((window, after))
    return out


def ramps_to_zero(window, step):
    """The command never grows, falls by at most the acceleration limit's step, and is exactly 0 from
    the first state it can be (|command| / step states in) to the window's end."""
    for k in range(1, len(window)):
        fall = abs(window[k - 1]) - abs(window[k])
        if fall < -1e-12 or fall > step + 1e-9:
            return False
    first_zero = math.ceil(abs(window[0]) / step - 1e-9) if window else 0
    return all(a == 0.0 for a in window[first_zero:])


def main():
    exe, conf, reference = sys.argv[1:4]
    step = reference_value(reference, "max_rotation_accel_radps2") / reference_value(reference, "tick_rate_hz")
    ok = False
    d = fwtest.workdir("pass-hold")
    try:
        held = passes(session(exe, conf, HOLD, d))
        free = passes(session(exe, conf, 0, d))
        if len(held) < 10 or len(free) < 10:
            fwtest.fail("too few passes to judge: %d with the hold, %d without" % (len(held), len(free)))
        held_ok = sum(ramps_to_zero(w, step) for w, _ in held)
        free_ok = sum(ramps_to_zero(w, step) for w, _ in free)
        released = [a for _, a in held if a is not None]
        print("evaluation passes of a near obstacle out of view: %d with the hold, %d without" % (len(held), len(free)))
        print("held      the command falls to 0 and stays there: %d of %d with the hold" % (held_ok, len(held)))
        print("released  moves again after %d states: %d of %d passes still out of view then"
              % (HOLD, sum(a != 0.0 for a in released), len(released)))
        print("turns     without the hold the same check holds in %d of %d" % (free_ok, len(free)))
        if held_ok != len(held):
            fwtest.fail("with the hold, %d of %d passes did not hold course" % (len(held) - held_ok, len(held)))
        if not any(a != 0.0 for a in released):
            fwtest.fail("the hold never ended: no command after %d states out of view (%d passes)"
                        % (HOLD, len(released)))
        if free_ok * 2 >= len(free):
            fwtest.fail("without the hold %d of %d passes look held: the check cannot tell" % (free_ok, len(free)))
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
