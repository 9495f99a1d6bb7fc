#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.offline_train: b21r-train trains HEDGER from a logged phase-one session and the
controller resumes phase two from its checkpoint (emulator, lockstep).
Claims checked:
1. Offline training from the session's experience log reproduces the learned state the
   controller itself ended phase one with, bit for bit (same HEDGER calls, same settings), and
   from its full log also the shift phase one's ranked pairs of example runs learned; and
   from the phase-two session's full log, where pair_runs = auto ran phase two in ranked pairs,
   the state the controller ended phase two with (B21R_RUN gives the pairs; an experience log
   cannot, and the trainer warns).
2. The controller, started with the offline checkpoint and the session's configuration, resumes
   in phase two (not one phase-one example run: phase two's policy drives, the greedy action or
   the advisor), and the evaluation block after its phase-two runs, where the learned policy
   drives alone, reaches the goal from all 10 evaluation poses, as the online-trained
   controller does in firmware.learn_rflex.
3. Errors name the file and the fix: another task, an existing output, a file that is not a log, an
   obstacle shift learned at another pair_obstacle_clearance_m or obstacle_pass_hold_steps (--init).
Also: two logs, --passes 2 and --init from the first pass's checkpoint give the same state.
usage: test_offline_train.py CONTROLLER SIM WORLD TRAIN"""
import os
import shutil
import struct
import subprocess
import sys
import zlib

from b21r import experience_t

import fwtest
from b21r_log import read_log

# 4 replay passes instead of the default 20: the sanitizer build is slow.
# Phase one's example runs in ranked pairs from the 11th on (pair_phase_one, the default; set here
# so that the test does not depend on it), so that the trainer's ranking of both phases' pairs and
# its vet of their steps (pair_shift_vet) are checked; the pairs perturb the imitation's weight
# too (pair_imitation_sigma), so that the trainer must learn it from the records as well.
SESSION = {"phase_one_runs": 30, "eval_every_runs": 1000, "eval_starts": 1, "hedger_replay_passes": 4,
           "pair_phase_one": "true", "pair_imitation_sigma": 0.25}
TRAINER_SETS = ["--set", "hedger_replay_passes=4", "--set", "pair_phase_one=true", "--set", "pair_imitation_sigma=0.25"]
# The learned policy's shift in the controller section (fw/progress.h): a, b (bytes 56-71), its
# pairs (72), the terms revision (76) and the imitation's weight w (80-87).
SHIFT = "<ddIId"


def shift_of(path):
    return struct.unpack_from(SHIFT, sections(path)[0], 56)


def sections(path):
    """(meta, payload) of a controller checkpoint (fw/checkpoint.h layout)."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"B21RCKPT":
        fwtest.fail("%s is not a checkpoint" % path)
    meta_n, payload_n = struct.unpack_from("<QQ", data, 16)
    return data[48:48 + meta_n], data[48 + meta_n:48 + meta_n + payload_n]


