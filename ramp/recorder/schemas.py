"""The recorder's channels: topics and JSON Schemas, as data.

Every channel is JSON-encoded with a JSON Schema (MCAP schema encoding `jsonschema`), which
Foxglove and Lichtblick decode with no plugin. Where Foxglove has a schema of its own for the
thing recorded (`foxglove.Log` here; `foxglove.LaserScan`, `foxglove.PoseInFrame`,
`foxglove.SceneUpdate` for the autonomy's view), the channel uses that schema's name and
fields, so the viewer's own panels (Log, 3D) show it.

A new channel is one more `ChannelSpec` (a topic, a schema name, a JSON Schema); the recorder
writes any payload a spec describes through `Recorder.publish`.

Topics (`MODULE` is a module name from `ramp.yaml`; `robot` is reserved there, so
`/robot/get` never clashes with a module's):

| topic | schema | one message per |
|---|---|---|
| `/mcp/in` | `ramp.McpLine` | MCP message received (client address, the line without `\\n`) |
| `/mcp/out` | `ramp.McpLine` | response line sent |
| `/robot/get` | `ramp.robot.get` | sample of `robot:robot.get=()`'s rows (10 Hz) |
| `/MODULE/get` | `ramp.MODULE.get` | sample of `MODULE:MODULE.get=()`'s rows (10 Hz) |
| `/robot/commands` | `ramp.Command` | command handed to a driver (bus, channel, duty, kind) |
| `/robot/module_state` | `ramp.ModuleState` | module state change (ok, fault, detached) and why |
| `/robot/events` | `ramp.Event` | watchdog, control, stall, bus fault and other supervisor events |
| `/log` | `foxglove.Log` | log record at WARNING or above |
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

MESSAGE_ENCODING = "json"
SCHEMA_ENCODING = "jsonschema"

TOPIC_MCP_IN = "/mcp/in"
TOPIC_MCP_OUT = "/mcp/out"
TOPIC_HEALTH = "/robot/get"
TOPIC_COMMANDS = "/robot/commands"
TOPIC_MODULE_STATE = "/robot/module_state"
TOPIC_EVENTS = "/robot/events"
TOPIC_LOG = "/log"

#: Event kinds the supervisor records (`Recorder.event`); `ramp log summary` counts them.
EVENT_KINDS = {
    "watchdog_trip": "the watchdog stopped every module (a commander silent or lost)",
    "watchdog": "the watchdog armed (motion) or went idle (nothing moving)",
    "control": "control acquired, released or taken over",
    "interlock": "an interlock rule became active (why) or was released",
    "stall": "the tick loop stalled and every module was stopped",
    "stop": "robot.stop or a module stop request",
    "fault": "a bus fault (the module state change says which module it hit)",
    "recorder": "the recorder started dropping records, or could not write",
    "audit": "a state-changing request: IDENTITY PEER OUTCOME REQUEST (accepted, or the "
             "refusal's code: forbidden, not_owner, interlocked, fault ...)",
    "note": "anything else worth a mark on the time line",
}


@dataclass(frozen=True)
class ChannelSpec:
    """One MCAP channel: its topic, the schema's name and the JSON Schema itself."""

    topic: str
    schema_name: str
    schema: Mapping[str, Any]
    metadata: Mapping[str, str] = field(default_factory=dict)

    def schema_bytes(self) -> bytes:
        return json.dumps(self.schema, sort_keys=True).encode()


def module_topic(module: str) -> str:
    """The topic of a module's (or, for `robot`, the supervisor's) get rows."""
    return f"/{module}/get"


# -- schemas ----------------------------------------------------------------------------------
MCP_LINE = {
    "title": "ramp.McpLine",
    "description": "One MCP message line, as received (/mcp/in) or sent (/mcp/out), "
                   "without its newline. The message's log time is when it arrived or was "
                   "answered.",
    "type": "object",
    "properties": {
        "client": {"type": "string", "description": "the client's address, host:port"},
        "line": {"type": "string",
                 "description": "the line; bytes that are not ASCII appear as \\xNN"},
    },
    "required": ["client", "line"],
    "additionalProperties": False,
}

COMMAND = {
    "title": "ramp.Command",
    "description": "A command handed to a driver: a motor's duty -1..1 as the controller "
                   "sees it (after polarity), or a digital output's 0 or 1.",
    "type": "object",
    "properties": {
        "bus": {"type": "string", "description": "the bus (ramp.yaml buses: key)"},
        "channel": {"type": "string", "description": "the device, as module.device"},
        "duty": {"type": "number", "minimum": -1.0, "maximum": 1.0},
        "kind": {"type": "string", "enum": ["motor", "output"],
                 "description": "a motor channel, or a digital output (an LED, a relay)"},
    },
    "required": ["bus", "channel", "duty"],
    "additionalProperties": False,
}

