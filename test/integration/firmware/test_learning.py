#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.learn_<base>: the unmodified b21r-controller learns the corridor task against the
emulator in lockstep (rFLEX over pseudo-terminals, or CANopen over the seqpacket bus): 30
example runs, then 5 runs driven by the learned policy; the evaluation block after phase two
must reach the goal from all 10 evaluation poses. The experience stream has no gaps, the
checkpoint is written and a restart resumes from it.
usage: test_learning.py CONTROLLER SIM WORLD rflex|canopen"""
import os
import sys

import fwtest
from b21r_log import experience_gaps, read_log


def main():
    controller, sim_exe, world, base = sys.argv[1:5]
    d = fwtest.workdir("learn-" + base)
    ok = False
    sim = fwtest.Sim(sim_exe, world, d, "sim", base=base, seed=1)
    try:
        ckpt = os.path.join(d, "hedger.ckpt")
        # The defaults but a shorter schedule (the sanitizer build is slow).
        settings = {"phase_one_runs": 30, "phase_two_runs": 5, "eval_every_runs": 30, "checkpoint_file": ckpt}
        rc, err, log = fwtest.run_controller(controller, sim, d, "learn", settings, timeout=600)
        if rc != 0:
            fwtest.fail("controller exit status %d:\n%s" % (rc, err))
        evals = [m for _, _, m in read_log(log, {"B21R_EVAL"})]
        for e in evals:
            fwtest.note("block %d after %d training runs (phase %d): %d/%d reached, mean %.1f +- %.1f steps" %
                        (e.block, e.training_runs, e.phase, e.successes, e.n_starts, e.mean_steps, e.ci95_halfwidth))
        if len(evals) != 2:
            fwtest.fail("expected 2 evaluation blocks, got %d" % len(evals))
        last = evals[-1]
        if last.phase != 2 or last.n_starts != 10 or last.successes != 10:
            fwtest.fail("phase two: reached the goal from %d of %d evaluation poses" % (last.successes, last.n_starts))
        exps = [m for _, _, m in read_log(log, {"B21R_EXPERIENCE"})]
        gaps = experience_gaps(exps)
        if gaps or not exps:
            fwtest.fail("experience stream: %d experiences, gaps %s" % (len(exps), gaps[:5]))
        learned = sum(1 for e in exps if e.phase == 2 and not e.evaluating)
        fwtest.note("%d experiences, no gaps; %d in phase-two training" % (len(exps), learned))
        if not os.path.exists(ckpt):
            fwtest.fail("no checkpoint written at %s" % ckpt)
        # A restart resumes: the schedule is over, so it runs one more block and stops.
        rc, err, _ = fwtest.run_controller(controller, sim, d, "resume", {"checkpoint_file": ckpt,
                                           "phase_one_runs": 30, "phase_two_runs": 5, "eval_every_runs": 30,
                                           "eval_starts": 1}, timeout=300)
        if rc != 0 or "resumed from" not in err or "35 training runs" not in err:
            fwtest.fail("restart did not resume from the checkpoint (status %d):\n%s" % (rc, err))
        fwtest.note("restart resumed from the checkpoint (35 training runs)")
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
