#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_session: one command for an emulated session, like a launch file: the emulator
(b21r-sim), the controller (b21r-controller), lcm-logger, when a display is present, lcm-spy
with the project's types (b21r-lcm-spy), and with --foxglove the live view for Foxglove
(tools/b21r_foxglove_bridge.py: connect Foxglove to ws://127.0.0.1:8765). Ctrl-C (or SIGTERM)
stops them in order: the controller first (it stops the base, sets the brake and saves the
learned state), then the recorder, the viewers and the emulator, each waited for; when a required program ends by itself (the schedule
is done, a crash) the others are stopped the same way.

    b21r_session.py [--out DIR] [--world FILE] [--base rflex|canopen] [--lockstep [--pace X]]
                    [--lcm-url URL] [--key FILE] [--spy | --no-spy] [--foxglove [--foxglove-port N]
                    [--foxglove-host ADDR]] [--config FILE] [--set KEY=VALUE]...
                    [-- CONTROLLER_ARGS...]

Everything goes into DIR (default build/sessions/<time>): session.lcmlog (lcm-logger),
controller.lcmlog (the controller's own --log, which loses nothing), hedger.ckpt (the learned
state; a second session with the same --out resumes from it), the programs' output (sim.log,
controller.log, progress.txt, logger.log, spy.log, foxglove.log) and, with --base canopen, the CAN
trace bus.log (candump -L). The controller's progress lines are shown as they come.
LCM: a host-local URL (udpm with ttl=0: nothing leaves this machine) unless --lcm-url is given;
B21R_TELEOP and B21R_COMMAND from tools/b21r_teleop.py with the same --lcm-url reach the controller,
signed with the operator key: --key FILE, default $B21R_OPERATOR_KEY, else
~/.config/b21r/operator.key (where b21r_teleop.py looks too), created (mode 600) when missing; the
controller gets it as operator_key_file (docs/robot.md, "Network and security").
--lockstep runs emulator and controller in lockstep, paced at --pace times real time (default 20:
minutes instead of hours, and lcm-logger and lcm-spy keep up over UDP, so session.lcmlog holds
every message); --pace 0 runs as fast as the controller goes, where lcm-logger may miss messages
(b21r_log.py --gaps shows how many). The controller's own controller.lcmlog is always complete.
Exit status: the controller's (0: schedule done; 130 after Ctrl-C, the learned state saved), or 1
when a program could not be started.
Runs from a plain shell after tools/setup.sh and a build (b21r_bootstrap finds the venv and the
programs).
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure(need_types=False)

import argparse
import os
import shutil
import signal
import subprocess
import sys
import threading
import time

import b21r_opauth

HOST_LOCAL_URL = "udpm://239.255.76.67:7667?ttl=0"
# lcm-logger's socket receive buffer over udpm [bytes]: about 1.5 s of a 20x lockstep run, so a
# recorder the scheduler leaves out for a moment loses nothing (the kernel caps it at
# net.core.rmem_max).
RECORDER_RECV_BUF = 4 * 1024 * 1024


def recorder_url(url):
    """The URL for lcm-logger: the session's, with a large receive buffer on udpm unless it names one."""
    if not url.startswith("udpm://") or "recv_buf_size=" in url:
        return url
    return url + ("&" if "?" in url else "?") + "recv_buf_size=%d" % RECORDER_RECV_BUF


# The lockstep pace at which lcm-logger over UDP records every message on a 2-core machine
# (tools.session_lossless checks it on a whole session).
DEFAULT_PACE = 20.0
STOP_TIMEOUT_S = 20.0  # the controller writes its checkpoint before it exits


class Child:
    """One program of the session, in its own process group (a Ctrl-C in the terminal reaches
    only the launcher, which stops the programs in order)."""

    def __init__(self, name, cmd, out_path, required=True, stop_signal=signal.SIGINT, echo=False, stdout_path=None):
        self.name = name
        self.required = required
        self.stop_signal = stop_signal
        self.log = open(out_path, "w")
        self.echo_thread = None
        if echo:
            self.out = open(stdout_path, "w")
            self.proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=self.log, text=True,
                                         start_new_session=True)
            self.echo_thread = threading.Thread(target=self._echo, daemon=True)
            self.echo_thread.start()
        else:
            self.out = None
            self.proc = subprocess.Popen(cmd, stdout=self.log, stderr=subprocess.STDOUT, start_new_session=True)
        say("started %-10s pid %d: %s" % (name, self.proc.pid, " ".join(cmd)))

    def _echo(self):
        for line in self.proc.stdout:
            self.out.write(line)
            self.out.flush()
            sys.stdout.write("  " + line)
            sys.stdout.flush()

    def running(self):
        return self.proc.poll() is None

    def stop(self):
        """Asks the program to stop, waits, kills it after STOP_TIMEOUT_S. Returns its exit status."""
        if self.running():
            try:
                self.proc.send_signal(self.stop_signal)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                say("%s did not stop within %.0f s: killing it" % (self.name, STOP_TIMEOUT_S))
                self.proc.kill()
                self.proc.wait()
        if self.echo_thread is not None:
            self.echo_thread.join(5)
        for f in (self.log, self.out):
            if f is not None:
                f.close()
        rc = self.proc.returncode
        say("stopped %-10s pid %d: %s" % (self.name, self.proc.pid, describe_status(rc)))
        return rc


