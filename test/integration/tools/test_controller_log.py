#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""The controller's --log explains itself: a short emulated session (lockstep, paced at 5x real
time, LCM udpm inside a private network namespace) in which an operator sends B21R_TELEOP and
PAUSE / RESUME / SHUTDOWN over LCM, signed with the operator key. The log must hold, in order:
- B21R_CONFIG first (every key, the command limits);
- the operator's B21R_TELEOP and B21R_COMMAND, as received;
- one B21R_RUN end record per run, after the run's experiences, also for runs that end without a
  terminal state (step limit, the operator's PAUSE as a safety stop, SHUTDOWN), whose experience
  counts and steps by driver match the experiences in the log;
- wall-clock event timestamps (non-decreasing, inside the test's own wall time), while each
  message's utime stays the simulated time;
- STATUS with the publisher's counters; and the pace cap holds (ticks per wall second).
Also: joystick driving in lockstep or with lcm_url = none is refused at start-up, naming the keys.
Usage: test_controller_log.py CONTROLLER SIM WORLD B21R_LOG_TOOL"""
import os
import subprocess
import sys
import time

import b21r_opauth
import fwtest
import lcm

import b21r
from b21r_log import read_log

URL = "udpm://239.255.76.67:7667?ttl=0"
FACTOR = 5.0          # lockstep pace cap: 50 ticks per second at 10 Hz
STEP_LIMIT = 30


def refusals(controller):
    for settings, keys in (({"lockstep": "true"}, ("phase_one_driver = joystick", "lockstep = true")),
                           ({"lcm_url": "none"}, ("phase_one_driver = joystick", "lcm_url = none"))):
        cmd = [controller, "--set", "phase_one_driver=joystick"]
        for k, v in settings.items():
            cmd += ["--set", "%s=%s" % (k, v)]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
        if p.returncode != 2 or not all(k in p.stderr for k in keys):
            fwtest.fail("%s: exit %d, stderr %r; expected 2 and a message naming %s" % (settings, p.returncode,
                                                                                       p.stderr, keys))
        fwtest.note("refused at start-up: %s" % p.stderr.strip().splitlines()[0][:150])


class Watcher:
    """B21R_STATUS and B21R_RUN as the operator sees them."""

    def __init__(self, lc):
        self.status = None
        self.runs = []
        lc.subscribe("B21R_STATUS", self.on_status)
        lc.subscribe("B21R_RUN", self.on_run)

    def on_status(self, channel, data):
        self.status = b21r.status_t.decode(data)

    def on_run(self, channel, data):
        self.runs.append(b21r.run_t.decode(data))


def pump_until(lc, cond, timeout, what, proc):
    deadline = time.time() + timeout
    while not cond():
        if time.time() > deadline:
            fwtest.fail("timed out waiting for %s" % what)
        if proc.poll() is not None:
            fwtest.fail("the controller exited (%d) while waiting for %s" % (proc.returncode, what))
        lc.handle_timeout(50)


def main():
    controller, sim_exe, world, log_tool = sys.argv[1:5]
    refusals(controller)
    d = fwtest.workdir("controller-log")
    ok = False
    sim = fwtest.Sim(sim_exe, world, d, "sim", seed=5)
    log_path = os.path.join(d, "session.lcmlog")
    lc = lcm.LCM(URL)
    w = Watcher(lc)
    key_path = os.path.join(d, "operator.key")
    key = b21r_opauth.create_key(key_path)
    signer = b21r_opauth.Signer(lc, key, b21r_opauth.SessionTracker(lc, key))
    sent = {"B21R_TELEOP": 0, "B21R_COMMAND": 0}

    def command(c):
        m = b21r.command_t()
        m.utime, m.command = int(time.time() * 1e6), c
        if not signer.publish("B21R_COMMAND", m):
            fwtest.fail("no B21R_SESSION from the controller")
        sent["B21R_COMMAND"] += 1

    wall_start = int(time.time() * 1e6)
    try:
        with open(os.path.join(d, "controller.log"), "w") as err, open(os.path.join(d, "progress.txt"), "w") as out:
            proc = subprocess.Popen([controller, "--endpoints", sim.endpoints, "--set", "lockstep=true",
                                     "--set", "lcm_url=" + URL, "--set", "lockstep_realtime_factor=%g" % FACTOR,
                                     "--set", "max_steps_per_run=%d" % STEP_LIMIT, "--set", "phase_one_runs=1000",
                                     "--set", "eval_every_runs=1000", "--set", "progress=true",
                                     "--set", "safety_auto_resume=false", "--set", "operator_key_file=" + key_path,
                                     "--log", log_path],
                                    stdout=out, stderr=err)
        try:
            pump_until(lc, lambda: len(w.runs) >= 2, 60, "two runs", proc)
            for i in range(5):  # the example policy drives: they are received, counted and recorded
                t = b21r.teleop_t()
                t.utime, t.deadman, t.rotation_radps = int(time.time() * 1e6), False, 0.0
                if not signer.publish("B21R_TELEOP", t):
                    fwtest.fail("no B21R_SESSION from the controller")
                sent["B21R_TELEOP"] += 1
            # PAUSE early in a run: it ends as a safety stop (operator pause), without a terminal state.
            # From step 4 on at least one decision (decision_ticks = 2, the default) has its outcome,
            # so the run has an experience; the aborted decision's is never observed.
            pump_until(lc, lambda: w.status is not None and w.status.mode == b21r.status_t.MODE_RUNNING
                       and 4 <= w.status.step_id <= 8, 30, "an early step of a run", proc)
            n = len(w.runs)
            command(b21r.command_t.PAUSE)
            pump_until(lc, lambda: len(w.runs) > n, 30, "the end record of the paused run", proc)
            if w.runs[n].end_reason != b21r.run_t.END_SAFETY_STOP:
                fwtest.fail("the paused run ended with %d (%s)" % (w.runs[n].end_reason, w.runs[n].detail))
            command(b21r.command_t.RESUME)
            n = len(w.runs)
            pump_until(lc, lambda: len(w.runs) > n, 60, "a run after RESUME", proc)
            # A run that has not ended yet (a STATUS of the run whose record just came is stale).
            ended = w.runs[-1].run_id
            pump_until(lc, lambda: w.status is not None and w.status.mode == b21r.status_t.MODE_RUNNING
                       and w.status.run_id > ended and w.status.step_id >= 4, 30, "a run under way", proc)
            command(b21r.command_t.SHUTDOWN)
            rc = proc.wait(60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        if rc != 0:
            fwtest.fail("controller exit status %d (see %s)" % (rc, os.path.join(d, "controller.log")))
        wall_end = int(time.time() * 1e6)
        check_log(log_path, sent, wall_start, wall_end)
        check_tool(log_tool, log_path)
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    fwtest.note("PASS")


def check_log(path, sent, wall_start, wall_end):
    events = read_log(path)
    if not events or events[0][1] != "B21R_CONFIG":
        fwtest.fail("the log does not start with B21R_CONFIG: %s" % [ch for _, ch, _ in events[:3]])
    cfg = events[0][2]
    if "lockstep_realtime_factor = %g\n" % FACTOR not in cfg.text or "max_steps_per_run = %d\n" % STEP_LIMIT \
            not in cfg.text or cfg.step_limit != STEP_LIMIT or not cfg.max_rotation_radps > 0 or not cfg.lockstep:
        fwtest.fail("B21R_CONFIG lacks the settings or the limits: step_limit %d, text %r..." %
                    (cfg.step_limit, cfg.text[:200]))
    fwtest.note("B21R_CONFIG first: %d keys, limits %.2f m/s, %.2f rad/s" %
                (len(cfg.text.splitlines()), cfg.max_translation_mps, cfg.max_rotation_radps))
    # Wall-clock timestamps, in write order; utime stays the simulated time.
    stamps = [t for t, _, _ in events]
    if any(b < a for a, b in zip(stamps, stamps[1:])) or stamps[0] < wall_start - 1000000 or \
            stamps[-1] > wall_end + 1000000:
        fwtest.fail("timestamps are not the wall clock of the session: %d..%d, session %d..%d" %
                    (stamps[0], stamps[-1], wall_start, wall_end))
    exps = [m for _, ch, m in events if ch == "B21R_EXPERIENCE"]
    if not exps or exps[-1].utime > 3600 * 1000000:
        fwtest.fail("experience utime is not the simulated time (last %d)" % (exps[-1].utime if exps else -1))
    fwtest.note("timestamps: wall clock over %.1f s; experience utime simulated (last %.1f s)" %
                ((stamps[-1] - stamps[0]) / 1e6, exps[-1].utime / 1e6))
    for ch, n in sent.items():
        got = sum(1 for _, c, _ in events if c == ch)
        if got != n:
            fwtest.fail("%s: %d sent, %d recorded" % (ch, n, got))
    commands = [m.command for _, ch, m in events if ch == "B21R_COMMAND"]
    if commands != [b21r.command_t.PAUSE, b21r.command_t.RESUME, b21r.command_t.SHUTDOWN]:
        fwtest.fail("recorded commands %s" % commands)
    fwtest.note("operator inputs recorded: %s" % sent)
    # One end record per run, after its experiences, consistent with them.
    runs = [(i, m) for i, (_, ch, m) in enumerate(events) if ch == "B21R_RUN"]
    ids = sorted({e.run_id for e in exps})
    if [m.run_id for _, m in runs] != ids:
        fwtest.fail("runs with experiences %s, end records %s" % (ids, [m.run_id for _, m in runs]))
    reasons = {}
    for i, r in runs:
        mine = [e for e in exps if e.run_id == r.run_id]
        later = [ev for ev in events[i + 1:] if ev[1] == "B21R_EXPERIENCE" and ev[2].run_id == r.run_id]
        if len(mine) != r.experiences or later or (mine and mine[0].seq != r.first_seq):
            fwtest.fail("run %d: record says %d experiences from seq %d; log has %d (first %s), %d after the record" %
                        (r.run_id, r.experiences, r.first_seq, len(mine), mine[0].seq if mine else None, len(later)))
        if sum(r.steps_by_source) != r.steps or abs(sum(e.reward for e in mine) - r.total_reward) > 1e-9:
            fwtest.fail("run %d: steps %d, by source %s, return %g" % (r.run_id, r.steps, list(r.steps_by_source),
                                                                       r.total_reward))
        reasons[r.end_reason] = reasons.get(r.end_reason, 0) + 1
    want = (b21r.run_t.END_STEP_LIMIT, b21r.run_t.END_SAFETY_STOP, b21r.run_t.END_SHUTDOWN)
    if not all(reasons.get(k) for k in want):
        fwtest.fail("end reasons %s; expected step limit, safety stop and shutdown" % reasons)
    paused = [m for _, m in runs if m.end_reason == b21r.run_t.END_SAFETY_STOP]
    if paused[0].stop_reason != b21r.status_t.STOP_OPERATOR or paused[0].steps >= STEP_LIMIT:
        fwtest.fail("the paused run: stop reason %d, %d steps" % (paused[0].stop_reason, paused[0].steps))
    fwtest.note("%d end records: %s" % (len(runs), reasons))
    # STATUS: the publisher's counters; the pace cap.
    statuses = [(t, m) for t, ch, m in events if ch == "B21R_STATUS"]
    last = statuses[-1][1]
    if last.messages_published <= 0 or last.lcm_publish_errors != 0 or last.log_write_errors != 0 or \
            last.operator_inputs_logged != sum(sent.values()):
        fwtest.fail("STATUS counters: published %d, lcm errors %d, log errors %d, inputs logged %d" %
                    (last.messages_published, last.lcm_publish_errors, last.log_write_errors,
                     last.operator_inputs_logged))
    (t0, s0), (t1, s1) = statuses[0], statuses[-1]
    rate = (s1.ticks - s0.ticks) / ((t1 - t0) / 1e6)
    if rate > 10.0 * FACTOR * 1.1:
        fwtest.fail("%.1f ticks per second with lockstep_realtime_factor %g (cap %g)" % (rate, FACTOR, 10 * FACTOR))
    fwtest.note("STATUS: %d messages published, 0 errors; pace %.1f ticks/s (cap %g)" %
                (last.messages_published, rate, 10 * FACTOR))


def check_tool(tool, path):
    p = subprocess.run([sys.executable, tool, path, "--runs"], capture_output=True, text=True, timeout=60)
    if p.returncode != 0 or "step limit" not in p.stdout or "shutdown" not in p.stdout or "stopped" not in p.stdout:
        fwtest.fail("b21r_log.py --runs: exit %d\n%s%s" % (p.returncode, p.stdout, p.stderr))
    p = subprocess.run([sys.executable, tool, path, "--config"], capture_output=True, text=True, timeout=60)
    if p.returncode != 0 or "lockstep_realtime_factor = %g" % FACTOR not in p.stdout or "# limits:" not in p.stdout:
        fwtest.fail("b21r_log.py --config: exit %d\n%s%s" % (p.returncode, p.stdout, p.stderr))
    fwtest.note("b21r_log.py --runs / --config read the records")


if __name__ == "__main__":
    main()
