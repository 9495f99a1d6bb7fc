#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.session: tools/b21r_session.py starts an emulated session (emulator, controller,
lcm-logger) with LCM confined to this private network namespace (run by netns-run); after a few
runs one SIGINT to the launcher stops everything in order (the controller first: it saves the
learned state; the emulator last), every program it started is gone, the launcher's exit status
is the controller's (130), and the recordings are written: the controller's own log holds every
run it finished, lcm-logger's recording holds experiences, the checkpoint exists. A second
session in the same folder resumes from the checkpoint; SIGTERM stops it the same way. The
launcher creates the operator key where B21R_OPERATOR_KEY names it (mode 600, checked by loading it)
and the controller signs its session with it.
usage: test_session.py SESSION_TOOL"""
import os
import re
import signal
import subprocess
import sys
import time

import b21r_opauth
import fwtest
from b21r_log import experience_gaps, read_log, runs_from_experiences


def start(tool, out, log):
    key = os.path.join(os.path.dirname(out), "operator.key")  # made by the launcher on first use
    return subprocess.Popen([sys.executable, tool, "--out", out, "--lockstep", "--no-spy",
                             "--set", "phase_one_runs=1000", "--set", "eval_every_runs=1000"],
                            stdout=log, stderr=subprocess.STDOUT,
                            env=dict(os.environ, DISPLAY="", B21R_OPERATOR_KEY=key))


def wait_for(path, pattern, count, timeout, proc):
    deadline = time.time() + timeout
    while time.time() < deadline:
        with open(path) as f:
            hits = re.findall(pattern, f.read(), re.M)
        if len(hits) >= count:
            return
        if proc.poll() is not None:
            fwtest.fail("the launcher exited (%d) early; see %s" % (proc.returncode, path))
        time.sleep(0.1)
    fwtest.fail("'%s' x%d not in %s within %d s" % (pattern, count, path, timeout))


def check_stopped(path, want_rc, rc):
    with open(path) as f:
        text = f.read()
    if rc != want_rc:
        fwtest.fail("launcher exit status %d, expected %d:\n%s" % (rc, want_rc, text))
    started = dict(re.findall(r"started (\S+)\s+pid (\d+)", text))
    stopped = re.findall(r"stopped (\S+)\s+pid (\d+)", text)
    if set(started) != {"emulator", "lcm-logger", "controller"}:
        fwtest.fail("started %s" % sorted(started))
    if [n for n, _ in stopped] != ["controller", "lcm-logger", "emulator"]:
        fwtest.fail("stop order %s, expected the controller first and the emulator last" % [n for n, _ in stopped])
    for name, pid in started.items():
        try:
            os.kill(int(pid), 0)
            fwtest.fail("%s (pid %s) is still running" % (name, pid))
        except ProcessLookupError:
            pass
    return text


def main():
    tool = sys.argv[1]
    d = fwtest.workdir("session")
    ok = False
    proc = None
    try:
        out = os.path.join(d, "s")
        log_path = os.path.join(d, "launcher.txt")
        with open(log_path, "w") as log:
            proc = start(tool, out, log)
        wait_for(log_path, r"^\s+run\s+\d+\s+phase 1\s+train\s+goal", 3, 120, proc)
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(90)
        check_stopped(log_path, 128 + signal.SIGINT, rc)
        with open(os.path.join(out, "controller.log")) as f:
            err = f.read()
        if "SAFETY STOP (signal)" not in err or "final checkpoint" not in err:
            fwtest.fail("the controller did not stop on the signal:\n%s" % err)
        # The launcher made the operator key (mode 600) and gave it to the controller.
        key_path = os.path.join(d, "operator.key")
        kid = b21r_opauth.key_id(b21r_opauth.load_key(key_path)).hex()
        if "key id %s" % kid not in err:
            fwtest.fail("the controller does not use the launcher's key %s (id %s):\n%s" % (key_path, kid, err))
        exps = [m for _, _, m in read_log(os.path.join(out, "controller.lcmlog"), {"B21R_EXPERIENCE"})]
        done = [r for r in runs_from_experiences(exps) if r["goal"]]
        if len(done) < 3 or experience_gaps(exps):
            fwtest.fail("controller.lcmlog: %d finished runs, gaps %s" % (len(done), experience_gaps(exps)[:3]))
        rec = [m for _, _, m in read_log(os.path.join(out, "session.lcmlog"), {"B21R_EXPERIENCE"})]
        if not rec:
            fwtest.fail("lcm-logger recorded no experience")
        if not os.path.exists(os.path.join(out, "hedger.ckpt")):
            fwtest.fail("no checkpoint")
        fwtest.note("SIGINT after %d runs: controller, lcm-logger, emulator stopped in order, exit 130; "
                    "controller.lcmlog %d experiences (no gaps), lcm-logger %d, checkpoint written" %
                    (len(done), len(exps), len(rec)))

        # The same folder again: the controller resumes; SIGTERM stops it the same way.
        log_path = os.path.join(d, "launcher2.txt")
        with open(log_path, "w") as log:
            proc = start(tool, out, log)
        wait_for(os.path.join(out, "controller.log"), r"resumed from", 1, 60, proc)
        wait_for(log_path, r"^\s+run\s+\d+", 1, 60, proc)
        proc.send_signal(signal.SIGTERM)
        rc = proc.wait(90)
        check_stopped(log_path, 128 + signal.SIGINT, rc)  # the launcher stops the controller with SIGINT
        fwtest.note("second session: resumed from the checkpoint; SIGTERM stopped everything in order")
        ok = True
    finally:
        if proc is not None and proc.poll() is None:
            proc.kill()
            proc.wait()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
