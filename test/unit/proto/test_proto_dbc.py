# SPDX-License-Identifier: MIT
"""The DBC file and the C CANopen encoder agree: every frame the C code encodes decodes with
cantools to the signal values the C code put in (raw, the controlword and statusword as their
CiA 402 bit fields), cantools re-encodes the same bytes, and every message of the DBC is
exercised; velocities and positions carry SI units with the drives' scales, and the value tables
name the CiA 402 states, the device control commands and the EMCY codes the drives send; the
bump-panel node's TPDO1 carries the 14 panels in the rFLEX numbering.

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
                decoded = self.db.decode_message(frame_id, data, decode_choices=False, scaling=False)
                self.assertEqual({k: int(v) for k, v in decoded.items()}, signals)

    def test_each_frame_reencodes_identically(self):
        # cantools encodes the same signal values to the same bytes (layout agrees both ways).
        for name, frame_id, data, signals in self.frames:
            with self.subTest(frame=name, id=hex(frame_id)):
                self.assertEqual(self.db.encode_message(frame_id, signals, scaling=False), data)

    def test_units_and_scales_are_the_drives(self):
        # SI units with the emulator's and the controller's default drive scales.
        for axis, unit, counts in (("Trans", "m", 103000.0), ("Rot", "rad", 35000.0)):
            for msg, sig, u in ((f"TPDO1_{axis}", "VelocityActual", unit + "/s"),
                                (f"RPDO1_{axis}", "TargetVelocity", unit + "/s"),
                                (f"TPDO2_{axis}", "PositionActual", unit)):
                s = self.db.get_message_by_name(msg).get_signal_by_name(sig)
                self.assertEqual(s.unit, u)
                self.assertAlmostEqual(s.scale * counts, 1.0, places=12)
        # 1 m/s forward = 103000 counts/s
        frame = self.db.encode_message("RPDO1_Trans", {"Command": 15, "OpModeSpecific": 0, "FaultReset": 0,
                                                       "Halt": 0, "ControlwordHigh": 0, "TargetVelocity": 1.0})
        self.assertEqual(frame, bytes.fromhex("0f00") + (103000).to_bytes(4, "little", signed=True))

    def test_value_tables_name_cia402_states_commands_and_emcy_codes(self):
        def name(msg, sig, raw):
            return self.db.get_message_by_name(msg).get_signal_by_name(sig).choices[raw]
        # Statusword 0x0237 (operation enabled, voltage on, remote) and 0x0218 (fault).
        d = self.db.decode_message(0x181, bytes.fromhex("3702") + bytes(4))
        self.assertEqual((str(d["DriveState"]), str(d["Remote"])), ("operation_enabled", "remote"))
        d = self.db.decode_message(0x182, bytes.fromhex("1802") + bytes(4))
        self.assertEqual(str(d["DriveState"]), "fault")
        for raw, state in ((0x00, "not_ready_to_switch_on"), (0x40, "switch_on_disabled"), (0x21, "ready_to_switch_on"),
                           (0x23, "switched_on"), (0x27, "operation_enabled"), (0x07, "quick_stop_active"),
                           (0x0F, "fault_reaction_active"), (0x08, "fault"), (0x31, "ready_to_switch_on")):
            self.assertEqual(name("TPDO1_Trans", "DriveState", raw), state)
        for raw, cmd in ((0x06, "shutdown"), (0x07, "switch_on_or_disable_operation"), (0x0F, "enable_operation"),
                         (0x02, "quick_stop"), (0x00, "disable_voltage")):
            self.assertEqual(name("RPDO1_Rot", "Command", raw), cmd)
        self.assertEqual(name("RPDO1_Rot", "FaultReset", 1), "fault_reset")
        # The codes the emulated drives send.
        self.assertEqual(name("EMCY_Trans", "ErrorCode", 0x2310), "continuous_over_current")
        self.assertEqual(name("EMCY_Rot", "ErrorCode", 0x0000), "no_error_or_reset")

    def test_bump_panel_node_has_one_mapping_for_both_bases(self):
        # CiA 401 node 16: TPDO1 0x190 with 14 four-bit panels at bit 4p (panel p = rFLEX DIO
        # 0x40 + p), its heartbeat 0x710, started by the controller's NMT like the drives.
        msg = self.db.get_message_by_frame_id(0x190)
        self.assertEqual((msg.name, msg.length, msg.senders), ("TPDO1_Bumpers", 7, ["BumpPanels"]))
        self.assertEqual([s.name for s in msg.signals], ["BumpPanel%02d" % p for p in range(14)])
        for p, s in enumerate(msg.signals):
            with self.subTest(panel=p):
                self.assertEqual((s.start, s.length, s.is_signed, s.byte_order), (4 * p, 4, False, "little_endian"))
                self.assertEqual(s.choices[0], "released")
                self.assertEqual(s.choices[15], "all_segments")
                self.assertIn("DIO 0x%02X" % (0x40 + p), s.comment)
                self.assertIn("upper enclosure" if p < 6 else "base skirt", s.comment)
        self.assertIn("every 100 ms", msg.comment)
        self.assertEqual(self.db.get_message_by_frame_id(0x710).name, "Heartbeat_Bumpers")
        self.assertIn("BumpPanels", self.db.get_message_by_name("NMT").get_signal_by_name("NMT_Command").receivers)
        # Panel 3 fully pressed, skirt panel 0 (panel 6) on segment 1.
        d = self.db.decode_message(0x190, bytes.fromhex("00f00002000000"))
        self.assertEqual(str(d["BumpPanel03"]), "all_segments")
        self.assertEqual(str(d["BumpPanel06"]), "segment_1")
        self.assertEqual(sum(1 for v in d.values() if str(v) == "released"), 12)

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
