#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.offline_train: b21r-train trains HEDGER from a logged phase-one session and the
controller resumes phase two from its checkpoint (emulator, lockstep).
Claims checked:
1. Offline training from the session's experience log reproduces the learned state the
   controller itself ended phase one with, bit for bit (same HEDGER calls, same settings), and so
   does its full log; and from the phase-two session's log, with --init from the checkpoint phase
   two began with, the state the controller ended phase two with.
2. The controller, started with the offline checkpoint and the session's configuration, resumes
   in phase two (not one phase-one example run: phase two's policy drives, the greedy action or
   the advisor), and the evaluation block after its phase-two runs, where the learned policy
   drives alone, reaches the goal from all 10 evaluation poses, as the online-trained
   controller does in firmware.learn_rflex.
3. Errors name the file and the fix: another task, an existing output, a file that is not a log, a
   misspelt key.
Also: two logs, --passes 2 and --init from the first pass's checkpoint give the same state.
usage: test_offline_train.py CONTROLLER SIM WORLD TRAIN"""
import os
import shutil
import struct
import subprocess
import sys

from b21r import experience_t

import fwtest
from b21r_log import read_log

# 4 replay passes, not the default 3: the trainer learns the session's state only when given the
# session's settings (--set).
SESSION = {"phase_one_runs": 30, "eval_every_runs": 1000, "eval_starts": 1, "hedger_replay_passes": 4}
TRAINER_SETS = ["--set", "hedger_replay_passes=4"]


def sections(path):
    """(meta, payload) of a controller checkpoint (fw/checkpoint.h layout)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"B21RCKPT":
        fwtest.fail("%s is not a checkpoint" % path)
    meta_n, payload_n = struct.unpack_from("<QQ", data, 16)
    return data[48:48 + meta_n], data[48 + meta_n:48 + meta_n + payload_n]


