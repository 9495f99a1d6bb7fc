#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.opauth: tools/b21r_opauth.py and tools/b21r_key.py, the operator's side of the
authenticated messages. The macs match the controller's on shared test vectors (the same values
as firmware.opauth's test_opauth_vectors_match_python); key files are created with mode 600 and
refused, naming the fix, when others may read them or their content is wrong; the session tracker
takes only announcements signed with its key, keeps the newest start, ignores a replayed older one
while the current session is announced and moves on after its silence; seq rises per channel and
across tools."""
import os
import stat
import subprocess
import sys
import tempfile
import unittest

from b21r import command_t, session_t, teleop_t

import b21r_opauth as oa

KEY = bytes(range(32))
NONCE = bytes(range(100, 116))
TOOLS = os.path.join(os.path.dirname(os.path.abspath(oa.__file__)))


class Vectors(unittest.TestCase):
    def test_same_macs_as_the_controller(self):
        self.assertEqual(oa.key_id(KEY).hex(), "630dcd2966c43366")
        t = teleop_t()
        t.utime, t.seq, t.deadman, t.rotation_radps, t.translation_mps = 1700000000000000, 42, True, 0.5, -0.25
        t.key_id, t.session = oa.key_id(KEY), NONCE
        self.assertEqual(oa.mac(KEY, "B21R_TELEOP", t).hex(),
                         "86348780984268ef02ddbf51d1d9e41167205a69eb8e40d42344803e4974beaf")
        c = command_t()
        c.utime, c.seq, c.command, c.argument = 1700000000000001, 43, command_t.PAUSE, 7
        c.key_id, c.session = oa.key_id(KEY), NONCE
        self.assertEqual(oa.mac(KEY, "B21R_COMMAND", c).hex(),
                         "dc95dee438ec21afe2a547d2d6de4ad3dffc6660b3fa2a1e27aa541f58c83d66")
        s = session(started_us=1700000000000002, utime=5)
        self.assertEqual(bytes(s.mac).hex(), "c5b4a2ad23d3849357b595a18137fafadaa99139fb100be9bf9915154aba8a49")
        self.assertTrue(oa.session_valid(KEY, s))

    def test_a_mac_binds_channel_and_every_field(self):
        t = teleop_t()
        t.key_id, t.session, t.seq = oa.key_id(KEY), NONCE, 1
        base = oa.mac(KEY, "B21R_TELEOP", t)
        self.assertNotEqual(base, oa.mac(KEY, "B21R_COMMAND", t))
        for field, value in (("seq", 2), ("deadman", True), ("rotation_radps", 0.1), ("session", bytes(16))):
            saved = getattr(t, field)
            setattr(t, field, value)
            self.assertNotEqual(base, oa.mac(KEY, "B21R_TELEOP", t), field)
            setattr(t, field, saved)
        self.assertEqual(base, oa.mac(KEY, "B21R_TELEOP", t))


def session(started_us, utime=0, key=KEY, nonce=NONCE):
    s = session_t()
    s.utime, s.started_us, s.key_id, s.nonce = utime, started_us, oa.key_id(key), nonce
    s.mac = oa.mac(key, "B21R_SESSION", s)
    return s


class KeyFiles(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.path = os.path.join(self.dir.name, "sub", "operator.key")

    def tearDown(self):
        self.dir.cleanup()

    def test_create_then_load(self):
        old = os.umask(0)  # whatever the umask, the key is 600 and its new folder 700
        try:
            key = oa.create_key(self.path)
        finally:
            os.umask(old)
        self.assertEqual(stat.S_IMODE(os.stat(self.path).st_mode), 0o600)
        self.assertEqual(stat.S_IMODE(os.stat(os.path.dirname(self.path)).st_mode), 0o700)
        self.assertEqual(oa.load_key(self.path), key)
        self.assertEqual(len(key), 32)
        with self.assertRaises(oa.KeyFileError) as cm:
            oa.create_key(self.path)
        self.assertIn("--force", str(cm.exception))
        self.assertNotEqual(oa.create_key(self.path, replace=True), key)

    def test_refusals_name_the_fix(self):
        oa.create_key(self.path)
        os.chmod(self.path, 0o640)
        with self.assertRaises(oa.KeyFileError) as cm:
            oa.load_key(self.path)
        self.assertIn("chmod 600 %s" % self.path, str(cm.exception))
        os.chmod(self.path, 0o600)
        with open(self.path, "w") as f:
            f.write("abcd\n")
        with self.assertRaises(oa.KeyFileError) as cm:
            oa.load_key(self.path)
        self.assertIn("64 hexadecimal digits", str(cm.exception))
        with self.assertRaises(oa.KeyFileError) as cm:
            oa.load_key(self.path + ".none")
        self.assertIn("tools/b21r_key.py create", str(cm.exception))

    def test_key_tool(self):
        env = dict(os.environ, B21R_OPERATOR_KEY=self.path)
        p = subprocess.run([sys.executable, os.path.join(TOOLS, "b21r_key.py"), "create"], env=env,
                           capture_output=True, text=True)
        self.assertEqual(p.returncode, 0, p.stderr)
        kid = oa.key_id(oa.load_key(self.path)).hex()
        self.assertIn(kid, p.stdout)
        p = subprocess.run([sys.executable, os.path.join(TOOLS, "b21r_key.py"), "id", self.path],
                           capture_output=True, text=True)
        self.assertEqual((p.returncode, p.stdout.split()[0]), (0, kid))
        os.chmod(self.path, 0o644)
        p = subprocess.run([sys.executable, os.path.join(TOOLS, "b21r_key.py"), "id", self.path],
                           capture_output=True, text=True)
        self.assertNotEqual(p.returncode, 0)
        self.assertIn("chmod 600", p.stderr)

    def test_lookup_order(self):
        env = dict(os.environ)
        try:
            os.environ["B21R_OPERATOR_KEY"] = "/x/y.key"
            self.assertEqual(oa.find_key_path("/a.key"), "/a.key")
            self.assertEqual(oa.find_key_path(None), "/x/y.key")
            del os.environ["B21R_OPERATOR_KEY"]
            os.environ["XDG_CONFIG_HOME"] = self.dir.name
            want = os.path.join(self.dir.name, "b21r", "operator.key")
            self.assertEqual(oa.user_key_path(), want)
            if not os.path.exists(oa.SYSTEM_KEY):
                self.assertEqual(oa.find_key_path(None), want)
        finally:
            os.environ.clear()
            os.environ.update(env)


class FakeLcm:
    def __init__(self):
        self.handlers = {}
        self.sent = []

    def subscribe(self, channel, handler):
        self.handlers[channel] = handler

    def publish(self, channel, data):
        self.sent.append((channel, data))

    def deliver(self, channel, data):
        self.handlers[channel](channel, data)


class Sessions(unittest.TestCase):
    def setUp(self):
        self.now = [0.0]
        self.lc = FakeLcm()
        self.tracker = oa.SessionTracker(self.lc, KEY, clock=lambda: self.now[0])

    def announce(self, s):
        self.lc.deliver("B21R_SESSION", s.encode())

    def test_takes_only_its_keys_announcements(self):
        self.assertIsNone(self.tracker.current())
        self.announce(session(10, key=bytes(32), nonce=bytes(16)))  # another key
        self.assertIsNone(self.tracker.current())
        self.assertIn("controller's key id is", self.tracker.describe())
        forged = session(10)
        forged.nonce = bytes(range(16))  # changed after signing
        self.announce(forged)
        self.lc.deliver("B21R_SESSION", b"garbage")
        self.assertIsNone(self.tracker.current())
        self.assertEqual(self.tracker.refused, 3)
        self.announce(session(10))
        self.assertEqual(self.tracker.current(), NONCE)

    def test_newest_start_wins_and_a_replay_cannot_go_back(self):
        old, new = bytes([1] * 16), bytes([2] * 16)
        self.announce(session(100, nonce=old))
        self.now[0] = 1.0
        self.announce(session(200, nonce=new))  # the controller restarted
        self.assertEqual(self.tracker.current(), new)
        self.now[0] = 1.5
        self.announce(session(100, nonce=old))  # replayed while the new one is announced
        self.assertEqual(self.tracker.current(), new)
        self.now[0] = 1.5 + oa.SESSION_SILENCE_S + 0.1
        self.announce(session(50, nonce=old))  # the new one went silent: a restart with a clock set back
        self.assertEqual(self.tracker.current(), old)

    def test_signer_fills_session_and_seq(self):
        wall = [1000.0]
        signer = oa.Signer(self.lc, KEY, self.tracker, wall=lambda: wall[0])
        t = teleop_t()
        self.assertFalse(signer.publish("B21R_TELEOP", t))
        self.assertEqual(self.lc.sent, [])
        self.announce(session(10))
        self.assertTrue(signer.publish("B21R_TELEOP", t))
        wall[0] = 2000.0
        self.assertTrue(signer.publish("B21R_TELEOP", t))  # one up per message, whatever the clock
        c = command_t()
        self.assertTrue(signer.publish("B21R_COMMAND", c))
        # A restarted tool starts at its wall clock, above what it sent before.
        again = oa.Signer(self.lc, KEY, self.tracker, wall=lambda: wall[0])
        self.assertTrue(again.publish("B21R_TELEOP", t))
        sent = [(ch, (teleop_t if ch == "B21R_TELEOP" else command_t).decode(d)) for ch, d in self.lc.sent]
        self.assertEqual([m.seq for ch, m in sent if ch == "B21R_TELEOP"], [1000000001, 1000000002, 2000000001])
        self.assertEqual([m.seq for ch, m in sent if ch == "B21R_COMMAND"], [2000000000])  # the clock
        for ch, m in sent:
            self.assertEqual(bytes(m.session), NONCE)
            self.assertEqual(bytes(m.mac), oa.mac(KEY, ch, m))

    def test_signer_follows_other_tools_not_forgeries(self):
        self.announce(session(10))
        signer = oa.Signer(self.lc, KEY, self.tracker, wall=lambda: 1000.0)
        later = oa.Signer(FakeLcm(), KEY, self.tracker, wall=lambda: 3000.0)  # a one-shot --command
        c = command_t()
        later.publish("B21R_COMMAND", c)
        forged = command_t()
        forged.seq, forged.key_id, forged.session, forged.mac = 2 ** 63 - 1, oa.key_id(KEY), NONCE, bytes(32)
        self.lc.deliver("B21R_COMMAND", forged.encode())
        self.assertEqual(signer.last_seq["B21R_COMMAND"], 1000000000)
        self.lc.deliver("B21R_COMMAND", later.lc.sent[0][1])
        self.assertEqual(signer.last_seq["B21R_COMMAND"], 3000000001)
        signer.publish("B21R_COMMAND", command_t())
        self.assertEqual(command_t.decode(self.lc.sent[-1][1]).seq, 3000000002)

    def test_commands_of_tools_that_do_not_hear_each_other_keep_their_order(self):
        # A person at the robot confirms with a one-shot tool (ttl=0: the remote tool does not hear
        # it); the remote operator's tool, started earlier, then pauses: its PAUSE must be newer.
        self.announce(session(10))
        wall = [1000.0]
        remote = oa.Signer(self.lc, KEY, self.tracker, wall=lambda: wall[0])
        remote.publish("B21R_TELEOP", teleop_t())
        wall[0] = 1500.0
        local = oa.Signer(FakeLcm(), KEY, self.tracker, wall=lambda: wall[0])
        local.publish("B21R_COMMAND", command_t())
        wall[0] = 1501.0
        remote.publish("B21R_COMMAND", command_t())
        confirm = command_t.decode(local.lc.sent[-1][1]).seq
        pause = command_t.decode(self.lc.sent[-1][1]).seq
        self.assertGreater(pause, confirm)

if __name__ == "__main__":
    unittest.main(argv=[sys.argv[0]] + sys.argv[1:])
