#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""tools.teleop: b21r_teleop's gamepad mode fed with recorded js_event records (a recording file,
replayed at the pace of its timestamps, and a FIFO written live), over LCM memq://.
Checks: nothing is sent before the deadman is pressed (a deadman held down when the device
opens does not count), B21R_TELEOP at the configured rate while it is held, the stick scaled to
the limit the tool is told and clamped to it (the full negative deflection, -32768, would
otherwise exceed it), the release sends one message with the deadman released and then nothing,
a lost device releases, commands fire once per press and long-press commands only after their
hold time; every message is signed for the session (its mac verifies with the key, it carries the
key id and the session nonce) and nothing goes out without a session; the map file's errors name
the file, the pad and the key; the keyboard's deadman is never latched."""
import os
import struct
import sys
import tempfile
import threading
import time
import unittest

import lcm
from b21r import command_t, teleop_t

import b21r_opauth
import b21r_teleop as tt

LIMIT_ROT = 0.6
LIMIT_TRANS = 0.5
RATE = 20.0
KEY = bytes(range(32))
NONCE = bytes(range(16))


class FixedSession:
    """A session as the tracker would hold it after a B21R_SESSION (nonce None: none yet)."""

    def __init__(self, nonce=NONCE):
        self.nonce = nonce

    def current(self):
        return self.nonce

    def describe(self):
        return "session %s" % self.nonce


def signer(lc, session=None):
    return b21r_opauth.Signer(lc, KEY, session or FixedSession())


def check_signed(test, channel, msgs):
    for m in msgs:
        test.assertEqual(bytes(m.key_id), b21r_opauth.key_id(KEY))
        test.assertEqual(bytes(m.session), NONCE)
        test.assertEqual(bytes(m.mac), b21r_opauth.mac(KEY, channel, m), "%s: wrong mac" % channel)


def ev(t_ms, kind, number, value, init=False):
    return tt.JS_EVENT.pack(t_ms & 0xFFFFFFFF, value, kind | (tt.JS_EVENT_INIT if init else 0), number)


def init_state(t_ms, buttons=9, axes=2, held=()):
    out = [ev(t_ms, tt.JS_EVENT_BUTTON, b, 1 if b in held else 0, init=True) for b in range(buttons)]
    out += [ev(t_ms, tt.JS_EVENT_AXIS, a, 0, init=True) for a in range(axes)]
    return out


class Quiet(tt.LineDisplay):
    def show(self, lines):
        pass


class Capture:
    """Runs the gamepad loop on a memq:// LCM and records every TELEOP / COMMAND it publishes."""

    def __init__(self):
        self.lc = lcm.LCM("memq://")
        self.teleop = []   # (monotonic receive time, teleop_t)
        self.commands = []
        self.lc.subscribe("B21R_TELEOP", lambda c, d: self.teleop.append((time.monotonic(), teleop_t.decode(d))))
        self.lc.subscribe("B21R_COMMAND", lambda c, d: self.commands.append((time.monotonic(), command_t.decode(d))))

    def run(self, js_path, stop=None, pad="default"):
        js = tt.Joystick(js_path)
        padmap = tt.load_pad_map(tt.DEFAULT_MAP, js.name, pad)
        teleop = tt.Teleop(self.lc, LIMIT_ROT, LIMIT_TRANS, RATE, signer(self.lc))
        state = tt.ControllerState(self.lc)
        self.t0 = time.monotonic()
        tt.gamepad_loop(self.lc, js, padmap, teleop, state, Quiet(), stop or tt.Stop(), exit_when_lost=True)
        self.lc.handle_timeout(0)
        js.close()
        return self


def expected_rotation(raw, sign=-1, deadzone=0.1):
    x = raw / 32767.0 * sign
    mag = (abs(x) - deadzone) / (1 - deadzone)
    return LIMIT_ROT * (min(mag, 1.0) if x > 0 else -min(mag, 1.0))


