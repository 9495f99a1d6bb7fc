#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""sim.can_log: `b21r-sim --can-log FILE` writes the emulated CAN bus of a controller session
(CiA 402 drives, lockstep, an injected drive fault) in candump -L format, and standard CAN tools
read it with the project's DBC:
1. every line is a candump -L line; times do not go back;
2. `cantools decode` (the command line of the venv's cantools) decodes every frame by the DBC:
   no unknown ID, and the trace shows the enable sequence (shutdown, switch on, enable
   operation), the drives in "operation_enabled", the EMCY of the fault by name, its reset, and
   target velocities in m/s and rad/s within the controller's limits;
3. a canplayer-style replay (python-can's candump-log reader, played with the recorded gaps onto
   a virtual bus) delivers every frame, unchanged, in order, over the recorded duration.
usage: test_can_log.py CONTROLLER SIM WORLD DBC"""
import io
import os
import re
import signal
import subprocess
import sys
import time

import can
import cantools
from cantools import logreader

import fwtest

LINE = re.compile(r"^\((\d+)\.(\d{6})\) vcan0 ([0-9A-F]{3})#([0-9A-F]*)$")


def wait_text(path, text, timeout, proc):
    deadline = time.time() + timeout
    while time.time() < deadline:
        with open(path) as f:
            if text in f.read():
                return
        if proc.poll() is not None:
            fwtest.fail("controller exited (%d) before '%s'" % (proc.returncode, text))
        time.sleep(0.05)
    fwtest.fail("'%s' not in %s within %d s" % (text, path, timeout))


def main():
    controller, sim_exe, world, dbc_path = sys.argv[1:5]
    d = fwtest.workdir("can-log")
    ok = False
    trace = os.path.join(d, "bus.log")
    sim = fwtest.Sim(sim_exe, world, d, "sim", base="canopen", seed=5, extra=("--can-log", trace))
    try:
        err_path = os.path.join(d, "controller.log")
        with open(err_path, "w") as err, open(os.path.join(d, "progress.txt"), "w") as out:
            proc = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, "run",
                                                          {"phase_one_runs": 1000, "safety_clear_ticks": 5,
                                                           "hedger_replay": "false"}), stdout=out, stderr=err)
        wait_text(err_path, "starting devices", 30, proc)
        time.sleep(0.5)
        sim.control("fault drive_fault 2")
        wait_text(err_path, "SAFETY STOP (base fault)", 120, proc)
        time.sleep(0.3)
        sim.control("fault clear")
        wait_text(err_path, "safety stop cleared", 120, proc)
        time.sleep(0.3)
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
        sim.control("quit")
        sim.proc.wait(10)
        with open(trace) as f:
            lines = f.read().splitlines()

        # 1. candump -L lines, time never going back.
        last = 0
        for i, line in enumerate(lines):
            m = LINE.match(line)
            if m is None:
                fwtest.fail("line %d is not a candump -L line: %r" % (i + 1, line))
            t = int(m.group(1)) * 1000000 + int(m.group(2))
            if t < last:
                fwtest.fail("line %d: time goes back" % (i + 1))
            last = t
        fwtest.note("%d frames in candump -L format" % len(lines))

        # 2. cantools decode (the command line), every frame known to the DBC.
        p = subprocess.run([sys.executable, "-m", "cantools", "decode", "--single-line", dbc_path], input="\n".join(lines),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=300)
        if p.returncode != 0:
            fwtest.fail("cantools decode: exit %d: %s" % (p.returncode, p.stderr))
        decoded = p.stdout.splitlines()
        unknown = [x for x in decoded if "Unknown frame id" in x]
        if len(decoded) != len(lines) or unknown:
            fwtest.fail("cantools decoded %d of %d lines; unknown: %s" % (len(decoded) - len(unknown), len(lines),
                                                                       unknown[:3]))
        text = p.stdout
        for want in ("Command: shutdown", "Command: switch_on_or_disable_operation", "Command: enable_operation",
                     "DriveState: operation_enabled", "ErrorCode: continuous_over_current", "ErrorCode: no_error_or_reset",
                     "FaultReset: fault_reset", "NMT_Command: start", "NMTState: operational"):
            if want not in text:
                fwtest.fail("cantools decode output lacks '%s'" % want)
        db = cantools.database.load_file(dbc_path)
        v_max = w_max = 0.0
        for frame in logreader.Parser(io.StringIO("\n".join(lines) + "\n")):
            msg = db.get_message_by_frame_id(frame.frame_id)
            sig = db.decode_message(frame.frame_id, frame.data)
            if msg.name == "RPDO1_Trans":
                v_max = max(v_max, abs(sig["TargetVelocity"]))
            elif msg.name == "RPDO1_Rot":
                w_max = max(w_max, abs(sig["TargetVelocity"]))
        if not (0.05 < v_max <= 0.8 + 1e-5 and 0.05 < w_max <= 1.0 + 1e-4):
            fwtest.fail("target velocities out of the controller's limits: %.4f m/s, %.4f rad/s" % (v_max, w_max))
        fwtest.note("cantools decode: every frame known; enable sequence, operation_enabled, the EMCY "
                    "continuous_over_current and its reset by name; |v| <= %.3f m/s, |w| <= %.3f rad/s" %
                    (v_max, w_max))

        # 3. canplayer-style replay onto a virtual bus, with the recorded gaps.
        rx = can.Bus(interface="virtual", channel="replay", receive_own_messages=False)
        tx = can.Bus(interface="virtual", channel="replay")
        recorded = list(can.CanutilsLogReader(trace))
        t0 = time.monotonic()
        for m in can.MessageSync(recorded, timestamps=True):
            tx.send(m)
        played_s = time.monotonic() - t0
        got = []
        while True:
            m = rx.recv(timeout=0.5)
            if m is None:
                break
            got.append(m)
        tx.shutdown()
        rx.shutdown()
        span = recorded[-1].timestamp - recorded[0].timestamp
        if [(m.arbitration_id, bytes(m.data)) for m in got] != [(m.arbitration_id, bytes(m.data)) for m in recorded]:
            fwtest.fail("the replay delivered %d frames, not the %d recorded in order" % (len(got), len(recorded)))
        if played_s < 0.9 * span:
            fwtest.fail("the replay took %.2f s for a %.2f s trace: the gaps were not kept" % (played_s, span))
        fwtest.note("replay: %d frames in order onto a virtual bus in %.2f s (trace span %.2f s)" %
                    (len(got), played_s, span))
        ok = True
    finally:
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