def describe_status(rc):
    if rc is None:
        return "still running"
    if rc < 0:
        return "ended by signal %d" % -rc
    if rc > 128:
        return "exit status %d (after signal %d)" % (rc, rc - 128)
    return "exit status %d" % rc


def say(msg):
    print("b21r-session: " + msg, flush=True)


def find(name):
    p = b21r_bootstrap.find_program(name)
    if p is None:
        sys.exit("b21r-session: %s is not built; build it with: %s" % (name, b21r_bootstrap.BUILD_HINT))
    return str(p)


def wait_for_file(path, child, timeout):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if os.path.exists(path) and os.path.getsize(path) > 0:
            return True
        if not child.running():
            return False
        time.sleep(0.05)
    return False


class Signals:
    def __init__(self):
        self.received = None
        for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            signal.signal(s, self)

    def __call__(self, signum, frame):
        self.received = signum


def main():
    repo = b21r_bootstrap.REPO
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", help="session folder (default build/sessions/<time>)")
    ap.add_argument("--world", default=str(repo / "sim" / "worlds" / "corridor10.world"))
    ap.add_argument("--base", choices=("rflex", "canopen"), default="rflex")
    ap.add_argument("--lockstep", action="store_true", help="emulator and controller in lockstep (fast)")
    ap.add_argument("--pace", type=float, default=DEFAULT_PACE, metavar="X",
                    help="with --lockstep: at most X times real time (0: as fast as possible; default %(default)g)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--lcm-url", default=HOST_LOCAL_URL, help="LCM provider (default: %(default)s)")
    ap.add_argument("--key", metavar="FILE", help="operator key (default: $B21R_OPERATOR_KEY, else "
                    "~/.config/b21r/operator.key; created when missing)")
    spy = ap.add_mutually_exclusive_group()
    spy.add_argument("--spy", dest="spy", action="store_true", default=None, help="start b21r-lcm-spy")
    spy.add_argument("--no-spy", dest="spy", action="store_false", help="do not start b21r-lcm-spy")
    ap.add_argument("--foxglove", action="store_true",
                    help="start the Foxglove bridge (tools/b21r_foxglove_bridge.py): the session live in Foxglove")
    ap.add_argument("--foxglove-port", type=int, default=8765, metavar="N", help="its WebSocket port (default %(default)s)")
    ap.add_argument("--foxglove-host", default="127.0.0.1", metavar="ADDR",
                    help="its address (default %(default)s: this machine only)")
    ap.add_argument("--config", action="append", default=[], help="controller config file (repeatable)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="controller setting (repeatable)")
    ap.add_argument("controller_args", nargs="*", help="more b21r-controller arguments (after --)")
    args = ap.parse_args()
    if args.pace < 0:
        ap.error("--pace must be 0 (as fast as possible) or a positive factor of real time")

    key_path = args.key or os.environ.get("B21R_OPERATOR_KEY") or b21r_opauth.user_key_path()
    try:
        if not os.path.exists(key_path):
            key = b21r_opauth.create_key(key_path)
            say("created the operator key %s (mode 600, key id %s): b21r_teleop.py signs with it"
                % (key_path, b21r_opauth.key_id(key).hex()))
        b21r_opauth.load_key(key_path)
    except (b21r_opauth.KeyFileError, OSError) as exc:
        sys.exit("b21r-session: %s" % exc)
    out = args.out or str(repo / "build" / "sessions" / time.strftime("%Y%m%d-%H%M%S"))
    os.makedirs(out, exist_ok=True)
    out = os.path.abspath(out)
    sim_exe, controller_exe = find("b21r-sim"), find("b21r-controller")
    logger_exe = shutil.which("lcm-logger")
    if logger_exe is None:
        sys.exit("b21r-session: lcm-logger is not installed (Debian package liblcm-bin); run tools/setup.sh")
    want_spy = args.spy if args.spy is not None else bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    spy_exe = b21r_bootstrap.find_program("b21r-lcm-spy") if want_spy else None
    if want_spy and spy_exe is None:
        say("b21r-lcm-spy is not built (needs a JDK): no viewer")

    sig = Signals()
    children = []  # in start order; stopped in reverse order except the controller, which goes first
    controller = None
    status = 1
    try:
        ctl = os.path.join(out, "sim.ctl")
        endpoints = os.path.join(out, "sim.endpoints")
        for p in (ctl, endpoints):
            if os.path.exists(p):
                os.unlink(p)
        sim_cmd = [sim_exe, "--world", args.world, "--base", args.base, "--seed", str(args.seed), "--control", ctl,
                   "--endpoints", endpoints, "--trace-svg", os.path.join(out, "trajectories.svg")]
        if args.lockstep:
            sim_cmd.append("--lockstep")
        if args.base == "canopen":
            sim_cmd += ["--can-log", os.path.join(out, "bus.log")]
        sim = Child("emulator", sim_cmd, os.path.join(out, "sim.log"), stop_signal=signal.SIGTERM)
        children.append(sim)
        if not wait_for_file(endpoints, sim, 20.0):
            say("the emulator did not start (see %s)" % os.path.join(out, "sim.log"))
            return 1
        children.append(Child("lcm-logger", [logger_exe, "--lcm-url=" + recorder_url(args.lcm_url), "--force",
                                             os.path.join(out, "session.lcmlog")],
                              os.path.join(out, "logger.log")))
        if spy_exe is not None:
            children.append(Child("lcm-spy", [str(spy_exe), "--lcm-url=" + args.lcm_url], os.path.join(out, "spy.log"),
                                  required=False, stop_signal=signal.SIGTERM))
        if args.foxglove:
            children.append(Child("foxglove", [sys.executable, str(repo / "tools" / "b21r_foxglove_bridge.py"),
                                               "--lcm-url", args.lcm_url, "--port", str(args.foxglove_port),
                                               "--host", args.foxglove_host], os.path.join(out, "foxglove.log"),
                                  required=False, stop_signal=signal.SIGTERM))
            say("Foxglove: open a connection to ws://%s:%d (layout: tools/foxglove/b21r-layout.json)" %
                (args.foxglove_host, args.foxglove_port))
        time.sleep(0.3)  # the recorder subscribes before the first message
        ccmd = [controller_exe]
        for c in args.config:
            ccmd += ["--config", c]
        ccmd += ["--endpoints", endpoints, "--set", "lcm_url=" + args.lcm_url, "--set", "progress=true",
                 "--set", "operator_key_file=" + os.path.abspath(key_path),
                 "--set", "lockstep=%s" % ("true" if args.lockstep else "false"),
                 *(["--set", "lockstep_realtime_factor=%g" % args.pace] if args.lockstep else []),
                 "--checkpoint", os.path.join(out, "hedger.ckpt"), "--log", os.path.join(out, "controller.lcmlog")]
        for s in args.set:
            ccmd += ["--set", s]
        ccmd += args.controller_args
        controller = Child("controller", ccmd, os.path.join(out, "controller.log"), echo=True,
                           stdout_path=os.path.join(out, "progress.txt"))
        children.append(controller)
        say("running; Ctrl-C stops everything (output in %s)" % out)
        ended = None
        while sig.received is None and ended is None:
            time.sleep(0.1)
            ended = next((c for c in children if c.required and not c.running()), None)
        if sig.received is not None:
            say("signal %d: stopping the controller first, then the others" % sig.received)
        else:
            say("%s ended (%s): stopping the others" % (ended.name, describe_status(ended.proc.returncode)))
    finally:
        # The controller first: it stops and brakes the base and saves the learned state while the
        # emulator still answers; then the rest in reverse start order.
        order = ([controller] if controller is not None else []) + [c for c in reversed(children) if c is not controller]
        results = {c.name: c.stop() for c in order}
        if controller is not None:
            status = results["controller"]
    ok = os.path.exists(os.path.join(out, "controller.lcmlog"))
    say("files: %s" % out)
    for name in ("progress.txt", "controller.lcmlog", "session.lcmlog", "hedger.ckpt", "trajectories.svg", "bus.log"):
        p = os.path.join(out, name)
        if os.path.exists(p):
            say("  %-18s %8d bytes" % (name, os.path.getsize(p)))
    if ok:
        say("check the recording: tools/b21r_log.py %s --gaps --runs" % os.path.join(out, "session.lcmlog"))
    return status if status is not None and status >= 0 else 1


if __name__ == "__main__":
    sys.exit(main())
