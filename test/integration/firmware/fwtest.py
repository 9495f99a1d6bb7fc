# SPDX-License-Identifier: MIT
"""fwtest: shared helpers of the firmware integration tests (the unmodified b21r-controller
against the b21r-sim emulator in lockstep): start/stop the emulator, talk to its control socket,
run the controller, read its LCM event log. B21R_TARGET_EMULATOR (a command, e.g.
"qemu-aarch64 -L SYSROOT", set by a cross build's CTest) runs both programs under it."""
import os
import shlex
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time

from b21r_log import read_log  # noqa: F401  (re-exported for the tests)

# The cross build's emulator of the target machine (CMAKE_CROSSCOMPILING_EMULATOR), or nothing.
TARGET = shlex.split(os.environ.get("B21R_TARGET_EMULATOR", ""))


def fail(msg):
    print("FAIL: " + msg, flush=True)
    sys.exit(1)


def note(msg):
    print(msg, flush=True)


class Sim:
    """b21r-sim (lockstep unless told otherwise) with a control socket; endpoints read from its
    ready file. prefix: a command that runs it (e.g. chrt)."""

    def __init__(self, exe, world, workdir, name, base="rflex", seed=1, extra=(), lockstep=True, prefix=()):
        self.ctl = os.path.join(workdir, name + ".ctl")
        self.endpoints = os.path.join(workdir, name + ".endpoints")
        self.log = open(os.path.join(workdir, name + ".sim.log"), "w")
        for p in (self.ctl, self.endpoints):
            if os.path.exists(p):
                os.unlink(p)
        self.proc = subprocess.Popen([*prefix, *TARGET, exe, "--world", world, *(["--lockstep"] if lockstep else []), "--base", base,
                                      "--seed", str(seed), "--control", self.ctl, "--endpoints", self.endpoints,
                                      *extra],
                                     stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.time() + 20
        while not (os.path.exists(self.endpoints) and os.path.getsize(self.endpoints) > 0):
            if self.proc.poll() is not None or time.time() > deadline:
                fail("b21r-sim did not start (see %s)" % self.log.name)
            time.sleep(0.05)
        self.sock = None

    def control(self, line, timeout=5.0):
        if self.sock is None:
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
            self.sock.connect(self.ctl)
        self.sock.settimeout(timeout)
        self.sock.send(line.encode())
        reply = self.sock.recv(4096).decode()
        if not reply.startswith("ok"):
            fail("emulator refused '%s': %s" % (line, reply))
        return reply

    def close(self):
        if self.sock is not None:
            self.sock.close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()


def relay_control(listener, target, stop, answer):
    """Relays the controller's emulator-control requests arriving at `listener` (a bound, listening
    SOCK_SEQPACKET socket) to the emulator's control socket `target`, until `stop` is set.
    answer(n, reply) decides the fate of answer n (from 0 on each connection): True passes it back
    (after whatever it waited), False holds it back for good. A frozen emulator's answer is awaited
    up to 10 s."""
    listener.settimeout(0.2)
    while not stop.is_set():
        try:
            conn, _ = listener.accept()
        except socket.timeout:
            continue
        with conn, socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET) as up:
            up.connect(target)
            up.settimeout(10.0)
            conn.settimeout(0.2)
            n = 0
            try:
                while not stop.is_set():
                    try:
                        request = conn.recv(4096)
                    except socket.timeout:
                        continue
                    if not request:
                        break  # the controller closed it: it may connect again
                    up.send(request)
                    reply = up.recv(4096)
                    if answer(n, reply):
                        conn.send(reply)
                    n += 1
            except OSError as e:
                note("relay: %s" % e)
                return


def controller_cmd(exe, sim, workdir, name, settings):
    cmd = [*TARGET, exe, "--endpoints", sim.endpoints, "--set", "lockstep=true", "--set", "lcm_url=none",
           "--set", "progress=true", "--log", os.path.join(workdir, name + ".lcmlog")]
    for k, v in settings.items():
        cmd += ["--set", "%s=%s" % (k, v)]
    return cmd


