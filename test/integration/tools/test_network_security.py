#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.network_security: an intruder on the robot's network tries to command it.

Two network namespaces made here (`ip netns add`) joined by a veth pair: "robot" runs b21r-sim (real
time) and b21r-controller (phase_one_driver = joystick, an operator key) and this script's observer;
"lan" is another machine on the robot's network, with the intruder (the product's own generated
types and raw UDP) and, in phase B, a remote operator. Multicast is routed to the veth in both
namespaces: the worst case, where the robot joins the LCM group on its network interface.

Phase A, the defaults (lcm_url and lcm_scope unset: this host only): the intruder sends forged
B21R_TELEOP (deadman held, 0.8 rad/s, seq 2^63 - 1), the old unauthenticated types (TELEOP, PAUSE,
RESUME, START_PHASE_TWO, SHUTDOWN) by multicast, and SHUTDOWN and TELEOP by unicast UDP to the
robot's address and port 7667. A plain LCM program on the robot receives the multicast ones (they do
reach the host); the controller sees none of them (every refusal counter stays 0), nothing acts (no
run starts, the robot stands still, no command is taken), and nothing of the robot's reaches the
lan. The local operator then drives (signed) and shuts the controller down.

Phase B, lcm_scope = network (ttl=1): a remote operator in "lan" drives with the key. The intruder,
who has seen all of it, sends messages that are malformed, of the old unauthenticated types, signed
with another key, forged with the current session and key id (wrong mac; seq 2^63 - 1; PAUSE,
RESUME, START_PHASE_TWO, SHUTDOWN, one SHUTDOWN by unicast), replays phase A's recorded operator
messages (another session), and replays the remote operator's own messages of this session (the
newest ones: already taken; the oldest: below the window). Every one is refused and counted by
reason on B21R_STATUS, exactly; nothing acts; then the operator still drives (no lockout), and its
PAUSE, RESUME and SHUTDOWN (tools/b21r_teleop.py --command) are obeyed.

Needs root (ip netns); exits 77 (skipped) without it.
usage: test_network_security.py CONTROLLER SIM WORLD TELEOP_TOOL"""
import json
import os
import random
import secrets
import socket
import struct
import subprocess
import sys
import threading
import time

ROBOT_IP = "10.246.0.1"
LAN_IP = "10.246.0.2"
GROUP, PORT = "239.255.76.67", 7667
URL_HOST = "udpm://%s:%d?ttl=0" % (GROUP, PORT)
URL_LAN = "udpm://%s:%d?ttl=1" % (GROUP, PORT)
LCM_SHORT_MAGIC = 0x4C433032  # "LC02": one LCM message in one datagram
SPIN = 0.5  # the operator's rotation [rad/s]
COUNTERS = ("malformed", "unauthenticated", "key", "mac", "session", "replay", "old")


def note(msg):
    print(msg, flush=True)


def fail(msg):
    print("FAIL: " + msg, flush=True)
    sys.exit(1)


# ---- outside: the namespaces -----------------------------------------------------------------

def sh(*cmd):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


def outer(argv):
    if os.geteuid() != 0:
        print("tools.network_security: needs root for ip netns (skipped)", flush=True)
        return 77
    tag = "%d" % (os.getpid() % 100000)
    robot, lan = "b21r-robot-" + tag, "b21r-lan-" + tag
    vr, vl = "vr" + tag, "vl" + tag
    try:
        sh("ip", "netns", "add", robot)
        sh("ip", "netns", "add", lan)
        sh("ip", "link", "add", vr, "type", "veth", "peer", "name", vl)
        sh("ip", "link", "set", vr, "netns", robot)
        sh("ip", "link", "set", vl, "netns", lan)
        for ns, dev, ip in ((robot, vr, ROBOT_IP), (lan, vl, LAN_IP)):
            sh("ip", "-n", ns, "link", "set", "lo", "up")
            sh("ip", "-n", ns, "addr", "add", ip + "/24", "dev", dev)
            sh("ip", "-n", ns, "link", "set", dev, "up")
            sh("ip", "-n", ns, "route", "add", "224.0.0.0/4", "dev", dev)
    except (subprocess.CalledProcessError, FileNotFoundError) as exc:
        for ns in (robot, lan):
            subprocess.run(["ip", "netns", "del", ns], stderr=subprocess.DEVNULL)
        err = exc.stderr.decode().strip() if getattr(exc, "stderr", None) else str(exc)
        print("tools.network_security: cannot make the namespaces (%s): skipped" % err, flush=True)
        return 77
    try:
        env = {k: v for k, v in os.environ.items() if k != "LCM_DEFAULT_URL"}
        return subprocess.run(["ip", "netns", "exec", robot, sys.executable, os.path.abspath(__file__), "robot", lan,
                               *argv], env=env).returncode
    finally:
        for ns in (robot, lan):
            subprocess.run(["ip", "netns", "del", ns], stderr=subprocess.DEVNULL)


# ---- in "lan": the intruder and the remote operator --------------------------------------------

def lcm_datagram(channel, payload):
    return struct.pack(">II", LCM_SHORT_MAGIC, random.getrandbits(32)) + channel.encode() + b"\0" + payload


class Sniffer:
    """Everything the lan hears from the robot's side, kept in arrival order."""

    def __init__(self, url):
        import lcm
        self.lc = lcm.LCM(url)
        self.lock = threading.Lock()
        self.heard = []  # (channel, bytes)
        self.lc.subscribe(".*", self._on)
        self.stop = False
        threading.Thread(target=self._run, daemon=True).start()

    def _on(self, channel, data):
        with self.lock:
            self.heard.append((channel, bytes(data)))

    def _run(self):
        while not self.stop:
            self.lc.handle_timeout(50)

    def of(self, channel):
        with self.lock:
            return [d for c, d in self.heard if c == channel]


