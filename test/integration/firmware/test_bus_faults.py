#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.bus_faults_<base>: faults a real line or bus could produce, injected by the emulator
while the unmodified controller learns in real time, each answered by a clear stop reason or a
counted and tolerated fault, with the emulator's CPU use measured during each (below a fifth of
a core: no fault makes it spin).
- both bases: a stuck laser (valid telegrams repeating the same distances) stops the base as
  "laser silent" with the detail "laser stuck", counted in laser_repeated_scans;
- rflex: line noise and framing errors on each serial line (bytes flipped or read as NUL) are
  counted in the decoders' error counters and tolerated (no stop);
- canopen: line noise on the laser's line, tolerated and counted as on rflex; failed CRCs
  (error frames, the frames sent again) are counted in can_error_frames and tolerated, and,
  unlike damaged payloads, never read as a bumper press or a drive fault; lost
  frames are counted in can_unanswered_syncs and tolerated; a drive stuck on its old values
  (stale PDOs while it reports a velocity) is a base fault; the bump-panel node stuck (stale
  PDOs, no heartbeat) is a base fault "heartbeat lost"; a babbling node that holds the bus is a
  base fault "CAN bus flooded", its frames counted in can_foreign_frames; this computer's
  controller going bus-off (its error frame, then nothing on the bus until its restart) is a base
  fault "CAN bus-off", cleared after the restart.
No STATUS counter that the message definition calls monotonic goes back.
usage: test_bus_faults.py CONTROLLER SIM WORLD rflex|canopen"""
import os
import re
import signal
import subprocess
import sys
import time

import fwtest
from fwtest import cpu_seconds, wait_for
from b21r_log import read_log


def stops_between(path, start, end):
    """The SAFETY STOP lines of the controller's log between two offsets."""
    with open(path) as f:
        f.seek(start)
        text = f.read(end - start)
    return re.findall(r"SAFETY STOP \(([^)]*)\)[^\n]*", text)


def main():
    controller, sim_exe, world, base = sys.argv[1:5]
    d = fwtest.workdir("bus-faults-" + base)
    ok = False
    procs = []
    sim = fwtest.Sim(sim_exe, world, d, "sim", base=base, seed=3, lockstep=False)
    try:
        settings = {"lockstep": "false", "phase_one_runs": 1000, "eval_every_runs": 1000,
                    "checkpoint_file": os.path.join(d, "hedger.ckpt"), "safety_clear_ticks": 5,
                    "hedger_replay": "false"}
        err_path = os.path.join(d, "run.controller.log")
        with open(err_path, "w") as err, open(os.path.join(d, "run.progress.txt"), "w") as out:
            proc = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, "run", settings), stdout=out, stderr=err)
            procs.append(proc)
        off = wait_for(err_path, "starting devices", 0, 30, proc)
        time.sleep(1.5)  # the first run is under way: the robot drives
        off = fwtest.settled(err_path, off, proc)

        def cpu_during(seconds):
            c0, w0 = cpu_seconds(sim.proc.pid), time.time()
            time.sleep(seconds)
            return (cpu_seconds(sim.proc.pid) - c0) / (time.time() - w0)

        def check_cpu(inject, share):
            fwtest.note("%-28s    emulator CPU use %.1f %% of a core" % ("", 100 * share))
            if share > 0.2:
                fwtest.fail("the emulator spins under '%s' (%.0f %% of a core)" % (inject, 100 * share))

        def stop_fault(inject, reason, detail, clear="fault clear"):
            """Injects a fault that must stop the base with reason and a detail containing `detail`."""
            nonlocal off
            t0 = time.time()
            sim.control(inject)
            share = cpu_during(1.0)
            off = wait_for(err_path, "SAFETY STOP (%s): " % reason, off, 30, proc)
            with open(err_path) as f:
                f.seek(off)
                line = f.readline()
            if detail not in line:
                fwtest.fail("'%s': stop '%s' without '%s' in its detail: %s" % (inject, reason, detail, line.strip()))
            fwtest.note("%-28s -> SAFETY STOP (%s): %s (seen within %.2f s)" % (inject, reason, line.strip(),
                                                                          time.time() - t0))
            check_cpu(inject, share)
            if clear is not None:
                sim.control(clear)
            off = wait_for(err_path, "safety stop cleared", off, 60, proc)
            time.sleep(1.0)  # a run drives again

        def tolerated_fault(inject, seconds):
            """Injects a fault that must be counted and tolerated: no stop while it lasts."""
            nonlocal off
            with open(err_path) as f:
                start = len(f.read())
            sim.control(inject)
            share = cpu_during(seconds)
            sim.control("fault clear")
            with open(err_path) as f:
                end = len(f.read())
            stops = stops_between(err_path, start, end)
            if stops:
                fwtest.fail("'%s' should be tolerated, but stopped the base: %s" % (inject, stops))
            fwtest.note("%-28s -> tolerated for %.0f s, no stop" % (inject, seconds))
            check_cpu(inject, share)
            off = end

        stop_fault("fault laser_stuck 1500", "laser silent", "laser stuck", clear=None)
        if base == "rflex":
            # Rare enough that 4 telegrams in a row (the laser's 0.35 s timeout at 10 scans/s) are
            # practically never hit, long enough that some are (about 8 bytes in 20 s).
            tolerated_fault("fault noise_laser 0.0001", 20.0)
            tolerated_fault("fault noise_base 0.01", 3.0)
        else:
            tolerated_fault("fault noise_laser 0.0001", 20.0)
            tolerated_fault("fault can_errors 0.2", 3.0)
            tolerated_fault("fault can_drop 0.03", 3.0)
            stop_fault("fault node_stuck 1 1500", "base fault", "stale PDOs", clear=None)
            stop_fault("fault node_stuck 16 1500", "base fault", "heartbeat lost", clear=None)
            stop_fault("fault babble 5 1000", "base fault", "CAN bus flooded", clear=None)
            stop_fault("fault bus_off 1000", "base fault", "CAN bus-off", clear=None)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(60)
        if rc != 128 + signal.SIGTERM:
            fwtest.fail("SIGTERM: exit status %d, expected %d" % (rc, 128 + signal.SIGTERM))
        statuses = [s for _, _, s in read_log(os.path.join(d, "run.lcmlog"), {"B21R_STATUS"})]
        fwtest.check_monotonic(statuses, "bus faults")
        last = statuses[-1]
        counted = {"laser_repeated_scans": last.laser_repeated_scans,
                   "laser_bytes_dropped + laser_crc_errors": last.laser_bytes_dropped + last.laser_crc_errors}
        if base == "rflex":
            counted["base_bytes_dropped + base_checksum_errors"] = last.base_bytes_dropped + last.base_checksum_errors
        else:
            counted.update({k: getattr(last, k) for k in ("can_error_frames", "can_unanswered_syncs",
                                                          "can_stale_pdos", "can_foreign_frames")})
            # Failed CRCs are resent, never delivered damaged: no bumper stop, no unknown statusword.
            if any(s.stop_reason == 4 for s in statuses):
                fwtest.fail("a bumper stop on the CANopen base: a damaged frame was taken for a press")
        for k, v in counted.items():
            fwtest.note("STATUS %s = %d" % (k, v))
            if v <= 0:
                fwtest.fail("B21R_STATUS %s did not count the injected fault" % k)
        ok = True
    finally:
        fwtest.stop_all(procs)
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
