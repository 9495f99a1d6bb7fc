#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.readme_commands: every tool command the READMEs and docs/*.md show runs as written from a
plain environment (PATH of the system only: no venv, no PYTHONPATH, no B21R_* variables), from the
repository's top folder, as an operator would type it after tools/setup.sh and a build.
- Every tools/*.py the READMEs name is run directly (its shebang, the system's python3) with
  --help: it must re-execute itself in the project's venv, find the generated types and print
  its usage.
- Every build/<preset>/bin/<program> they name prints its usage with --help (the program of
  this build when that preset is not built here, or the README writes "<preset>").
- The shell scripts they name are executable and parse (bash -n); they are not run (set-up and
  the main job).
- A few commands are run for real, exactly as the README writes them (checked verbatim), with
  files made here in place of the README's placeholders: sending an operator command (signed with
  the key in the plain environment's home, for a controller session this test announces: the
  command must arrive with a valid mac), creating and identifying an operator key, reading a log,
  drawing its trajectories, offline training from it, converting it to MCAP, drawing what the
  trained checkpoint learned; one seed of an exploration experiment (docs/experiments.md); the
  installed programs of docs/robot.md as their sources in this checkout (b21r-teleop:
  tools/b21r_teleop.py, ...), the controller on the package's /etc/b21r/b21r-controller.conf as
  this build makes it.
- The lcm-spy command is started for real under Xvfb (with PROBE_JAR, the accessibility probe
  of the lcm-spy tests): it must open its window and show a B21R_STATUS message sent to the URL
  the command names, decoded.
- Every `cmake|ctest|cpack --preset NAME` names a preset of CMakePresets.json of that kind.
- The commands of docs/robot.md that need root and a robot (sudo, systemctl, journalctl) are not
  run; the unit, configuration file and package file they name are checked against the package's.
The READMEs are README.md, sim/README.md and docs/*.md.
Run inside netns-run: the commands that publish on LCM's default URL stay in this namespace.
usage: test_readme_commands.py REPO BUILD_DIR [PROBE_JAR]"""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

import lcm
from b21r import command_t, experience_t, pose_t, session_t, status_t

import b21r_opauth
import fwtest

# HOME: a fresh one (made in main), as an operator's after set-up, with the operator key installed.
PLAIN_ENV = {"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": "", "LANG": "C.UTF-8"}

# Commands run for real: (text as the README shows it, placeholder substitutions).
REAL = [
    ("tools/b21r_teleop.py --command CONFIRM_START_POSE", {}),
    ("tools/b21r_key.py create /etc/b21r/operator.key", {"/etc/b21r/operator.key": "{tmp}/etc/b21r/operator.key"}),
    ("tools/b21r_key.py id", {}),
    ("tools/b21r_log.py FILE --gaps --runs", {"FILE": "{log}"}),
    ("tools/b21r_trajectories.py LOG --out runs.png", {"LOG": "{log}", "runs.png": "{tmp}/runs.png"}),
    ("build/host-release/bin/b21r-train --config robot.conf --out trained.ckpt run1.lcmlog run2.lcmlog",
     {"build/host-release": "{build}", "robot.conf": "{tmp}/robot.conf", "trained.ckpt": "{tmp}/trained.ckpt",
      "run1.lcmlog": "{log}", "run2.lcmlog": "{log}"}),
    # docs/tools.md (after b21r-train: its checkpoint is drawn)
    ("tools/b21r_mcap.py build/sessions/NAME/controller.lcmlog", {"build/sessions/NAME": "{tmp}"}),
    ("tools/b21r_policy_map.py --checkpoint build/sessions/NAME/hedger.ckpt",
     {"build/sessions/NAME/hedger.ckpt": "{tmp}/trained.ckpt"}),
    # docs/robot.md: the package's programs, as their sources here.
    ("b21r-teleop --command CONFIRM_START_POSE", {"b21r-teleop": "tools/b21r_teleop.py"}),
    ("b21r-log FILE --runs", {"b21r-log": "tools/b21r_log.py", "FILE": "{log}"}),
    ("b21r-controller --config /etc/b21r/b21r-controller.conf --print-config",
     {"b21r-controller --config": "{build}/bin/b21r-controller --config",
      "/etc/b21r/b21r-controller.conf": "{build}/package/b21r-controller.conf"}),
    # docs/experiments.md: one seed of one variant of the sensitivity study, shortened.
    ("build/host-release/bin/b21r-experiment --config tools/experiments/explore_goal_random.conf --seed 1 "
     "--variant experiment.explore_random=both --set experiment.explore_runs=2 "
     "--set experiment.explore_time_limit_s=3600 --out /tmp/explore.json",
     {"build/host-release": "{build}", "/tmp/explore.json": "{tmp}/explore.json"}),
]
SPY_COMMAND = "LCM_DEFAULT_URL='udpm://239.255.76.67:7667?ttl=0' build/host-release/bin/b21r-lcm-spy"
PRESET_KINDS = {"cmake": "configurePresets", "cmake --build": "buildPresets", "cmake --workflow": "workflowPresets",
                "ctest": "testPresets", "cpack": "packagePresets"}


def check_presets(repo, text):
    with open(os.path.join(repo, "CMakePresets.json")) as f:
        presets = json.load(f)
    n = 0
    for m in re.finditer(r"\b(cmake --build|cmake --workflow|cmake|ctest|cpack) --preset ([A-Za-z0-9_-]+)", text):
        kind = PRESET_KINDS[m.group(1)]
        if m.group(2) not in {p["name"] for p in presets.get(kind, [])}:
            fwtest.fail("`%s` names no preset of %s" % (m.group(0), kind))
        n += 1
    fwtest.note("%d `--preset` commands name existing presets" % n)


def check_robot_commands(repo):
    """docs/robot.md's root-and-robot commands: not run; what they name is the package's."""
    with open(os.path.join(repo, "docs/robot.md")) as f:
        text = f.read()
    with open(os.path.join(repo, "CMakeLists.txt")) as f:
        version = re.search(r"project\(b21r_learning\s+VERSION\s+([0-9.]+)", f.read()).group(1)
    with open(os.path.join(repo, "firmware/app/package/conffiles")) as f:
        conffiles = f.read().split()
    units = [u[:-len(".service")] for u in os.listdir(os.path.join(repo, "firmware/app/package")) if u.endswith(".service")]
    lines = [ln.split("#")[0].strip() for ln in text.splitlines()]
    shown = [ln for ln in lines if re.match(r"(sudo |sudoedit |systemctl |journalctl )", ln)]
    shown += [c for c in re.findall(r"`((?:sudo |systemctl |journalctl )[^`]*)`", text)]
    if not shown:
        fwtest.fail("docs/robot.md shows no systemctl/journalctl command")
    for cmd in shown:
        for unit in re.findall(r"\bb21r-[a-z-]+(?=\s|$)", cmd.replace("sudo ", "")):
            if ("systemctl" in cmd or "journalctl" in cmd) and unit not in units:
                fwtest.fail("`%s`: no unit %s.service in the package (%s)" % (cmd, unit, units))
        for path in re.findall(r"/etc/\S+", cmd):
            if path not in conffiles:
                fwtest.fail("`%s`: %s is not the package's configuration file %s" % (cmd, path, conffiles))
        for deb in re.findall(r"b21r-controller_([0-9.]+)_[a-z0-9]+\.deb", cmd):
            if deb != version:
                fwtest.fail("`%s`: the package's version is %s" % (cmd, version))
        fwtest.note("%-44s needs root and the robot: not run; names the package's files" % cmd[:44])


def readme_text(repo):
    parts = []
    docs = sorted(os.path.join("docs", n) for n in os.listdir(os.path.join(repo, "docs")) if n.endswith(".md"))
    for path in ["README.md", "sim/README.md"] + docs:
        with open(os.path.join(repo, path)) as f:
            parts.append(f.read())
    return "\n".join(parts)


def run_spy(repo, build, probe_jar, tmp, text):
    """The README's lcm-spy command for real, on a virtual display: its window shows B21R_STATUS decoded."""
    import xdisplay
    if SPY_COMMAND not in text:
        fwtest.fail("the README no longer shows `%s`: update this test with it" % SPY_COMMAND)
    exe = os.path.join(repo, "build", "host-release", "bin", "b21r-lcm-spy")
    if not os.path.exists(exe):
        exe = os.path.join(build, "bin", "b21r-lcm-spy")
    x = xdisplay.Xvfb(tmp)
    spy = None
    try:
        probe = os.path.join(tmp, "probe.txt")
        env = dict(PLAIN_ENV, DISPLAY=x.display, LCM_DEFAULT_URL="udpm://239.255.76.67:7667?ttl=0",
                   JDK_JAVA_OPTIONS="-javaagent:%s=%s" % (probe_jar, probe))
        with open(os.path.join(tmp, "spy.log"), "w") as log:
            spy = subprocess.Popen([exe], cwd=repo, env=env, stdout=log, stderr=subprocess.STDOUT)
        lc = lcm.LCM("udpm://239.255.76.67:7667?ttl=0")
        deadline = time.time() + 90
        while time.time() < deadline:
            s = status_t()
            s.stop_detail = ""
            lc.publish("B21R_STATUS", s.encode())
            got = xdisplay.channel_table(probe)
            if got is not None and got[0].get("B21R_STATUS", {}).get("Type") == "status_t":
                fwtest.note("%-34s ran under Xvfb: B21R_STATUS decoded as status_t" % SPY_COMMAND.split()[-1])
                return
            if spy.poll() is not None:
                break
            time.sleep(0.3)
        with open(os.path.join(tmp, "spy.log")) as f:
            fwtest.fail("`%s` under Xvfb (exit %s) did not show B21R_STATUS decoded:\n%s" %
                        (SPY_COMMAND, spy.poll(), f.read()[-3000:]))
    finally:
        if spy is not None and spy.poll() is None:
            spy.terminate()
            spy.wait(10)
        x.close()


def run(cmd, repo, timeout=120):
    p = subprocess.run(cmd, cwd=repo, env=PLAIN_ENV, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                       timeout=timeout)
    return p.returncode, p.stdout


def write_session_log(path):
    """A short corridor session as the controller logs it with its default decision_ticks = 2: two
    runs of 20 steps, a pose every step and an experience every decision (at its last step)."""
    log = lcm.EventLog(path, "w", overwrite=True)
    seq = 0
    t = 0
    for run_id in range(2):
        for k in range(20):
            p = pose_t()
            p.run_id, p.step_id, p.x_m = run_id, k + 1, 0.3 * k
            log.write_event(t, "B21R_POSE", p.encode())
            t += 10
            if k % 2 == 0:
                continue
            d = k // 2  # the decision: steps 2d and 2d + 1
            e = experience_t()
            # The controller's learner state: features, then the executed rotation (state_rotation).
            e.seq, e.run_id, e.step_id, e.phase, e.task, e.state_dim = seq, run_id, k, 1, 0, 4
            e.s = [9.0 - 0.6 * d, 0.5, 0.0, 0.01 * (d - 1) if d > 0 else 0.0] + [0.0] * 4
            e.s_next = [8.4 - 0.6 * d, 0.5, 0.0, 0.01 * d] + [0.0] * 4
            e.action_radps = 0.01 * d
            e.terminal = k == 19
            e.reward = 10.0 if k == 19 else 0.0
            log.write_event(t - 5, "B21R_EXPERIENCE", e.encode())
            seq += 1
    log.close()


class Controller:
    """A controller's session as the operator tools see it: B21R_SESSION announced (signed) five
    times a second on LCM's default URL, and the B21R_COMMANDs that arrive with a valid mac."""

    def __init__(self, key):
        self.key = key
        self.lc = lcm.LCM()
        self.nonce = os.urandom(16)
        self.commands = []
        self.lc.subscribe("B21R_COMMAND", self._on_command)
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _on_command(self, channel, data):
        m = command_t.decode(data)
        if bytes(m.session) == self.nonce and bytes(m.mac) == b21r_opauth.mac(self.key, channel, m):
            self.commands.append(m.command)

    def _run(self):
        next_t = 0.0
        while not self.stop:
            if time.monotonic() >= next_t:
                s = session_t()
                s.utime, s.started_us = int(time.time() * 1e6), int(time.time() * 1e6)
                s.key_id, s.nonce = b21r_opauth.key_id(self.key), self.nonce
                self.lc.publish("B21R_SESSION", b21r_opauth.sign(self.key, "B21R_SESSION", s))
                next_t = time.monotonic() + 0.2
            self.lc.handle_timeout(50)


def main():
    repo, build = sys.argv[1:3]
    probe_jar = sys.argv[3] if len(sys.argv) > 3 else ""
    text = readme_text(repo)
    tools = sorted(set(re.findall(r"\btools/[A-Za-z0-9_.-]+\.(?:py|sh)\b", text)))
    programs = sorted(set(p for p in re.findall(r"\bbuild/(<preset>|[A-Za-z0-9_-]+)/bin/([A-Za-z0-9_.-]+)", text)
                          if p[0] != "venv"))
    if not tools or not programs:
        fwtest.fail("no tool commands found in the READMEs")
    check_presets(repo, text)
    check_robot_commands(repo)
    for t in tools:
        path = os.path.join(repo, t)
        if not os.access(path, os.X_OK):
            fwtest.fail("%s is named in a README but is not an executable file" % t)
        if t.endswith(".sh"):
            rc, out = run(["bash", "-n", t], repo)
            if rc != 0:
                fwtest.fail("%s does not parse: %s" % (t, out))
            fwtest.note("%-34s executable, parses (not run)" % t)
            continue
        rc, out = run([t, "--help"], repo)
        if rc != 0 or "usage:" not in out:
            fwtest.fail("`%s --help` from a plain shell: exit %d\n%s" % (t, rc, out))
        fwtest.note("%-34s --help ok" % t)
    for preset, name in programs:
        exe = os.path.join(repo, "build", preset, "bin", name)
        if not os.path.exists(exe):
            exe = os.path.join(build, "bin", name)  # that preset is not built here: this build's
        if not os.path.exists(exe):
            fwtest.fail("build/%s/bin/%s is named in a README but this build does not make it" % (preset, name))
        rc, out = run([exe, "--help"], repo)
        ok = "usage" in out.lower() and (rc == 0 or (name == "b21r-lcm-spy" and rc == 1))  # lcm-spy --help exits 1
        if not ok:
            fwtest.fail("`build/%s/bin/%s --help`: exit %d\n%s" % (preset, name, rc, out[-2000:]))
        fwtest.note("build/%s/bin/%-18s --help ok" % (preset, name))

    tmp = tempfile.mkdtemp(prefix="b21r-readme-")
    controller = None
    try:
        PLAIN_ENV["HOME"] = os.path.join(tmp, "home")
        key = b21r_opauth.create_key(os.path.join(PLAIN_ENV["HOME"], ".config", "b21r", "operator.key"))
        controller = Controller(key)
        log = os.path.join(tmp, "session.lcmlog")
        write_session_log(log)
        shutil.copy(log, os.path.join(tmp, "controller.lcmlog"))  # docs/tools.md's session folder
        with open(os.path.join(tmp, "robot.conf"), "w") as f:
            f.write("# the controller's settings\ntask = corridor\n")
        release = os.path.join(repo, "build", "host-release")
        for shown, subst in REAL:
            if shown not in text:
                fwtest.fail("the README no longer shows `%s`: update this test with it" % shown)
            cmd = shown
            for k, v in subst.items():
                cmd = cmd.replace(k, v.format(log=log, tmp=tmp, build=release if os.path.isdir(release) else build))
            rc, out = run(cmd.split(), repo)
            if rc != 0:
                fwtest.fail("`%s` (as `%s`): exit %d\n%s" % (shown, cmd, rc, out))
            fwtest.note("%-34s ran: %s" % (shown.split()[0], out.strip().splitlines()[-1] if out.strip() else "ok"))
        time.sleep(0.3)
        if command_t.CONFIRM_START_POSE not in controller.commands:
            fwtest.fail("`tools/b21r_teleop.py --command CONFIRM_START_POSE`: no signed command arrived")
        made = os.path.join(tmp, "etc", "b21r", "operator.key")
        if oct(os.stat(made).st_mode & 0o777) != "0o600" or len(b21r_opauth.load_key(made)) != 32:
            fwtest.fail("`tools/b21r_key.py create`: %s is not a key with mode 600" % made)
        fwtest.note("the operator command arrived signed for the session; the new key has mode 600")
        if probe_jar:
            run_spy(repo, build, probe_jar, tmp, text)
        else:
            fwtest.note("no lcm-spy probe (no JDK in this build): lcm-spy checked with --help only")
    finally:
        if controller is not None:
            controller.stop = True
            controller.thread.join(2)
        shutil.rmtree(tmp, ignore_errors=True)
    print("PASS")
    return 0


if __name__ == "__main__":
    sys.exit(main())
