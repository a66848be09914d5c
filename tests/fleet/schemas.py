"""The official VDA 5050 2.1.0 JSON schemas (tests/data/vda5050/, VDA's licence beside them),
loaded once: `validate(kind, message)` raises jsonschema's error naming the bad field."""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any

import jsonschema

SCHEMAS = Path(__file__).resolve().parent.parent / "data" / "vda5050"
KINDS = ("connection", "state", "visualization", "factsheet", "order", "instantActions")


@functools.cache
def validator(kind: str) -> jsonschema.protocols.Validator:
    schema = json.loads((SCHEMAS / f"{kind}.schema").read_text())
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema, format_checker=cls.FORMAT_CHECKER)


def validate(kind: str, message: dict[str, Any]) -> None:
    validator(kind).validate(message)
