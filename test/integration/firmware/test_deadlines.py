#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.deadlines (label rt): real-time operation against the emulator under stress-ng load on
every core, the controller with its real-time options (SCHED_FIFO, memory locked, buffers
pre-faulted, pinned to the last CPU). Claim checked: no scheduled tick is missed (STATUS
missed_periods = 0) and no false safety stop happens (laser/base silence, base fault or device
loss, none of which is injected). Prints the wake-up lateness, compute time, late starts, the
longest gap between ticks and the resident memory before and after the learner's store filled.
The emulator stands in for devices that do not share the CPU: it runs under SCHED_FIFO too, below
the controller. Needs CAP_SYS_NICE or RLIMIT_RTPRIO >= 60 (and CAP_IPC_LOCK or a large enough
RLIMIT_MEMLOCK unless B21R_RT_LOCK_MEMORY=false).
Also prints the lateness of every tick's start over the whole run (p50, p99, max; from the
start times its B21R_POSE messages carry), which the benchmark firmware.deadlines_bench reports
for 10 minutes, beside the platform's own: cyclictest runs a bare SCHED_FIFO thread one priority
below the controller on the same CPU over the same interval (on a virtual machine the hypervisor
alone can wake it late by several milliseconds, and /proc/stat's steal time says how much the
CPUs waited for it). Fails when the start lateness p99 exceeds 2 ms, or its maximum exceeds 10 ms
and the platform's own maximum by more than 2 ms (lateness the controller adds).
With B21R_RT_STORE_SAMPLES > 0 a lockstep session first learns (examples, then learned runs with
the backward replay) until the store holds that many samples; the real-time run resumes from its
checkpoint and goes on learning, so its ticks and run ends work on a full store (the design's
20,000 points) and the compute time is measured there.
Environment: B21R_RT_SECONDS (default 600) the length of the run; B21R_RT_LOCK_MEMORY
(default true); B21R_RT_STORE_SAMPLES (default 0); B21R_RT_STRESS (default true; false measures
the same without stress-ng).
The late scans' reference (PTY_LATENCY, test/support/pty_latency.c): over the same interval a
block of a telegram's size goes every 100 ms through a pseudo-terminal and through a socketpair
between real-time threads at the emulator's and the laser line's priorities; the pty passes every
block through the kernel's tty flip-buffer work, a time-shared kernel worker. A "laser silent"
stop counts as false unless that reference itself held a block longer than the laser's timeout
(then the platform's pty path lost the scans, not the controller; printed either way).
usage: test_deadlines.py CONTROLLER SIM WORLD [PTY_LATENCY]"""
import os
import re
import signal
import subprocess
import sys
import time

import fwtest
import rtload
from b21r import status_t

PRIORITY = 60
LASER_TIMEOUT_MS = 350  # laser_timeout_s's default
FALSE_STOPS = {status_t.STOP_LASER_SILENT: "laser silent", status_t.STOP_BASE_SILENT: "base silent",
               status_t.STOP_BASE_FAULT: "base fault", status_t.STOP_DEVICE_LOST: "device lost"}


def fill_store(controller, sim_exe, world, d, ckpt, samples):
    """Learns in lockstep (30 example runs, then learned runs with the backward replay) until the
    store holds `samples` samples; the checkpoint is written at the SIGTERM."""
    sim = fwtest.Sim(sim_exe, world, d, "fill", seed=2)
    try:
        settings = {"phase_one_runs": 30, "phase_two_runs": 100000, "seed": 7, "checkpoint_file": ckpt,
                    "eval_every_runs": 100000}
        err_path = os.path.join(d, "fill.controller.log")
        log_path = os.path.join(d, "fill.lcmlog")
        t0 = time.time()
        with open(err_path, "w") as err, open(os.path.join(d, "fill.progress.txt"), "w") as out:
            p = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, "fill", settings), stdout=out, stderr=err)
            fill = 0
            while fill < samples:
                time.sleep(2)
                if p.poll() is not None or time.time() - t0 > 1800:
                    p.kill()
                    fwtest.fail("filling the store: the controller %s (see %s)" %
                                ("ended" if p.returncode is not None else "took more than 30 min", err_path))
                st = fwtest.read_log(log_path, {"B21R_STATUS"}, cut=True)
                fill = st[-1][2].store_fill if st else 0
            p.send_signal(signal.SIGTERM)
            if p.wait(120) != 128 + signal.SIGTERM:
                fwtest.fail("filling the store: exit status %d (see %s)" % (p.returncode, err_path))
        fwtest.note("store filled to %d samples in lockstep in %.0f s" % (fill, time.time() - t0))
    finally:
        sim.close()


def main():
    controller, sim_exe, world = sys.argv[1:4]
    pty_exe = sys.argv[4] if len(sys.argv) > 4 else None
    seconds = int(os.environ.get("B21R_RT_SECONDS", "600"))
    lock = os.environ.get("B21R_RT_LOCK_MEMORY", "true")
    if not rtload.may_use_realtime(PRIORITY):
        fwtest.fail("real-time scheduling is not permitted: run as root, with CAP_SYS_NICE, or with "
                    "RLIMIT_RTPRIO >= %d (e.g. prlimit --rtprio=%d --pid $$)" % (PRIORITY, PRIORITY))
    store = int(os.environ.get("B21R_RT_STORE_SAMPLES", "0"))
    loaded = os.environ.get("B21R_RT_STRESS", "true") != "false"
    d = fwtest.workdir("deadlines")
    ok = False
    cpu = max(os.sched_getaffinity(0))
    ckpt = os.path.join(d, "hedger.ckpt")
    if store > 0:
        fill_store(controller, sim_exe, world, d, ckpt, store)
    stress = rtload.start_stress(seconds + 60, os.path.join(d, "stress.log")) if loaded else None
    ref = None
    pty_ref = None
    sim = fwtest.Sim(sim_exe, world, d, "rt", seed=1, lockstep=False, prefix=["chrt", "-f", str(PRIORITY - 10)])
    try:
        settings = {"lockstep": "false", "phase_one_runs": 100000, "phase_two_runs": 100000, "seed": 3,
                    "rt_scheduler": "fifo", "rt_priority": PRIORITY, "rt_cpus": str(cpu), "rt_lock_memory": lock,
                    "rt_prefault": "true"}
        if store > 0:
            settings.update({"checkpoint_file": ckpt, "phase_one_runs": 30})
        cmd = fwtest.controller_cmd(controller, sim, d, "rt", settings)
        err_path = os.path.join(d, "rt.controller.log")
        with open(err_path, "w") as err, open(os.path.join(d, "rt.progress.txt"), "w") as out:
            p = subprocess.Popen(cmd, stdout=out, stderr=err)
            ref_log = os.path.join(d, "cyclictest.log")
            ref = rtload.start_reference(cpu, PRIORITY - 1, seconds, ref_log)
            pty_log = os.path.join(d, "pty_latency.log")
            if pty_exe is not None:
                pty_ref = subprocess.Popen([pty_exe, str(seconds), str(PRIORITY - 10), str(PRIORITY - 1), str(cpu)],
                                           stdout=open(pty_log, "w"), stderr=subprocess.STDOUT)
            steal0 = rtload.steal_jiffies()
            time.sleep(min(10, seconds / 4))
            rss_start = rtload.rss_kib(p.pid)
            deadline = time.time() + seconds - min(10, seconds / 4)
            while time.time() < deadline and p.poll() is None:
                time.sleep(1)
            rss_end = rtload.rss_kib(p.pid)
            if p.poll() is not None:
                with open(err_path) as f:
                    fwtest.fail("the controller ended early (status %d):\n%s" % (p.returncode, f.read()[-3000:]))
            ref_max_us = rtload.reference_max_us(ref, ref_log)
            pty_lines = {}
            if pty_ref is not None:
                try:
                    pty_ref.wait(60)
                except subprocess.TimeoutExpired:
                    rtload.stop(pty_ref)
                with open(pty_log) as f:
                    for line in f:
                        m = re.match(r"(pty|socketpair): blocks (\d+) of (\d+), delay p99 ([\d.]+) ms, max ([\d.]+) ms, "
                                     r"later than 50 ms (\d+)", line)
                        if m:
                            pty_lines[m.group(1)] = (line.strip(), float(m.group(5)))
            steal_ms = (rtload.steal_jiffies() - steal0) * 1000 // os.sysconf("SC_CLK_TCK")
            p.send_signal(signal.SIGTERM)
            rc = p.wait(60)
        with open(err_path) as f:
            err_text = f.read()
        if rc != 128 + signal.SIGTERM:
            fwtest.fail("controller exit status %d:\n%s" % (rc, err_text[-3000:]))
    finally:
        sim.close()
        if stress is not None:
            rtload.stop(stress)
        if ref is not None:
            rtload.stop(ref)
        if pty_ref is not None:
            rtload.stop(pty_ref)

    log = fwtest.read_log(os.path.join(d, "rt.lcmlog"), {"B21R_STATUS", "B21R_POSE", "B21R_RUN"})
    statuses = [m for _, c, m in log if c == "B21R_STATUS"]
    # Every tick publishes its pose stamped with the tick's start (real time: the monotonic clock).
    starts = [m.utime for _, c, m in log if c == "B21R_POSE"]
    run_ends = sum(1 for _, c, _ in log if c == "B21R_RUN")
    running = [s for s in statuses if s.mode != status_t.MODE_DONE]
    if not running:
        fwtest.fail("no STATUS in the log")
    last = running[-1]
    false_stops = {}
    prev = 0
    for s in statuses:
        if s.stop_reason != prev and s.stop_reason in FALSE_STOPS:
            false_stops[FALSE_STOPS[s.stop_reason]] = false_stops.get(FALSE_STOPS[s.stop_reason], 0) + 1
        prev = s.stop_reason
    first_fill = next((s.store_fill for s in running if s.utime > running[0].utime + 9e6), running[0].store_fill)
    fwtest.note("real time %d s at 10 Hz %s; controller SCHED_FIFO %d on CPU %d, rt_lock_memory=%s, "
                "rt_prefault=true; %s" %
                (seconds, "under stress-ng (--cpu %d --io 1 --vm 1 --vm-bytes 512M)" % os.cpu_count() if loaded
                 else "without stress-ng", PRIORITY, cpu, lock,
                 "learning from a store of %d samples (resumed)" % first_fill if store > 0 else "example runs"))
    late = rtload.lateness_us(starts, 100000)
    if late:
        fwtest.note("  tick start lateness over all %d ticks: p50 %.2f ms, p99 %.2f ms, max %.2f ms; starts more "
                    "than 10 ms late %d, more than 2 ms late %d; %d run ends" %
                    (len(late), rtload.percentile(late, 50) / 1e3, rtload.percentile(late, 99) / 1e3,
                     max(late) / 1e3, sum(1 for x in late if x > 10000), sum(1 for x in late if x > 2000),
                     run_ends))
    fwtest.note("  platform reference (cyclictest, SCHED_FIFO %d on CPU %d, 1 kHz, same interval): wake-up "
                "lateness max %s ms; CPUs waiting for the hypervisor (steal) %d ms in all" %
                (PRIORITY - 1, cpu, "%.2f" % (ref_max_us / 1e3) if ref_max_us is not None else "?", steal_ms))
    for name in ("pty", "socketpair"):
        if name in pty_lines:
            fwtest.note("  late scans' reference (a telegram's bytes every 100 ms, FIFO %d -> FIFO %d): %s" %
                        (PRIORITY - 10, PRIORITY - 1, pty_lines[name][0]))
    platform_lost_scans = "pty" in pty_lines and pty_lines["pty"][1] > LASER_TIMEOUT_MS
    fwtest.note("  ticks %d, missed periods %d, late starts (> 10 ms) %d, overruns %d" %
                (last.ticks, last.missed_periods, last.late_starts, last.tick_overruns))
    fwtest.note("  wake-up lateness: max %d us (p99 of the last %d ticks %d us); longest gap between tick "
                "starts %d us (period 100000 us)" %
                (last.late_max_ever_us, min(last.ticks, 1024), last.late_p99_us, last.gap_max_ever_us))
    fwtest.note("  tick compute: max %d us, p99 %d us, p50 %d us" %
                (last.tick_max_ever_us, last.tick_p99_us, last.tick_p50_us))
    fwtest.note("  safety stops %d (false: %s); store %d -> %d samples; RSS %d KiB -> %d KiB" %
                (last.safety_stops, false_stops or "none", first_fill, last.store_fill, rss_start, rss_end))
    if last.ticks < 0.95 * seconds * 10 - 100:
        fwtest.fail("only %d ticks in %d s" % (last.ticks, seconds))
    if last.missed_periods != 0:
        fwtest.fail("%d missed periods" % last.missed_periods)
    if platform_lost_scans and "laser silent" in false_stops:
        fwtest.note("  %d \"laser silent\" stops counted as the platform's: its pty path itself held a block "
                    "longer than the laser's timeout (%d ms)" % (false_stops.pop("laser silent"), LASER_TIMEOUT_MS))
    if false_stops:
        fwtest.fail("false safety stops: %s" % false_stops)
    if late and rtload.percentile(late, 99) > 2000:
        fwtest.fail("tick start lateness p99 %.2f ms > 2 ms" % (rtload.percentile(late, 99) / 1e3))
    if late and max(late) > 10000 and (ref_max_us is None or max(late) > ref_max_us + 2000):
        fwtest.fail("tick start lateness max %.2f ms: above 10 ms and above the platform's own %s ms by more "
                    "than 2 ms" % (max(late) / 1e3, "%.2f" % (ref_max_us / 1e3) if ref_max_us is not None else "?"))
    ok = True
    fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
