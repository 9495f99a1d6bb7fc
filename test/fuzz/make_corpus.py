#!/usr/bin/env python3
# SPDX-License-Identifier: MIT
"""Writes the seed corpus of the fuzz targets (test/fuzz/corpus/<target>/) from the protocol
facts of protocols.md: valid telegrams, packets and frames, plus a few damaged variants.
Deterministic; re-run after changing a protocol so the seeds stay meaningful."""
import functools
import pathlib
import struct

HERE = pathlib.Path(__file__).resolve().parent


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
    write("rflex", "raw_esc_and_filler", b"\x09" + rflex(2, 0, 7, struct.pack(">BIIIB", 0, 0x1B1B,
          0x1B, 30000, 1), False) + b"\x1b\x02\x1b\x02\x02\x00\x0a\x1b\x01\x00\x08\x1b\x03"
          + b"\x1b\x1b\x02\x09\x00" + rflex(6, 0, 1, bytes(range(40)), True))
    # CANopen: 11-byte records (id u16 LE, dlc, 8 data bytes).
    write("canopen", "enable_sequence", b"".join([
        can(0x000, b"\x01\x00"), can(0x080, b""), can(0x201, b"\x06\x00\x00\x00\x00\x00"),
        can(0x181, b"\x31\x02\x00\x00\x00\x00"), can(0x201, b"\x07\x00\x00\x00\x00\x00"),
        can(0x181, b"\x33\x02\x00\x00\x00\x00"), can(0x201, b"\x0f\x00\x2c\xc9\x00\x00"),
        can(0x181, b"\x37\x02\x2c\xc9\x00\x00"), can(0x281, b"\x10\x27\x00\x00"),
        can(0x701, b"\x05"), can(0x081, b"\x10\x23\x03\x00\x00\x00\x00\x00"),
        can(0x201, b"\x80\x00\x00\x00\x00\x00"), can(0x182, b"\x18\x02\x00\x00\x00\x00")]))


if __name__ == "__main__":
    main()
