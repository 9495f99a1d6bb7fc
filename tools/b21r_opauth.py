# SPDX-License-Identifier: MIT
"""b21r_opauth: the operator's side of authenticated B21R_TELEOP / B21R_COMMAND (docs/robot.md,
"Network and security"; the controller's side is firmware/core/include/fw/opauth.h).

The operator key is 32 random bytes written as 64 hexadecimal digits in a file that only its
owner may read (mode 600). The controller announces its session on B21R_SESSION (a random nonce
per start, the key's id, signed); every operator message carries the key id, that nonce, a seq
and mac = HMAC-SHA256(key, channel name + b"\\0" + the message encoded with mac all zero).

Library use (the teleop tool, the session launcher, tests):
    key = load_key(find_key_path(args.key))       # KeyFileError names the fix
    sessions = SessionTracker(lc, key)             # follows B21R_SESSION
    signer = Signer(lc, key, sessions)
    signer.publish("B21R_COMMAND", msg)            # seq, key_id, session, mac filled in; False: no session yet
"""
import hashlib
import hmac
import os
import secrets
import stat
import time

KEY_BYTES = 32
KEY_ID_BYTES = 8
NONCE_BYTES = 16
MAC_BYTES = 32
SYSTEM_KEY = "/etc/b21r/operator.key"
# A session whose controller has not announced it for this long is given up for a newer one,
# even one that says it started earlier (the robot's clock may have been set back).
SESSION_SILENCE_S = 3.0


class KeyFileError(Exception):
    """A key file that cannot be used; the text names the file and the fix."""


def user_key_path():
    """The operator's own key file: $XDG_CONFIG_HOME/b21r/operator.key (~/.config by default)."""
    base = os.environ.get("XDG_CONFIG_HOME") or os.path.join(os.path.expanduser("~"), ".config")
    return os.path.join(base, "b21r", "operator.key")


def find_key_path(explicit=None):
    """Where the tools look for the key: --key FILE, else $B21R_OPERATOR_KEY, else the user's key
    file when it exists, else /etc/b21r/operator.key when it exists, else the user's (to create)."""
    if explicit:
        return explicit
    env = os.environ.get("B21R_OPERATOR_KEY")
    if env:
        return env
    user = user_key_path()
    if not os.path.exists(user) and os.path.exists(SYSTEM_KEY):
        return SYSTEM_KEY
    return user


def load_key(path):
    """The key in path (bytes), checked as the controller checks its operator_key_file: a regular
    file of the effective user or root, no permission for group or others, 64 hex digits."""
    hint = "create one with: tools/b21r_key.py create %s" % path
    try:
        fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    except FileNotFoundError:
        raise KeyFileError("operator key %s: no such file; %s (the controller's operator_key_file must hold the "
                           "same key)" % (path, hint))
    except OSError as exc:
        raise KeyFileError("operator key %s: %s" % (path, exc.strerror))
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise KeyFileError("operator key %s: not a regular file; %s" % (path, hint))
        if st.st_uid not in (os.geteuid(), 0):
            raise KeyFileError("operator key %s belongs to uid %d: it must be yours (uid %d) or root's: chown %d %s"
                               % (path, st.st_uid, os.geteuid(), os.geteuid(), path))
        if st.st_mode & 0o077:
            raise KeyFileError("operator key %s has mode %04o: group or others may access it, so the key is not "
                               "secret; chmod 600 %s (and make a new key if others may have read it)"
                               % (path, stat.S_IMODE(st.st_mode), path))
        text = os.read(fd, 200).decode("ascii", errors="replace").rstrip("\r\n")
    finally:
        os.close(fd)
    try:
        key = bytes.fromhex(text) if len(text) == 2 * KEY_BYTES else None
    except ValueError:
        key = None
    if key is None:
        raise KeyFileError("operator key %s: expected %d hexadecimal digits (a %d-byte key) and a newline; %s"
                           % (path, 2 * KEY_BYTES, KEY_BYTES, hint))
    return key


def create_key(path, replace=False):
    """Writes a new random key to path (mode 600, its folder made with mode 700 when missing) and
    returns it. An existing file is kept unless replace (then it is replaced atomically)."""
    if os.path.exists(path) and not replace:
        raise KeyFileError("operator key %s exists already (--force replaces it: a new key, the old one "
                           "stops working)" % path)
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, mode=0o700, exist_ok=True)
    key = secrets.token_bytes(KEY_BYTES)
    tmp = "%s.tmp%d" % (path, os.getpid())
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
    try:
        os.fchmod(fd, 0o600)  # whatever the umask
        os.write(fd, (key.hex() + "\n").encode())
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    dfd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)
    return key


def key_id(key):
    """The key's id: the first 8 bytes of its SHA-256."""
    return hashlib.sha256(key).digest()[:KEY_ID_BYTES]


def mac(key, channel, msg):
    """The mac msg should carry on channel: HMAC-SHA256 over the channel's name, a zero byte and
    msg encoded with its mac all zero (msg itself is left as it was)."""
    saved = msg.mac
    msg.mac = bytes(MAC_BYTES)
    try:
        data = msg.encode()
    finally:
        msg.mac = saved
    return hmac.new(key, channel.encode() + b"\0" + data, hashlib.sha256).digest()


