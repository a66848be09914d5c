"""JSON bytes for a recorded or streamed message: compact, and a NaN or infinity (which JSON
cannot carry) as null. Shared by the flight recorder and the autonomy's live Foxglove view,
which send the same messages."""

from __future__ import annotations

import json
import math
from typing import Any

_encode = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode


def json_payload(obj: Any) -> bytes:
    """Compact JSON bytes; the common case (every number finite) is encoded once."""
    try:
        return _encode(obj).encode()
    except ValueError:
        return _encode(_finite(obj)).encode()


def _finite(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite(v) for v in obj]
    return obj
