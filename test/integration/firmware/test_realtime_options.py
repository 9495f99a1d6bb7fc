#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""firmware.realtime_options: the rt_* settings the process has no privilege for stop the
controller before the first tick, with exit status 2 and a message that names the key, the
missing privilege or limit and how to grant it; settings it may apply are applied and reported.
The privileges are taken away for the controller only: RLIMIT_RTPRIO / RLIMIT_MEMLOCK lowered,
and (when the test runs as root) CAP_SYS_NICE and CAP_IPC_LOCK dropped from the bounding set
with setpriv.
usage: test_realtime_options.py CONTROLLER SIM WORLD"""
import os
import resource
import shutil
import subprocess
import sys

import fwtest

CAP_IPC_LOCK = 14
CAP_SYS_NICE = 23


def effective_caps():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("CapEff:"):
                return int(line.split()[1], 16)
    return 0


def unprivileged_prefix():
    """Command prefix that runs without CAP_SYS_NICE and CAP_IPC_LOCK, or None if impossible."""
    caps = effective_caps()
    if not caps & ((1 << CAP_SYS_NICE) | (1 << CAP_IPC_LOCK)):
        return []
    if os.geteuid() == 0 and shutil.which("setpriv"):
        return ["setpriv", "--bounding-set", "-sys_nice,-ipc_lock", "--inh-caps", "-sys_nice,-ipc_lock", "--"]
    return None


def sanitized(exe):
    """True for an AddressSanitizer build (its runtime intercepts mlockall and returns success)."""
    with open(exe, "rb") as f:
        return b"__asan_init" in f.read()


def run(controller, sim_exe, world, d, name, settings, prefix=(), limits=()):
    sim = fwtest.Sim(sim_exe, world, d, name, seed=1)
    try:
        cmd = list(prefix) + fwtest.controller_cmd(controller, sim, d, name, settings)

        def lower_limits():
            for res, value in limits:
                resource.setrlimit(res, (value, value))

        p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=120,
                           preexec_fn=lower_limits)
    finally:
        sim.close()
    fwtest.note("%s: exit %d: %s" % (name, p.returncode, p.stderr.strip().splitlines()[-1:]))
    return p.returncode, p.stderr


def expect_refusal(rc, err, name, *needles):
    if rc != 2:
        fwtest.fail("%s: exit status %d, expected 2 (configuration):\n%s" % (name, rc, err))
    for n in needles:
        if n not in err:
            fwtest.fail("%s: the message does not say '%s':\n%s" % (name, n, err))
    if "starting devices" in err and "real time:" in err:
        fwtest.fail("%s: the settings were reported as applied:\n%s" % (name, err))


def main():
    controller, sim_exe, world = sys.argv[1:4]
    d = fwtest.workdir("realtime-options")
    ok = False
    short = {"phase_one_runs": 1, "phase_two_runs": 0, "eval_every_runs": 5, "eval_starts": 1}
    try:
        prefix = unprivileged_prefix()
        if prefix is None:
            fwtest.note("SKIP of the privilege cases: cannot drop CAP_SYS_NICE / CAP_IPC_LOCK here")
        else:
            rc, err = run(controller, sim_exe, world, d, "fifo", dict(short, rt_scheduler="fifo", rt_priority=50),
                          prefix, [(resource.RLIMIT_RTPRIO, 0)])
            expect_refusal(rc, err, "fifo", "rt_scheduler = fifo, rt_priority = 50", "Operation not permitted",
                           "CAP_SYS_NICE", "RLIMIT_RTPRIO (0)", "LimitRTPRIO=50", "rt_scheduler = other")
            if sanitized(controller):
                fwtest.note("SKIP of the mlockall case: AddressSanitizer makes mlockall a no-op")
            else:
                rc, err = run(controller, sim_exe, world, d, "mlock", dict(short, rt_lock_memory="true"), prefix,
                              [(resource.RLIMIT_MEMLOCK, 64 * 1024)])
                expect_refusal(rc, err, "mlock", "rt_lock_memory = true: mlockall", "RLIMIT_MEMLOCK (64 KiB)",
                               "CAP_IPC_LOCK", "ulimit -l unlimited")
        rc, err = run(controller, sim_exe, world, d, "cpus", dict(short, rt_cpus="63"))
        expect_refusal(rc, err, "cpus", "rt_cpus = \"63\": CPU 63 is not available to this process")

        # What the process may do is applied and reported: affinity to the CPU it runs on, and
        # SCHED_RR when it has CAP_SYS_NICE (or a sufficient RLIMIT_RTPRIO), with pre-faulting.
        cpu = min(os.sched_getaffinity(0))
        settings = dict(short, rt_cpus=str(cpu), rt_prefault="true")
        may_rt = effective_caps() & (1 << CAP_SYS_NICE) or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= 10
        if may_rt:
            settings.update(rt_scheduler="rr", rt_priority=10)
        rc, err = run(controller, sim_exe, world, d, "applied", settings)
        want = "real time: scheduler %s, priority %d, CPUs %d, buffers pre-faulted" % (
            ("rr", 10, cpu) if may_rt else ("other", 0, cpu))
        if rc != 0 or want not in err:
            fwtest.fail("applied: exit %d, expected 0 and '%s':\n%s" % (rc, want, err))
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