def sign(key, channel, msg):
    """Sets msg.mac for key and returns msg's encoding."""
    msg.mac = mac(key, channel, msg)
    return msg.encode()


def session_valid(key, session):
    """True when a decoded session_t was signed with key."""
    return hmac.compare_digest(mac(key, "B21R_SESSION", session), bytes(session.mac))


class SessionTracker:
    """Follows B21R_SESSION on lc: the newest valid announcement (by the controller's start time)
    is the current session; one signed with another key, or not at all, is ignored (counted), and
    so is an older session while the current one is still announced (a replayed announcement
    cannot take the operator back to a dead session)."""

    def __init__(self, lc, key, clock=time.monotonic):
        from b21r import session_t
        self._type = session_t
        self.key = key
        self.key_id = key_id(key)
        self.clock = clock
        self.nonce = None
        self.started_us = None
        self.seen = None
        self.changes = 0
        self.other_key = None   # key id of the newest announcement signed with another key
        self.refused = 0        # announcements not taken (another key, a wrong mac, an older session)
        lc.subscribe("B21R_SESSION", self._on_session)

    def _on_session(self, channel, data):
        try:
            s = self._type.decode(data)
        except ValueError:
            self.refused += 1
            return
        now = self.clock()
        if bytes(s.key_id) != self.key_id:
            self.other_key = bytes(s.key_id)
            self.refused += 1
            return
        if not session_valid(self.key, s):
            self.refused += 1
            return
        nonce = bytes(s.nonce)
        if nonce == self.nonce:
            self.seen = now
            return
        current_alive = self.seen is not None and now - self.seen < SESSION_SILENCE_S
        if self.nonce is not None and current_alive and s.started_us <= self.started_us:
            self.refused += 1
            return
        self.nonce, self.started_us, self.seen = nonce, s.started_us, now
        self.changes += 1

    def current(self):
        """The current session nonce (bytes), or None before the first valid announcement."""
        return self.nonce

    def describe(self):
        if self.nonce is not None:
            age = self.clock() - self.seen
            return "session %s (key id %s)%s" % (self.nonce.hex()[:8], self.key_id.hex(),
                                                 "  (not announced for %.0f s)" % age if age > 2.0 else "")
        if self.other_key is not None:
            return ("no session: the controller's key id is %s, yours %s (use the controller's key, its "
                    "operator_key_file)" % (self.other_key.hex(), self.key_id.hex()))
        return "no session yet: waiting for B21R_SESSION (is b21r-controller running with operator_key_file, " \
               "with LCM on this URL?)"


class Signer:
    """Signs and publishes operator messages for the current session. seq starts from the wall
    clock in µs when the signer is made (so a restarted tool goes on above the seqs it sent
    before). On B21R_TELEOP it then counts the messages, one up each, so that the controller's
    window of 64 covers the last 64 (a joystick drives from one tool at a time). On B21R_COMMAND it
    is the wall clock in µs (one up at least), so that the commands of several tools keep their
    order even where one tool does not hear the other (a person at the robot confirming the start
    pose with ttl=0 while a remote operator's tool runs: the remote PAUSE that follows is newer).
    The tools' clocks must agree to well under the time between two commands (NTP). A signer that
    hears an authentic message of the current session on its channels (another tool's) also moves
    its own seq above it; a forged one cannot move it (its mac is checked)."""

    CHANNELS = ("B21R_TELEOP", "B21R_COMMAND")
    CLOCKED = ("B21R_COMMAND",)

    def __init__(self, lc, key, sessions, wall=time.time):
        from b21r import command_t, teleop_t
        self.lc = lc
        self.key = key
        self.key_id = key_id(key)
        self.sessions = sessions
        self.wall = wall
        start = int(wall() * 1e6)
        self.last_seq = {ch: start for ch in self.CHANNELS}
        self._types = {"B21R_TELEOP": teleop_t, "B21R_COMMAND": command_t}
        for ch in self.CHANNELS:
            lc.subscribe(ch, self._on_heard)

    def _on_heard(self, channel, data):
        try:
            m = self._types[channel].decode(data)
        except (ValueError, KeyError):
            return
        if m.seq <= self.last_seq[channel] or bytes(m.key_id) != self.key_id or \
                bytes(m.session) != self.sessions.current() or \
                not hmac.compare_digest(mac(self.key, channel, m), bytes(m.mac)):
            return
        self.last_seq[channel] = m.seq

    def next_seq(self, channel):
        seq = self.last_seq[channel] + 1
        if channel in self.CLOCKED:
            seq = max(seq, int(self.wall() * 1e6))
        self.last_seq[channel] = seq
        return seq

    def publish(self, channel, msg):
        """Fills msg's seq, key_id, session and mac and publishes it. Returns False (nothing sent)
        while there is no session."""
        nonce = self.sessions.current()
        if nonce is None:
            return False
        msg.seq = self.next_seq(channel)
        msg.key_id = self.key_id
        msg.session = nonce
        self.lc.publish(channel, sign(self.key, channel, msg))
        return True