class GamepadRecording(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        records = init_state(5000)
        records += [
            ev(5100, tt.JS_EVENT_AXIS, 0, -16384),  # stick half left: turn left
            ev(5200, tt.JS_EVENT_BUTTON, 4, 1),     # deadman pressed
            ev(6200, tt.JS_EVENT_AXIS, 0, -32768),  # full left: beyond -32767
            ev(6700, tt.JS_EVENT_BUTTON, 4, 0),     # deadman released
            ev(7200, tt.JS_EVENT_BUTTON, 0, 1),     # A: CONFIRM_START_POSE
            ev(7300, tt.JS_EVENT_BUTTON, 0, 0),
            ev(7400, tt.JS_EVENT_BUTTON, 3, 1),     # Y tapped: START_PHASE_TWO needs 1 s
            ev(7700, tt.JS_EVENT_BUTTON, 3, 0),
            ev(7800, tt.JS_EVENT_BUTTON, 3, 1),     # Y held 1.2 s: fires once
            ev(9000, tt.JS_EVENT_BUTTON, 3, 0),
            ev(9100, tt.JS_EVENT_AXIS, 0, 32767),   # full right
            ev(9150, tt.JS_EVENT_BUTTON, 4, 1),     # deadman again; the recording then ends
            ev(9600, tt.JS_EVENT_AXIS, 1, 0),
        ]
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "drive.js")
            with open(path, "wb") as f:
                f.write(b"".join(records))
            cls.cap = Capture().run(path)
        cls.msgs = [(t - cls.cap.t0, m) for t, m in cls.cap.teleop]

    def window(self, lo, hi):
        return [(t, m) for t, m in self.msgs if lo <= t < hi]

    def test_nothing_before_the_deadman(self):
        first = self.msgs[0][0]
        self.assertGreater(first, 0.15, "TELEOP before the deadman was pressed")

    def test_steady_rate_while_held(self):
        held = [(t, m) for t, m in self.window(0.15, 1.75) if m.deadman]
        n_expected = 1.5 * RATE
        self.assertTrue(n_expected - 3 <= len(held) <= n_expected + 2, "%d messages in 1.5 s" % len(held))
        dts = [b[0] - a[0] for a, b in zip(held, held[1:])]
        self.assertLess(max(dts), 2.0 / RATE, "a gap of %.3f s" % max(dts))
        self.assertAlmostEqual(sum(dts) / len(dts), 1.0 / RATE, delta=0.1 / RATE)
        seqs = [m.seq for _, m in self.msgs]
        self.assertEqual(seqs, sorted(set(seqs)), "seq must increase")

    def test_scaled_to_the_limit_and_clamped(self):
        half = [m.rotation_radps for _, m in self.window(0.25, 1.15) if m.deadman]
        full = [m.rotation_radps for _, m in self.window(1.25, 1.65) if m.deadman]
        self.assertTrue(half and full)
        for r in half:
            self.assertAlmostEqual(r, expected_rotation(-16384), places=12)
        for r in full:
            self.assertEqual(r, LIMIT_ROT)  # -32768 would be 1.00003 x the limit unclamped
        for _, m in self.msgs:
            self.assertLessEqual(abs(m.rotation_radps), LIMIT_ROT)
            self.assertLessEqual(abs(m.translation_mps), LIMIT_TRANS)

    def test_release_sends_one_stop_then_silence(self):
        first = self.window(0.0, 4.1)
        released = [i for i, (_, m) in enumerate(first) if not m.deadman]
        self.assertEqual(released, [len(first) - 1], "one release message, the last before the next press")
        t, m = first[-1]
        self.assertEqual(m.rotation_radps, 0.0)
        self.assertLess(t, 1.7 + 2.0 / RATE)

    def test_lost_device_releases(self):
        last_held = [(t, m) for t, m in self.msgs if t > 4.1]
        self.assertTrue(last_held and last_held[0][1].deadman)
        self.assertAlmostEqual(last_held[0][1].rotation_radps, -LIMIT_ROT, places=12)
        self.assertFalse(last_held[-1][1].deadman, "the end of the recording must release the deadman")

    def test_every_message_signed_for_the_session(self):
        check_signed(self, "B21R_TELEOP", [m for _, m in self.msgs])
        check_signed(self, "B21R_COMMAND", [c for _, c in self.cap.commands])

    def test_commands_once_per_press_and_long_press(self):
        got = [(round(t - self.cap.t0, 2), c.command) for t, c in self.cap.commands]
        self.assertEqual([c for _, c in got], [command_t.CONFIRM_START_POSE, command_t.START_PHASE_TWO], got)
        t_phase_two = got[1][0]
        self.assertGreater(t_phase_two, 2.8 + 0.95, "START_PHASE_TWO before its 1 s hold")
        self.assertLess(t_phase_two, 2.8 + 1.2)
        seqs = [c.seq for _, c in self.cap.commands]
        self.assertLess(seqs[0], seqs[1])


class GamepadFifo(unittest.TestCase):
    def test_deadman_held_at_open_does_not_count_and_fifo_drives(self):
        with tempfile.TemporaryDirectory() as d:
            path = os.path.join(d, "js")
            os.mkfifo(path)
            marks = {}

            def writer():
                with open(path, "wb", buffering=0) as f:
                    f.write(b"".join(init_state(0, held=(4,))))  # deadman down at open: ignored
                    time.sleep(0.5)
                    marks["released"] = time.monotonic()
                    f.write(ev(500, tt.JS_EVENT_BUTTON, 4, 0))
                    f.write(ev(510, tt.JS_EVENT_AXIS, 0, 16384))
                    time.sleep(0.2)
                    marks["pressed"] = time.monotonic()
                    f.write(ev(700, tt.JS_EVENT_BUTTON, 4, 1))
                    time.sleep(0.5)
                    marks["closed"] = time.monotonic()
                # closing the FIFO = the device is gone

            th = threading.Thread(target=writer)
            th.start()
            cap = Capture().run(path)
            th.join()
        msgs = cap.teleop
        self.assertTrue(msgs)
        self.assertGreaterEqual(msgs[0][0], marks["pressed"], "sent before a fresh deadman press")
        held = [m for _, m in msgs if m.deadman]
        self.assertTrue(8 <= len(held) <= 12, len(held))
        for m in held:
            self.assertAlmostEqual(m.rotation_radps, expected_rotation(16384), places=12)
        self.assertFalse(msgs[-1][1].deadman)
        self.assertLess(msgs[-1][0] - marks["closed"], 0.2)


