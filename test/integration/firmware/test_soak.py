#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.soak_<base> (label soak, not in CI: `ctest --preset soak`): hours of real-time
learning against the emulator with a random fault every few minutes. The unmodified controller
learns with its defaults (30 example runs, then learned runs with the backward replay between
runs, evaluation blocks) and, where permitted, its real-time options (SCHED_FIFO 60 on the last
CPU, memory locked, buffers pre-faulted; the emulator at FIFO 50). Faults are drawn from a seeded
generator: each stop fault must stop the base with its reason and the stop must clear; each
tolerated fault (line noise, failed CAN CRCs, lost frames) must cause no stop; a SIGKILL restarts
the controller from its checkpoint and journal.
Asserted:
- no crash: every session ends by the test's SIGKILL or SIGTERM (exit 128+15 after a checkpoint);
- no deadline miss: STATUS missed_periods = 0 in every session;
- no false stop: every laser/base silence, base fault or device loss falls within an injected
  fault's window (bumper stops outside them are the learner's collisions, counted);
- every fault answered: its stop seen and cleared, and a run finishes after each fault;
- no leak: what the controller has allocated (VmData: heap and other private mappings) does not
  grow after the first two minutes of a session by more than 256 KiB, nor the emulator's after
  its first two minutes (their resident memory is printed: the emulator's grows while its
  fixed-size trace of the robot's path, allocated at its start, is written);
- every finished run durable: every restart resumes at least the training runs reported
  finished before it, none is reported finished twice, and a last session after the final
  SIGTERM resumes every one.
Prints the figures (ticks, lateness, compute time, memory, faults, runs, collisions).
Environment: B21R_SOAK_SECONDS (default 7200), B21R_SOAK_SEED (default 1),
B21R_SOAK_FAULT_EVERY_S (default "90,240": the pause before each fault is drawn from it).
usage: test_soak.py CONTROLLER SIM WORLD rflex|canopen"""
import os
import random
import re
import signal
import subprocess
import sys
import time

import fwtest
import rtload

PRIORITY = 60
LEAK_KIB = 256
FINISHED = (0, 1, 2)  # run_t.END_GOAL, END_COLLISION, END_STEP_LIMIT
FALSE = ("laser silent", "base silent", "base fault", "device lost")

# (name, command, stop reason expected (or a tuple: any of them answers the fault, and the others
# may follow) or None when tolerated, clear command or None, seconds)
COMMON = [("laser drop", "fault laser_drop 1500", "laser silent", None, 0),
          ("laser stuck", "fault laser_stuck 1500", "laser silent", None, 0),
          ("bumper", "fault bumper 3", "bumper", "fault clear", 0),
          ("laser line noise", "fault noise_laser 0.0001", None, "fault clear", 20),
          ("kill", None, None, None, 0)]
BASE = {"rflex": [("base silent", "fault base_silent 1500", "base silent", "fault clear", 0),
                  ("base line noise", "fault noise_base 0.002", None, "fault clear", 20)],
        "canopen": [("drive fault", "fault drive_fault 2", "base fault", "fault clear", 0),
                    # silent drives: their answers stop (base silence, 350 ms) and so do their heartbeats
                    # (a base fault 500 ms after the last one): either may be seen first
                    ("drives silent", "fault base_silent 1500", ("base silent", "base fault"), "fault clear", 0),
                    ("bump-panel silent", "fault bumper_silent 1500", "base fault", None, 0),
                    ("drive stuck", "fault node_stuck 1 1500", "base fault", None, 0),
                    ("babbling node", "fault babble 5 1000", "base fault", None, 0),
                    ("bus-off", "fault bus_off 1000", "base fault", None, 0),
                    ("failed CRCs", "fault can_errors 0.2", None, "fault clear", 20),
                    ("lost frames", "fault can_drop 0.03", None, "fault clear", 20)]}


def memory_kib(pid):
    """(VmData, RssAnon) of a process [KiB]: what it has allocated (heap, private mappings) and
    what of its anonymous memory is resident; (-1, -1) when it is gone."""
    out = {}
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                key = line.split(":")[0]
                if key in ("VmData", "RssAnon"):
                    out[key] = int(line.split()[1])
    except OSError:
        pass
    return out.get("VmData", -1), out.get("RssAnon", -1)


class Session:
    """One controller process, its logs and its memory samples."""

    def __init__(self, controller, sim, d, index, settings):
        self.name = "s%02d" % index
        self.err_path = os.path.join(d, self.name + ".controller.log")
        self.log_path = os.path.join(d, self.name + ".lcmlog")
        self.offset = 0
        self.started = time.time()
        self.base = None   # (VmData, RssAnon) two minutes after the start
        self.max = (0, 0)
        with open(self.err_path, "w") as err, open(os.path.join(d, self.name + ".progress.txt"), "w") as out:
            self.proc = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, self.name, settings),
                                         stdout=out, stderr=err)
        self.offset = fwtest.wait_for(self.err_path, "starting devices", 0, 60, self.proc)
        with open(self.err_path) as f:
            m = re.search(r"(resumed from|no checkpoint yet at) \S+ \(phase (\d), (\d+) training runs", f.read())
        self.resumed = int(m.group(3)) if m else None

    def sample(self):
        m = memory_kib(self.proc.pid)
        if m[0] < 0:
            return
        if time.time() - self.started >= 120:
            if self.base is None:
                self.base = m
            self.max = (max(self.max[0], m[0]), max(self.max[1], m[1]))

    def new_text(self):
        with open(self.err_path) as f:
            f.seek(self.offset)
            text = f.read()
        self.offset += len(text)
        return text


def main():
    controller, sim_exe, world, base = sys.argv[1:5]
    seconds = int(os.environ.get("B21R_SOAK_SECONDS", "7200"))
    rnd = random.Random(int(os.environ.get("B21R_SOAK_SEED", "1")))
    lo, hi = (float(x) for x in os.environ.get("B21R_SOAK_FAULT_EVERY_S", "90,240").split(","))
    faults = COMMON + BASE[base]
    rt = rtload.may_use_realtime(PRIORITY)
    d = fwtest.workdir("soak-" + base)
    ok = False
    cpu = max(os.sched_getaffinity(0))
    sim = fwtest.Sim(sim_exe, world, d, "sim", base=base, seed=4, lockstep=False,
                     prefix=["chrt", "-f", str(PRIORITY - 10)] if rt else [])
    ckpt = os.path.join(d, "hedger.ckpt")
    settings = {"lockstep": "false", "phase_one_runs": 30, "phase_two_runs": 100000, "seed": 5,
                "checkpoint_file": ckpt}
    if rt:
        settings.update({"rt_scheduler": "fifo", "rt_priority": PRIORITY, "rt_cpus": str(cpu),
                         "rt_lock_memory": "true", "rt_prefault": "true"})
    sessions = []
    reported = []  # (session index, run_t) of every finished run reported
    done = {}      # fault name -> times answered
    false_stops = []
    collisions_outside = 0
    sim_mem = []   # (seconds since the start, (VmData, RssAnon)) of the emulator

    def account(s, text, allowed):
        """Stops in a stretch of the controller's log: `allowed` are the reasons an injected fault
        explains (or None). Returns the reasons seen."""
        nonlocal collisions_outside
        reasons = re.findall(r"SAFETY STOP \(([^)]*)\)", text)
        for r in reasons:
            if allowed is not None and r in allowed:
                continue
            if r == "bumper":
                collisions_outside += 1
            elif r in FALSE:
                false_stops.append("%s in session %s (%.0f s after its start)" % (r, s.name, time.time() - s.started))
        return reasons

    def runs_of(s):
        return [m for _, _, m in fwtest.read_log(s.log_path, {"B21R_RUN"}, cut=True)]

    def start_session():
        s = Session(controller, sim, d, len(sessions), settings)
        before = sum(1 for _, r in reported if r.kind == 0 and r.end_reason in FINISHED)
        if s.resumed is None or s.resumed < before:
            fwtest.fail("session %s resumed %s training runs, but %d were reported finished before it" %
                        (s.name, s.resumed, before))
        sessions.append(s)
        return s

    def end_session(s, sig):
        if s.proc.poll() is not None:
            with open(s.err_path) as f:
                fwtest.fail("session %s ended by itself (status %d):\n%s" % (s.name, s.proc.returncode,
                                                                            f.read()[-3000:]))
        s.proc.send_signal(sig)
        rc = s.proc.wait(120)
        if sig == signal.SIGTERM and rc != 128 + signal.SIGTERM:
            fwtest.fail("session %s: SIGTERM gave exit status %d" % (s.name, rc))
        account(s, s.new_text(), None)
        statuses = [m for _, _, m in fwtest.read_log(s.log_path, {"B21R_STATUS"}, cut=True)]
        if statuses and statuses[-1].missed_periods != 0:
            fwtest.fail("session %s: %d missed periods" % (s.name, statuses[-1].missed_periods))
        runs = runs_of(s)
        if runs and reported and runs[0].run_id <= reported[-1][1].run_id:
            fwtest.fail("session %s reported run id %d again" % (s.name, runs[0].run_id))
        reported.extend((s.name, r) for r in runs)
        return statuses

    t_start = time.time()
    t_end = t_start + seconds
    all_status = []
    try:
        s = start_session()
        while True:
            pause = rnd.uniform(lo, hi)
            if time.time() + pause + 60 > t_end:
                break
            until = time.time() + pause
            while time.time() < until:
                time.sleep(5)
                s.sample()
                sim_mem.append((time.time() - t_start, memory_kib(sim.proc.pid)))
                if s.proc.poll() is not None:
                    end_session(s, signal.SIGTERM)  # fails with the log
            account(s, s.new_text(), None)
            name, inject, reason, clear, hold = faults[rnd.randrange(len(faults))]
            runs_before = len(runs_of(s))
            fwtest.note("%6.0f s  %s (session %s)" % (time.time() - t_start, name, s.name))
            if name == "kill":
                time.sleep(rnd.uniform(0, 15))  # anywhere in a run or in the pause between runs
                all_status.append(end_session(s, signal.SIGKILL))
                s = start_session()
                done[name] = done.get(name, 0) + 1
                continue
            sim.control(inject)
            if reason is not None:
                reasons = reason if isinstance(reason, tuple) else (reason,)
                _, off = fwtest.wait_for_any(s.err_path, ["SAFETY STOP (%s)" % r for r in reasons], s.offset, 60,
                                             s.proc)
                if clear is not None:
                    time.sleep(0.5)
                    sim.control(clear)
                fwtest.wait_for(s.err_path, "safety stop cleared", off, 120, s.proc)
                time.sleep(2.0)  # a cleared stop's detail lines
                account(s, s.new_text(), reasons)
            else:
                time.sleep(hold)
                sim.control(clear)
                seen = account(s, s.new_text(), None)
                if any(r in FALSE for r in seen):
                    fwtest.fail("'%s' should be tolerated, but stopped the base: %s" % (inject, seen))
            # Recovered: a run finishes after the fault.
            deadline = time.time() + 120
            while len(runs_of(s)) <= runs_before:
                if time.time() > deadline:
                    fwtest.fail("no run finished within 120 s after '%s' (session %s)" % (name, s.name))
                time.sleep(1)
            done[name] = done.get(name, 0) + 1
        while time.time() < t_end:
            time.sleep(5)
            s.sample()
        all_status.append(end_session(s, signal.SIGTERM))
        # Every finished run durable: a last session loads the checkpoint and journal.
        last = start_session()
        time.sleep(3)
        all_status.append(end_session(last, signal.SIGTERM))
    finally:
        for x in sessions:
            if x.proc.poll() is None:
                x.proc.kill()
                x.proc.wait()
        sim.close()

    train = [(n, r) for n, r in reported if r.kind == 0 and r.end_reason in FINISHED]
    seen = {}
    for n, r in train:
        if r.training_index in seen:
            fwtest.fail("training run %d reported finished twice (sessions %s and %s): a finished run was lost" %
                        (r.training_index, seen[r.training_index], n))
        seen[r.training_index] = n
    evals = [r for _, r in reported if r.kind == 1 and r.end_reason in FINISHED]
    collided = sum(1 for _, r in train if r.end_reason == 1)
    ticks = sum(st[-1].ticks for st in all_status if st)
    late_max = max((st[-1].late_max_ever_us for st in all_status if st), default=0)
    gap_max = max((st[-1].gap_max_ever_us for st in all_status if st), default=0)
    tick_max = max((st[-1].tick_max_ever_us for st in all_status if st), default=0)
    fill = max((st[-1].store_fill for st in all_status if st), default=0)
    fwtest.note("soak %s: %d s real time, %s; %d sessions (%d SIGKILLs)" %
                (base, seconds, "controller SCHED_FIFO %d on CPU %d, memory locked, pre-faulted" % (PRIORITY, cpu)
                 if rt else "without real-time options (not permitted)", len(sessions), done.get("kill", 0)))
    fwtest.note("  faults answered: %s" % ", ".join("%s %d" % (k, v) for k, v in sorted(done.items())))
    fwtest.note("  ticks %d, missed periods 0; wake-up lateness max %d us, longest gap between ticks %d us, tick "
                "compute max %d us; store %d samples" % (ticks, late_max, gap_max, tick_max, fill))
    fwtest.note("  finished runs reported %d (%d training, %d of them collisions; %d evaluation), all resumed; "
                "bumper stops outside injected faults %d" % (len(train) + len(evals), len(train), collided,
                                                             len(evals), collisions_outside))
    growth = [(x.name, x.base, x.max) for x in sessions if x.base is not None]
    for n, b, m in growth:
        fwtest.note("  controller %s: VmData %d -> max %d KiB, RssAnon %d -> max %d KiB" % (n, b[0], m[0], b[1], m[1]))
    later = [m for t, m in sim_mem if t >= 120 and m[0] >= 0]
    if later:
        fwtest.note("  emulator: VmData %d -> max %d KiB, RssAnon %d -> max %d KiB" %
                    (later[0][0], max(m[0] for m in later), later[0][1], max(m[1] for m in later)))
    with open(os.path.join(d, "emulator_memory.txt"), "w") as f:
        f.write("".join("%.0f %d %d\n" % (t, m[0], m[1]) for t, m in sim_mem))
    if false_stops:
        fwtest.fail("%d false safety stops: %s" % (len(false_stops), "; ".join(false_stops[:10])))
    for n, b, m in growth:
        if m[0] - b[0] > LEAK_KIB:
            fwtest.fail("controller session %s allocated %d KiB more after its first two minutes" % (n, m[0] - b[0]))
    if later and max(m[0] for m in later) - later[0][0] > LEAK_KIB:
        fwtest.fail("the emulator allocated %d KiB more after its first two minutes" %
                    (max(m[0] for m in later) - later[0][0]))
    if sessions[-1].resumed < len(train):
        fwtest.fail("the last session resumed %d training runs; %d were reported finished" %
                    (sessions[-1].resumed, len(train)))
    ok = True
    fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
