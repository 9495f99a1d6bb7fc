# SPDX-License-Identifier: MIT
"""Device loss: the emulator is killed under a running controller (real time), which closes the
pseudo-terminals of the laser and the rFLEX base (or the CAN bus socket).

Checks, per base:
- the stop reason is "device lost" (STOP_DEVICE_LOST on B21R_STATUS) and the message names the
  device and its path, not "laser silent";
- while the device is gone the controller does not spin: CPU use over 3 s stays under 10 % of
  one core (measured from /proc/<pid>/stat);
- a new emulator behind the same device paths (stable links, as udev's /dev/serial/by-id gives a
  real robot) is reopened, the stop clears and runs go on;
- like udev, the links go away with the device (they dangle until the new emulator is up): a
  pseudo-terminal number the kernel hands to another program meanwhile is never opened (other
  tests running in parallel would lose their data to this controller);
- every B21R_STATUS counter that the message definition calls monotonic (lib/msgs/status_t.lcm)
  never goes back over the loss and the reopen; corrupted bytes on the lines before the loss make
  the laser's and the base's error counters non-zero first;
- with device_lost_action = exit the controller exits with status 6 after the loss.
Usage: test_device_lost.py <b21r-controller> <b21r-sim> <world> <rflex|canopen>
"""
import os
import signal
import subprocess
import sys
import time

import fwtest
from fwtest import read_log
from test_safety import wait_for

EXIT_DEVICE_LOST = 6
STOP_DEVICE_LOST = 9


def endpoints(sim):
    with open(sim.endpoints) as f:
        return dict(kv.split("=", 1) for kv in f.read().split())


def link(target, path):
    tmp = path + ".new"
    if os.path.lexists(tmp):
        os.unlink(tmp)
    os.symlink(target, tmp)
    os.replace(tmp, path)  # atomic, like udev


def cpu_seconds(pid):
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def unplug(d, *links):
    """What udev does when a USB adapter goes: the stable links stop resolving."""
    for path in links:
        link(os.path.join(d, "unplugged"), path)


def start_sim(sim_exe, world, d, base, laser_link, base_link):
    sim = fwtest.Sim(sim_exe, world, d, "sim", base=base, seed=3, lockstep=False)
    ep = endpoints(sim)
    link(ep["laser"], laser_link)
    if base == "rflex":
        link(ep["base"], base_link)
    return sim


