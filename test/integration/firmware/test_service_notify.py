#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.service_notify: the controller under a service manager, played by this test: a
datagram socket named by NOTIFY_SOCKET, the watchdog asked for with WATCHDOG_USEC. Real time,
against the emulator (rFLEX).

1. READY=1 arrives once the devices are open and run (the emulator streams and has answered),
   with a STATUS= naming them; no WATCHDOG=1 comes before it.
2. WATCHDOG=1 comes at half the interval: every gap at least WATCHDOG_USEC/2 (less a little
   delivery jitter) and below WATCHDOG_USEC (what the manager needs to keep the service).
3. With the test fault B21R_TEST_HANG_AFTER_TICKS the tick thread hangs: the pings stop (the
   manager would now abort and restart the service), the robot drives on under the last command
   until the emulator's own command watchdog (1 s) stops it: its status counts one trip and the
   pose stands still.
4. SIGTERM on a healthy controller: STOPPING=1, exit status 128 + 15, the checkpoint written.
Usage: test_service_notify.py <b21r-controller> <b21r-sim> <world>
"""
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import fwtest
from test_safety import wait_for

WATCHDOG_S = 2.0
HANG_AFTER_TICKS = 80  # 8 s at 10 Hz


class Manager:
    """The service manager's notification socket: records (arrival time, message)."""

    def __init__(self, path):
        self.path = path
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(path)
        self.sock.settimeout(0.1)
        self.messages = []
        self.lock = threading.Lock()
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop:
            try:
                data = self.sock.recv(4096)
            except socket.timeout:
                continue
            with self.lock:
                self.messages.append((time.monotonic(), data.decode()))

    def snapshot(self):
        with self.lock:
            return list(self.messages)

    def wait(self, key, timeout, proc):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for t, m in self.snapshot():
                if key in m.split("\n"):
                    return t, m
            if proc.poll() is not None:
                fwtest.fail("controller exited (%d) before sending %s" % (proc.returncode, key))
            time.sleep(0.02)
        fwtest.fail("no %s within %d s" % (key, timeout))

    def close(self):
        self.stop = True
        self.thread.join()
        self.sock.close()


def pose(sim):
    f = sim.control("pose").split()
    return float(f[2]), float(f[3])


def status(sim):
    return dict(kv.split("=", 1) for kv in sim.control("status").split()[1:])


def start(controller, sim, d, name, env_extra):
    settings = {"lockstep": "false", "phase_one_runs": 1000, "eval_every_runs": 1000, "progress": "false",
                "checkpoint_file": os.path.join(d, name + ".ckpt")}
    env = dict(os.environ, NOTIFY_SOCKET=os.path.join(d, name + ".notify"), **env_extra)
    err_path = os.path.join(d, name + ".controller.log")
    with open(err_path, "w") as err:
        proc = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, name, settings), stdout=subprocess.DEVNULL,
                                stderr=err, env=env)
    return proc, err_path


