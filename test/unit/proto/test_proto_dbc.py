# SPDX-License-Identifier: MIT
"""The DBC file and the C CANopen encoder agree: every frame the C code encodes decodes with
cantools to the signal values the C code put in, cantools re-encodes the same bytes, and every
message of the DBC is exercised.

Usage: test_proto_dbc.py <b21r_canopen.dbc> <dir with canopen_frames.txt from proto.canopen>
"""
import pathlib
import sys
import unittest

import cantools

DBC_PATH = None
FRAMES_PATH = None


def load_frames():
    """Parses '<name> <0xID> <hex data> sig=value ...' lines written by test_proto_canopen."""
    frames = []
    for line in FRAMES_PATH.read_text().splitlines():
        parts = line.split()
        if not parts:
            continue
        name, frame_id = parts[0], int(parts[1], 16)
        rest = parts[2:]
        data = b""
        if rest and "=" not in rest[0]:
            data = bytes.fromhex(rest[0])
            rest = rest[1:]
        signals = {k: int(v) for k, v in (item.split("=", 1) for item in rest)}
        frames.append((name, frame_id, data, signals))
    return frames


class DbcAgreesWithEncoder(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.db = cantools.database.load_file(str(DBC_PATH))
        cls.frames = load_frames()

    def test_frames_present(self):
        # The C test wrote a non-trivial set of frames.
        self.assertGreater(len(self.frames), 50)

    def test_each_frame_decodes_to_encoded_signals(self):
        # cantools decodes the C encoder's bytes to the values the C code encoded.
        for name, frame_id, data, signals in self.frames:
            with self.subTest(frame=name, id=hex(frame_id), data=data.hex()):
                msg = self.db.get_message_by_frame_id(frame_id)
                self.assertEqual(msg.name, name)
                self.assertEqual(msg.length, len(data), "DLC differs from the DBC")
                decoded = self.db.decode_message(frame_id, data, decode_choices=False)
                self.assertEqual({k: int(v) for k, v in decoded.items()}, signals)

    def test_each_frame_reencodes_identically(self):
        # cantools encodes the same signal values to the same bytes (layout agrees both ways).
        for name, frame_id, data, signals in self.frames:
            with self.subTest(frame=name, id=hex(frame_id)):
                self.assertEqual(self.db.encode_message(frame_id, signals), data)

    def test_every_dbc_message_exercised(self):
        # No DBC message lacks a C encoder counterpart, and no C frame lacks a DBC message.
        dbc_names = {m.name for m in self.db.messages}
        c_names = {f[0] for f in self.frames}
        self.assertEqual(dbc_names, c_names)


def main():
    global DBC_PATH, FRAMES_PATH
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    DBC_PATH = pathlib.Path(sys.argv[1])
    FRAMES_PATH = pathlib.Path(sys.argv[2]) / "canopen_frames.txt"
    if not FRAMES_PATH.exists():
        print(f"missing {FRAMES_PATH}: run the proto.canopen test first", file=sys.stderr)
        return 1
    result = unittest.main(argv=[sys.argv[0], "-v"], exit=False).result
    return 0 if result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