def main():
    controller, sim_exe, world, base = sys.argv[1:5]
    d = fwtest.workdir("device-lost-" + base)
    laser_link = os.path.join(d, "laser.tty")
    base_link = os.path.join(d, "base.tty")
    ok = False
    procs = []
    sim = start_sim(sim_exe, world, d, base, laser_link, base_link)
    try:
        settings = {"lockstep": "false", "phase_one_runs": 1000, "eval_every_runs": 1000, "hedger_replay": "false",
                    "safety_clear_ticks": 5, "device_reopen_backoff_s": 0.2, "device_reopen_backoff_max_s": 1,
                    "laser_device": laser_link}
        if base == "rflex":
            settings["base_device"] = base_link
        err_path = os.path.join(d, "run.controller.log")
        with open(err_path, "w") as err, open(os.path.join(d, "run.progress.txt"), "w") as out:
            proc = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, "run", settings), stdout=out, stderr=err)
            procs.append(proc)
        off = wait_for(err_path, "starting devices", 0, 30, proc)
        time.sleep(2.0)  # runs under way
        # Some corrupted bytes on the lines: the error counters count before the loss.
        sim.control("fault corrupt 0.002")
        time.sleep(1.5)
        sim.control("fault clear")
        time.sleep(1.5)
        unplug(d, laser_link, base_link)
        sim.proc.kill()
        sim.proc.wait()
        t0 = time.time()
        off = wait_for(err_path, "SAFETY STOP (device lost)", off, 10, proc)
        fwtest.note("emulator killed -> 'SAFETY STOP (device lost)' after %.2f s" % (time.time() - t0))
        with open(err_path) as f:
            text = f.read()
        line = [x for x in text.splitlines() if "SAFETY STOP (device lost)" in x][0]
        named = ("laser device lost: " + laser_link) in line or \
            (("base device lost: " + base_link) in line if base == "rflex" else "CAN bus lost: " in line)
        if not named:
            fwtest.fail("the message does not name the lost device and its path: %s" % line)
        fwtest.note(line.strip())
        # No spinning while the devices are gone.
        c0, w0 = cpu_seconds(proc.pid), time.time()
        time.sleep(3.0)
        share = (cpu_seconds(proc.pid) - c0) / (time.time() - w0)
        fwtest.note("CPU use while the devices are gone: %.1f %% of a core" % (100 * share))
        if share > 0.10:
            fwtest.fail("the controller spins while the device is gone (%.0f %% of a core)" % (100 * share))
        sim.close()
        # The devices come back behind the same paths: reopened, the stop clears, runs go on.
        sim = start_sim(sim_exe, world, d, base, laser_link, base_link)
        t0 = time.time()
        off = wait_for(err_path, "reopened", off, 20, proc)
        off = wait_for(err_path, "safety stop cleared", off, 30, proc)
        fwtest.note("emulator back -> reopened and stop cleared after %.2f s" % (time.time() - t0))
        time.sleep(1.0)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(60)
        if rc != 128 + signal.SIGTERM:
            fwtest.fail("SIGTERM: exit status %d" % rc)
        seen = [s.stop_detail for _, _, s in read_log(os.path.join(d, "run.lcmlog"), {"B21R_STATUS"})
                if s.stop_reason == STOP_DEVICE_LOST]
        if not seen or "lost" not in seen[0]:
            fwtest.fail("B21R_STATUS never reported STOP_DEVICE_LOST with its detail")
        fwtest.note("STATUS stop_reason %d: %s" % (STOP_DEVICE_LOST, seen[0]))
        statuses = [s for _, _, s in read_log(os.path.join(d, "run.lcmlog"), {"B21R_STATUS"})]
        lost_at = next(i for i, s in enumerate(statuses) if s.stop_reason == STOP_DEVICE_LOST)
        before = statuses[lost_at]
        if before.laser_crc_errors + before.laser_bytes_dropped == 0:
            fwtest.fail("no laser error counted before the loss: the reopen check would prove nothing")
        if base == "rflex" and before.base_checksum_errors + before.base_bytes_dropped == 0:
            fwtest.fail("no base error counted before the loss: the reopen check would prove nothing")
        after = [s for s in statuses[lost_at:] if s.stop_reason != STOP_DEVICE_LOST]
        if not after:
            fwtest.fail("no B21R_STATUS after the reopen")
        fields = fwtest.check_monotonic(statuses, "device reopened")
        fwtest.note("%d monotonic counters never went back over %d STATUS messages (laser CRC errors %d, bytes "
                    "dropped %d, restarts %d before the loss; %d, %d, %d at the end)" %
                    (len(fields), len(statuses), before.laser_crc_errors, before.laser_bytes_dropped,
                     before.laser_restarts, statuses[-1].laser_crc_errors, statuses[-1].laser_bytes_dropped,
                     statuses[-1].laser_restarts))

        # device_lost_action = exit: the documented status after the loss.
        settings["device_lost_action"] = "exit"
        err2 = os.path.join(d, "exit.controller.log")
        with open(err2, "w") as err, open(os.path.join(d, "exit.progress.txt"), "w") as out:
            proc = subprocess.Popen(fwtest.controller_cmd(controller, sim, d, "exit", settings), stdout=out,
                                    stderr=err)
            procs.append(proc)
        wait_for(err2, "starting devices", 0, 30, proc)
        time.sleep(2.0)
        unplug(d, laser_link, base_link)
        sim.proc.kill()
        sim.proc.wait()
        rc = proc.wait(30)
        if rc != EXIT_DEVICE_LOST:
            fwtest.fail("device_lost_action = exit: exit status %d, expected %d" % (rc, EXIT_DEVICE_LOST))
        wait_for(err2, "SAFETY STOP (device lost)", 0, 1)
        fwtest.note("device_lost_action = exit -> exit status %d" % rc)
        ok = True
    finally:
        # A controller left running after a failure would reopen its device paths, which the
        # kernel hands to other tests' emulators (pseudo-terminal numbers are reused).
        fwtest.stop_all(procs)
        sim.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