def intruder(phase, url, old_log):
    """Waits for "attack" on stdin (sniffing meanwhile), attacks, prints what it sent (JSON)."""
    import lcm
    from b21r import command_t, command_v1_t, session_t, teleop_t, teleop_v1_t
    import b21r_opauth as oa
    sniff = Sniffer(url)
    pub = lcm.LCM(url)
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sys.stdin.readline()
    sent = {k: 0 for k in COUNTERS}
    sent["reached_us"] = len(sniff.heard)
    operator_msgs = sniff.of("B21R_TELEOP")  # before the intruder's own loop back into the sniffer

    def mcast(channel, data, kind):
        pub.publish(channel, data)
        sent[kind] += 1
        time.sleep(0.004)

    def unicast(channel, data, kind):
        udp.sendto(lcm_datagram(channel, data), (ROBOT_IP, PORT))
        sent[kind] += 1
        time.sleep(0.004)

    def v1_teleop():
        m = teleop_v1_t()
        m.utime, m.seq, m.deadman, m.rotation_radps = int(time.time() * 1e6), 2 ** 63 - 1, True, 0.8
        return m.encode()

    def v1_command(c):
        m = command_v1_t()
        m.utime, m.seq, m.command = int(time.time() * 1e6), 2 ** 63 - 2, c
        return m.encode()

    sessions = [session_t.decode(d) for d in sniff.of("B21R_SESSION")]
    key_id = bytes(sessions[-1].key_id) if sessions else secrets.token_bytes(8)
    nonce = bytes(sessions[-1].nonce) if sessions else secrets.token_bytes(16)

    def forged(t):  # the current session and key id, a mac made up
        t.key_id, t.session, t.mac = key_id, nonce, secrets.token_bytes(32)
        return t.encode()

    stops = (command_t.PAUSE, command_t.RESUME, command_t.START_PHASE_TWO, command_t.SHUTDOWN)
    for _ in range(20):
        t = teleop_t()
        t.utime, t.seq, t.deadman, t.rotation_radps = int(time.time() * 1e6), 2 ** 63 - 1, True, 0.8
        mcast("B21R_TELEOP", forged(t), "mac")
        mcast("B21R_TELEOP", v1_teleop(), "unauthenticated")
    for c in stops:
        m = command_t()
        m.utime, m.seq, m.command = int(time.time() * 1e6), 2 ** 63 - 1, c
        mcast("B21R_COMMAND", forged(m), "mac")
        mcast("B21R_COMMAND", v1_command(c), "unauthenticated")
    m = command_t()
    m.utime, m.seq, m.command = int(time.time() * 1e6), 2 ** 63 - 1, command_t.SHUTDOWN
    unicast("B21R_COMMAND", forged(m), "mac")
    unicast("B21R_COMMAND", v1_command(command_t.SHUTDOWN), "unauthenticated")
    for _ in range(5):
        unicast("B21R_TELEOP", v1_teleop(), "unauthenticated")
    if phase == "B":
        own = secrets.token_bytes(32)  # a key of the intruder's own
        for i in range(10):
            t = teleop_t()
            t.seq, t.deadman, t.rotation_radps, t.key_id, t.session = i + 1, True, 0.8, oa.key_id(own), nonce
            mcast("B21R_TELEOP", oa.sign(own, "B21R_TELEOP", t), "key")
        for _ in range(5):
            mcast("B21R_TELEOP", secrets.token_bytes(random.randint(1, 200)), "malformed")
            mcast("B21R_COMMAND", secrets.token_bytes(random.randint(1, 200)), "malformed")
            t = teleop_t()
            t.key_id, t.session, t.mac = key_id, nonce, bytes(32)
            mcast("B21R_TELEOP", t.encode()[:-7], "malformed")
        # Phase A's operator messages, recorded in the controller's own log: another session.
        ev = lcm.EventLog(old_log, "r")
        for e in ev:
            if e.channel in ("B21R_TELEOP", "B21R_COMMAND"):
                mcast(e.channel, bytes(e.data), "session")
        ev.close()
        # The remote operator's messages of this session, as heard: the newest 10 were taken a
        # moment ago (replays), the oldest 10 are more than 63 below the newest (old).
        heard = operator_msgs
        if len(heard) < 64 + 20:
            print(json.dumps({"error": "heard only %d operator messages" % len(heard)}), flush=True)
            return 1
        for d in heard[-10:]:
            mcast("B21R_TELEOP", d, "replay")
        for d in heard[:10]:
            mcast("B21R_TELEOP", d, "old")
        sent["heard_operator"] = len(heard)
    sent["heard_sessions"] = len(sessions)
    print(json.dumps(sent), flush=True)
    return 0


