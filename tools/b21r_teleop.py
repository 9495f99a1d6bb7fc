#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""b21r_teleop: drive the B21r with a gamepad or the keyboard (B21R_TELEOP) and send operator
commands (B21R_COMMAND) to b21r-controller over LCM, showing the controller's state.

Gamepad (Linux joystick API, /dev/input/js*; used when one is present, or with --joystick):
    b21r_teleop.py [--joystick /dev/input/js0] [--map FILE] [--pad NAME]
  Hold the deadman button (default: left shoulder) to drive: the left stick turns (and drives,
  where the task leaves the translation free), scaled so that full deflection is the limit
  (--max-rotation, --max-translation: the controller's max_rotation_radps / max_translation_mps;
  nothing beyond them is ever sent). Release it and the messages stop: the controller stops the
  robot within its teleop_timeout_s (one last message with the deadman released makes it stop
  at once). Buttons send the operator commands; the map is tools/b21r_gamepads.toml (Xbox-style
  and DualShock pads; --probe shows the numbers of your pad's axes and buttons).
Keyboard (--keyboard, or when no joystick is present):
  hold <- or ->   turn left / right at the turn rate     hold up or space   drive straight
  a / z           turn rate +/- 0.1 rad/s                w / s              translation +/- 0.1 m/s
  c CONFIRM_START_POSE   2 START_PHASE_TWO   p PAUSE   r RESUME   x SHUTDOWN   q quit
  The deadman is held only while a driving key repeats: --key-hold-s (default 0.6 s, longer than
  the usual keyboard repeat delay) after the last driving key press the messages stop.
Both send B21R_TELEOP at --rate Hz (default 20) while the deadman is held, and show the mode,
phase, run and last stop reason from B21R_STATUS.
One command and exit:
    b21r_teleop.py --command START_PHASE_TWO|CONFIRM_START_POSE|PAUSE|RESUME|SHUTDOWN
Every message is signed with the operator key (--key FILE; default $B21R_OPERATOR_KEY, else
~/.config/b21r/operator.key, else /etc/b21r/operator.key) for the controller's current session,
which the tool takes from B21R_SESSION: until one signed with the same key arrives nothing is sent
(and --command waits up to --wait-s for it). The controller refuses anything else (docs/robot.md,
"Network and security"; tools/b21r_key.py creates a key).
Runs from a plain shell after tools/setup.sh and a build (b21r_bootstrap finds the venv and the
generated types).
"""
import b21r_bootstrap  # noqa: E402 (first: runs the tool in the project's venv)

b21r_bootstrap.ensure()

import argparse
import array
import errno
import fcntl
import glob
import os
import select
import signal
import stat
import struct
import sys
import time
import tomllib

import lcm

import b21r_opauth
from b21r import command_t, status_t, teleop_t

COMMANDS = {"START_PHASE_TWO": command_t.START_PHASE_TWO, "CONFIRM_START_POSE": command_t.CONFIRM_START_POSE,
            "PAUSE": command_t.PAUSE, "RESUME": command_t.RESUME, "SHUTDOWN": command_t.SHUTDOWN}
DEFAULT_MAP = os.path.join(os.path.dirname(os.path.abspath(__file__)), "b21r_gamepads.toml")

# linux/joystick.h: struct js_event { __u32 time; __s16 value; __u8 type; __u8 number; }
JS_EVENT = struct.Struct("<IhBB")
JS_EVENT_BUTTON = 0x01
JS_EVENT_AXIS = 0x02
JS_EVENT_INIT = 0x80
JS_AXIS_MAX = 32767.0


def _ioc(direction, nr, size):  # linux/ioctl.h with type 'j'
    return (direction << 30) | (size << 16) | (ord("j") << 8) | nr


JSIOCGAXES = _ioc(2, 0x11, 1)
JSIOCGBUTTONS = _ioc(2, 0x12, 1)


def JSIOCGNAME(length):
    return _ioc(2, 0x13, length)


def _names(prefix):
    return {getattr(status_t, k): k[len(prefix):] for k in dir(status_t) if k.startswith(prefix)}


MODE_NAMES = _names("MODE_")
STOP_NAMES = _names("STOP_")


class ConfigError(Exception):
    pass


# ---- the gamepad ------------------------------------------------------------------------------

class Joystick:
    """A joystick read through the Linux joystick API: a character device (/dev/input/jsN) or a
    FIFO carrying js_event records is read as it comes; a regular file (a recording made with
    --record) is replayed at the pace of the records' own timestamps. Keeps the latest value of
    every axis and button. lost becomes True when the device goes away (unplugged, the FIFO's
    writer closed, the end of a recording). Buttons reported held only by the driver's initial
    state events (held while the device was opened) are in `held_at_open` until released: a
    deadman held down at start-up does not count (it must be pressed)."""

    def __init__(self, path, clock=time.monotonic, record=None):
        self.path = path
        self.clock = clock
        self.axes = {}
        self.buttons = {}
        self.held_at_open = set()
        self.lost = False
        self.record = record
        self._buf = b""
        st = os.stat(path)
        self.replay = stat.S_ISREG(st.st_mode)
        self.chardev = stat.S_ISCHR(st.st_mode)
        # Blocking open first: a FIFO then waits for its writer instead of reading EOF at once.
        self.fd = os.open(path, os.O_RDONLY)
        if not self.replay:
            fl = fcntl.fcntl(self.fd, fcntl.F_GETFL)
            fcntl.fcntl(self.fd, fcntl.F_SETFL, fl | os.O_NONBLOCK)
        self.name = self._ioctl_name()
        self._t0_ms = None
        self._start = clock()
        self._pending = None

    def _ioctl_name(self):
        buf = array.array("B", [0] * 128)
        try:
            fcntl.ioctl(self.fd, JSIOCGNAME(len(buf)), buf, True)
        except OSError:
            return ""
        return buf.tobytes().split(b"\0", 1)[0].decode(errors="replace")

    def counts(self):
        """(axes, buttons) the driver reports, or None for a FIFO or a recording."""
        out = []
        for req in (JSIOCGAXES, JSIOCGBUTTONS):
            buf = array.array("B", [0])
            try:
                fcntl.ioctl(self.fd, req, buf, True)
            except OSError:
                return None
            out.append(buf[0])
        return tuple(out)

    def fileno(self):
        return self.fd

    def _apply(self, raw):
        t_ms, value, kind, number = JS_EVENT.unpack(raw)
        if self.record is not None:
            self.record.write(raw)
        if kind & ~JS_EVENT_INIT == JS_EVENT_BUTTON:
            self.buttons[number] = value != 0
            if kind & JS_EVENT_INIT and value != 0:
                self.held_at_open.add(number)
            else:
                self.held_at_open.discard(number)
        elif kind & ~JS_EVENT_INIT == JS_EVENT_AXIS:
            self.axes[number] = value
        return t_ms, value, kind, number

    def read(self):
        """Takes every event due now. Returns the events taken [(time_ms, value, type, number)]."""
        if self.lost:
            return []
        if self.replay:
            return self._read_replay()
        events = []
        while True:
            try:
                chunk = os.read(self.fd, 64 * JS_EVENT.size)
            except OSError as exc:
                if exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK):
                    break
                self._lose()
                break
            if not chunk:
                self._lose()
                break
            self._buf += chunk
        while len(self._buf) >= JS_EVENT.size:
            events.append(self._apply(self._buf[:JS_EVENT.size]))
            self._buf = self._buf[JS_EVENT.size:]
        return events

    def _read_replay(self):
        events = []
        now_ms = (self.clock() - self._start) * 1000.0
        while True:
            if self._pending is None:
                raw = os.read(self.fd, JS_EVENT.size)
                if len(raw) < JS_EVENT.size:
                    self._lose()
                    break
                self._pending = raw
            t_ms = JS_EVENT.unpack(self._pending)[0]
            if self._t0_ms is None:
                self._t0_ms = t_ms
            if (t_ms - self._t0_ms) & 0xFFFFFFFF > now_ms:
                break
            events.append(self._apply(self._pending))
            self._pending = None
        return events

    def next_due(self):
        """Replay: the clock time of the next record (None when reading a live device)."""
        if not self.replay or self._pending is None or self._t0_ms is None:
            return None
        t_ms = JS_EVENT.unpack(self._pending)[0]
        return self._start + ((t_ms - self._t0_ms) & 0xFFFFFFFF) / 1000.0

    def _lose(self):
        self.lost = True
        self.axes.clear()
        self.buttons.clear()
        self.held_at_open.clear()

    def reopen(self):
        """A character device that went away (unplugged): tries to open it again. True on success."""
        if not (self.lost and self.chardev):
            return False
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
        except OSError:
            return False
        os.close(self.fd)
        self.fd = fd
        self.name = self._ioctl_name()
        self._buf = b""
        self.lost = False
        return True

    def pressed(self, button):
        """Held, and pressed since the device was opened."""
        return self.buttons.get(button, False) and button not in self.held_at_open

    def close(self):
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class PadMap:
    """One pad's mapping from axes and buttons to (deadman, rotation, translation, commands)."""

    KEYS = {"match", "deadman_button", "rotation_axis", "rotation_sign", "translation_axis", "translation_sign",
            "deadzone", "gain", "commands"}

    def __init__(self, name, table, source):
        self.name = name
        where = "%s [%s]" % (source, name)
        unknown = set(table) - self.KEYS
        if unknown:
            raise ConfigError("%s: unknown key(s) %s; allowed: %s" % (where, sorted(unknown), sorted(self.KEYS)))

        def number(key, kind, lo, hi, default=None):
            v = table.get(key, default)
            if v is None:
                raise ConfigError("%s: %s is missing" % (where, key))
            if not isinstance(v, (int, float)) or isinstance(v, bool) or (kind is int and not isinstance(v, int)) \
                    or not lo <= v <= hi:
                raise ConfigError("%s: %s = %r: expected %s in [%s, %s]" % (where, key, v, kind.__name__, lo, hi))
            return v

        self.match = [str(m) for m in table.get("match", [])]
        self.deadman = number("deadman_button", int, 0, 255)
        self.rotation_axis = number("rotation_axis", int, 0, 255)
        self.translation_axis = number("translation_axis", int, 0, 255) if "translation_axis" in table else None
        self.rotation_sign = number("rotation_sign", int, -1, 1, default=1)
        self.translation_sign = number("translation_sign", int, -1, 1, default=1)
        if 0 in (self.rotation_sign, self.translation_sign):
            raise ConfigError("%s: rotation_sign and translation_sign are +1 or -1" % where)
        self.deadzone = number("deadzone", float, 0.0, 0.499, default=0.1)
        self.gain = number("gain", float, 0.01, 100.0, default=1.0)
        self.commands = []
        for cname, spec in table.get("commands", {}).items():
            if cname not in COMMANDS:
                raise ConfigError("%s: unknown command %s; the commands are %s" % (where, cname, sorted(COMMANDS)))
            if not isinstance(spec, dict) or set(spec) - {"button", "hold_s"} or "button" not in spec:
                raise ConfigError("%s: command %s: expected {button = N, hold_s = S}" % (where, cname))
            button = spec["button"]
            hold_s = spec.get("hold_s", 0.0)
            if not isinstance(button, int) or not 0 <= button <= 255 or button == self.deadman:
                raise ConfigError("%s: command %s: button must be 0..255 and not the deadman" % (where, cname))
            if not isinstance(hold_s, (int, float)) or not 0.0 <= hold_s <= 10.0:
                raise ConfigError("%s: command %s: hold_s must be in [0, 10] s" % (where, cname))
            self.commands.append((cname, button, float(hold_s)))
        self._pressed_at = {}
        self._fired = set()

    def axis(self, js, number, sign):
        """Deflection in [-1, 1] after the dead zone (rescaled so the output is continuous) and the
        gain, clamped: the raw range is -32768..32767, so the full negative deflection would
        otherwise come out slightly beyond -1."""
        raw = js.axes.get(number, 0) / JS_AXIS_MAX * sign
        mag = abs(raw)
        if mag <= self.deadzone:
            return 0.0
        x = (mag - self.deadzone) / (1.0 - self.deadzone) * self.gain
        return min(x, 1.0) if raw > 0 else -min(x, 1.0)

    def evaluate(self, js, now):
        """(deadman held, rotation in [-1, 1], translation in [-1, 1], [commands due now])."""
        deadman = js.pressed(self.deadman)
        rot = self.axis(js, self.rotation_axis, self.rotation_sign)
        trans = self.axis(js, self.translation_axis, self.translation_sign) if self.translation_axis is not None \
            else 0.0
        due = []
        for cname, button, hold_s in self.commands:
            if js.pressed(button):
                t0 = self._pressed_at.setdefault(button, now)
                if cname not in self._fired and now - t0 >= hold_s:
                    self._fired.add(cname)
                    due.append(cname)
            else:
                self._pressed_at.pop(button, None)
                self._fired.discard(cname)
        return deadman, rot, trans, due

    def next_due(self, js, now):
        """Clock time at which a held command button reaches its hold time (None: none pending)."""
        times = [self._pressed_at[b] + h for c, b, h in self.commands
                 if b in self._pressed_at and c not in self._fired and js.pressed(b)]
        return min(times) if times else None


def load_pad_map(path, device_name, pad=None):
    try:
        with open(path, "rb") as f:
            tables = tomllib.load(f)
    except OSError as exc:
        raise ConfigError("%s: %s" % (path, exc.strerror))
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("%s: %s" % (path, exc))
    if not tables:
        raise ConfigError("%s: no pad tables" % path)
    if pad is not None:
        if pad not in tables:
            raise ConfigError("%s: no pad [%s]; the file has %s" % (path, pad, sorted(tables)))
        name = pad
    else:
        name = next((n for n, t in tables.items() if any(m in device_name for m in t.get("match", []))), None)
        if name is None:
            name = "default" if "default" in tables else next(iter(tables))
    if not isinstance(tables[name], dict):
        raise ConfigError("%s: [%s] is not a table" % (path, name))
    return PadMap(name, tables[name], path)


# ---- messages ---------------------------------------------------------------------------------

class Teleop:
    """Publishes B21R_TELEOP at a steady rate while the deadman is held, values clamped to the
    limits; on release one message with the deadman released (the controller stops at its next
    tick), then silence (the controller also stops by itself after teleop_timeout_s). Messages go
    out signed by signer (b21r_opauth.Signer), and only while it has a session: without one the
    controller hears nothing, and stops."""

    def __init__(self, lc, max_rotation, max_translation, rate_hz, signer, clock=time.monotonic, wall=time.time):
        self.lc = lc
        self.max_rotation = max_rotation
        self.max_translation = max_translation
        self.period = 1.0 / rate_hz
        self.signer = signer
        self.clock = clock
        self.wall = wall
        self.active = False
        self.next_send = None
        self.rotation = 0.0
        self.translation = 0.0
        self.sent = 0
        self.unsent = 0  # messages due while there was no session

    def _publish(self, deadman):
        m = teleop_t()
        m.utime = int(self.wall() * 1e6)
        m.deadman = deadman
        m.rotation_radps = self.rotation if deadman else 0.0
        m.translation_mps = self.translation if deadman else 0.0
        if self.signer.publish("B21R_TELEOP", m):
            self.sent += 1
        else:
            self.unsent += 1

    def step(self, now, deadman, rotation, translation):
        """rotation, translation: requests [rad/s], [m/s]; clamped here to the limits."""
        self.rotation = max(-self.max_rotation, min(self.max_rotation, rotation))
        self.translation = max(-self.max_translation, min(self.max_translation, translation))
        if deadman:
            if not self.active:
                self.active = True
                self.next_send = now
            if now >= self.next_send:
                self._publish(True)
                self.next_send += self.period
                if self.next_send <= now:  # late (a stall): keep the rate from now on, no burst
                    self.next_send = now + self.period
        elif self.active:
            self.active = False
            self.next_send = None
            self._publish(False)

    def release(self):
        if self.active:
            self.step(self.clock(), False, 0.0, 0.0)

    def command(self, name):
        """Sends one operator command; False when there is no session to sign it for."""
        return send_command(self.signer, name, self.wall)


def send_command(signer, name, wall=time.time):
    m = command_t()
    m.utime = int(wall() * 1e6)
    m.command = COMMANDS[name]
    m.argument = 0
    return signer.publish("B21R_COMMAND", m)


class ControllerState:
    """The newest B21R_STATUS and the session, as text for the display."""

    def __init__(self, lc, sessions=None, clock=time.monotonic):
        self.clock = clock
        self.sessions = sessions
        self.msg = None
        self.received = None
        lc.subscribe("B21R_STATUS", self._on_status)

    def _on_status(self, channel, data):
        try:
            self.msg = status_t.decode(data)
        except ValueError:
            return
        self.received = self.clock()

    def lines(self):
        session = [self.sessions.describe()] if self.sessions is not None else []
        if self.msg is None:
            return ["controller: no B21R_STATUS yet (is b21r-controller running, with LCM on this URL?)", *session]
        s = self.msg
        age = self.clock() - self.received
        stop = STOP_NAMES.get(s.stop_reason, str(s.stop_reason))
        out = ["controller: %-13s phase %d  run %d  step %d  training runs %d  evaluation blocks %d%s" %
               (MODE_NAMES.get(s.mode, str(s.mode)), s.phase, s.run_id, s.step_id, s.training_runs, s.eval_blocks,
                "   (STATUS %.1f s old)" % age if age > 1.0 else ""),
               "last stop: %s%s" % (stop, (" - " + s.stop_detail) if s.stop_detail else ""),
               "teleop accepted %d, refused %d (out of range %d, stale %d, repeated %d, NaN %d)" %
               (s.teleop_accepted, s.teleop_rejected, s.teleop_rejected_range, s.teleop_rejected_stale,
                s.teleop_rejected_seq, s.teleop_rejected_nan),
               "operator messages refused: malformed %d, unauthenticated %d, other key %d, wrong mac %d, "
               "other session %d, replayed %d, old seq %d" %
               (s.operator_refused_malformed, s.operator_refused_unauthenticated, s.operator_refused_key,
                s.operator_refused_mac, s.operator_refused_session, s.operator_refused_replay,
                s.operator_refused_old),
               *session]
        return out


# ---- display ----------------------------------------------------------------------------------

class LineDisplay:
    """Without a terminal: prints the state whenever it changes (logs, tests)."""

    def __init__(self):
        self.last = None

    def show(self, lines):
        text = "\n".join(lines)
        if text != self.last:
            self.last = text
            print(text, flush=True)

    def getch(self):
        return -1

    def close(self):
        pass


class CursesDisplay:
    def __init__(self):
        import curses
        self.curses = curses
        self.scr = curses.initscr()
        curses.noecho()
        curses.cbreak()
        self.scr.keypad(True)
        self.scr.nodelay(True)

    def show(self, lines):
        self.scr.erase()
        h, w = self.scr.getmaxyx()
        for i, line in enumerate(lines[:h]):
            self.scr.addnstr(i, 0, line, max(1, w - 1))
        self.scr.refresh()

    def getch(self):
        return self.scr.getch()

    def close(self):
        self.scr.keypad(False)
        self.curses.nocbreak()
        self.curses.echo()
        self.curses.endwin()


# ---- main loops -------------------------------------------------------------------------------

class Stop:
    def __init__(self):
        self.requested = False

    def __call__(self, signum, frame):
        self.requested = True


def _wait(fds, until, clock):
    timeout = max(0.0, until - clock())
    try:
        ready, _, _ = select.select([f for f in fds if f is not None and f >= 0], [], [], timeout)
    except InterruptedError:
        return []
    return ready


def gamepad_loop(lc, js, pad, teleop, state, display, stop, clock=time.monotonic, exit_when_lost=False):
    """Runs until stop.requested, or (exit_when_lost) the joystick is lost. Returns 0."""
    note = "pad [%s] for '%s'" % (pad.name, js.name or js.path)
    lfd = lc.fileno()
    next_reopen = clock()
    while not stop.requested:
        now = clock()
        if js.lost and now >= next_reopen:
            next_reopen = now + 1.0
            if js.reopen():
                note = "joystick back (%s)" % js.path
        wake = [now + 0.1]  # display refresh
        for t in (teleop.next_send if teleop.active else None, js.next_due(), pad.next_due(js, now)):
            if t is not None:
                wake.append(t)
        ready = _wait([None if js.lost or js.replay else js.fileno(), lfd], min(wake), clock)
        if lfd in ready:
            lc.handle_timeout(0)
        js.read()
        now = clock()
        deadman, rot, trans, due = pad.evaluate(js, now)
        for cname in due:
            note = ("sent %s" % cname) if teleop.command(cname) else "%s not sent: no session" % cname
        teleop.step(now, deadman and not js.lost, rot * teleop.max_rotation, trans * teleop.max_translation)
        if js.lost:
            note = "joystick lost (%s): messages stopped" % js.path
            if exit_when_lost:
                break
        display.show(["B21r teleop: gamepad '%s' (%s)" % (js.name or js.path, pad.name),
                      "deadman %-8s rotation %+.2f rad/s (limit %.2f)  translation %+.2f m/s (limit %.2f)  %s" %
                      ("HELD" if teleop.active else "released", teleop.rotation if teleop.active else 0.0,
                       teleop.max_rotation, teleop.translation if teleop.active else 0.0, teleop.max_translation,
                       "sending %.0f Hz" % (1.0 / teleop.period) if teleop.active else "not sending"),
                      *state.lines(), note])
        if display.getch() == ord("q"):
            break
    teleop.release()
    return 0


class HeldKeys:
    """The keyboard's deadman: held while driving keys keep arriving (the terminal repeats a held
    key), released hold_s after the last one. Never latched."""

    def __init__(self, hold_s):
        self.hold_s = hold_s
        self.last = None
        self.direction = 0

    def press(self, now, direction):
        self.last = now
        self.direction = direction

    def held(self, now):
        return self.last is not None and now - self.last <= self.hold_s

    def expires(self):
        return None if self.last is None else self.last + self.hold_s


def keyboard_loop(lc, teleop, state, display, stop, hold_s, clock=time.monotonic):
    import curses
    keys = HeldKeys(hold_s)
    turn = min(0.5, teleop.max_rotation)
    trans = 0.0
    note = ""
    lfd = lc.fileno()
    command_keys = {ord("c"): "CONFIRM_START_POSE", ord("2"): "START_PHASE_TWO", ord("p"): "PAUSE",
                    ord("r"): "RESUME", ord("x"): "SHUTDOWN"}
    while not stop.requested:
        now = clock()
        wake = [now + 0.05]
        for t in (teleop.next_send if teleop.active else None, keys.expires()):
            if t is not None and t > now:
                wake.append(t)
        ready = _wait([sys.stdin.fileno(), lfd], min(wake), clock)
        if lfd in ready:
            lc.handle_timeout(0)
        quit_now = False
        while True:
            k = display.getch()
            if k == -1:
                break
            now = clock()
            if k == ord("q"):
                quit_now = True
            elif k == curses.KEY_LEFT:
                keys.press(now, +1)
            elif k == curses.KEY_RIGHT:
                keys.press(now, -1)
            elif k in (curses.KEY_UP, ord(" ")):
                keys.press(now, 0)
            elif k == ord("a"):
                turn = min(teleop.max_rotation, round(turn + 0.1, 2))
            elif k == ord("z"):
                turn = max(0.0, round(turn - 0.1, 2))
            elif k == ord("w"):
                trans = min(teleop.max_translation, round(trans + 0.1, 2))
            elif k == ord("s"):
                trans = max(-teleop.max_translation, round(trans - 0.1, 2))
            elif k in command_keys:
                sent = teleop.command(command_keys[k])
                note = ("sent %s" % command_keys[k]) if sent else "%s not sent: no session" % command_keys[k]
        if quit_now:
            break
        now = clock()
        teleop.step(now, keys.held(now), keys.direction * turn, trans)
        display.show(["B21r teleop: keyboard (deadman held while a driving key repeats, %.1f s after the last)" % hold_s,
                      "deadman %-8s rotation %+.2f rad/s (turn rate %.2f, limit %.2f)  translation %+.2f m/s  %s" %
                      ("HELD" if teleop.active else "released", teleop.rotation if teleop.active else 0.0, turn,
                       teleop.max_rotation, trans, "sending %.0f Hz" % (1.0 / teleop.period) if teleop.active
                       else "not sending"),
                      *state.lines(), note,
                      "hold <-/-> turn, up/space straight | a/z turn rate | w/s translation | c confirm pose | "
                      "2 phase two | p pause | r resume | x shutdown | q quit"])
    teleop.release()
    return 0


def probe(js, stop):
    counts = js.counts()
    print("device %s: name '%s', %s" % (js.path, js.name, "%d axes, %d buttons" % counts if counts else
                                        "no driver counts (FIFO or recording)"), flush=True)
    print("move the sticks and press the buttons (Ctrl-C ends):", flush=True)
    while not stop.requested and not js.lost:
        _wait([None if js.replay else js.fileno()], time.monotonic() + 0.1, time.monotonic)
        for t_ms, value, kind, number in js.read():
            what = "axis" if kind & ~JS_EVENT_INIT == JS_EVENT_AXIS else "button"
            print("%10d ms  %-6s %2d = %6d%s" % (t_ms, what, number, value,
                                                 "  (initial state)" if kind & JS_EVENT_INIT else ""), flush=True)
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lcm-url", default=None, help="LCM provider (default: LCM's default or $LCM_DEFAULT_URL)")
    ap.add_argument("--key", metavar="FILE", help="operator key (default: $B21R_OPERATOR_KEY, else "
                    "~/.config/b21r/operator.key, else /etc/b21r/operator.key)")
    ap.add_argument("--command", choices=sorted(COMMANDS), help="send one operator command and exit")
    ap.add_argument("--wait-s", type=float, default=5.0, metavar="S",
                    help="--command: wait this long for the controller's session (default %(default)s)")
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--joystick", metavar="DEV", help="joystick device, FIFO of js_event records, or a recording "
                     "(default: /dev/input/js0 when present)")
    src.add_argument("--keyboard", action="store_true", help="drive with the keyboard")
    ap.add_argument("--map", default=DEFAULT_MAP, help="gamepad map file (default: %(default)s)")
    ap.add_argument("--pad", help="table of the map file to use (default: the first that matches the device name)")
    ap.add_argument("--max-rotation", type=float, default=1.0, metavar="RADPS",
                    help="rotation limit: the controller's max_rotation_radps (default %(default)s)")
    ap.add_argument("--max-translation", type=float, default=0.8, metavar="MPS",
                    help="translation limit: the controller's max_translation_mps (default %(default)s)")
    ap.add_argument("--rate", type=float, default=20.0, metavar="HZ", help="B21R_TELEOP rate (default %(default)s)")
    ap.add_argument("--key-hold-s", type=float, default=0.6, metavar="S",
                    help="keyboard: the deadman stays held this long after the last driving key (default %(default)s)")
    ap.add_argument("--record", metavar="FILE", help="also write the joystick's js_event records to FILE (a recording "
                    "that --joystick FILE replays)")
    ap.add_argument("--probe", action="store_true", help="print the joystick's name and every axis/button event")
    ap.add_argument("--no-ui", action="store_true", help="print state changes as lines instead of a full-screen view")
    args = ap.parse_args(argv)
    for name, v, hi in (("--max-rotation", args.max_rotation, 4.0), ("--max-translation", args.max_translation, 2.0),
                        ("--rate", args.rate, 100.0), ("--key-hold-s", args.key_hold_s, 5.0),
                        ("--wait-s", args.wait_s, 60.0)):
        if not 0.0 < v <= hi:
            ap.error("%s must be in (0, %g]" % (name, hi))

    try:
        key = b21r_opauth.load_key(b21r_opauth.find_key_path(args.key))
    except b21r_opauth.KeyFileError as exc:
        sys.exit("b21r_teleop: %s" % exc)
    lc = lcm.LCM(args.lcm_url) if args.lcm_url else lcm.LCM()
    sessions = b21r_opauth.SessionTracker(lc, key)
    signer = b21r_opauth.Signer(lc, key, sessions)
    if args.command:
        deadline = time.monotonic() + args.wait_s
        while sessions.current() is None and time.monotonic() < deadline:
            lc.handle_timeout(50)
        if not send_command(signer, args.command):
            sys.exit("b21r_teleop: %s not sent: %s" % (args.command, sessions.describe()))
        return 0

    stop = Stop()
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    joystick = args.joystick
    if joystick is None and not args.keyboard:
        found = sorted(glob.glob("/dev/input/js*"))
        joystick = found[0] if found else None
    if args.probe:
        if joystick is None:
            ap.error("--probe needs a joystick (none under /dev/input/js*; give --joystick DEV)")
        return probe(Joystick(joystick), stop)

    teleop = Teleop(lc, args.max_rotation, args.max_translation, args.rate, signer)
    state = ControllerState(lc, sessions)
    tty = sys.stdin.isatty() and sys.stdout.isatty() and not args.no_ui
    if joystick is None:
        if not tty:
            sys.exit("b21r_teleop: no joystick under /dev/input/js* and no terminal for the keyboard mode")
        display = CursesDisplay()
        try:
            return keyboard_loop(lc, teleop, state, display, stop, args.key_hold_s)
        finally:
            display.close()
    try:
        record = open(args.record, "wb") if args.record else None
        js = Joystick(joystick, record=record)
        pad = load_pad_map(args.map, js.name, args.pad)
    except (OSError, ConfigError) as exc:
        sys.exit("b21r_teleop: %s" % exc)
    display = CursesDisplay() if tty else LineDisplay()
    try:
        return gamepad_loop(lc, js, pad, teleop, state, display, stop, exit_when_lost=js.replay)
    finally:
        display.close()
        js.close()
        if record is not None:
            record.close()


if __name__ == "__main__":
    sys.exit(main())
