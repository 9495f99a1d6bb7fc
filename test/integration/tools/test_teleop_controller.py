#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.teleop_controller: the operator drives the unmodified b21r-controller (phase one by
joystick, the emulator in real time) with tools/b21r_teleop.py, over LCM udpm inside a private
network namespace (run by test/support/netns-run; nothing leaves the namespace's loopback).
1. Gamepad (js_event records written into a FIFO): with the deadman held, the robot turns at the
   commanded, scaled rotation (measured on B21R_POSE); the deadman released, the controller
   reports a deadman stop and the robot stands still within teleop_timeout_s + one tick.
2. The teleop process is killed (kill -9, no last message) while the deadman is held: the
   controller still stops the robot within teleop_timeout_s + one tick.
3. Keyboard (the tool on a pseudo-terminal, a held arrow key repeating at 30 Hz): B21R_TELEOP
   flows only while the key repeats; the controller drives with it and stops after it.
usage: test_teleop_controller.py CONTROLLER SIM WORLD TELEOP_TOOL"""
import os
import pty
import signal
import subprocess
import sys
import threading
import time

import lcm
from b21r import pose_t, status_t, teleop_t

import b21r_opauth
import fwtest
import b21r_teleop as tt

URL = "udpm://239.255.76.67:7667?ttl=0"
TIMEOUT_S = 0.3
TICK_S = 0.1
SLACK_S = 1.0  # this process's view of a shared 2-core machine: only for the robot standing still
LIMIT = 1.0
KEY = None  # the operator key file, made in main()


class Bus:
    """Receives STATUS, POSE and TELEOP in a thread, with monotonic arrival times."""

    def __init__(self):
        self.lc = lcm.LCM(URL)
        self.lock = threading.Lock()
        self.status, self.pose, self.teleop = [], [], []
        for ch, t, dst in (("B21R_STATUS", status_t, self.status), ("B21R_POSE", pose_t, self.pose),
                           ("B21R_TELEOP", teleop_t, self.teleop)):
            self.lc.subscribe(ch, self._handler(t, dst))
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _handler(self, t, dst):
        def on(channel, data):
            with self.lock:
                dst.append((time.monotonic(), t.decode(data)))
        return on

    def _run(self):
        while not self.stop:
            self.lc.handle_timeout(50)

    def since(self, what, t0):
        with self.lock:
            return [(t, m) for t, m in getattr(self, what) if t >= t0]

    def wait(self, what, pred, t0, timeout, why):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            hits = [(t, m) for t, m in self.since(what, t0) if pred(m)]
            if hits:
                return hits[0]
            time.sleep(0.02)
        last = self.since("status", time.monotonic() - 1.0)
        fwtest.fail("%s within %.1f s (last STATUS: %s)" % (why, timeout, describe(last[-1][1]) if last else "none"))


def describe(s):
    return "mode %s stop %s (%s) run %d" % (tt.MODE_NAMES.get(s.mode), tt.STOP_NAMES.get(s.stop_reason), s.stop_detail,
                                          s.run_id)


def running(m):
    return m.mode == status_t.MODE_RUNNING


def deadman_stop(m):
    return m.mode == status_t.MODE_STOPPED and m.stop_reason == status_t.STOP_DEADMAN


def turning_at(target, tol=0.06):
    return lambda p: abs(p.rotation_radps - target) < tol


def still(p):
    return abs(p.rotation_radps) < 0.02


def check_stop(bus, t_event, what):
    """The controller stops within teleop_timeout_s + a tick of the last deadman message it took,
    measured on its own clock (STATUS utime: the tick times, late ticks included), so that the
    load of a shared machine on this test's process does not count; the robot then stands still."""
    t_stop, stop = bus.wait("status", deadman_stop, t_event, 5.0, "no deadman stop after " + what)
    accepted = [m for _, m in bus.since("status", t_event - 2.0) if m.teleop_accepted == stop.teleop_accepted]
    t_last_taken = accepted[0].utime  # the first tick that had taken the last message
    dt = (stop.utime - t_last_taken) * 1e-6
    t_still, _ = bus.wait("pose", still, t_event, 5.0, "the robot kept turning after " + what)
    fwtest.note("%s: deadman stop %.3f s (controller clock) after the last message taken; seen here %.3f s after "
                "the event, the robot still %.3f s after it" % (what, dt, t_stop - t_event, t_still - t_event))
    if dt > TIMEOUT_S + 2 * TICK_S + 1e-3:
        fwtest.fail("%s: the stop came %.3f s after the last message (limit teleop_timeout_s %.1f s + a tick)" %
                    (what, dt, TIMEOUT_S))
    decel = LIMIT / 2.86  # the rotation acceleration limit brings |w| <= 1 rad/s to 0 in 0.35 s
    if t_still - t_event > TIMEOUT_S + TICK_S + decel + SLACK_S:
        fwtest.fail("%s: the robot turned for %.3f s more" % (what, t_still - t_event))


def gamepad(bus, teleop_tool, d):
    fifo = os.path.join(d, "js0")
    os.mkfifo(fifo)
    log = open(os.path.join(d, "teleop-gamepad.log"), "w")
    tool = subprocess.Popen([sys.executable, teleop_tool, "--joystick", fifo, "--no-ui", "--lcm-url", URL,
                             "--key", KEY, "--max-rotation", str(LIMIT)], stdout=log, stderr=subprocess.STDOUT)
    js = open(fifo, "wb", buffering=0)  # waits for the tool to open it
    try:
        js.write(b"".join(tt.JS_EVENT.pack(0, 0, tt.JS_EVENT_BUTTON | tt.JS_EVENT_INIT, b) for b in range(9)))
        js.write(tt.JS_EVENT.pack(10, -16384, tt.JS_EVENT_AXIS, 0))  # stick half left
        js.write(tt.JS_EVENT.pack(20, 1, tt.JS_EVENT_BUTTON, 4))      # deadman held
        target = LIMIT * (16384 / 32767.0 - 0.1) / 0.9
        t0 = time.monotonic()
        bus.wait("status", running, t0, 15.0, "no run started with the deadman held")
        t_turn, _ = bus.wait("pose", turning_at(target), t0, 10.0, "the robot did not turn at %.3f rad/s" % target)
        fwtest.note("gamepad: the robot turns at the commanded %.3f rad/s (%.2f s after the press)" %
                    (target, t_turn - t0))
        time.sleep(1.0)
        t_release = time.monotonic()
        js.write(tt.JS_EVENT.pack(3000, 0, tt.JS_EVENT_BUTTON, 4))
        check_stop(bus, t_release, "deadman release")
        late = [m for t, m in bus.since("teleop", t_release + 0.2)]
        if late:
            fwtest.fail("the tool kept sending after the release: %d messages" % len(late))

        # Held again: the controller resumes (safety_clear_ticks), repositions and runs; then the
        # tool dies without a last word.
        js.write(tt.JS_EVENT.pack(4000, 1, tt.JS_EVENT_BUTTON, 4))
        t1 = time.monotonic()
        bus.wait("status", running, t1, 20.0, "no new run after the deadman was pressed again")
        bus.wait("pose", turning_at(target), t1, 10.0, "the robot did not turn again")
        time.sleep(0.5)
        t_kill = time.monotonic()
        tool.send_signal(signal.SIGKILL)
        tool.wait()
        check_stop(bus, t_kill, "kill -9 of the teleop tool")
    finally:
        js.close()
        if tool.poll() is None:
            tool.kill()
            tool.wait()
        log.close()


def keyboard(bus, teleop_tool, d):
    master, slave = pty.openpty()
    env = dict(os.environ, TERM="xterm", LINES="30", COLUMNS="160")
    tool = subprocess.Popen([sys.executable, teleop_tool, "--keyboard", "--lcm-url", URL, "--key", KEY,
                             "--key-hold-s", "0.5"],
                            stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
    os.close(slave)
    drain = threading.Thread(target=lambda: _drain(master), daemon=True)
    drain.start()
    try:
        time.sleep(1.5)  # curses is up
        t_first = time.monotonic()
        t_end = t_first + 3.0
        while time.monotonic() < t_end:  # a held left arrow (keypad mode), as the terminal repeats it
            os.write(master, b"\x1bOD")
            time.sleep(1.0 / 30)
        t_last = time.monotonic()
        t_last_wall = time.time()
        t_turn, _ = bus.wait("pose", turning_at(0.5), t_first, 0.1, "keyboard: the robot did not turn at +0.5 rad/s")
        if t_turn > t_last:
            fwtest.fail("keyboard: the robot turned only after the keys stopped")
        time.sleep(1.2)
        msgs = bus.since("teleop", t_first - 0.05)
        held = [(t, m) for t, m in msgs if m.deadman]
        if not held or any(abs(m.rotation_radps - 0.5) > 1e-12 for _, m in held):
            fwtest.fail("keyboard: expected TELEOP at +0.5 rad/s while the key repeats, got %d messages" % len(held))
        after_last_key = held[-1][1].utime * 1e-6 - t_last_wall  # the tool's own send time
        if after_last_key > 0.5 + 0.05 + 0.25:
            fwtest.fail("keyboard: TELEOP went on %.3f s after the last key (hold 0.5 s)" % after_last_key)
        if msgs[-1][1].deadman:
            fwtest.fail("keyboard: no release message after the keys stopped")
        n_expected = (t_last - t_first) * 20
        if len(held) < 0.8 * n_expected:
            fwtest.fail("keyboard: %d messages while the key repeated for %.1f s" % (len(held), t_last - t_first))
        fwtest.note("keyboard: %d TELEOP at +0.5 rad/s while the key repeated, the last sent %.3f s after the last "
                    "key, then the release" % (len(held), after_last_key))
        check_stop(bus, t_last + 0.5, "the keyboard's deadman timeout")
        os.write(master, b"q")
        tool.wait(10)
    finally:
        if tool.poll() is None:
            tool.kill()
            tool.wait()
        os.close(master)


def _drain(fd):
    try:
        while os.read(fd, 4096):
            pass
    except OSError:
        pass


def main():
    controller, sim_exe, world, teleop_tool = sys.argv[1:5]
    global KEY
    d = fwtest.workdir("teleop")
    KEY = os.path.join(d, "operator.key")
    b21r_opauth.create_key(KEY)
    ok = False
    sim = fwtest.Sim(sim_exe, world, d, "sim", seed=3, lockstep=False)
    bus = Bus()
    proc = None
    try:
        err = open(os.path.join(d, "controller.log"), "w")
        proc = subprocess.Popen([controller, "--endpoints", sim.endpoints, "--set", "lcm_url=" + URL,
                                 "--set", "phase_one_driver=joystick", "--set", "operator_key_file=" + KEY,
                                 "--set", "teleop_timeout_s=%g" % TIMEOUT_S,
                                 "--set", "max_rotation_radps=%g" % LIMIT, "--set", "phase_one_runs=50",
                                 "--set", "safety_clear_ticks=5", "--set", "progress=true",
                                 # the between-run replay in a few ticks: this test is about the
                                 # operator's latency, not the tick's bound (firmware.bench)
                                 "--set", "learn_updates_per_tick=200",
                                 "--log", os.path.join(d, "session.lcmlog")],
                                stdout=err, stderr=subprocess.STDOUT)
        bus.wait("status", lambda m: True, time.monotonic(), 20.0, "no B21R_STATUS from the controller")
        gamepad(bus, teleop_tool, d)
        keyboard(bus, teleop_tool, d)
        ok = True
    finally:
        bus.stop = True
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