def operator(url, key_path, drive_s, rotation):
    """Drives with the deadman held for drive_s at rotation [rad/s] (signed), then releases."""
    import lcm
    from b21r import teleop_t
    import b21r_opauth as oa
    lc = lcm.LCM(url)
    key = oa.load_key(key_path)
    sessions = oa.SessionTracker(lc, key)
    signer = oa.Signer(lc, key, sessions)
    deadline = time.monotonic() + 15
    while sessions.current() is None:
        if time.monotonic() > deadline:
            print(json.dumps({"error": sessions.describe()}), flush=True)
            return 1
        lc.handle_timeout(50)
    sent = 0
    end = time.monotonic() + drive_s
    while True:
        now = time.monotonic()
        t = teleop_t()
        t.utime = int(time.time() * 1e6)
        t.deadman = now < end
        t.rotation_radps = rotation if t.deadman else 0.0
        sent += signer.publish("B21R_TELEOP", t)
        if not t.deadman:
            break
        lc.handle_timeout(0)
        time.sleep(0.05)
    print(json.dumps({"sent": sent}), flush=True)
    return 0


# ---- in "robot": the controller, the emulator and the observer ----------------------------------

class Observer:
    """STATUS and POSE from the controller, and any TELEOP / COMMAND a plain LCM program here hears."""

    def __init__(self):
        import lcm
        from b21r import pose_t, status_t
        self.lc = lcm.LCM()  # LCM's default URL, as lcm-spy and the tools on the robot
        self.lock = threading.Lock()
        self.status, self.pose, self.operator_heard = [], [], 0
        self.lc.subscribe("B21R_STATUS", lambda c, d: self._add(self.status, status_t.decode(d)))
        self.lc.subscribe("B21R_POSE", lambda c, d: self._add(self.pose, pose_t.decode(d)))
        self.lc.subscribe("B21R_TELEOP|B21R_COMMAND", self._heard)
        self.stop = False
        threading.Thread(target=self._run, daemon=True).start()

    def _add(self, dst, m):
        with self.lock:
            dst.append((time.monotonic(), m))

    def _heard(self, channel, data):
        with self.lock:
            self.operator_heard += 1

    def _run(self):
        while not self.stop:
            self.lc.handle_timeout(50)

    def since(self, what, t0):
        with self.lock:
            return [(t, m) for t, m in getattr(self, what) if t >= t0]

    def last(self):
        with self.lock:
            return self.status[-1][1] if self.status else None

    def wait(self, pred, timeout, why, what="status", t0=None):
        t0 = time.monotonic() if t0 is None else t0
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            hits = [m for _, m in self.since(what, t0) if pred(m)]
            if hits:
                return hits[0]
            time.sleep(0.02)
        s = self.last()
        fail("%s within %.0f s (last STATUS: %s)" % (why, timeout, describe(s) if s else "none"))


