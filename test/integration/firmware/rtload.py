# SPDX-License-Identifier: MIT
"""rtload: helpers of the deadline tests (label rt): stress-ng on every core, the privilege to
use real-time scheduling, a process's resident memory."""
import os
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
    return subprocess.Popen([exe, "--cpu", str(os.cpu_count()), "--io", "1", "--vm", "1", "--vm-bytes", "256M",
                             "--timeout", "%ds" % seconds, "--metrics-brief"], stdout=log, stderr=subprocess.STDOUT)


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