def run_controller(exe, sim, workdir, name, settings, timeout):
    """Runs the controller to completion; returns (exit status, stderr text, log path)."""
    out = open(os.path.join(workdir, name + ".progress.txt"), "w")
    err_path = os.path.join(workdir, name + ".controller.log")
    with open(err_path, "w") as err:
        p = subprocess.Popen(controller_cmd(exe, sim, workdir, name, settings), stdout=out, stderr=err)
        try:
            rc = p.wait(timeout)
        except subprocess.TimeoutExpired:
            p.send_signal(signal.SIGTERM)
            p.wait(10)
            fail("controller did not finish within %d s (progress: %s)" % (timeout, out.name))
    out.close()
    with open(err_path) as f:
        text = f.read()
    return rc, text, os.path.join(workdir, name + ".lcmlog")


STATUS_LCM = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "lib", "msgs",
                          "status_t.lcm")


def monotonic_fields(path=STATUS_LCM):
    """The fields of status_t that its definition calls monotonic: those of a section whose
    heading comment says so (up to the next comment line or blank line), those whose own comment
    says so, and the maxima "since start"."""
    fields = []
    section = False
    heading = False  # the previous line was a comment: a heading may span lines
    with open(path) as f:
        for raw in f:
            line = raw.strip()
            if not line:
                section = heading = False
                continue
            if line.startswith("//"):
                section = (section and heading) or "monotonic" in line
                heading = True
                continue
            heading = False
            parts = line.split("//", 1)
            decl = parts[0].split()
            if len(decl) != 2 or not decl[1].endswith(";") or decl[0] not in ("int32_t", "int64_t"):
                continue
            comment = parts[1] if len(parts) > 1 else ""
            if section or "(monotonic)" in comment or "since start" in comment:
                fields.append(decl[1][:-1])
    return fields


def check_monotonic(statuses, what):
    """Fails on the first monotonic counter that went back between two B21R_STATUS messages."""
    fields = monotonic_fields()
    if len(fields) < 40:
        fail("only %d monotonic fields found in %s" % (len(fields), STATUS_LCM))
    for i in range(1, len(statuses)):
        for name in fields:
            a, b = getattr(statuses[i - 1], name), getattr(statuses[i], name)
            if b < a:
                fail("%s: B21R_STATUS %s went back from %s to %s (message %d of %d)" %
                            (what, name, a, b, i, len(statuses)))
    return fields


def wait_for(path, text, start, timeout, proc=None):
    """Waits until `text` appears in the file after offset `start`; returns the new offset."""
    return wait_for_any(path, [text], start, timeout, proc)[1]


def wait_for_any(path, texts, start, timeout, proc=None):
    """Waits until one of `texts` appears in the file after offset `start`; returns (the text that
    appears first, the offset after it)."""
    what = "'%s'" % texts[0] if len(texts) == 1 else "one of %s" % texts
    deadline = time.time() + timeout
    while time.time() < deadline:
        with open(path) as f:
            f.seek(start)
            data = f.read()
        found = [(i, t) for i, t in ((data.find(t), t) for t in texts) if i >= 0]
        if found:
            i, t = min(found)
            return t, start + i + len(t)
        if proc is not None and proc.poll() is not None:
            fail("controller exited (%d) while waiting for %s" % (proc.returncode, what))
        time.sleep(0.05)
    fail("%s did not appear in %s within %d s" % (what, path, timeout))
    return None, start


def settled(path, start, proc=None):
    """The offset of the controller's log `path` from which a first injected fault's stop is read:
    its end once no stop is in force after `start`. A stop that came before the fault (a machine too
    busy to pass on the laser's 10 scans a second in time stops the base, as it would on the robot)
    is waited out first, so that it is not read as the fault's answer."""
    while True:
        with open(path) as f:
            f.seek(start)
            data = f.read()
        stop = data.rfind("SAFETY STOP")
        if stop <= data.rfind("safety stop cleared"):  # none, or cleared since
            return start + len(data)
        start = wait_for(path, "safety stop cleared", start + stop, 60, proc)
        time.sleep(1.0)  # a run drives again


def cpu_seconds(pid):
    """User + system CPU time of a process [s] (/proc/<pid>/stat)."""
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stop_all(procs):
    """Kills the processes of a list that still run (a test's clean-up after a failure)."""
    for p in procs:
        if p.poll() is None:
            p.kill()
            p.wait()


def workdir(name):
    base = os.environ.get("B21R_TEST_TMP", tempfile.gettempdir())
    d = tempfile.mkdtemp(prefix="b21r-%s-" % name, dir=base)
    return d


def cleanup(d, ok):
    if ok and os.environ.get("B21R_KEEP") is None:
        shutil.rmtree(d, ignore_errors=True)
    else:
        note("files kept in %s" % d)
