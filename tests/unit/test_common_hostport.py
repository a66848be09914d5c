"""The one HOST:PORT parser (`ramp.common.hostport`) behind every command line and file that
names a TCP peer: the autonomy's backend, the LIDAR, ramp-shell, ramp-teleop."""

from __future__ import annotations

import pytest

from ramp.common.hostport import format_hostport, parse_hostport


@pytest.mark.parametrize(("text", "expected"), [
    ("10.0.0.2:5577", ("10.0.0.2", 5577)),
    ("robot.local:1", ("robot.local", 1)),
    ("[::1]:5577", ("::1", 5577)),
    ("  [fe80::1%eth0]:65535 ", ("fe80::1%eth0", 65535)),
])
def test_host_and_port(text: str, expected: tuple[str, int]) -> None:
    assert parse_hostport(text) == expected


@pytest.mark.parametrize(("text", "expected"), [
    ("", ("127.0.0.1", 7)), ("7000", ("127.0.0.1", 7000)), (":7000", ("127.0.0.1", 7000)),
    ("h", ("h", 7)), ("h:", ("h", 7)), ("[::1]", ("::1", 7)), ("::1", ("::1", 7)),
])
def test_defaults_fill_what_the_caller_allows(text: str, expected: tuple[str, int]) -> None:
    assert parse_hostport(text, default_host="127.0.0.1", default_port=7) == expected


@pytest.mark.parametrize(("text", "reason"), [
    ("", "empty address"), ("robot", "no port"), (":5577", "no host"), ("h:", "no port"),
    ("h:0", "1-65535"), ("h:65536", "1-65535"), ("h:http", "1-65535"),
    ("[::1", "unclosed '['"), ("[]:5", "empty host"), ("[::1]5577", "expected ':' after ']'"),
    ("fe80::1:5577", "goes in brackets"), ("a b:1", "is not a host name"),
    ("a\x00b:1", "is not a host name"), ("5577", "no port"),
])
def test_every_refusal_says_what_is_wrong_and_what_was_expected(text: str, reason: str) -> None:
    with pytest.raises(ValueError) as info:
        parse_hostport(text, example="x.local:1")
    assert reason in str(info.value)
    assert "expected HOST:PORT (for example x.local:1)" in str(info.value)


def test_format_puts_ipv6_in_brackets() -> None:
    assert format_hostport("::1", 5) == "[::1]:5"
    assert format_hostport("robot", 5) == "robot:5"
    assert parse_hostport(format_hostport("fe80::1", 9)) == ("fe80::1", 9)
