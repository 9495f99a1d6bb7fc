#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.session: one short learning session of the controller against the emulator (lockstep,
rFLEX over pseudo-terminals), small enough to run under qemu-user in the arm64 cross build
(CTest sets B21R_TARGET_EMULATOR there): 4 example runs, 2 runs of the learned policy, an
evaluation block from 2 poses. It must end with exit status 0 after every run, an experience
stream without gaps that filled the learner's store, a checkpoint, and a restart that resumes.
usage: test_session.py CONTROLLER SIM WORLD"""
import os
import sys
import time

import fwtest
from b21r_log import experience_gaps, read_log


def main():
    controller, sim_exe, world = sys.argv[1:4]
    d = fwtest.workdir("session")
    ok = False
    sim = fwtest.Sim(sim_exe, world, d, "sim", seed=4)
    try:
        ckpt = os.path.join(d, "hedger.ckpt")
        settings = {"phase_one_runs": 4, "phase_two_runs": 2, "eval_every_runs": 6, "eval_starts": 2,
                    "hedger_replay_passes": 2, "checkpoint_file": ckpt}
        t0 = time.time()
        rc, err, log = fwtest.run_controller(controller, sim, d, "session", settings, timeout=900)
        if rc != 0:
            fwtest.fail("controller exit status %d:\n%s" % (rc, err))
        runs = [m for _, _, m in read_log(log, {"B21R_RUN"})]
        exps = [m for _, _, m in read_log(log, {"B21R_EXPERIENCE"})]
        evals = [m for _, _, m in read_log(log, {"B21R_EVAL"})]
        status = [m for _, _, m in read_log(log, {"B21R_STATUS"})]
        fwtest.note("%d runs, %d experiences, %d evaluation block(s), store %d samples in %.1f s%s"
                    % (len(runs), len(exps), len(evals), status[-1].store_fill if status else 0, time.time() - t0,
                       " under " + " ".join(fwtest.TARGET) if fwtest.TARGET else ""))
        if len(runs) != 8 or len(evals) != 1 or evals[0].n_starts != 2:
            fwtest.fail("expected 6 training runs and one block of 2 evaluation runs, got %d runs and %d blocks"
                        % (len(runs), len(evals)))
        gaps = experience_gaps(exps)
        if gaps or not exps:
            fwtest.fail("experience stream: %d experiences, gaps %s" % (len(exps), gaps[:5]))
        if not status or status[-1].store_fill < 100:
            fwtest.fail("the learner stored %d samples" % (status[-1].store_fill if status else 0))
        if not os.path.exists(ckpt):
            fwtest.fail("no checkpoint at %s" % ckpt)
        rc, err, _ = fwtest.run_controller(controller, sim, d, "resume", dict(settings, eval_starts=1), timeout=600)
        if rc != 0 or "resumed from" not in err or "6 training runs" not in err:
            fwtest.fail("the restart did not resume from the checkpoint (status %d):\n%s" % (rc, err))
        fwtest.note("the restart resumed from the checkpoint (6 training runs)")
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
