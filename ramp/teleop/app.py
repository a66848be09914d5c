"""The web side: the page, its files, and one WebSocket per open page (Starlette).

The page talks only to this process; only the console talks MCP. A page's WebSocket closing
(tab closed, browser killed, network gone) is the event the controller's safety rules start
from, so the socket is read until it ends and the console is told at once.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import AsyncIterator
from importlib import resources
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.middleware import Middleware
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket

from ramp.teleop.console import Console
from ramp.teleop.pagereader import PageReader

log = logging.getLogger("ramp.teleop")

#: Messages waiting for a slow page; past this, status updates are dropped (the next one
#: replaces them anyway), never the page's own answers.
_QUEUE = 256
LOCAL_HOSTS = ["127.0.0.1", "localhost", "[::1]"]
#: Messages a newer one of the same kind replaces within a second: dropped for a slow page
#: (the map and the alerts are sent only when they change, so they are kept).
_REPLACED = frozenset({"status", "autonomy", "autonomy_scan", "bandwidth"})


def static_dir() -> Path:
    return Path(str(resources.files("ramp.teleop").joinpath("static")))


class _PageSocket:
    """One open page: a bounded outgoing queue drained by a writer task."""

    def __init__(self, ws: WebSocket) -> None:
        self.ws = ws
        self.queue: asyncio.Queue[str] = asyncio.Queue(_QUEUE)

    def post(self, message: dict[str, Any]) -> None:
        text = json.dumps(message, separators=(",", ":"))
        try:
            self.queue.put_nowait(text)
        except asyncio.QueueFull:
            if message.get("type") in _REPLACED:
                return  # stale news is worthless; the next one comes soon
            with contextlib.suppress(asyncio.QueueEmpty):
                self.queue.get_nowait()
            self.queue.put_nowait(text)

    async def write_loop(self) -> None:
        while True:
            text = await self.queue.get()
            await self.ws.send_text(text)


def create_app(console: Console) -> Starlette:
    index_file = static_dir() / "index.html"

    async def index(request: Request) -> Response:
        return FileResponse(index_file, headers={"Cache-Control": "no-store"})

    async def page_socket(ws: WebSocket) -> None:
        # A page from any other site open in the same browser could otherwise reach this
        # socket on 127.0.0.1 and drive the robot (cross-site WebSocket hijacking).
        origin = ws.headers.get("origin")
        if origin is not None and origin != f"http://{ws.headers.get('host', '')}":
            log.warning("refused a page socket from origin %s", origin)
            await ws.close(code=1008)
            return
        await ws.accept()
        sock = _PageSocket(ws)
        page = console.open_page(sock.post)
        writer = asyncio.create_task(sock.write_loop())
        reader = PageReader(console, page)
        try:
            await reader.read(ws)
        finally:
            reader.close()
            console.close_page(page)
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await writer

    @contextlib.asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        await console.start()
        try:
            yield
        finally:
            await console.stop()

    routes = [
        Route("/", index),
        WebSocketRoute("/ws", page_socket),
        Mount("/static", StaticFiles(directory=static_dir()), name="static"),
    ]
    # Only names of this machine: a DNS-rebinding page (evil.example resolving to 127.0.0.1)
    # sends its own Host and is refused.
    middleware = [Middleware(TrustedHostMiddleware, allowed_hosts=LOCAL_HOSTS)]
    return Starlette(routes=routes, lifespan=lifespan, middleware=middleware)
