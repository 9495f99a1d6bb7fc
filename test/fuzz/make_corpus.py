#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Writes the seed corpus of the fuzz targets (test/fuzz/corpus/<target>/): valid telegrams,
packets and frames from the protocol facts of protocols.md, plus a few damaged variants; the
reference config, ready lines, worlds, control commands and operator messages; record streams
for the driver and loop targets (their formats are described in each fuzz_<target>.c).
Deterministic; re-run after changing a format so the seeds stay meaningful. The checkpoint seeds
come from the target itself: B21R_FUZZ_SEEDS_OUT=test/fuzz/corpus/checkpoint fuzz_checkpoint."""
import functools
import pathlib
import struct

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent.parent


def sick_crc(data: bytes) -> int:
    crc, prev = 0, 0
    for cur in data:
        crc = (((crc & 0x7FFF) << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1) & 0xFFFF
        crc ^= cur | (prev << 8)
        prev = cur
    return crc


def telegram(adr: int, cmd: int, data: bytes, status=None) -> bytes:
    body = bytes([cmd]) + data + (bytes([status]) if status is not None else b"")
    head = bytes([0x02, adr]) + struct.pack("<H", len(body)) + body
    return head + struct.pack("<H", sick_crc(head))


def rflex(port: int, ident: int, opcode: int, data: bytes, stuff: bool) -> bytes:
    body = bytes([port, ident, opcode, len(data)]) + data
    body += bytes([functools.reduce(lambda a, b: a ^ b, body, 0)])
    if stuff:
        body = body.replace(b"\x1b", b"\x1b\x00")
    return b"\x1b\x02" + body + b"\x1b\x03"


def can(frame_id: int, data: bytes) -> bytes:
    return struct.pack("<HB", frame_id, len(data)) + data.ljust(8, b"\x00")


def write(target: str, name: str, data: bytes) -> None:
    d = HERE / "corpus" / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data)


def main() -> None:
    # LMS200: first byte = chunk size selector; then a byte stream.
    scan3 = bytes.fromhex("02 80 0a 00 b0 03 00 e8 03 ff 1f c4 09 00 90 eb")
    vals = b"".join(struct.pack("<H", (i * 37) % 8192) for i in range(181))
    scan181 = telegram(0x80, 0xB0, struct.pack("<H", 181 | (1 << 14)) + vals, 0)
    write("lms200", "scan_vector", b"\x00" + b"\x06" + scan3)
    write("lms200", "scan_181_mm", b"\x05" + scan181)
    write("lms200", "replies", b"\x03" + b"\x06" + telegram(0x80, 0xA0, b"\x00", 0)
          + b"\x15" + telegram(0x80, 0xBA, b"LMS200;30106", 0)
          + telegram(0x80, 0xBB, b"\x01\xb4\x00\x64\x00", 0)
          + telegram(0x80, 0xF4, bytes(7) + bytes(25), 0)
          + telegram(0x80, 0xB1, bytes(152), 0) + telegram(0x80, 0x92, b"", 0))
    write("lms200", "requests", b"\x01" + bytes.fromhex(
        "02 00 02 00 20 25 35 08 02 00 02 00 20 40 50 08 02 00 01 00 3a 1e 12"
        "02 00 05 00 3b b4 00 32 00 3b 1f") + telegram(0x00, 0x20, b"\x00SICK_LMS")
        + telegram(0x00, 0x77, bytes(32)) + telegram(0x00, 0x30, b"\x01"))
    write("lms200", "garbage_and_false_starts", b"\x07" + b"\x02\x02\x80\xff\x7f\x55\x02\x80\x28\x00"
          + telegram(0x80, 0x92, b"", 7) + b"\x33" * 40)
    # rFLEX: first byte = chunk size selector; then device and host packets.
    ex = [
        "1b 02 02 00 07 0e 00 00 00 c9 2c 00 01 19 a4 00 00 75 30 01 16 1b 03",
        "1b 02 02 00 07 0e 01 00 00 29 04 00 01 86 a0 00 00 88 b8 01 31 1b 03",
        "1b 02 02 00 0c 00 0e 1b 03", "1b 02 02 00 0b 00 09 1b 03", "1b 02 02 00 0a 00 08 1b 03",
        "1b 02 01 00 01 00 00 1b 03", "1b 02 02 00 22 08 00 01 86 a0 00 00 00 03 0c 1b 03",
        "1b 02 05 00 00 04 00 01 86 a0 26 1b 03",
        "1b 02 04 04 00 0d 00 00 75 30 00 00 00 00 00 00 00 00 02 4a 1b 03",
    ]
    write("rflex", "worked_examples", b"\x04" + b"".join(bytes.fromhex(h) for h in ex))
    motor = struct.pack(">IIBiiII", 0, 0x1B1B, 1, -0x1B1B, 27, 0, 0)
    write("rflex", "stuffed_reports", b"\x02" + rflex(2, 3, 33, motor, True)
          + rflex(1, 4, 1, struct.pack(">IIB", 5, 2480, 1), True)
          + rflex(5, 5, 1, struct.pack(">IBH", 9, 0x45, 0x0B), True))
    raw = rflex(2, 0, 7, struct.pack(">BIIIB", 0, 0x1B1B, 0x1B, 30000, 1), False) \
        + b"\x1b\x02\x1b\x02\x02\x00\x0a\x1b\x01\x00\x08\x1b\x03" + b"\x1b\x1b\x02\x09\x00" \
        + rflex(6, 0, 1, bytes(range(40)), True)
    write("rflex", "raw_esc_and_filler", b"\x09" + raw)  # host role: the raw packet is refused
    write("rflex", "raw_esc_device_role", b"\x89" + raw)  # device role (byte 0 bit 7)
    # CANopen: 11-byte records (id u16 LE, dlc, 8 data bytes).
    write("canopen", "enable_sequence", b"".join([
        can(0x000, b"\x01\x00"), can(0x080, b""), can(0x201, b"\x06\x00\x00\x00\x00\x00"),
        can(0x181, b"\x31\x02\x00\x00\x00\x00"), can(0x201, b"\x07\x00\x00\x00\x00\x00"),
        can(0x181, b"\x33\x02\x00\x00\x00\x00"), can(0x201, b"\x0f\x00\x2c\xc9\x00\x00"),
        can(0x181, b"\x37\x02\x2c\xc9\x00\x00"), can(0x281, b"\x10\x27\x00\x00"),
        can(0x701, b"\x05"), can(0x081, b"\x10\x23\x03\x00\x00\x00\x00\x00"),
        can(0x201, b"\x80\x00\x00\x00\x00\x00"), can(0x182, b"\x18\x02\x00\x00\x00\x00")]))
    # The CiA 401 bump-panel node (16): boot-up, NMT start, TPDO1 released / panels 3 and 6 / short.
    write("canopen", "bump_panel_node", b"".join([
        can(0x710, b"\x00"), can(0x000, b"\x01\x10"), can(0x190, bytes(7)),
        can(0x190, b"\x00\xf0\x00\x02\x00\x00\x00"), can(0x710, b"\x05"), can(0x190, b"\xff" * 6)]))


def can_record(can_id: int, data: bytes, dlc=None) -> bytes:
    """A struct can_frame (16 bytes) as one length-prefixed record of fuzz_can_read."""
    frame = struct.pack("<IB3x", can_id, len(data) if dlc is None else dlc) + data.ljust(8, b"\x00")
    return bytes([len(frame)]) + frame


def progress(task: int, state_dim: int, phase: int, p1: int, p2: int, blocks: int, ex_runs: int,
             ex_sum: float, best: int, run_id: int) -> bytes:
    body = b"FWMETA02" + struct.pack("<IIIIIIIIdII", task, state_dim, phase, p1 + p2, p1, p2, blocks,
                                     ex_runs, ex_sum, best, run_id + 1)
    assert len(body) == 56
    return body


def progress_v4(task: int, state_dim: int, phase: int, p1: int, p2: int, blocks: int, ex_runs: int,
                ex_sum: float, best: int, run_id: int, policy: int, actor_bytes: int, saved: float,
                pairs: int) -> bytes:
    """Revision 4 (the controller's today): policy 0 actor, 1 greedy, 2 select with its ranked pairs."""
    body = progress(task, state_dim, phase, p1, p2, blocks, ex_runs, ex_sum, best, run_id)
    body = b"FWMETA04" + body[8:] + struct.pack("<IIQdII", policy, 0, actor_bytes, saved, pairs, 0)
    assert len(body) == 88
    return body


def progress_v1(task: int, state_dim: int, phase: int, p1: int, p2: int, blocks: int, ex_runs: int,
                ex_sum: float, best: int, run_id: int, shift=(0.0, 0.0, 0), terms: int = 1,
                imitation: float = 0.0, clearance: float = 0.0, pass_hold=None) -> bytes:
    """Revision 1 of the section (older controllers', with their policy shift), still read."""
    body = b"FWMETA01" + struct.pack("<IIIIIIIIdIIddIIdd", task, state_dim, phase, p1 + p2, p1, p2, blocks,
                                     ex_runs, ex_sum, best, run_id + 1, *shift, terms, imitation, clearance)
    assert len(body) == 96
    if pass_hold is not None:  # a section that records the hold past the obstacle (104 bytes)
        body += struct.pack("<II", pass_hold + 1, 0)
    return body


def teleop(seq: int, deadman: bool, rot: float, trans: float, offset_ms: int) -> bytes:
    return b"\x00" + struct.pack("<qBddh", seq, int(deadman), rot, trans, offset_ms)


def command(seq: int, cmd: int, arg: int = 0) -> bytes:
    return b"\x01" + struct.pack("<Hbi", seq, cmd, arg)


def ticks(n: int) -> bytes:
    return bytes([2, n - 1])


def more_seeds() -> None:
    # Config: the reference file, and --set arguments (byte 0 picks the form).
    ref = (ROOT / "firmware/app/b21r-controller.conf").read_bytes()
    write("config", "reference_file", b"\x00" + ref)
    write("config", "small_file", b"\x00" + b"task = obstacles\n# comment\nlog_file = \"out dir/#1\"  # c\n"
          b"hedger_input_scale = 1, 2,3 ,4,0.5\nlaser_resolution_deg = 0.25\nlaser_fov_deg = 100\n")
    write("config", "set_args", b"\x01" + b"\n".join([
        b"tick_rate_hz=20", b"lockstep = true", b"seed=18446744073709551615", b"hedger_k_min=70",
        b"checkpoint_file=/tmp/h.ckpt", b"max_rotation_radps=0", b"gamma=-0", b"nokey=1", b"=1",
        b"phase_switch=auto", b"hedger_input_scale=", b"alpha=1e-320"]))
    # --endpoints: b21r-sim's ready lines.
    write("endpoints", "rflex", b"laser=/dev/pts/5 base=/dev/pts/6 control=/tmp/b21r.ctl\n")
    write("endpoints", "canopen", b"laser=/dev/pts/7\tcan=/tmp/b21r.can control=/tmp/c.ctl world=x\n")
    write("endpoints", "bad", b"laser= base=/dev/pts/1 can")
    # Checkpoint controller sections.
    write("progress", "fresh", progress(0, 3, 1, 0, 0, 0, 0, 0.0, 0, -1))
    write("progress", "phase_two", progress(1, 4, 2, 30, 12, 9, 27, 27 * 130.0 + 17, 126, 130))
    write("progress", "bad_phase", progress(0, 3, 7, 3, 0, 1, 2, 300.0, 140, 5))
    write("progress", "v4_select", progress_v4(1, 5, 2, 30, 12, 9, 27, 27 * 130.0 + 17, 126, 130, 2, 5484992,
                                               -37.0, 6))
    write("progress", "v4_greedy", progress_v4(0, 4, 2, 30, 35, 13, 30, 30 * 139.0, 127, 194, 1, 0, 0.0, 0))
    write("progress", "v1_phase_two", progress_v1(1, 4, 2, 30, 12, 9, 27, 27 * 130.0 + 17, 126, 130))
    write("progress", "v1_shifted", progress_v1(0, 4, 2, 30, 35, 13, 30, 30 * 139.0, 127, 194, (1.0625, 1.5, 17)))
    write("progress", "v1_obstacle_pass_hold", progress_v1(1, 5, 2, 30, 35, 13, 30, 30 * 139.0, 127, 194,
                                                           (1.0625, 1.5, 17), 1, -0.625, 0.4, 10))
    # Worlds: the ones the product ships.
    for w in sorted((ROOT / "sim/worlds").glob("*.world")):
        write("world", w.stem, w.read_bytes())
    write("world", "edge_cases", b"b21r-world 1\nname x.y-z_1\narena -1e6 -1e6 1e6 1e6\n"
          b"wall 0 0 1e-300 1 0.1 # thin\ncylinder 3 3 1e-9\ngoal 1 1 0.5\nstart 0 0 -7\nbounds -2 -2 2 2\n")
    # Emulator control commands (byte 0: bit 0 = CANopen emulator, bits 1..7 = reply capacity).
    cmds = b"pose\nstatus\nreset 1.5 0.2 0.3\nfault laser_drop 1500\nfault corrupt 0.1\n" \
           b"fault base_silent 200\nfault latency 200\nfault bumper 3\nfault bumper 0x4d\n" \
           b"fault drive_fault 2\nfault bumper_silent 500\nfault clear\nreset nan 0 0\nfault\nquit\n"
    write("emu_control", "rflex_commands", b"\x00" + cmds)
    write("emu_control", "canopen_commands", b"\x01" + cmds)
    write("emu_control", "short_replies", b"\x07" + cmds)
    # LMS200 driver: the scanner's side of a whole start-up, then scans (op 0 = bytes, 1 = time).
    def dev(b: bytes) -> bytes:
        out = b""
        for i in range(0, len(b), 200):
            out += bytes([0, len(b[i:i + 200])]) + b[i:i + 200]
        return out
    ok = b"\x06" + telegram(0x80, 0xA0, b"\x00", 0)
    vals = b"".join(struct.pack("<H", (i * 37) % 8192) for i in range(181))
    scan = telegram(0x80, 0xB0, struct.pack("<H", 181) + vals, 0)
    # A first step with no bytes: the driver sends its request, then each reply answers one.
    start_up = (b"\x01\x00\x00" + dev(ok) + dev(ok) + dev(b"\x06" + telegram(0x80, 0xBA, b"LMS200;30106", 0)) + dev(ok)
                + dev(b"\x06" + telegram(0x80, 0xBB, b"\x01\xb4\x00\x64\x00", 0))
                + dev(b"\x06" + telegram(0x80, 0xF4, bytes(32), 0)) + dev(ok))
    write("lms200_driver", "start_up_and_scans", start_up + dev(scan) + dev(scan) + b"\x01\x64\x00" + dev(scan))
    write("lms200_driver", "timeouts_and_naks", b"\x01\xb8\x0b" + dev(b"\x15") + b"\x01\x10\x27" + dev(ok)
          + b"\x02" + dev(b"\x06" + telegram(0x80, 0x92, b"", 0)) + b"\x03")
    # CAN records (byte 0: 0 = emulated bus, 1 = SocketCAN): good frames, extended / RTR / error
    # ids, DLC 9, short, long and empty records.
    write("can_read", "mixed_records", b"\x00" + can_record(0x181, bytes(6)) + can_record(0x701, b"\x05")
          + can_record(0x80000123, bytes(8)) + can_record(0x40000181, b"") + can_record(0x20000004, bytes(8))
          + can_record(0x181, bytes(8), dlc=9) + bytes([8]) + bytes(8) + bytes([20]) + bytes(20)
          + can_record(0x081, b"\x10\x23\x03\x00\x00\x00\x00\x00"))
    write("can_read", "socketcan_records", b"\x01" + can_record(0x701, b"\x05") + bytes([0])
          + can_record(0x80000001, bytes(8)) + can_record(0x202, bytes(6)))
    # Operator messages through the loop (op 0 TELEOP, 1 COMMAND, 2 ticks, 3 signal).
    drive = b"".join(teleop(i, True, 0.1 * (i % 5) - 0.2, 0.3, 0) + ticks(1) for i in range(1, 40))
    write("loop_commands", "joystick_drive", drive)
    write("loop_commands", "operator_commands", ticks(16) + command(1, 3) + ticks(4) + command(2, 4) + ticks(4)
          + command(3, 1) + ticks(8) + command(3, 2) + command(4, 2) + ticks(8) + command(5, 5) + ticks(2))
    write("loop_commands", "bad_teleops", teleop(5, True, float("nan"), 0.0, 0) + teleop(4, True, 0.1, 0.0, 0)
          + teleop(6, True, 9.0, 0.0, 0) + teleop(7, True, 0.1, 0.0, -5000) + ticks(3) + b"\x03")
    # Base input: genuine data (op 1) with injected packets / frames (op 0) and gaps (op 2).
    genuine = b"\x01" * 40
    motor = struct.pack(">IIBiiII", 0, 0x1B1B, 1, -0x1B1B, 27, 0, 0)
    pk = rflex(2, 3, 33, motor, True) + rflex(5, 5, 1, struct.pack(">IBH", 9, 0x45, 0x0B), True) \
        + rflex(1, 4, 1, struct.pack(">IIB", 5, 2480, 1), True)
    write("base_dispatch", "rflex_injected", b"\x00" + genuine + bytes([0, len(pk)]) + pk + genuine + b"\x02" * 8
          + genuine)
    frames = b"".join(b"\x00" + struct.pack("<HB", i, d) + data.ljust(8, b"\x00") for i, d, data in [
        (0x081, 8, b"\x10\x23\x03"), (0x181, 6, b"\x08\x02"), (0x701, 1, b"\x04"), (0x281, 4, b"\xff\xff\xff\x7f"),
        (0x190, 7, b"\x00\x00\x00\x03"), (0x190, 6, b"\xff"), (0x710, 1, b"\x00"), (0x191, 7, b"\xff" * 7)])
    write("base_dispatch", "canopen_injected", b"\x01" + genuine + frames + genuine + b"\x02" * 8 + genuine)



def opauth_record(op: int, body: bytes) -> bytes:
    return bytes([op, len(body)]) + body


def opauth_msg(seq: int, what: int = 1, rot: float = 0.5, arg: int = 0, choice: int = 0, where: int = 0) -> bytes:
    """The body of an op-1 record of fuzz_opauth.c: a message the target builds and signs."""
    return struct.pack("<qBdiBB", seq, what, rot, arg, choice, where)


def opauth_seeds() -> None:
    # fuzz_opauth: records [op][len][bytes]; op 1/5 build a TELEOP/COMMAND and sign it, 2 replays
    # the last one, 0/4 feed raw bytes, 3/7 check an LCM URL (host / network scope).
    teleop_v1 = bytes.fromhex("7cc1b7370df20bb8") + struct.pack(">qqbdd", 1, 2 ** 63 - 1, 1, 0.8, 0.0)
    command_v1 = bytes.fromhex("3652044819c40f11") + struct.pack(">qqbi", 1, 2 ** 63 - 2, 5, 0)
    write("opauth", "window", b"".join(opauth_record(1, opauth_msg(s)) for s in (10, 12, 11, 11, 12 - 64, 12 + 64))
          + opauth_record(2, b"") + opauth_record(1, opauth_msg(2 ** 63 - 1)))
    write("opauth", "refusals", opauth_record(1, opauth_msg(5, choice=1)) + opauth_record(1, opauth_msg(6, choice=2))
          + opauth_record(1, opauth_msg(7, choice=4)) + opauth_record(1, opauth_msg(8, choice=8, where=40))
          + opauth_record(1, opauth_msg(9)) + opauth_record(0, teleop_v1) + opauth_record(4, command_v1)
          + opauth_record(0, teleop_v1[:-3]) + opauth_record(0, b"\xa5" * 97))
    write("opauth", "commands", b"".join(opauth_record(5, opauth_msg(s, what=c, arg=s)) for s, c in
                                         ((1, 3), (2, 4), (2, 4), (4, 5), (3, 1))) + opauth_record(2, b""))
    write("opauth", "urls", b"".join(opauth_record(op, u.encode()) for op, u in (
        (3, "udpm://239.255.76.67:7667?ttl=0"), (3, "udpm://239.255.76.67:7667?ttl=1"), (7, "udpm://239.1.2.3:9?ttl=1"),
        (3, "memq://"), (3, "tcpq://192.0.2.1:7700"), (7, "tcpq://192.0.2.1:7700"), (3, "udpm://10.0.0.1:7667"),
        (3, "udpm://"), (3, "udpm://239.255.76.67?recv_buf_size=1&ttl=0x0"))))


if __name__ == "__main__":
    main()
    more_seeds()
    opauth_seeds()
