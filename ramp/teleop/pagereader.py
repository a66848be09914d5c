"""Reading one page's WebSocket: stamped as it arrives, never held up by a slow answer.

Why a reader and a dispatcher instead of `await console.page_message(...)` in a loop:
- An answer the robot is slow to give (a call, a STOP on a busy link) must not hold up the
  page's next messages. A dead-man release read late is a release ignored: the 0.3 s
  staleness rule stops the robot instead and latches driving. So calls, STOP, control and
  profile messages run as their own tasks (started in the order they came, so their
  requests go out in that order), and input frames are applied at once.
- Staleness is judged by when a frame arrived, not by when it is processed: the reader does
  nothing but stamp and queue, and the dispatcher takes the whole backlog at once and
  applies only its newest input frame, with that frame's arrival time. A page that bursts
  frames and then falls silent is stale 0.3 s after its last frame came, however long the
  burst would have taken to process one frame at a time.
- A binary frame is not something the page sends: the socket is closed with 1003
  (unsupported data) and a log line, instead of an ASGI traceback.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import re
from collections import deque
from typing import Any

from starlette.websockets import WebSocket

from ramp.teleop.console import Console

log = logging.getLogger("ramp.teleop")

#: Largest message a page may send; inputs are a few hundred bytes.
MAX_MESSAGE = 16384
#: Calls of one page waiting for their answers at once; more are answered "busy".
MAX_PENDING = 32
CLOSE_UNSUPPORTED_DATA = 1003
#: How the page writes an input frame (JSON.stringify: `{"type":"input",...`), spaces allowed.
_INPUT = re.compile(r'\{\s*"type"\s*:\s*"input"')


class PageReader:
    """The reading side of one page's socket (see the module docstring)."""

    def __init__(self, console: Console, page: str) -> None:
        self.console = console
        self.page = page
        self.inbox: deque[tuple[float, str]] = deque()
        self.wake = asyncio.Event()
        self.pending: set[asyncio.Task[None]] = set()
        self.dispatcher = asyncio.create_task(self._dispatch())
        #: Input frames skipped because a newer one had arrived with them (for tests).
        self.collapsed = 0

    async def read(self, ws: WebSocket) -> None:
        """Read until the page's socket ends; each message stamped with its arrival.

        A frame is queued by the server's protocol when its bytes are read, which happens
        only while this loop runs other work. So while this reader takes messages without
        waiting, each was queued before it last waited: its arrival is at most the time of
        that wake-up, however long the run of reads takes. Reading is kept cheap anyway
        (no JSON here)."""
        loop = asyncio.get_running_loop()
        arrived = loop.time()
        while True:
            waited = [False]
            probe = loop.call_soon(waited.__setitem__, 0, True)
            try:
                message = await ws.receive()
            except (RuntimeError, OSError):
                return
            if waited[0]:
                arrived = loop.time()  # the loop ran: this one was read in just now
            else:
                probe.cancel()
            if message.get("type") == "websocket.disconnect":
                return
            if message.get("bytes") is not None:
                log.warning("page %s sent a binary frame (%d bytes): closing its socket "
                            "(1003, unsupported data)", self.page, len(message["bytes"]))
                with contextlib.suppress(RuntimeError, OSError):
                    await ws.close(code=CLOSE_UNSUPPORTED_DATA)
                return
            text = message.get("text")
            if not isinstance(text, str) or len(text) > MAX_MESSAGE:
                continue
            self.inbox.append((arrived, text))
            self.wake.set()

    def close(self) -> None:
        self.dispatcher.cancel()
        for task in list(self.pending):
            task.cancel()

    async def _dispatch(self) -> None:
        while True:
            await self.wake.wait()
            self.wake.clear()
            batch = list(self.inbox)
            self.inbox.clear()
            # The page writes input frames as {"type":"input",...}: only the newest of a
            # backlog is parsed and applied; every other message is parsed and run in order.
            last_input = max((i for i, (_, text) in enumerate(batch)
                              if _INPUT.match(text)), default=-1)
            for i, (at, text) in enumerate(batch):
                if _INPUT.match(text) and i != last_input:
                    self.collapsed += 1
                    continue
                try:
                    msg = json.loads(text)
                except ValueError:
                    continue
                if not isinstance(msg, dict):
                    continue
                if msg.get("type") == "input":
                    try:
                        self.console.page_input(self.page, msg, at)
                    except Exception:  # one bad frame must not end the page's dispatcher
                        log.exception("page %s: input frame failed", self.page)
                    continue
                self._spawn(at, msg)

    def _spawn(self, at: float, msg: dict[str, Any]) -> None:
        if len(self.pending) >= MAX_PENDING and msg.get("type") != "stop":
            self.console.busy(self.page, msg)
            return
        task = asyncio.create_task(self.console.page_message(self.page, msg, at))
        self.pending.add(task)
        task.add_done_callback(self._done)

    def _done(self, task: asyncio.Task[None]) -> None:
        self.pending.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("page %s: a message failed", self.page, exc_info=task.exception())
