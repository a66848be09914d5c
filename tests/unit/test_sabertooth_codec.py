"""Sabertooth packet codec: byte strings in, byte strings out."""

from __future__ import annotations

import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from ramp.hal import sabertooth_codec as codec
from ramp.hal.sabertooth_codec import Packet


def test_checksum_matches_the_datasheet_example() -> None:
    assert codec.checksum(130, 0, 64) == 66
    assert codec.encode(130, 0, 64) == bytes([130, 0, 64, 66])


def test_checksum_keeps_seven_bits() -> None:
    # 135 + 127 + 127 = 389 = 0b1_1000_0101 -> 0b000_0101
    assert codec.encode(135, 127, 127) == bytes([135, 127, 127, 5])


@pytest.mark.parametrize(
    ("motor", "duty", "expected"),
    [
        (1, 0.5, [128, 0, 64, 64]),  # round(63.5) = 64
        (1, -1.0, [128, 1, 127, 0]),  # (128+1+127) & 127 = 0
        (1, 0.0, [128, 0, 0, 0]),  # stop is "forward 0"
        (1, -0.0, [128, 0, 0, 0]),
        (2, 1.0, [128, 4, 127, 3]),  # 259 & 127 = 3
        (2, -0.25, [128, 5, 32, 37]),  # round(31.75) = 32
        (2, 0.004, [128, 4, 1, 5]),  # round(0.508) = 1
        (2, 0.003, [128, 4, 0, 4]),
    ],
)
def test_encode_motor(motor: int, duty: float, expected: list[int]) -> None:
    assert codec.encode_motor(128, motor, duty) == bytes(expected)


@pytest.mark.parametrize(
    "args",
    [(127, 1, 0.0), (136, 1, 0.0), (128, 0, 0.0), (128, 3, 0.0), (128, True, 0.0),
     (128, 1, 1.01), (128, 1, -1.5), (128, 1, math.nan), (128, 1, math.inf)],
)
def test_encode_motor_rejects(args: tuple[int, int, float]) -> None:
    with pytest.raises(ValueError):
        codec.encode_motor(*args)


@pytest.mark.parametrize("args", [(127, 0, 0), (136, 0, 0), (128, 128, 0), (128, 0, 128),
                                  (128, 0, -1), (128, 0, 1.0)])
def test_encode_rejects_out_of_range_bytes(args: tuple[int, int, int]) -> None:
    with pytest.raises(ValueError):
        codec.encode(*args)


@pytest.mark.parametrize(
    ("seconds", "units"),
    [(0, 0), (0.0, 0), (0.5, 5), (0.3, 3), (0.7, 7), (0.31, 4), (0.01, 1), (0.1, 1),
     (1.0, 10), (12.7, 127), (12.71, 127), (60, 127)],
)
def test_timeout_rounds_up_and_clamps(seconds: float, units: int) -> None:
    assert codec.timeout_units(seconds) == units
    assert codec.encode_timeout(129, seconds) == bytes(
        [129, 14, units, (129 + 14 + units) & 0x7F]
    )


@pytest.mark.parametrize("seconds", [-0.1, math.nan, math.inf, True])
def test_timeout_rejects(seconds: float) -> None:
    with pytest.raises(ValueError):
        codec.timeout_units(seconds)


def test_decode_one_packet_and_need_more() -> None:
    assert codec.decode(bytes([130, 0, 64, 66])) == (4, Packet(130, 0, 64))
    assert codec.decode(b"") == (0, None)
    assert codec.decode(bytes([130, 0, 64])) == (0, None)


def test_decode_drops_bad_checksum() -> None:
    buf = bytes([130, 0, 64, 67]) + bytes([130, 0, 64, 66])
    assert codec.decode(buf) == (4, None)
    packets, rest = codec.decode_all(buf)
    assert packets == [Packet(130, 0, 64)]
    assert rest == b""


def test_decode_resyncs_mid_stream() -> None:
    good = codec.encode(129, 4, 10)
    # noise, a packet cut short by a new address byte, then a good packet and half of one
    buf = bytes([5, 64, 0]) + bytes([128, 0]) + good + bytes([130, 1])
    assert codec.decode(buf) == (3, None)
    assert codec.decode(buf[3:]) == (2, None)
    packets, rest = codec.decode_all(buf)
    assert packets == [Packet(129, 4, 10)]
    assert rest == bytes([130, 1])


def test_decode_resyncs_when_short_buffer_already_holds_next_address() -> None:
    assert codec.decode(bytes([128, 129, 4])) == (1, None)


def test_decode_autobaud_byte_is_skipped_before_a_packet() -> None:
    packets, rest = codec.decode_all(bytes([codec.AUTOBAUD]) + codec.encode(128, 14, 5))
    assert packets == [Packet(128, 14, 5)]
    assert rest == b""


@given(
    noise=st.lists(st.integers(0, 127), max_size=8),
    address=st.integers(128, 135),
    command=st.integers(0, 127),
    data=st.integers(0, 127),
)
def test_round_trip_after_noise(noise: list[int], address: int, command: int, data: int) -> None:
    packets, rest = codec.decode_all(bytes(noise) + codec.encode(address, command, data))
    assert packets == [Packet(address, command, data)]
    assert rest == b""


@given(st.binary(max_size=64))
def test_decode_never_gets_stuck(buf: bytes) -> None:
    """Any byte string is consumed down to at most one incomplete packet."""
    packets, rest = codec.decode_all(buf)
    assert len(rest) < codec.PACKET_LEN
    assert all(p.address >= 128 for p in packets)
