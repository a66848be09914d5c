"""The server side of Foxglove's WebSocket protocol (`foxglove.websocket.v1`), sans I/O.

What the live view needs of the protocol, as bytes and strings in and out (the server in
`foxglove_live.py` moves them over a socket):

- sent as text: `serverInfo` (first, to every new client), `advertise` (the channels: topic,
  `json` encoding, schema name, the JSON Schema as a string, `jsonschema` schema encoding),
  `status` (a request we refuse, and why);
- sent as binary: Message Data, opcode 0x01, then the client's subscription id (uint32), the
  message's time in ns since the Unix epoch (uint64), both little-endian, then the payload;
- received as text: `subscribe` (subscription ids chosen by the client, channel ids from our
  advertise) and `unsubscribe`. Everything else (client publishing, parameters, services,
  binary client messages) needs a capability this server does not declare, and is answered
  with a status message.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

#: The WebSocket subprotocol a client must offer (the handshake fails without it).
SUBPROTOCOL = "foxglove.websocket.v1"
#: Message encoding and schema encoding of every channel we advertise.
MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"

OP_MESSAGE_DATA = 0x01
_MESSAGE_DATA = struct.Struct("<BIQ")
#: Bytes before a Message Data frame's payload.
MESSAGE_DATA_HEADER = _MESSAGE_DATA.size

STATUS_INFO, STATUS_WARNING, STATUS_ERROR = 0, 1, 2
_UINT32_MAX = 2**32 - 1

_dumps = json.JSONEncoder(separators=(",", ":")).encode


class ClientRequestError(ValueError):
    """A client message this server cannot act on; its text goes back as a status."""


@dataclass(frozen=True)
class Subscribe:
    """`subscribe`: (subscription id, channel id) pairs."""

    subscriptions: tuple[tuple[int, int], ...]


@dataclass(frozen=True)
class Unsubscribe:
    """`unsubscribe`: subscription ids."""

    subscription_ids: tuple[int, ...]


ClientRequest = Subscribe | Unsubscribe


# -- server to client -------------------------------------------------------------------------
def server_info(name: str, session_id: str, metadata: Mapping[str, str] | None = None) -> str:
    """The first message of every connection. No optional capability is declared: the
    client can subscribe and nothing else."""
    return _dumps({"op": "serverInfo", "name": name, "capabilities": [],
                   "metadata": dict(metadata or {}), "sessionId": session_id})


def channel_advert(channel_id: int, topic: str, schema_name: str,
                   schema: Mapping[str, Any]) -> dict[str, Any]:
    """One entry of `advertise`'s `channels`: JSON messages described by a JSON Schema."""
    return {"id": channel_id, "topic": topic, "encoding": MESSAGE_ENCODING,
            "schemaName": schema_name, "schema": json.dumps(schema, sort_keys=True),
            "schemaEncoding": SCHEMA_ENCODING}


def advertise(channels: Iterable[Mapping[str, Any]]) -> str:
    """`advertise` with entries made by `channel_advert`."""
    return _dumps({"op": "advertise", "channels": list(channels)})


def status(level: int, message: str) -> str:
    """`status`: information for the person at the client (0 info, 1 warning, 2 error)."""
    return _dumps({"op": "status", "level": level, "message": message})


def message_data(subscription_id: int, timestamp_ns: int, payload: bytes) -> bytes:
    """A Message Data frame for one subscriber."""
    return _MESSAGE_DATA.pack(OP_MESSAGE_DATA, subscription_id, timestamp_ns) + payload


# -- client to server -------------------------------------------------------------------------
def parse_client_text(text: str) -> ClientRequest:
    """A text message from a client, or ClientRequestError saying what is wrong with it."""
    try:
        msg = json.loads(text)
    except ValueError as exc:
        raise ClientRequestError(f"not JSON: {exc}") from None
    if not isinstance(msg, dict) or not isinstance(msg.get("op"), str):
        raise ClientRequestError("a client message is a JSON object with an 'op' string")
    op = msg["op"]
    if op == "subscribe":
        subs = msg.get("subscriptions")
        if not isinstance(subs, list):
            raise ClientRequestError("subscribe: 'subscriptions' must be a list")
        pairs = []
        for sub in subs:
            if not isinstance(sub, dict):
                raise ClientRequestError("subscribe: each subscription is an object "
                                         "{id, channelId}")
            pairs.append((_uint32(sub.get("id"), "subscribe: id"),
                          _uint32(sub.get("channelId"), "subscribe: channelId")))
        return Subscribe(tuple(pairs))
    if op == "unsubscribe":
        ids = msg.get("subscriptionIds")
        if not isinstance(ids, list):
            raise ClientRequestError("unsubscribe: 'subscriptionIds' must be a list")
        return Unsubscribe(tuple(_uint32(i, "unsubscribe: subscriptionIds") for i in ids))
    raise ClientRequestError(f"{op}: not supported by this server (it only streams: "
                             "subscribe and unsubscribe)")


def _uint32(value: Any, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= _UINT32_MAX:
        raise ClientRequestError(f"{what} must be an integer 0..{_UINT32_MAX}, not {value!r}")
    return value


# -- for clients and tests --------------------------------------------------------------------
def parse_message_data(frame: bytes) -> tuple[int, int, bytes]:
    """(subscription id, timestamp ns, payload) of a Message Data frame."""
    if len(frame) < MESSAGE_DATA_HEADER or frame[0] != OP_MESSAGE_DATA:
        raise ValueError(f"not a Message Data frame: {bytes(frame[:MESSAGE_DATA_HEADER])!r}")
    _, sub, ts = _MESSAGE_DATA.unpack_from(frame)
    return sub, ts, bytes(frame[MESSAGE_DATA_HEADER:])