class MapFile(unittest.TestCase):
    def load(self, text, name="", pad=None):
        with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
            f.write(text)
        try:
            return tt.load_pad_map(f.name, name, pad)
        finally:
            os.unlink(f.name)

    def test_default_map_selects_by_device_name(self):
        self.assertEqual(tt.load_pad_map(tt.DEFAULT_MAP, "Sony Interactive Entertainment Wireless Controller").name,
                         "dualshock")
        self.assertEqual(tt.load_pad_map(tt.DEFAULT_MAP, "Microsoft X-Box 360 pad").name, "default")
        self.assertEqual(tt.load_pad_map(tt.DEFAULT_MAP, "Some Unknown Pad").name, "default")

    def test_errors_name_file_pad_and_key(self):
        cases = [
            ("[p]\ndeadman_button = 4\n", "rotation_axis is missing"),
            ("[p]\ndeadman_button = 4\nrotation_axis = 0\ndeadzone = 0.7\n", "deadzone = 0.7"),
            ("[p]\ndeadman_button = 4\nrotation_axis = 0\nrotation_sign = 0\n", "rotation_sign"),
            ("[p]\ndeadman_button = 4\nrotation_axis = 0\ndeadman = 3\n", "unknown key(s) ['deadman']"),
            ("[p]\ndeadman_button = 4\nrotation_axis = 0\n[p.commands]\nSTOP = {button = 1}\n", "unknown command STOP"),
            ("[p]\ndeadman_button = 4\nrotation_axis = 0\n[p.commands]\nPAUSE = {button = 4}\n", "not the deadman"),
            ("[p\n", ".toml"),
        ]
        for text, want in cases:
            with self.assertRaises(tt.ConfigError) as cm:
                self.load(text)
            self.assertIn(want, str(cm.exception))
            self.assertIn(".toml", str(cm.exception))
        with self.assertRaises(tt.ConfigError) as cm:
            self.load("[p]\ndeadman_button = 4\nrotation_axis = 0\n", pad="q")
        self.assertIn("no pad [q]", str(cm.exception))


class Keyboard(unittest.TestCase):
    def test_deadman_held_only_while_keys_repeat(self):
        k = tt.HeldKeys(0.6)
        self.assertFalse(k.held(0.0))
        k.press(1.0, +1)
        self.assertTrue(k.held(1.5))       # the keyboard's repeat delay
        for i in range(30):                # repeating at 30 Hz
            k.press(1.5 + i / 30.0, +1)
            self.assertTrue(k.held(1.5 + i / 30.0 + 0.02))
        last = 1.5 + 29 / 30.0
        self.assertTrue(k.held(last + 0.59))
        self.assertFalse(k.held(last + 0.61))
        self.assertFalse(k.held(last + 100.0))  # never latched

    def test_teleop_publishes_only_while_held(self):
        lc = lcm.LCM("memq://")
        got = []
        lc.subscribe("B21R_TELEOP", lambda c, d: got.append(teleop_t.decode(d)))
        clock = [0.0]
        t = tt.Teleop(lc, LIMIT_ROT, LIMIT_TRANS, 10.0, signer(lc), clock=lambda: clock[0])
        for i in range(10):  # 1 s held at a 10 Hz send rate, requesting more than the limit
            clock[0] = i * 0.1
            t.step(clock[0], True, 5.0, -5.0)
        t.step(1.0, False, 0.0, 0.0)
        t.step(1.1, False, 0.0, 0.0)
        lc.handle_timeout(0)
        while lc.handle_timeout(0):
            pass
        self.assertEqual(len(got), 11)
        self.assertTrue(all(m.deadman and m.rotation_radps == LIMIT_ROT and m.translation_mps == -LIMIT_TRANS
                            for m in got[:10]))
        self.assertFalse(got[10].deadman)
        check_signed(self, "B21R_TELEOP", got)

    def test_nothing_sent_without_a_session(self):
        lc = lcm.LCM("memq://")
        got = []
        lc.subscribe("B21R_TELEOP", lambda c, d: got.append(d))
        lc.subscribe("B21R_COMMAND", lambda c, d: got.append(d))
        t = tt.Teleop(lc, LIMIT_ROT, LIMIT_TRANS, 10.0, signer(lc, FixedSession(None)), clock=lambda: 0.0)
        for i in range(5):
            t.step(i * 0.1, True, 0.3, 0.0)
        t.step(0.5, False, 0.0, 0.0)
        self.assertFalse(t.command("PAUSE"))
        while lc.handle_timeout(0):
            pass
        self.assertEqual(got, [])
        self.assertEqual((t.sent, t.unsent), (0, 6))


if __name__ == "__main__":
    unittest.main(argv=[sys.argv[0]] + sys.argv[1:])
