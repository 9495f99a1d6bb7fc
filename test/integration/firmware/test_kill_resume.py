#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.kill_resume: no finished run is ever lost. The unmodified b21r-controller learns
against the emulator in lockstep and is killed with SIGKILL at random moments (B21R_KILLS times,
50 by default; the moment drawn uniformly from B21R_KILL_MAX_S seconds after each start), then
restarted with the same checkpoint; a last session completes the schedule (30 example runs, then
B21R_KILL_PHASE_TWO learned runs, 120 by default; a block of 2 evaluation runs every 10; the
backward replay after each training run with B21R_KILL_REPLAY_PASSES passes, 20 by default: a
longer replay than the controller's 3 passes, so that more kills land between runs).

A run counts as reported when its B21R_RUN reached the controller's event log. Asserted:
- every restart resumes at least the finished training runs reported before it (its "resumed
  from ... N training runs" line), and its first run id follows every reported one;
- no reported finished run is ever run again: each training index and each evaluation start of
  a block appears at most once among the reported finished runs (a lost run would be repeated
  with its index);
- the last session completes the schedule.
usage: test_kill_resume.py CONTROLLER SIM WORLD [SEED]"""
import os
import random
import re
import signal
import subprocess
import sys
import time

import fwtest

FINISHED = (0, 1, 2)  # run_t.END_GOAL, END_COLLISION, END_STEP_LIMIT


def read_runs(path):
    """The B21R_RUN messages of an event log that a kill may have cut anywhere."""
    return [m for _, _, m in fwtest.read_log(path, {"B21R_RUN"}, cut=True)]


def main():
    controller, sim_exe, world = sys.argv[1:4]
    seed = int(sys.argv[4]) if len(sys.argv) > 4 else int(os.environ.get("B21R_KILL_SEED", "1"))
    kills = int(os.environ.get("B21R_KILLS", "50"))
    kill_max_s = float(os.environ.get("B21R_KILL_MAX_S", "2.0"))
    rnd = random.Random(seed)
    d = fwtest.workdir("kill-resume")
    ok = False
    sim = fwtest.Sim(sim_exe, world, d, "sim", base="rflex", seed=3)
    ckpt = os.path.join(d, "hedger.ckpt")
    phase_two = int(os.environ.get("B21R_KILL_PHASE_TWO", "120"))
    settings = {"phase_one_runs": 30, "phase_two_runs": phase_two, "eval_every_runs": 10, "eval_starts": 2,
                "hedger_replay_passes": int(os.environ.get("B21R_KILL_REPLAY_PASSES", "20")), "checkpoint_file": ckpt}
    reported = []          # (session, run_t) of every reported run, in order
    resumed_runs = []      # per session: the training runs it said it resumed
    t0 = time.time()
    try:
        for session in range(kills + 1):
            name = "s%02d" % session
            err_path = os.path.join(d, name + ".controller.log")
            with open(os.path.join(d, name + ".progress.txt"), "w") as out, open(err_path, "w") as err:
                p = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, name, settings), stdout=out, stderr=err)
                if session < kills:
                    time.sleep(rnd.uniform(0.05, kill_max_s))
                    if p.poll() is None:
                        p.send_signal(signal.SIGKILL)
                    rc = p.wait(30)
                else:
                    try:
                        rc = p.wait(600)
                    except subprocess.TimeoutExpired:
                        p.kill()
                        fwtest.fail("the last session did not finish within 600 s (see %s)" % err_path)
            with open(err_path) as f:
                text = f.read()
            m = re.search(r"(resumed from|no checkpoint yet at) \S+ \(phase (\d), (\d+) training runs", text)
            if m is None:
                if session < kills and rc == -signal.SIGKILL:
                    resumed_runs.append(None)  # killed before it had loaded
                else:
                    fwtest.fail("session %d (status %s) did not report its start:\n%s" % (session, rc, text))
            else:
                resumed_runs.append(int(m.group(3)))
            if session == kills and rc != 0:
                fwtest.fail("the last session ended with status %d:\n%s" % (rc, text))
            runs = read_runs(os.path.join(d, name + ".lcmlog"))
            # What the sessions before reported is on disk: this one resumed all of it.
            done_before = sum(1 for _, r in reported if r.kind == 0 and r.end_reason in FINISHED)
            if resumed_runs[-1] is not None and resumed_runs[-1] < done_before:
                fwtest.fail("session %d resumed %d training runs, but %d were reported finished before it" %
                            (session, resumed_runs[-1], done_before))
            if runs and reported and runs[0].run_id <= reported[-1][1].run_id:
                fwtest.fail("session %d reported run id %d again (last reported before: %d)" %
                            (session, runs[0].run_id, reported[-1][1].run_id))
            reported += [(session, r) for r in runs]
        elapsed = time.time() - t0
        train = [(s, r) for s, r in reported if r.kind == 0 and r.end_reason in FINISHED]
        evals = [(s, r) for s, r in reported if r.kind == 1 and r.end_reason in FINISHED]
        seen = {}
        for s, r in train:
            if r.training_index in seen:
                fwtest.fail("training run %d was reported finished twice (runs %d in session %d and %d in "
                            "session %d): a reported run was lost" %
                            (r.training_index, seen[r.training_index][1], seen[r.training_index][0], r.run_id, s))
            seen[r.training_index] = (s, r.run_id)
        eseen = set()
        for s, r in evals:
            key = (r.eval_block, r.eval_index)
            if key in eseen:
                fwtest.fail("evaluation start %d of block %d was reported finished twice: a reported run was lost" %
                            (r.eval_index, r.eval_block))
            eseen.add(key)
        total = settings["phase_one_runs"] + settings["phase_two_runs"]
        last = reported[-1][1] if reported else None
        if len(train) > total or max(seen) != total - 1:
            fwtest.fail("%d training runs reported, indices up to %d; the schedule has %d" %
                        (len(train), max(seen), total))
        fwtest.note("%d kills in %.0f s: %d finished runs reported (%d training, %d evaluation), none repeated; "
                    "%d training runs on disk whose report the kill cut from the log; last run id %d" %
                    (kills, elapsed, len(train) + len(evals), len(train), len(evals), total - len(train),
                     last.run_id if last else -1))
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
