"""The sans-IO client core: messages out, bytes in, each reply paired with its request."""

from __future__ import annotations

import pytest

from ramp.errors import ProtocolError
from ramp.mcp.messages import Request, Response
from ramp.mcp.session import McpSession, Reply, encode_message


def test_encode_message_takes_text_bytes_and_requests() -> None:
    assert encode_message("base:base.get=()") == b"base:base.get=()\n"
    assert encode_message(b"base:base.get=()\n") == b"base:base.get=()\n"
    assert encode_message("") == b"\n"
    assert encode_message(Request("base", "base", "drive", ("50", "0"))) == \
        b"base:base.drive=(50,0)\n"
    assert encode_message([Request("base", "base", "stop"), Request("ble", "ble", "stop")]) == \
        b"base:base.stop=()ble:ble.stop=()\n"
    assert encode_message([]) == b"\n"


def test_encode_message_refuses_two_messages_in_one() -> None:
    with pytest.raises(ValueError, match="line break"):
        encode_message("a:b.c=()\nd:e.f=()")


def test_replies_pair_with_requests_in_order_across_fragments() -> None:
    s: McpSession[str] = McpSession()
    assert s.send("base:base.get=()", "first", now=1.0) == b"base:base.get=()\n"
    assert s.send("", "beat", now=1.5) == b"\n"
    assert s.in_flight == 2 and s.oldest_sent_at() == 1.0
    assert s.feed(b"base:lf_wheel.vel=(1", now=2.0) == []
    replies = s.feed(b"0)\r\n\n", now=2.25)
    assert [(r.tag, r.request, r.line) for r in replies] == [
        ("first", b"base:base.get=()", b"base:lf_wheel.vel=(10)"),
        ("beat", b"", b""),
    ]
    assert replies[0].rtt == pytest.approx(1.25) and replies[1].rtt == pytest.approx(0.75)
    assert replies[0].responses() == [Response("base", "lf_wheel", "vel", (10,))]
    assert replies[1].responses() == []
    assert s.in_flight == 0 and s.oldest_sent_at() is None


def test_a_line_nobody_asked_for_is_unsolicited() -> None:
    s: McpSession[None] = McpSession()
    (reply,) = s.feed(b"robot:mcp.error=(busy,8 clients connected)\n")
    assert reply.unsolicited and reply.tag is None and reply.rtt is None
    assert reply.responses()[0].values[0] == "busy"


def test_an_over_long_line_still_answers_its_request_and_the_next_pairs_right() -> None:
    s: McpSession[int] = McpSession(max_line=16)
    s.send("a:b.get=()", 1)
    s.send("a:b.get=()", 2)
    replies = s.feed(b"a:b.c=(" + b"9" * 40 + b")\na:b.c=(2)\n")
    assert [r.tag for r in replies] == [1, 2]
    assert replies[0].error is not None
    with pytest.raises(ProtocolError, match="longer than 16"):
        replies[0].responses()
    assert replies[1].responses() == [Response("a", "b", "c", (2,))]


def test_garbage_is_a_protocol_error_when_parsed_not_when_fed() -> None:
    s: McpSession[None] = McpSession()
    s.send("a:b.get=()")
    (reply,) = s.feed(b"HTTP/1.1 400 Bad Request\n")
    assert reply.line == b"HTTP/1.1 400 Bad Request"
    with pytest.raises(ProtocolError):
        reply.responses()


def test_reset_returns_what_went_unanswered_and_drops_a_partial_line() -> None:
    s: McpSession[str] = McpSession()
    s.send("a:b.get=()", "x", now=3.0)
    s.feed(b"a:b.c=(1")
    lost = s.reset()
    assert [(p.request, p.tag, p.sent_at) for p in lost] == [(b"a:b.get=()", "x", 3.0)]
    assert s.in_flight == 0
    s.send("a:b.get=()", "y")
    (reply,) = s.feed(b"a:b.c=(2)\n")
    assert reply.tag == "y" and reply.responses() == [Response("a", "b", "c", (2,))]


def test_a_refused_message_leaves_the_session_unchanged() -> None:
    s: McpSession[None] = McpSession()
    with pytest.raises(ValueError):
        s.send("a\nb")
    assert s.in_flight == 0


def test_reply_defaults() -> None:
    r: Reply[None] = Reply(b"")
    assert r.unsolicited and r.rtt is None and r.responses() == []
