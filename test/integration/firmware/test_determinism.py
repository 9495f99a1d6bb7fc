#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.determinism_<base>: the same run twice (fresh emulator, same seeds, lockstep) gives
bit-identical experience streams: the controller's --experience-log files are byte-identical
(SHA-256), and a different controller seed gives a different stream. Three more runs of the same
seed must give the same stream again, each with the laser never restarted:
- the emulator frozen (SIGSTOP) for 2.5 s twice mid-run, as a loaded machine may stall it:
  lockstep does not depend on wall time;
- the emulator frozen for 4 s from before the controller starts, so the laser's start-up requests
  outlive the driver's reply timeouts (1 s, 3 s for a mode change) and the CANopen start's first
  cycles wait;
- every start-pose answer held 0.2 s on its way back (a relay on the control socket) with
  emulator_reply_timeout_s at its least (10 ms): lockstep awaits the answers as it awaits the
  period's data, so the runs start at the same ticks.
usage: test_determinism.py CONTROLLER SIM WORLD rflex|canopen"""
import hashlib
import os
import signal
import socket
import sys
import threading
import time

import fwtest
from b21r_log import experience_gaps, read_log


def freeze(proc, stop, times, at_s=1.0, for_s=2.5):
    """Freezes the emulator process `times` times for for_s seconds each, at_s apart."""
    for _ in range(times):
        if stop.wait(at_s):
            return
        proc.send_signal(signal.SIGSTOP)
        time.sleep(for_s)
        proc.send_signal(signal.SIGCONT)


def slow_relay(listener, target, stop, relayed, delay_s=0.2):
    """Passes the controller's control requests to the emulator's socket `target` and holds each
    answer delay_s before it goes back; counts them in relayed[0]."""
    def answer(n, reply):
        time.sleep(delay_s)
        relayed[0] += 1
        return True
    fwtest.relay_control(listener, target, stop, answer)


def one_run(controller, sim_exe, world, base, d, name, seed, stalls=0, stall_at_s=1.0, stall_s=2.5,
            slow_replies=False):
    sim = fwtest.Sim(sim_exe, world, d, name, base=base, seed=1)
    stop = threading.Event()
    helper = (threading.Thread(target=freeze, args=(sim.proc, stop, stalls, stall_at_s, stall_s))
              if stalls else None)
    extra = {}
    relayed = [0]
    listener = None
    try:
        if slow_replies:
            relay_path = os.path.join(d, name + ".relay.ctl")
            listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            listener.bind(relay_path)
            listener.listen(1)
            helper = threading.Thread(target=slow_relay, args=(listener, sim.ctl, stop, relayed))
            extra = {"emulator_control": relay_path, "emulator_reply_timeout_s": 0.01}
        if helper is not None:
            helper.start()
        exp = os.path.join(d, name + ".experiences.lcmlog")
        settings = {"phase_one_runs": 3, "phase_two_runs": 2, "eval_every_runs": 5, "eval_starts": 2,
                    "seed": seed, "experience_log_file": exp}
        settings.update(extra)
        rc, err, log = fwtest.run_controller(controller, sim, d, name, settings, timeout=300)
        if rc != 0:
            fwtest.fail("%s: controller exit status %d:\n%s" % (name, rc, err))
    finally:
        stop.set()
        if helper is not None:
            helper.join(15)
            sim.proc.send_signal(signal.SIGCONT)
        if listener is not None:
            listener.close()
        sim.close()
    if slow_replies:
        if relayed[0] == 0:
            fwtest.fail("%s: no start-pose request went through the relay" % name)
        fwtest.note("%s: %d start-pose answers held 0.2 s each" % (name, relayed[0]))
    status = [m for _, _, m in read_log(log, {"B21R_STATUS"})]
    if not status or status[-1].laser_restarts != 0:
        fwtest.fail("%s: the laser stream was restarted (%s times)" % (
            name, status[-1].laser_restarts if status else "no STATUS:"))
    with open(exp, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()
    exps = [m for _, _, m in read_log(exp)]
    if not exps or experience_gaps(exps):
        fwtest.fail("%s: %d experiences, gaps %s" % (name, len(exps), experience_gaps(exps)[:5]))
    fwtest.note("%s: %d experiences, sha256 %s" % (name, len(exps), digest))
    return digest


def main():
    controller, sim_exe, world, base = sys.argv[1:5]
    d = fwtest.workdir("determinism-" + base)
    ok = False
    try:
        a = one_run(controller, sim_exe, world, base, d, "first", 7)
        b = one_run(controller, sim_exe, world, base, d, "second", 7)
        c = one_run(controller, sim_exe, world, base, d, "other-seed", 8)
        frozen = one_run(controller, sim_exe, world, base, d, "emulator-frozen", 7, stalls=2)
        frozen_start = one_run(controller, sim_exe, world, base, d, "emulator-frozen-at-start", 7, stalls=1,
                               stall_at_s=0.0, stall_s=4.0)
        slow = one_run(controller, sim_exe, world, base, d, "slow-replies", 7, slow_replies=True)
        if a != b:
            fwtest.fail("the same run twice gave different experience streams")
        if frozen != a:
            fwtest.fail("freezing the emulator changed the experience stream")
        if frozen_start != a:
            fwtest.fail("freezing the emulator during the devices' start changed the experience stream")
        if slow != a:
            fwtest.fail("start-pose answers later than emulator_reply_timeout_s changed the experience stream")
        if a == c:
            fwtest.fail("a different seed gave the same stream (the seed is not used?)")
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
