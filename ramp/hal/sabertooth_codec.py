"""Sabertooth packetized serial, legacy 4-byte protocol, as pure functions (sans-IO).

A packet is `[address, command, data, checksum]` with `checksum = (address + command + data)
& 0x7F`. Address bytes are 128-135 and every other byte is 0-127, which is what lets a
receiver find the start of a packet again after noise or a lost byte. The link is one-way
(host to controller): there is no reply and no NAK, so a bad packet is simply dropped.

The driver (`ramp.hal.sabertooth`) only moves the bytes built here; tests and the `spy://`
decoding use `decode`. The emulator in `firmware_like/` has its own decoder on purpose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

ADDRESS_MIN: Final = 128
ADDRESS_MAX: Final = 135
PACKET_LEN: Final = 4
#: Sent once before anything else so older controllers can measure the baud rate.
AUTOBAUD: Final = 0xAA

CMD_M1_FORWARD: Final = 0
CMD_M1_BACKWARD: Final = 1
CMD_MIN_VOLTAGE: Final = 2
CMD_MAX_VOLTAGE: Final = 3
CMD_M2_FORWARD: Final = 4
CMD_M2_BACKWARD: Final = 5
CMD_M1_7BIT: Final = 6
CMD_M2_7BIT: Final = 7
CMD_SERIAL_TIMEOUT: Final = 14
CMD_BAUD_RATE: Final = 15
CMD_RAMPING: Final = 16
CMD_DEADBAND: Final = 17

#: One unit of command 14 is 100 ms; 127 units (12.7 s) is the largest value a data byte holds.
TIMEOUT_UNIT_S: Final = 0.1
TIMEOUT_MAX_UNITS: Final = 127


@dataclass(frozen=True)
class Packet:
    """One decoded packet (its checksum was good)."""

    address: int
    command: int
    data: int

    def to_bytes(self) -> bytes:
        return encode(self.address, self.command, self.data)


def checksum(address: int, command: int, data: int) -> int:
    """The 7-bit checksum of a packet: the low 7 bits of the sum of the first three bytes."""
    return (address + command + data) & 0x7F


def _check_byte(value: int, lo: int, hi: int, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ValueError(f"{value!r} is not {what} ({lo}-{hi})")


def encode(address: int, command: int, data: int) -> bytes:
    """A raw packet. Validates ranges so a caller bug cannot put a sync byte mid-packet."""
    _check_byte(address, ADDRESS_MIN, ADDRESS_MAX, "a Sabertooth address")
    _check_byte(command, 0, 127, "a Sabertooth command")
    _check_byte(data, 0, 127, "a Sabertooth data byte")
    return bytes((address, command, data, checksum(address, command, data)))


def duty_command(motor: int, duty: float) -> tuple[int, int]:
    """(command, data) for a signed duty: forward/backward command, magnitude 0-127.

    Zero is sent as "forward 0" (there is no separate stop command). Polarity is not handled
    here: the duty's sign is what the controller sees.
    """
    if motor not in (1, 2) or isinstance(motor, bool):
        raise ValueError(f"{motor!r} is not a Sabertooth motor number (1 or 2)")
    if isinstance(duty, bool) or not isinstance(duty, int | float) or not math.isfinite(duty):
        raise ValueError(f"duty must be a finite number, got {duty!r}")
    if not -1.0 <= duty <= 1.0:
        raise ValueError(f"duty {duty} is outside -1..1")
    forward = CMD_M1_FORWARD if motor == 1 else CMD_M2_FORWARD
    command = forward + 1 if duty < 0 else forward
    return command, round(abs(duty) * 127)


def encode_motor(address: int, motor: int, duty: float) -> bytes:
    """The packet that sets `motor` (1 or 2) of controller `address` to `duty` (-1..1)."""
    command, data = duty_command(motor, duty)
    return encode(address, command, data)


def timeout_units(seconds: float) -> int:
    """Command-14 units for a timeout: 0 disables it; otherwise 100 ms units rounded UP
    (the controller must never give up earlier than asked), clamped to 1..127."""
    if isinstance(seconds, bool) or not isinstance(seconds, int | float):
        raise ValueError(f"timeout must be a number of seconds, got {seconds!r}")
    if not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f"timeout must be finite and >= 0 s, got {seconds!r}")
    if seconds == 0:
        return 0
    # The small epsilon keeps 0.3 s at 3 units: 0.3 / 0.1 is 2.9999999999999996 in floats,
    # and 0.7 * 10 is 7.000000000000001.
    units = math.ceil(seconds / TIMEOUT_UNIT_S - 1e-9)
    return max(1, min(TIMEOUT_MAX_UNITS, units))


def encode_timeout(address: int, seconds: float) -> bytes:
    """Command 14: stop both motors when no valid packet arrives for `seconds` (0 = off)."""
    return encode(address, CMD_SERIAL_TIMEOUT, timeout_units(seconds))


def decode(buf: bytes | bytearray | memoryview) -> tuple[int, Packet | None]:
    """Find the next packet in `buf`.

    Returns `(used, packet)`: the caller drops `used` bytes from the front and, when `packet`
    is not None, acts on it. `(0, None)` means "need more bytes". Bytes before an address
    byte, a packet cut short by a new address byte, and a packet with a bad checksum are
    consumed with `packet=None`, as the firmware would drop them.
    """
    view = bytes(buf)
    start = 0
    while start < len(view) and view[start] < ADDRESS_MIN:
        start += 1
    if start:
        return start, None  # noise before the first address byte
    if len(view) < PACKET_LEN:
        # An incomplete packet may still be cut short by a new address byte already here.
        for i in range(1, len(view)):
            if view[i] >= ADDRESS_MIN:
                return i, None
        return 0, None
    for i in range(1, PACKET_LEN):
        if view[i] >= ADDRESS_MIN:
            return i, None  # resync: a new packet starts before this one ended
    address, command, data, check = view[0], view[1], view[2], view[3]
    if checksum(address, command, data) != check:
        return PACKET_LEN, None
    return PACKET_LEN, Packet(address, command, data)


def decode_all(buf: bytes | bytearray) -> tuple[list[Packet], bytes]:
    """Every packet in `buf`, and the unconsumed tail (an incomplete packet)."""
    packets: list[Packet] = []
    rest = bytes(buf)
    while True:
        used, packet = decode(rest)
        if used == 0:
            return packets, rest
        rest = rest[used:]
        if packet is not None:
            packets.append(packet)
