#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.lcm_spy: lcm-spy opens on a display and decodes the product's channels.
Under Xvfb and inside netns-run (LCM over udpm on a private loopback):
1. build/<preset>/bin/b21r-lcm-spy runs during a short lockstep session: its channel table, read
   through the Java accessibility API (B21rSpyProbe), lists B21R_CONFIG, B21R_STATUS,
   B21R_POSE, B21R_EXPERIENCE and B21R_RUN (the launcher's: all but B21R_CONFIG, sent once before
   lcm-spy's JVM may listen) with their types decoded (no '?? fingerprint', no
   undecodable message) and growing counts; a screenshot is not blank and shows a line of text
   per table row where the accessibility tree places the table;
2. tools/b21r_session.py with DISPLAY set starts lcm-spy itself (no --spy): the same checks on its
   window, and Ctrl-C stops it with the others.
The screenshots are kept in the test's folder when it fails (B21R_KEEP=1 keeps them always).
usage: test_lcm_spy.py CONTROLLER SIM REPO BUILD_DIR PROBE_JAR"""
import os
import re
import signal
import subprocess
import sys
import time

import fwtest
import xdisplay

URL = "udpm://239.255.76.67:7667?ttl=0"
CHANNELS = ("B21R_CONFIG", "B21R_STATUS", "B21R_POSE", "B21R_EXPERIENCE", "B21R_RUN")


def stop(p, sig=signal.SIGTERM, timeout=20):
    if p is not None and p.poll() is None:
        p.send_signal(sig)
        try:
            p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def check_window(d, display, probe, name, procs, channels=CHANNELS):
    rows, bounds = xdisplay.wait_channels(probe, channels, 120, procs)
    ours = xdisplay.check_decoded(rows)
    time.sleep(1.0)  # a repaint after the last table update
    img = xdisplay.screenshot(display, os.path.join(d, name + ".png"))
    rows, bounds = xdisplay.channel_table(probe)
    colours, lines = xdisplay.check_screenshot(img, bounds, len(rows))
    fwtest.note("%s: lcm-spy decodes %s; screenshot %dx%d, %d colours, %d text lines in its table of %d rows" % (
        name, ", ".join("%s=%s (%s)" % (ch, r["Type"], r["Num Msgs"].strip()) for ch, r in sorted(ours.items())),
        img.size[0], img.size[1], colours, lines, len(rows)))


def main():
    controller, sim_exe, repo, build, probe_jar = sys.argv[1:6]
    spy = os.path.join(build, "bin", "b21r-lcm-spy")
    d = fwtest.workdir("lcm-spy")
    ok = False
    x = spy_p = ctl = launcher = sim = None
    try:
        x = xdisplay.Xvfb(d)
        # 1. b21r-lcm-spy during a short session.
        probe = os.path.join(d, "probe1.txt")
        with open(os.path.join(d, "spy.log"), "w") as log:
            spy_p = subprocess.Popen([spy, "--lcm-url=" + URL], env=xdisplay.spy_env(x.display, probe_jar, probe),
                                     stdout=log, stderr=subprocess.STDOUT)
        deadline = time.time() + 60
        while xdisplay.channel_table(probe) is None:
            if spy_p.poll() is not None or time.time() > deadline:
                with open(os.path.join(d, "spy.log")) as f:
                    fwtest.fail("lcm-spy did not open its window (exit %s):\n%s" % (spy_p.poll(), f.read()[-3000:]))
            time.sleep(0.2)
        sim = fwtest.Sim(sim_exe, os.path.join(repo, "sim", "worlds", "corridor10.world"), d, "sim")
        cmd = fwtest.controller_cmd(controller, sim, d, "session", {
            "lcm_url": URL, "lockstep_realtime_factor": 5, "phase_one_runs": 1000, "eval_every_runs": 1000})
        with open(os.path.join(d, "session.controller.log"), "w") as err:
            ctl = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        check_window(d, x.display, probe, "b21r-lcm-spy", [("lcm-spy", spy_p), ("the controller", ctl)])
        stop(ctl, signal.SIGINT)
        stop(spy_p)
        sim.close()
        sim = None

        # 2. The session launcher with a display starts lcm-spy itself.
        probe = os.path.join(d, "probe2.txt")
        env = xdisplay.spy_env(x.display, probe_jar, probe)
        out = os.path.join(d, "session")
        launcher_log = os.path.join(d, "launcher.txt")
        with open(launcher_log, "w") as log:
            launcher = subprocess.Popen([sys.executable, os.path.join(repo, "tools", "b21r_session.py"), "--out", out,
                                         "--lockstep", "--pace", "5", "--set", "phase_one_runs=1000",
                                         "--set", "eval_every_runs=1000"], env=env, stdout=log,
                                        stderr=subprocess.STDOUT)
        # B21R_CONFIG (once, at the controller's start) may come before lcm-spy's JVM listens.
        check_window(d, x.display, probe, "b21r_session.py", [("the launcher", launcher)],
                     [ch for ch in CHANNELS if ch != "B21R_CONFIG"])
        launcher.send_signal(signal.SIGINT)
        launcher.wait(90)
        with open(launcher_log) as f:
            text = f.read()
        if not re.search(r"started lcm-spy\s+pid", text) or not re.search(r"stopped lcm-spy\s+pid", text):
            fwtest.fail("the launcher did not start and stop lcm-spy:\n%s" % text)
        with open(os.path.join(out, "spy.log")) as f:
            spy_text = f.read()
        if "Exception" in spy_text:
            fwtest.fail("lcm-spy reported an exception:\n%s" % spy_text[-3000:])
        fwtest.note("b21r_session.py: started lcm-spy with the display, stopped it on Ctrl-C")
        ok = True
    finally:
        for p in (ctl, launcher):
            stop(p, signal.SIGINT)
        stop(spy_p)
        if sim is not None:
            sim.close()
        if x is not None:
            x.close()
        fwtest.cleanup(d, ok)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