def write_checkpoint(path, like, meta, payload):
    """A checkpoint of the format of `like` holding meta and payload (fw/checkpoint.h layout, its CRC-32s)."""
    with open(like, "rb") as f:
        magic_version_size = f.read(16)
    head = bytearray(magic_version_size + struct.pack("<QQIII", len(meta), len(payload), zlib.crc32(meta),
                                                      zlib.crc32(payload), 0))
    head += struct.pack("<I", zlib.crc32(bytes(head)))
    with open(path, "wb") as f:
        f.write(bytes(head) + meta + payload)


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
        # The examples drive phase one; in its pair runs the safety filter's recovery law (source
        # advisor) takes over where even the example's own command would come too near a wall.
        recovery = sum(1 for e in training if e.source == experience_t.SOURCE_ADVISOR)
        if (not training or any(e.phase != 1 for e in training) or recovery > len(training) // 100 or
                any(e.source not in (experience_t.SOURCE_EXAMPLE, experience_t.SOURCE_ADVISOR) for e in training)):
            fwtest.fail("the session's training steps must all be phase-one example steps (or, rarely, the pair "
                        "runs' recovery law: %d steps)" % recovery)
        fwtest.note("phase one: %d experiences logged, %d of training runs (%d by the pair runs' recovery law)" %
                    (len(exps), len(training), recovery))

        offline = os.path.join(d, "offline.ckpt")
        args = ["--set", "phase_one_runs=30", "--set", "eval_every_runs=1000", "--out", offline, explog]
        out, _ = train(trainer, args)
        fwtest.note(out.strip())
        # Under a configuration that runs pairs (given here as pair_runs = true: the same learner as
        # auto) the trainer warns that phase one's pairs in an experience log are learned unranked.
        _, err0 = train(trainer, ["--set", "pair_runs=true", *args[:4], "--out", os.path.join(d, "unranked-one.ckpt"),
                                  explog])
        if "of phases that run pairs" not in err0:
            fwtest.fail("an experience log of a session with phase-one pairs: expected the unranked warning, got:\n%s" %
                        err0)
        if "%d experiences learned" % len(training) not in out:
            fwtest.fail("b21r-train did not learn every training experience (%d)" % len(training))
        if sections(offline)[1] != sections(online)[1]:
            fwtest.fail("the offline learned state differs from the controller's own after phase one")
        fwtest.note("claim 1: the offline learned state equals the controller's after phase one, bit for bit")
        # pair_phase_one (set above) ran phase one's example runs from run 10 on in ranked pairs: their
        # points are imitated whole, so the experience log gives the same store, but only the full
        # log's B21R_RUN records give the shift they learned (bytes 56-87 of the controller section).
        shift_phase_one = shift_of(online)
        if shift_phase_one[2] != 10 or shift_phase_one[:2] == (0.0, 0.0) or shift_phase_one[4] == 0.0:
            fwtest.fail("phase one's 20 paired example runs should have ranked 10 pairs into the shift: %s" %
                        (shift_phase_one,))
        offline_full = os.path.join(d, "offline-full.ckpt")
        out1, _ = train(trainer, ["--set", "phase_one_runs=30", "--set", "eval_every_runs=1000", "--out",
                                  offline_full, log1])
        if (sections(offline_full)[1] != sections(online)[1] or
                shift_of(offline_full) != shift_phase_one or
                "10 pairs of runs ranked" not in out1):
            fwtest.fail("from the phase-one full log the trainer should reach the controller's store and shift %s, "
                        "got %s:\n%s" % (shift_phase_one, shift_of(offline_full),
                                          out1))
        fwtest.note("claim 1, phase one's pairs: from the full log the trainer ranks the 10 pairs as the controller "
                    "did and reaches its shift (%.4f, %.4f) and imitation weight %+.4f bit for bit" %
                    (shift_phase_one[0], shift_phase_one[1], shift_phase_one[4]))

        # Claim 2: phase two from the offline checkpoint, the full log's (with phase one's shift: the
        # recommended input; without it phase two's first pairs start the shift again from zero).
        shutil.copyfile(offline_full, offline)
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

        # Claim 1 for phase two: from the full log (B21R_RUN says which runs were pairs and which the
        # safety filter corrected) the trainer ranks the pairs as the controller did, bit for bit.
        runs2 = [m for _, _, m in read_log(log, {"B21R_RUN"}) if m.kind == 0]
        if [r.pair_member for r in runs2] != [0, 1, 0, 1, 0]:
            fwtest.fail("pair_runs = auto in the emulated corridor: expected phase two in pairs, got pair_member %s" %
                        [r.pair_member for r in runs2])
        ranked = os.path.join(d, "ranked.ckpt")
        out, _ = train(trainer, ["--init", before_two, "--out", ranked, log])
        if "2 pairs of runs ranked" not in out:
            fwtest.fail("b21r-train did not rank the 2 pairs of the phase-two log:\n%s" % out)
        if sections(ranked)[1] != sections(offline)[1]:
            fwtest.fail("the offline learned state differs from the controller's own after phase two (pairs ranked)")
        # The learned policy's shift, its pair count and the imitation's weight (controller section, bytes 56-87:
        # fw/progress.h) are the same too, phase one's 10 pairs and phase two's 2 (a pair whose runs
        # took equal steps leaves the shift where it was: the rule alone is tested in firmware.loop).
        shift_online = shift_of(offline)
        shift_offline = shift_of(ranked)
        if shift_online != shift_offline or shift_online[2] != shift_phase_one[2] + 2:
            fwtest.fail("the learned policy's shift: controller %r, b21r-train %r (expected equal, after %d pairs)" %
                        (shift_online, shift_offline, shift_phase_one[2] + 2))
        if "shift: %.4f rad/s per rad of target angle, %.4f" % shift_online[:2] not in out:
            fwtest.fail("b21r-train did not report the shift %r:\n%s" % (shift_online, out))
        if "the greedy action counts %.4f times" % (1.0 + shift_online[4]) not in out:
            fwtest.fail("b21r-train did not report the imitation's weight %r:\n%s" % (shift_online[4], out))
        # An experience log cannot say which runs were pairs: under a configuration that runs pairs
        # (the session's, here given as pair_runs = true: the same learner as auto) the trainer
        # learns them unranked and says so (and the state then differs from the controller's).
        unranked = os.path.join(d, "unranked.ckpt")
        _, err2 = train(trainer, ["--set", "pair_runs=true", "--init", before_two, "--out", unranked, explog2])
        if "learned unranked" not in err2 or "log_file" not in err2:
            fwtest.fail("an experience log of pair runs: expected the warning, got:\n%s" % err2)
        if sections(unranked)[1] == sections(offline)[1]:
            fwtest.fail("unranked pairs gave the ranked state")
        if shift_of(unranked) != shift_of(before_two):
            fwtest.fail("an experience log moved the shift: it has no pair records to move it with")
        # --init carries the shift: training on from the controller's checkpoint after phase two
        # keeps its shift (an experience log has no pairs to move it).
        carried = os.path.join(d, "carried.ckpt")
        train(trainer, ["--set", "pair_runs=true", "--init", offline, "--out", carried, explog2])
        if shift_of(carried) != shift_online:
            fwtest.fail("b21r-train --init lost the checkpoint's shift %r: wrote %r" %
                        (shift_online, shift_of(carried)))
        # A second pass over the full log takes the shift from its records instead of moving it
        # again, and says so.
        pairs_twice = os.path.join(d, "pairs-twice.ckpt")
        out2, _ = train(trainer, ["--init", before_two, "--passes", "2", "--out", pairs_twice, log])
        if (shift_of(pairs_twice) != shift_online
                or "follows the log's records" not in out2):
            fwtest.fail("two passes over the phase-two log: expected the controller's shift %r and the note, got %r:\n%s"
                        % (shift_online, shift_of(pairs_twice), out2))
        fwtest.note("claim 1, phase two: the trainer ranks the pairs of the full log as the controller did, bit for "
                    "bit, and reaches its shift (%.4f, %.4f, %d pairs, imitation weight %+.4f); from an experience "
                    "log it warns" % (shift_online[0], shift_online[1], shift_online[2], shift_online[4]))

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
        # An obstacle shift resumes only with the clearance its terms bent around (bytes 88-95 of
        # the controller section): the refusal names the setting. The checkpoint is this session's,
        # its controller section made an obstacle one learned at 0.45 m (checked before the state).
        meta, payload = sections(offline)
        meta = bytearray(meta)
        struct.pack_into("<II", meta, 8, 1, 5)  # task obstacles, its state dimension
        struct.pack_into("<d", meta, 88, 0.45)
        obstacle = os.path.join(d, "obstacle-0.45.ckpt")
        write_checkpoint(obstacle, offline, bytes(meta), payload)
        _, err = train(trainer, ["--set", "task=obstacles", "--init", obstacle, "--out", os.path.join(d, "o.ckpt"),
                                 explog], expect_rc=1)
        if obstacle not in err or "train with pair_obstacle_clearance_m = 0.45" not in err:
            fwtest.fail("an obstacle shift learned at another clearance: %s" % err)
        # ... and with the hold past the obstacle it was learned and vetted with, where a 104-byte
        # section records it (bytes 96-99, the hold + 1). The clearance is the trainer's
        # (pair_obstacle_clearance_m, set below). (tools.train_checkpoint: the other cases.)
        struct.pack_into("<d", meta, 88, 0.45)
        held = os.path.join(d, "obstacle-hold-6.ckpt")
        write_checkpoint(held, offline, bytes(meta) + struct.pack("<II", 6 + 1, 0), payload)
        _, err = train(trainer, ["--set", "task=obstacles", "--set", "pair_obstacle_clearance_m=0.45",
                                 "--set", "obstacle_pass_hold_steps=10", "--init", held,
                                 "--out", os.path.join(d, "h.ckpt"), explog], expect_rc=1)
        if held not in err or "train with obstacle_pass_hold_steps = 6" not in err:
            fwtest.fail("an obstacle shift learned with another hold: %s" % err)
        fwtest.note("claim 3: errors name the file and the fix")
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
