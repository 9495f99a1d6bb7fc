# SPDX-License-Identifier: MIT
"""rtload: helpers of the deadline tests (label rt): stress-ng on every core, the privilege to
use real-time scheduling, a process's resident memory."""
import os
import re
import resource
import shutil
import subprocess

import fwtest

CAP_SYS_NICE = 23


def may_use_realtime(priority):
    """True when this process may use SCHED_FIFO at priority (CAP_SYS_NICE or RLIMIT_RTPRIO)."""
    with open("/proc/self/status") as f:
        caps = next((int(line.split()[1], 16) for line in f if line.startswith("CapEff:")), 0)
    soft = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
    return bool(caps & (1 << CAP_SYS_NICE)) or soft == resource.RLIM_INFINITY or soft >= priority


def start_stress(seconds, log_path):
    """stress-ng loading every online core with CPU work, plus one I/O and one memory worker (the
    load of the field report: --cpu N --io 1 --vm 1). Returns the process."""
    exe = shutil.which("stress-ng")
    if exe is None:
        fwtest.fail("stress-ng is not installed (tools/setup.sh installs it from tools/debian-packages.txt)")
    log = open(log_path, "w")
    return subprocess.Popen([exe, "--cpu", str(os.cpu_count()), "--io", "1", "--vm", "1", "--vm-bytes", "512M",
                             "--timeout", "%ds" % seconds, "--metrics-brief"], stdout=log, stderr=subprocess.STDOUT)


def start_reference(cpu, priority, seconds, log_path):
    """cyclictest (rt-tests): a bare SCHED_FIFO thread at `priority` on `cpu` waking every
    millisecond for `seconds`, memory locked: the platform's own wake-up latency over the same
    interval and load, the reference the controller's lateness is judged against (a thread that
    does nothing can be late only because of the kernel, the hypervisor or the hardware)."""
    exe = shutil.which("cyclictest")
    if exe is None:
        fwtest.fail("cyclictest is not installed (tools/setup.sh installs rt-tests from tools/debian-packages.txt)")
    log = open(log_path, "w")
    return subprocess.Popen([exe, "-m", "-q", "-p", str(priority), "-a", str(cpu), "-i", "1000", "-D", "%ds" % seconds],
                            stdout=log, stderr=subprocess.STDOUT)


def reference_max_us(proc, log_path):
    """Waits for cyclictest to end; returns its largest wake-up latency [us] or None."""
    try:
        proc.wait(60)
    except subprocess.TimeoutExpired:
        stop(proc)
    with open(log_path) as f:
        m = [int(x) for x in re.findall(r"Max:\s*(\d+)", f.read())]
    return max(m) if m else None


def steal_jiffies():
    """The time every CPU of this (virtual) machine waited for its hypervisor [USER_HZ ticks]."""
    with open("/proc/stat") as f:
        return int(f.readline().split()[8])


def stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def rss_kib(pid):
    """VmRSS of a process [KiB], or -1 when it is gone."""
    try:
        with open("/proc/%d/status" % pid) as f:
            for line in f:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        pass
    return -1


def lateness_us(starts_us, period_us):
    """The wake-up lateness of every tick from its start times A_k [us, the controller's monotonic
    clock, as B21R_POSE.utime carries them in real time]: A_k minus its scheduled start S_0 + n P.
    The schedule's origin S_0 is not in the log: most ticks start within a fraction of a
    millisecond of their schedule, so their phases (A_k mod P) cluster; the origin is the earliest
    phase up to 2 ms before the end of the densest millisecond. Valid for latenesses up to P minus 2 ms (a
    tick a whole period late is a missed period, which the controller counts itself). Returns the
    latenesses in tick order."""
    if not starts_us:
        return []
    bins = [0] * 100
    for a in starts_us:
        bins[(a % period_us) * 100 // period_us] += 1
    mode = ((max(range(100), key=lambda k: bins[k]) + 1) * period_us) // 100  # the end of the densest bin
    back = max(d for d in ((mode - a % period_us) % period_us for a in starts_us) if d <= 2000)
    origin = (mode - back) % period_us
    return [(a - origin) % period_us for a in starts_us]


def percentile(values, q):
    """Nearest-rank percentile (q in [0, 100]) of a non-empty list."""
    s = sorted(values)
    k = max(0, min(len(s) - 1, int(-(-q * len(s) // 100)) - 1))
    return s[k]