def refused(s):
    return {k: getattr(s, "operator_refused_" + k) for k in COUNTERS}


def describe(s):
    return "mode %d phase %d run %d stop %d (%s), commands taken %d, teleop taken %d, refused %s" % (
        s.mode, s.phase, s.run_id, s.stop_reason, s.stop_detail, s.commands_accepted, s.teleop_accepted, refused(s))


class Robot:
    def __init__(self, args, d, key, name, extra):
        import fwtest
        from b21r import status_t
        self.status_t = status_t
        self.sim = fwtest.Sim(args.sim, args.world, d, "sim-" + name, seed=3, lockstep=False)
        self.log = os.path.join(d, name + ".lcmlog")
        self.err_path = os.path.join(d, name + ".controller.log")
        self.err = open(self.err_path, "w")
        self.proc = subprocess.Popen(
            [args.controller, "--endpoints", self.sim.endpoints, "--set", "phase_one_driver=joystick",
             "--set", "operator_key_file=" + key, "--set", "teleop_timeout_s=0.3", "--set", "phase_one_runs=50",
             "--set", "safety_clear_ticks=5", "--set", "learn_updates_per_tick=200", "--log", self.log, *extra],
            stdout=self.err, stderr=subprocess.STDOUT)

    def alive(self):
        return self.proc.poll() is None

    def close(self):
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.err.close()
        self.sim.close()


def in_lan(lan, *args, stdin=None):
    return subprocess.Popen(["ip", "netns", "exec", lan, sys.executable, os.path.abspath(__file__), *args],
                            stdin=stdin, stdout=subprocess.PIPE, text=True)


def result(proc, what, timeout=60):
    out, _ = proc.communicate(timeout=timeout)
    lines = [l for l in out.splitlines() if l.startswith("{")]
    if proc.returncode != 0 or not lines:
        fail("%s: exit %s, output %r" % (what, proc.returncode, out))
    r = json.loads(lines[-1])
    if "error" in r:
        fail("%s: %s" % (what, r["error"]))
    return r


def check_nothing_acted(obs, robot, t0, before, what):
    """Since t0: no run started, the robot stood still, no command or teleop was taken, and the
    controller still runs in phase one."""
    s = obs.last()
    moving = [p for _, p in obs.since("pose", t0) if abs(p.rotation_radps) > 0.02]
    running = [m for _, m in obs.since("status", t0) if m.mode in (obs_status().MODE_RUNNING, obs_status().MODE_PAUSED)]
    if not robot.alive():
        fail("%s: the controller exited (%s)" % (what, robot.proc.returncode))
    if moving or running:
        fail("%s: the robot moved (%d poses turning, %d STATUS running or paused)" % (what, len(moving), len(running)))
    if (s.commands_accepted, s.teleop_accepted, s.phase) != (before.commands_accepted, before.teleop_accepted, 1):
        fail("%s: something was taken: before %s, now %s" % (what, describe(before), describe(s)))


def obs_status():
    from b21r import status_t
    return status_t


def start_operator(lan_or_none, url, key, drive_s):
    cmd = ("operator", url, key, str(drive_s), str(SPIN))
    if lan_or_none:
        return in_lan(lan_or_none, *cmd)
    return subprocess.Popen([sys.executable, os.path.abspath(__file__), *cmd], stdout=subprocess.PIPE, text=True)


