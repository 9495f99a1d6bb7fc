#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.session_lossless: a whole emulated session recorded by lcm-logger over UDP loses nothing
at the documented pace. tools/b21r_session.py runs a complete schedule (phase one, phase two,
evaluation blocks) in lockstep at its default pace (20 x real time) with LCM udpm confined to this
private network namespace (run by netns-run). The recording lcm-logger made (session.lcmlog) must
hold exactly the experiences and run records of the controller's own log (controller.lcmlog, which
the controller writes itself and never drops): the same messages, byte for byte, in the same
order, with no sequence gap; and the controller's STATUS reports no publisher error or drop.
The same session at --pace 0 (as fast as possible) is run too and its loss, if any, printed: it
is what the cap is for, not a requirement.
usage: test_session_lossless.py SESSION_TOOL"""
import os
import subprocess
import sys
import time

import fwtest
import lcm
from b21r_log import experience_gaps, read_log

CHANNELS = ("B21R_EXPERIENCE", "B21R_RUN", "B21R_EVAL")
SCHEDULE = ["phase_one_runs=3", "phase_two_runs=2", "eval_every_runs=5", "eval_starts=3", "seed=5"]


def raw(path):
    """{channel: [message bytes, in file order]} for CHANNELS."""
    out = {c: [] for c in CHANNELS}
    log = lcm.EventLog(path, "r")
    try:
        for ev in log:
            if ev.channel in out:
                out[ev.channel].append(bytes(ev.data))
    finally:
        log.close()
    return out


def session(tool, out, pace):
    cmd = [sys.executable, tool, "--out", out, "--lockstep", "--no-spy", "--pace", str(pace)]
    for s in SCHEDULE:
        cmd += ["--set", s]
    t0 = time.time()
    with open(out + ".launcher.txt", "w") as log:
        p = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, timeout=600,
                           env=dict(os.environ, DISPLAY="", B21R_OPERATOR_KEY=out + ".operator.key"))
    if p.returncode != 0:
        fwtest.fail("session (pace %g) exit status %d; see %s.launcher.txt" % (pace, p.returncode, out))
    return time.time() - t0


def main():
    tool = sys.argv[1]
    d = fwtest.workdir("session-lossless")
    ok = False
    try:
        out = os.path.join(d, "paced")
        wall = session(tool, out, 20)
        own = raw(os.path.join(out, "controller.lcmlog"))
        rec = raw(os.path.join(out, "session.lcmlog"))
        exps = [m for _, _, m in read_log(os.path.join(out, "controller.lcmlog"), {"B21R_EXPERIENCE"})]
        runs = [m for _, _, m in read_log(os.path.join(out, "controller.lcmlog"), {"B21R_RUN"})]
        if len(runs) < 8 or not exps or experience_gaps(exps):
            fwtest.fail("the controller's own log: %d runs, %d experiences, gaps %s (a whole session expected)" %
                        (len(runs), len(exps), experience_gaps(exps)[:3]))
        for c in CHANNELS:
            if rec[c] != own[c]:
                missing = len(own[c]) - len(rec[c])
                first = next((i for i, (a, b) in enumerate(zip(own[c], rec[c])) if a != b), min(len(own[c]), len(rec[c])))
                fwtest.fail("%s: lcm-logger recorded %d of the controller's %d messages (%d missing; first "
                            "difference at message %d)" % (c, len(rec[c]), len(own[c]), missing, first))
        status = [m for _, _, m in read_log(os.path.join(out, "controller.lcmlog"), {"B21R_STATUS"})]
        last = status[-1]
        counters = {k: getattr(last, k) for k in ("messages_published", "lcm_publish_errors", "log_write_errors",
                                                  "experiences_dropped")}
        if counters["messages_published"] <= 0 or any(v != 0 for k, v in counters.items() if k != "messages_published"):
            fwtest.fail("publisher counters on the last STATUS: %s" % counters)
        fwtest.note("pace 20: %d runs, %d experiences in %.1f s; lcm-logger recorded all of them byte for byte "
                    "(%s); publisher %s" % (len(runs), len(exps), wall,
                                           ", ".join("%s %d" % (c, len(rec[c])) for c in CHANNELS), counters))

        out = os.path.join(d, "unpaced")
        wall = session(tool, out, 0)
        own, rec = raw(os.path.join(out, "controller.lcmlog")), raw(os.path.join(out, "session.lcmlog"))
        fwtest.note("pace 0 (for comparison): %.1f s, lcm-logger missed %d of %d experiences" %
                    (wall, len(own["B21R_EXPERIENCE"]) - len(rec["B21R_EXPERIENCE"]), len(own["B21R_EXPERIENCE"])))
        ok = True
    finally:
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
