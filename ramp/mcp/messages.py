"""The two MCP message shapes, as plain values (thesis section 4.6)."""

from __future__ import annotations

from dataclasses import dataclass

Value = int | float | str


@dataclass(frozen=True)
class Request:
    """`module:device.function=(params)`; params stay text until a module table types them."""

    module: str
    device: str
    function: str
    params: tuple[str, ...] = ()


@dataclass(frozen=True)
class Response:
    """`module:device.property=(values)`."""

    module: str
    device: str
    prop: str
    values: tuple[Value, ...] = ()


def error_response(module: str, device: str, code: str, detail: str) -> Response:
    """An error response; the detail is cleaned of the characters MCP reserves."""
    return Response(module, device, "error", (code, clean_detail(detail)))


def clean_detail(text: str) -> str:
    """Detail text never contains `,` `)` `(` or line breaks, and stays printable ASCII."""
    out = []
    for ch in text:
        if ch in ",)(":
            out.append(";" if ch == "," else " ")
        elif ch in "\r\n\t":
            out.append(" ")
        elif 32 <= ord(ch) < 127:
            out.append(ch)
        else:
            out.append("?")
    return "".join(out).strip()[:200]