def turning(obs, t0, what):
    obs.wait(lambda m: abs(m.rotation_radps - SPIN) < 0.06, 15, what + ": the robot did not turn at %.2f rad/s" % SPIN,
             what="pose", t0=t0)


def drive(obs, lan_or_none, url, key, what):
    """The operator drives for 4.5 s: the robot turns at SPIN. Returns the messages sent."""
    t0 = time.monotonic()
    p = start_operator(lan_or_none, url, key, 4.5)
    turning(obs, t0, what)
    sent = result(p, what)["sent"]
    obs.wait(lambda m: m.mode == obs_status().MODE_STOPPED and m.stop_reason == obs_status().STOP_DEADMAN, 5,
             what + ": no deadman stop after the release", t0=time.monotonic())
    note("%s: the robot turned at %.2f rad/s while %d signed TELEOP came, and stopped at the release" %
         (what, SPIN, sent))
    return sent


def command(obs, args, lan_or_none, url, key, name, pred, why):
    cmd = [sys.executable, args.teleop_tool, "--lcm-url", url, "--key", key, "--command", name]
    if lan_or_none:
        cmd = ["ip", "netns", "exec", lan_or_none, *cmd]
    t0 = time.monotonic()
    p = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    if p.returncode != 0:
        fail("b21r_teleop.py --command %s: exit %d: %s" % (name, p.returncode, p.stderr))
    if pred is not None:
        obs.wait(pred, 10, why, t0=t0)


def attack(obs, robot, lan, phase, url, old_log, expected_nonzero, intruder_proc=None):
    proc = intruder_proc or in_lan(lan, "intruder", phase, url, old_log, stdin=subprocess.PIPE)
    time.sleep(1.0 if intruder_proc is None else 0.0)  # the intruder listens for a moment (phase A: nothing)
    # The robot stands still before the attack (after a drive it slows down within 0.2 s).
    obs.wait(lambda p: abs(p.rotation_radps) < 0.02, 5, "the robot still turns before the attack", what="pose")
    time.sleep(0.3)
    before = obs.last()
    t0 = time.monotonic()
    proc.stdin.write("attack\n")
    proc.stdin.flush()
    sent = result(proc, "intruder")
    want = {k: before_k + (sent[k] if expected_nonzero else 0)
            for k, before_k in refused(before).items()}
    deadline = time.monotonic() + 8
    while refused(obs.last()) != want and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(0.5)  # and nothing more comes
    now = refused(obs.last())
    if now != want:
        fail("phase %s: refusal counters %s, expected %s (sent %s)" % (phase, now, want, sent))
    check_nothing_acted(obs, robot, t0, before, "phase %s" % phase)
    return sent