def hang_run(controller, sim_exe, world, d):
    sim = fwtest.Sim(sim_exe, world, d, "hang", seed=2, lockstep=False)
    mgr = Manager(os.path.join(d, "hang.notify"))
    proc = None
    try:
        proc, err_path = start(controller, sim, d, "hang", {"WATCHDOG_USEC": str(int(WATCHDOG_S * 1e6)),
                                                           "B21R_TEST_HANG_AFTER_TICKS": str(HANG_AFTER_TICKS)})
        t_ready, ready = mgr.wait("READY=1", 120, proc)
        st = status(sim)
        if st["streaming"] != "1" or int(st["scans"]) < 1 or int(st["base_reports"]) < 1:
            fwtest.fail("READY=1 came before the devices ran: emulator status %s" % st)
        if "STATUS=running: laser " not in ready:
            fwtest.fail("READY=1 without the STATUS line naming the devices: %r" % ready)
        with open(err_path) as f:
            if "starting devices" not in f.read():
                fwtest.fail("READY=1 before the controller started its devices")
        fwtest.note("READY=1 after the devices started (emulator: %s scans, %s base reports): %r"
                    % (st["scans"], st["base_reports"], ready))
        wait_for(err_path, "test fault: the tick thread hangs", 0, 120, proc)
        t_hang = time.monotonic()
        x0, y0 = pose(sim)
        time.sleep(WATCHDOG_S + 1.0)  # the manager would have fired by now
        msgs = mgr.snapshot()
        early = [t for t, m in msgs if "WATCHDOG=1" in m.split("\n") and t < t_ready]
        if early:
            fwtest.fail("WATCHDOG=1 before READY=1")
        pings = [t for t, m in msgs if m == "WATCHDOG=1"]
        before = [t for t in pings if t < t_hang]
        after = [t for t in pings if t > t_hang + 0.2]
        gaps = [b - a for a, b in zip([t_ready] + before, before)]
        fwtest.note("%d pings in %.1f s before the hang, gaps %.3f-%.3f s (WATCHDOG_USEC %.1f s); %d after it"
                    % (len(before), t_hang - t_ready, min(gaps or [0]), max(gaps or [0]), WATCHDOG_S, len(after)))
        if len(before) < 3:
            fwtest.fail("only %d WATCHDOG=1 in %.1f s before the hang" % (len(before), t_hang - t_ready))
        if min(gaps) < 0.45 * WATCHDOG_S:
            fwtest.fail("pings come faster than half the interval: gap %.3f s" % min(gaps))
        if max(gaps) >= WATCHDOG_S:
            fwtest.fail("a gap of %.3f s between pings: the manager would have aborted the service" % max(gaps))
        if after:
            fwtest.fail("%d WATCHDOG=1 after the tick thread hung" % len(after))
        if proc.poll() is not None:
            fwtest.fail("the controller exited (%d) instead of hanging" % proc.returncode)
        # The emulator's own command watchdog stopped the robot, which had driven on meanwhile.
        st = status(sim)
        x1, y1 = pose(sim)
        time.sleep(0.5)
        x2, y2 = pose(sim)
        moved = ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5
        fwtest.note("after the hang: moved %.3f m under the last command, then %s watchdog trip(s); pose "
                    "change over 0.5 s: %.6f m" % (moved, st["watchdog_trips"], abs(x2 - x1) + abs(y2 - y1)))
        if st["watchdog_trips"] != "1":
            fwtest.fail("the emulator's command watchdog did not stop the base: %s" % st)
        if abs(x2 - x1) + abs(y2 - y1) > 1e-6:
            fwtest.fail("the robot still moves after the command watchdog: (%f, %f) -> (%f, %f)" % (x1, y1, x2, y2))
        if moved < 0.01:
            fwtest.fail("the robot stood still at the hang (%.4f m): the test shows nothing" % moved)
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()  # hung: SIGTERM is taken and ignored, as by a stuck tick
            proc.wait()
        mgr.close()
        sim.close()


def sigterm_run(controller, sim_exe, world, d):
    sim = fwtest.Sim(sim_exe, world, d, "term", seed=3, lockstep=False)
    mgr = Manager(os.path.join(d, "term.notify"))
    proc = None
    try:
        proc, err_path = start(controller, sim, d, "term", {})
        mgr.wait("READY=1", 120, proc)
        time.sleep(1.0)
        t_term = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(60)
        if rc != 128 + signal.SIGTERM:
            fwtest.fail("SIGTERM: exit status %d, expected %d" % (rc, 128 + signal.SIGTERM))
        time.sleep(0.2)
        stopping = [m for t, m in mgr.snapshot() if "STOPPING=1" in m.split("\n") and t >= t_term]
        if stopping != ["STOPPING=1\nSTATUS=stopping: signal 15"]:
            fwtest.fail("after SIGTERM expected one STOPPING=1 with its status, got %r" % stopping)
        ckpt = os.path.join(d, "term.ckpt")
        if not os.path.exists(ckpt) or os.path.getsize(ckpt) == 0:
            fwtest.fail("no checkpoint after SIGTERM")
        if any(m == "WATCHDOG=1" for _, m in mgr.snapshot()):
            fwtest.fail("WATCHDOG=1 sent without WATCHDOG_USEC")
        fwtest.note("SIGTERM -> %r, exit status %d, checkpoint %d bytes" % (stopping[0], rc, os.path.getsize(ckpt)))
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        mgr.close()
        sim.close()


def main():
    controller, sim_exe, world = sys.argv[1:4]
    d = fwtest.workdir("service-notify")
    ok = False
    try:
        hang_run(controller, sim_exe, world, d)
        sigterm_run(controller, sim_exe, world, d)
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
