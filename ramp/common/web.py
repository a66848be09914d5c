"""Serving a page's web app (the console, the fleet page) with uvicorn on a socket the
command has already bound, so a port in use is the command's own clear error and the page's
address is known before it announces it.

uvicorn shuts down gracefully on SIGINT/SIGTERM and then raises the signal again to whatever
handler was there before; the handlers installed here make that the end of it, so Ctrl-C and
`kill` exit 0 without a traceback. uvicorn is an optional extra: it is imported here only
when a page is served, never by the backend.
"""

from __future__ import annotations

import asyncio
import signal
import socket
from collections.abc import Callable
from typing import Any, Literal


def serve_app(app: Any, sock: socket.socket, announce: Callable[[], None], *,
              ws: str | None = None, lifespan: Literal["on", "off"] = "off",
              graceful_s: int = 1) -> None:
    """Serve `app` on `sock` until SIGINT/SIGTERM; `announce()` once it serves."""
    import uvicorn

    options: dict[str, Any] = {"ws": ws} if ws is not None else {}
    config = uvicorn.Config(app, lifespan=lifespan, log_level="warning",
                            timeout_graceful_shutdown=graceful_s, **options)
    server = uvicorn.Server(config)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, frame: setattr(server, "should_exit", True))

    async def serve() -> None:
        task = asyncio.create_task(server.serve(sockets=[sock]))
        while not server.started and not task.done():
            await asyncio.sleep(0.01)
        if server.started:
            announce()
        await task

    asyncio.run(serve())