def robot_side(lan, controller, sim, world, teleop_tool):
    import fwtest
    import b21r_opauth as oa

    class Args:
        pass
    args = Args()
    args.controller, args.sim, args.world, args.teleop_tool = controller, sim, world, teleop_tool
    d = fwtest.workdir("netsec")
    key = os.path.join(d, "operator.key")
    oa.create_key(key)
    obs = Observer()
    ok = False
    robot = None
    status_t = obs_status()
    try:
        # ---- Phase A: the defaults.
        robot = Robot(args, d, key, "A", [])
        obs.wait(lambda m: True, 30, "no B21R_STATUS from the controller")
        time.sleep(1.0)
        heard_before = obs.operator_heard
        sent = attack(obs, robot, lan, "A", URL_LAN, "-", expected_nonzero=False)
        heard = obs.operator_heard - heard_before
        multicast = sum(v for k, v in sent.items() if k in COUNTERS) - 7  # 7 went by unicast
        note("phase A (this host only): the intruder sent %d operator messages (%d by unicast to %s:%d); a plain "
             "LCM program on the robot heard %d of them, the controller none: every refusal counter 0, nothing taken, "
             "the robot still; the lan heard %d messages of the robot's" %
             (multicast + 7, 7, ROBOT_IP, PORT, heard, sent["reached_us"]))
        if heard < multicast:
            fail("phase A: the intruder's multicast did not reach the robot host (%d of %d): the test shows nothing"
                 % (heard, multicast))
        if sent["reached_us"] != 0 or sent["heard_sessions"] != 0:
            fail("phase A: %d messages of the robot reached the lan" % sent["reached_us"])
        drive(obs, None, URL_HOST, key, "phase A, the local operator")
        command(obs, args, None, URL_HOST, key, "SHUTDOWN", None, "")
        rc = robot.proc.wait(30)
        if rc != 0:
            fail("phase A: the controller's exit status after the operator's SHUTDOWN: %d" % rc)
        robot.close()
        old_log = robot.log

        # ---- Phase B: other hosts may reach the robot.
        robot = Robot(args, d, key, "B", ["--set", "lcm_scope=network", "--set", "lcm_url=" + URL_LAN])
        obs.wait(lambda m: True, 30, "no B21R_STATUS from the second controller", t0=time.monotonic())
        intruder_proc = in_lan(lan, "intruder", "B", URL_LAN, old_log, stdin=subprocess.PIPE)
        time.sleep(1.0)
        before = obs.last()
        n = drive(obs, lan, URL_LAN, key, "phase B, the remote operator")
        # Every one of them passed the authentication (the loop may still drop one that waited too
        # long for its tick: stale), so the intruder's copies below are of taken messages.
        after = obs.last()
        reached = (after.teleop_accepted + after.teleop_rejected) - (before.teleop_accepted + before.teleop_rejected)
        if reached != n or refused(after) != refused(before):
            fail("phase B: %d of the operator's %d messages reached the loop, refusals %s -> %s" %
                 (reached, n, refused(before), refused(after)))
        sent = attack(obs, robot, lan, "B", URL_LAN, old_log, expected_nonzero=True, intruder_proc=intruder_proc)
        note("phase B (lcm_scope = network): every message of the intruder refused and counted: %s; nothing acted" %
             {k: sent[k] for k in COUNTERS})
        # The operator keeps control: it drives (the forged seq of 2^63 - 1 locked nothing), its
        # PAUSE stops the robot while the deadman is held, its RESUME lets it drive again.
        t0 = time.monotonic()
        op = start_operator(lan, URL_LAN, key, 14.0)
        turning(obs, t0, "phase B, the remote operator after the attack")
        command(obs, args, lan, URL_LAN, key, "PAUSE", lambda m: m.mode == status_t.MODE_PAUSED,
                "the remote operator's PAUSE was not obeyed")
        t_paused = time.monotonic()
        obs.wait(lambda p: abs(p.rotation_radps) < 0.02, 5, "the robot kept turning after PAUSE", what="pose",
                 t0=t_paused)
        time.sleep(1.0)
        if obs.last().mode != status_t.MODE_PAUSED:
            fail("the pause did not hold while the deadman was held: %s" % describe(obs.last()))
        t0 = time.monotonic()
        command(obs, args, lan, URL_LAN, key, "RESUME", None, "")
        turning(obs, t0, "phase B, after RESUME")
        result(op, "the remote operator")
        command(obs, args, lan, URL_LAN, key, "SHUTDOWN", None, "")
        rc = robot.proc.wait(30)
        if rc != 0:
            fail("phase B: exit status %d after the operator's SHUTDOWN" % rc)
        note("phase B: the remote operator drives again; its PAUSE stopped the robot with the deadman held, its "
             "RESUME let it drive, its SHUTDOWN ended the controller (exit 0)")
        ok = True
    finally:
        obs.stop = True
        if robot is not None:
            robot.close()
        fwtest.cleanup(d, ok)
    print("PASS", flush=True)
    return 0


def main():
    role = sys.argv[1] if len(sys.argv) > 1 else ""
    if role == "robot":
        return robot_side(*sys.argv[2:7])
    if role == "intruder":
        return intruder(*sys.argv[2:5])
    if role == "operator":
        return operator(sys.argv[2], sys.argv[3], float(sys.argv[4]), float(sys.argv[5]))
    return outer(sys.argv[1:5])


if __name__ == "__main__":
    sys.exit(main())
