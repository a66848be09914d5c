"""Foxglove's WebSocket protocol (`foxglove.websocket.v1`), server side, as strings and bytes:
what we send (serverInfo, advertise, status, Message Data frames) and what we accept
(subscribe, unsubscribe) or refuse with a reason."""

from __future__ import annotations

import json
import struct

import pytest

from ramp.autonomy.live import protocol as p


def test_message_data_is_opcode_1_then_subscription_and_time_little_endian_then_payload(
) -> None:
    frame = p.message_data(7, 1_779_285_600_123_456_789, b'{"x":1}')
    assert frame == (b"\x01" + (7).to_bytes(4, "little")
                     + (1_779_285_600_123_456_789).to_bytes(8, "little") + b'{"x":1}')
    assert p.MESSAGE_DATA_HEADER == 13
    assert p.parse_message_data(frame) == (7, 1_779_285_600_123_456_789, b'{"x":1}')


def test_the_largest_ids_and_times_fit_and_larger_ones_do_not() -> None:
    frame = p.message_data(2**32 - 1, 2**64 - 1, b"")
    assert p.parse_message_data(frame) == (2**32 - 1, 2**64 - 1, b"")
    with pytest.raises(struct.error):
        p.message_data(2**32, 0, b"")


def test_a_frame_that_is_not_message_data_is_refused_by_the_reader() -> None:
    with pytest.raises(ValueError, match="not a Message Data frame"):
        p.parse_message_data(b"\x02" + bytes(12))
    with pytest.raises(ValueError):
        p.parse_message_data(b"\x01\x00")


def test_server_info_declares_no_optional_capability_and_names_the_session() -> None:
    info = json.loads(p.server_info("ramp-autonomy", "1779285600000000000", {"robot": "MARTE"}))
    assert info == {"op": "serverInfo", "name": "ramp-autonomy", "capabilities": [],
                    "metadata": {"robot": "MARTE"}, "sessionId": "1779285600000000000"}


def test_a_channel_is_advertised_as_json_with_its_json_schema_as_a_string() -> None:
    schema = {"title": "foxglove.PoseInFrame", "type": "object",
              "properties": {"frame_id": {"type": "string"}}}
    msg = json.loads(p.advertise([p.channel_advert(3, "/pose/estimated",
                                                   "foxglove.PoseInFrame", schema)]))
    assert msg["op"] == "advertise"
    (ch,) = msg["channels"]
    assert {k: v for k, v in ch.items() if k != "schema"} == {
        "id": 3, "topic": "/pose/estimated", "encoding": "json",
        "schemaName": "foxglove.PoseInFrame", "schemaEncoding": "jsonschema"}
    assert isinstance(ch["schema"], str) and json.loads(ch["schema"]) == schema


def test_status_carries_a_level_and_a_message() -> None:
    assert json.loads(p.status(p.STATUS_ERROR, "no")) == {"op": "status", "level": 2,
                                                          "message": "no"}


def test_subscribe_and_unsubscribe_are_read_as_id_pairs_and_ids() -> None:
    sub = p.parse_client_text(json.dumps({"op": "subscribe", "subscriptions": [
        {"id": 0, "channelId": 3}, {"id": 1, "channelId": 5}]}))
    assert sub == p.Subscribe(((0, 3), (1, 5)))
    assert p.parse_client_text('{"op":"unsubscribe","subscriptionIds":[0,1]}') == \
        p.Unsubscribe((0, 1))


@pytest.mark.parametrize(("text", "reason"), [
    ("hello", "not JSON"),
    ("[1, 2]", "JSON object with an 'op'"),
    ('{"subscriptions": []}', "JSON object with an 'op'"),
    ('{"op": "subscribe"}', "'subscriptions' must be a list"),
    ('{"op": "subscribe", "subscriptions": [3]}', "each subscription is an object"),
    ('{"op": "subscribe", "subscriptions": [{"id": -1, "channelId": 1}]}', "id must be"),
    ('{"op": "subscribe", "subscriptions": [{"id": 1, "channelId": "a"}]}', "channelId must"),
    ('{"op": "subscribe", "subscriptions": [{"id": true, "channelId": 1}]}', "id must be"),
    ('{"op": "subscribe", "subscriptions": [{"id": 4294967296, "channelId": 1}]}',
     "id must be"),
    ('{"op": "unsubscribe", "subscriptionIds": 3}', "must be a list"),
    ('{"op": "unsubscribe", "subscriptionIds": [1.5]}', "subscriptionIds must be"),
    ('{"op": "getParameters", "parameterNames": []}', "getParameters: not supported"),
    ('{"op": "advertise", "channels": []}', "advertise: not supported"),
])
def test_a_client_message_we_cannot_act_on_is_refused_with_the_reason(
        text: str, reason: str) -> None:
    with pytest.raises(p.ClientRequestError, match=reason):
        p.parse_client_text(text)