def train(exe, args, expect_rc=0):
    p = subprocess.run([exe, *TRAINER_SETS, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=300)
    if p.returncode != expect_rc:
        fwtest.fail("b21r-train %s: exit %d, expected %d\n%s%s" % (" ".join(args), p.returncode, expect_rc, p.stdout,
                                                                 p.stderr))
    return p.stdout, p.stderr


def main():
    controller, sim_exe, world, trainer = sys.argv[1:5]
    d = fwtest.workdir("offline-train")
    ok = False
    sim = fwtest.Sim(sim_exe, world, d, "phase1", seed=4)
    try:
        online = os.path.join(d, "online.ckpt")
        explog = os.path.join(d, "phase1-experiences.lcmlog")
        settings = dict(SESSION, phase_two_runs=0, checkpoint_file=online, experience_log_file=explog)
        rc, err, log1 = fwtest.run_controller(controller, sim, d, "phase1", settings, timeout=600)
        if rc != 0:
            fwtest.fail("phase-one session: exit %d\n%s" % (rc, err))
        sim.close()
        exps = [m for _, _, m in read_log(explog, {"B21R_EXPERIENCE"})]
        training = [e for e in exps if not e.evaluating]
        if not training or any(e.phase != 1 or e.source != experience_t.SOURCE_EXAMPLE for e in training):
            fwtest.fail("the session's training steps must all be phase-one example steps")
        # The default decision_ticks = 2: the log's experiences are the decisions, each ending at
        # an odd step (steps 0-1, 2-3, ...) but a run's last, which may end inside a decision.
        last_of_run = {e.run_id: e.step_id for e in training}
        if any(e.step_id % 2 != 1 and e.step_id != last_of_run[e.run_id] for e in training):
            fwtest.fail("decision_ticks = 2 (the default): every experience but a run's last must end at an odd step")
        fwtest.note("phase one: %d experiences logged, %d of training runs" % (len(exps), len(training)))

        offline = os.path.join(d, "offline.ckpt")
        args = ["--set", "phase_one_runs=30", "--set", "eval_every_runs=1000", "--out", offline, explog]
        out, _ = train(trainer, args)
        fwtest.note(out.strip())
        if "%d experiences learned" % len(training) not in out:
            fwtest.fail("b21r-train did not learn every training experience (%d)" % len(training))
        if sections(offline)[1] != sections(online)[1]:
            fwtest.fail("the offline learned state differs from the controller's own after phase one")
        offline_full = os.path.join(d, "offline-full.ckpt")
        train(trainer, ["--set", "phase_one_runs=30", "--set", "eval_every_runs=1000", "--out", offline_full, log1])
        if sections(offline_full)[1] != sections(online)[1]:
            fwtest.fail("from the phase-one full log the trainer should reach the controller's store")
        fwtest.note("claim 1: the offline learned state equals the controller's after phase one, bit for bit, "
                    "from the experience log and from the full log")

        # Claim 1 with a decision every tick (decision_ticks = 1, the paper's): given the setting,
        # the trainer learns the log's experiences with the session's discount (gamma) and reaches
        # the controller's state; a log of the other setting is refused.
        sim = fwtest.Sim(sim_exe, world, d, "every-tick", seed=4)
        online1 = os.path.join(d, "online-every-tick.ckpt")
        explog_1 = os.path.join(d, "every-tick-experiences.lcmlog")
        rc, err, _ = fwtest.run_controller(controller, sim, d, "every-tick",
                                           dict(SESSION, phase_one_runs=10, phase_two_runs=0, decision_ticks=1,
                                                checkpoint_file=online1, experience_log_file=explog_1), timeout=600)
        if rc != 0:
            fwtest.fail("decision_ticks = 1 session: exit %d\n%s" % (rc, err))
        sim.close()
        trained_1 = [m for _, _, m in read_log(explog_1, {"B21R_EXPERIENCE"}) if not m.evaluating]
        by_run = {}
        for m in trained_1:
            by_run.setdefault(m.run_id, []).append(m.step_id)
        if not trained_1 or any(steps != list(range(len(steps))) for steps in by_run.values()):
            fwtest.fail("decision_ticks = 1: a run's experiences must be its steps 0, 1, 2, ...")
        path = os.path.join(d, "every-tick.ckpt")
        train(trainer, ["--set", "decision_ticks=1", "--set", "phase_one_runs=10", "--quiet", "--out", path, explog_1])
        if sections(path)[1] != sections(online1)[1]:
            fwtest.fail("decision_ticks = 1: the trainer given the setting should reach the controller's state")
        # A log of the other setting is refused, naming the setting it was recorded with.
        for sets, log, want in (([], explog_1, "--set decision_ticks=1"),
                                (["--set", "decision_ticks=1"], explog, "--set decision_ticks=2")):
            _, err = train(trainer, [*sets, "--quiet", "--out", os.path.join(d, "refused.ckpt"), log], expect_rc=1)
            if want not in err or log not in err or os.path.exists(os.path.join(d, "refused.ckpt")):
                fwtest.fail("a log of another decision_ticks: expected a refusal naming %r and the log, no output; "
                            "got:\n%s" % (want, err))
        fwtest.note("claim 1 with decision_ticks = 1: %d steps learned; the trainer given the setting reaches "
                    "the controller's state, bit for bit; a log of the other setting is refused: %s" %
                    (len(trained_1), err.strip().splitlines()[-1]))

        # Claim 2: phase two from the offline checkpoint.
        before_two = os.path.join(d, "before-phase-two.ckpt")
        explog2 = os.path.join(d, "phase2-experiences.lcmlog")
        shutil.copyfile(offline, before_two)
        sim = fwtest.Sim(sim_exe, world, d, "phase2", seed=4)
        rc, err, log = fwtest.run_controller(controller, sim, d, "phase2",
                                             dict(SESSION, phase_two_runs=5, eval_every_runs=5, eval_starts=10,
                                                  checkpoint_file=offline, experience_log_file=explog2), timeout=600)
        if rc != 0 or "resumed from %s (phase 2, 0 training runs" % offline not in err:
            fwtest.fail("the controller did not resume phase two from the offline checkpoint (exit %d):\n%s" % (rc, err))
        exps2 = [m for _, _, m in read_log(log, {"B21R_EXPERIENCE"})]
        trained2 = [e for e in exps2 if not e.evaluating]
        by_source = {}
        for e in trained2:
            by_source[e.source] = by_source.get(e.source, 0) + 1
        if any(e.phase != 2 for e in exps2) or experience_t.SOURCE_EXAMPLE in by_source:
            fwtest.fail("phase two expected throughout, phase two's policy driving (sources %s)" % by_source)
        evals = [m for _, _, m in read_log(log, {"B21R_EVAL"})]
        if len(evals) != 1 or evals[0].phase != 2 or evals[0].n_starts != 10:
            fwtest.fail("expected one phase-two evaluation block of 10 poses, got %d" % len(evals))
        e = evals[0]
        fwtest.note("claim 2: phase two from the offline checkpoint: %d training steps (by source %s); evaluation "
                    "after 5 phase-two runs: %d/%d reached the goal, mean %.1f +- %.1f steps" %
                    (len(trained2), by_source, e.successes, e.n_starts, e.mean_steps, e.ci95_halfwidth))
        if e.successes != e.n_starts:
            fwtest.fail("phase two from the offline checkpoint reached the goal from %d of %d poses" %
                        (e.successes, e.n_starts))
        sim.close()

        # Claim 1 for phase two: from the checkpoint phase two began with, the phase-two log gives the
        # state the controller ended phase two with, bit for bit (from the full log and the
        # experience log alike).
        for name, source in (("full", log), ("experiences", explog2)):
            trained = os.path.join(d, "phase-two-%s.ckpt" % name)
            train(trainer, ["--init", before_two, "--out", trained, source])
            if sections(trained)[1] != sections(offline)[1]:
                fwtest.fail("the offline learned state differs from the controller's own after phase two (%s log)" %
                            name)
        fwtest.note("claim 1, phase two: from --init and the phase-two log the trainer reaches the controller's "
                    "state, bit for bit")

        # Several logs, in order: the second pass learns the same data again (twice the updates).
        twice = os.path.join(d, "twice.ckpt")
        out, _ = train(trainer, ["--out", twice, "--quiet", explog, explog])
        if "%d experiences learned from 2 log(s)" % (2 * len(training)) not in out:
            fwtest.fail("two logs: %s" % out)
        if sections(twice)[1] == sections(offline)[1]:
            fwtest.fail("learning the data twice left the state unchanged")
        # Continuing from a checkpoint (--init) is the same as learning everything in one go, and
        # --passes 2 is the same as giving the log twice.
        first = os.path.join(d, "first.ckpt")  # offline.ckpt has learned phase two meanwhile
        train(trainer, ["--out", first, "--quiet", explog])
        for name, extra in (("init", ["--init", first, explog]), ("passes", ["--passes", "2", explog])):
            path = os.path.join(d, name + ".ckpt")
            train(trainer, ["--out", path, "--quiet", *extra])
            if sections(path)[1] != sections(twice)[1]:
                fwtest.fail("%s: the learned state differs from learning the log twice in one go" % " ".join(extra))
        fwtest.note("several logs, --passes and --init (continuing from a checkpoint) agree bit for bit")

        # Claim 3: errors name the file and the fix.
        _, err = train(trainer, ["--set", "task=obstacles", "--out", os.path.join(d, "x.ckpt"), explog], expect_rc=1)
        if explog not in err or "task = " not in err:
            fwtest.fail("another task: %s" % err)
        _, err = train(trainer, ["--out", offline, explog], expect_rc=1)
        if "--force" not in err:
            fwtest.fail("an existing output: %s" % err)
        _, err = train(trainer, ["--out", os.path.join(d, "y.ckpt"), online], expect_rc=1)
        if "not an LCM event log" not in err:
            fwtest.fail("a checkpoint given as a log: %s" % err)
        _, err = train(trainer, ["--set", "hedger_k_mn=3", "--out", os.path.join(d, "z.ckpt"), explog], expect_rc=2)
        if "did you mean 'hedger_k_min'" not in err:
            fwtest.fail("a misspelt key: %s" % err)
        fwtest.note("claim 3: errors name the file and the fix")
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