MODULE_STATE = {
    "title": "ramp.ModuleState",
    "description": "A module's new state and why it changed.",
    "type": "object",
    "properties": {
        "module": {"type": "string"},
        "state": {"type": "string", "enum": ["ok", "fault", "detached"]},
        "reason": {"type": "string"},
    },
    "required": ["module", "state", "reason"],
    "additionalProperties": False,
}

EVENT = {
    "title": "ramp.Event",
    "description": "A supervisor event. Kinds: " + "; ".join(
        f"{k}: {v}" for k, v in EVENT_KINDS.items()),
    "type": "object",
    "properties": {
        "kind": {"type": "string", "enum": sorted(EVENT_KINDS)},
        "text": {"type": "string"},
    },
    "required": ["kind", "text"],
    "additionalProperties": False,
}

#: foxglove.Log, the fields of Foxglove's own schema (so its Log panel shows the records).
FOXGLOVE_LOG = {
    "title": "foxglove.Log",
    "description": "A log message",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "title": "time",
            "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999},
            },
            "description": "Timestamp of log message",
        },
        "level": {
            "title": "foxglove.LogLevel",
            "description": "Log level",
            "oneOf": [{"title": name, "const": value} for name, value in (
                ("UNKNOWN", 0), ("DEBUG", 1), ("INFO", 2), ("WARNING", 3), ("ERROR", 4),
                ("FATAL", 5))],
        },
        "message": {"type": "string", "description": "Log message"},
        "name": {"type": "string", "description": "Process or node name"},
        "file": {"type": "string", "description": "Filename"},
        "line": {"type": "integer", "minimum": 0, "description": "Line number in the file"},
    },
    "required": ["timestamp", "level", "message", "name", "file", "line"],
}

#: What a get row's value may be: MCP values are ints, floats and names; a row of several
#: values (`tick.late=(p50,p99,max)`) is a list.
_VALUE = {"type": ["number", "string", "array", "null"],
          "items": {"type": ["number", "string"]}}
_KIND = {int: "integer", float: "number", str: "string"}


def rows_schema(module: str, sample: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The schema of a module's get rows, `{device: {property: value}}`, naming the devices
    and properties seen in the first sample (so the viewer completes plot paths such as
    `/base/get.battery.volt`) while accepting any other row."""
    devices: dict[str, Any] = {}
    for device, props in sample.items():
        properties = {prop: _value_schema(value) for prop, value in props.items()}
        devices[device] = {"type": "object", "properties": properties,
                           "additionalProperties": _VALUE}
    what = "robot.get (supervisor health)" if module == "robot" else f"{module}.get"
    return {
        "title": f"ramp.{module}.get",
        "description": f"The rows of {module}:{what} as {{device: {{property: value}}}}; "
                       "a row of several values is a list.",
        "type": "object",
        "properties": devices,
        "additionalProperties": {"type": "object", "additionalProperties": _VALUE},
    }


def _value_schema(value: Any) -> dict[str, Any]:
    if isinstance(value, list):
        return {"type": "array", "items": {"type": ["number", "string"]}}
    kind = _KIND.get(type(value))
    if kind == "integer":
        return {"type": "number"}  # an int row may read as a float later (MCP's own typing)
    if kind == "string":  # a row of names may hold several later (`interlock.active`)
        return {"type": ["string", "array"], "items": {"type": "string"}}
    return {"type": kind} if kind else dict(_VALUE)


FIXED_CHANNELS: tuple[ChannelSpec, ...] = (
    ChannelSpec(TOPIC_MCP_IN, "ramp.McpLine", MCP_LINE),
    ChannelSpec(TOPIC_MCP_OUT, "ramp.McpLine", MCP_LINE),
    ChannelSpec(TOPIC_COMMANDS, "ramp.Command", COMMAND),
    ChannelSpec(TOPIC_MODULE_STATE, "ramp.ModuleState", MODULE_STATE),
    ChannelSpec(TOPIC_EVENTS, "ramp.Event", EVENT),
    ChannelSpec(TOPIC_LOG, "foxglove.Log", FOXGLOVE_LOG),
)


def by_topic(specs: Iterable[ChannelSpec]) -> dict[str, ChannelSpec]:
    return {s.topic: s for s in specs}
