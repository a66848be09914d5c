"""Reading a page's socket: a slow answer never holds up the next frame; a backlog of input
frames is applied once, the newest, with its arrival time; a binary frame closes with 1003."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from ramp.teleop.pagereader import PageReader


class FakeConsole:
    def __init__(self) -> None:
        self.inputs: list[tuple[dict[str, Any], float | None]] = []
        self.calls: list[dict[str, Any]] = []
        self.answer: asyncio.Future[None] | None = None

    def page_input(self, page: str, msg: dict[str, Any], at: float | None = None) -> None:
        self.inputs.append((msg, at))

    async def page_message(self, page: str, msg: dict[str, Any], at: float | None = None
                           ) -> None:
        self.calls.append(msg)
        assert self.answer is not None
        await self.answer  # the robot is slow to answer

    def busy(self, page: str, msg: dict[str, Any]) -> None:
        pass


class FakeSocket:
    def __init__(self) -> None:
        self.queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue()
        self.closed: int | None = None

    def text(self, obj: dict[str, Any]) -> None:
        self.queue.put_nowait({"type": "websocket.receive", "text": json.dumps(obj)})

    async def receive(self) -> dict[str, Any]:
        return await self.queue.get()

    async def close(self, code: int = 1000) -> None:
        self.closed = code


def pad(lb: bool) -> dict[str, Any]:
    return {"type": "input", "pad": {"lb": lb}}


def test_a_dead_man_release_is_read_while_a_call_waits_for_its_answer() -> None:
    async def run() -> FakeConsole:
        console = FakeConsole()
        console.answer = asyncio.get_running_loop().create_future()
        ws = FakeSocket()
        reader = PageReader(console, "1")  # type: ignore[arg-type]
        reading = asyncio.create_task(reader.read(ws))  # type: ignore[arg-type]
        ws.text({"type": "call", "id": 1, "target": "base:base.get", "params": ""})
        await asyncio.sleep(0.01)
        ws.text(pad(False))  # the release, while the call's answer has not come
        await asyncio.sleep(0.01)
        assert console.calls and console.inputs == [(pad(False), console.inputs[0][1])]
        console.answer.set_result(None)
        ws.queue.put_nowait({"type": "websocket.disconnect"})
        await reading
        reader.close()
        return console

    asyncio.run(run())


def test_a_backlog_of_input_frames_is_applied_once_with_the_newest_arrival_time() -> None:
    async def run() -> tuple[FakeConsole, PageReader]:
        console = FakeConsole()
        reader = PageReader(console, "1")  # type: ignore[arg-type]
        for i in range(500):
            reader.inbox.append((float(i), json.dumps({"type": "input", "n": i},
                                                      separators=(",", ":"))))
        reader.wake.set()
        await asyncio.sleep(0.01)
        reader.close()
        return console, reader

    console, reader = asyncio.run(run())
    assert console.inputs == [({"type": "input", "n": 499}, 499.0)]
    assert reader.collapsed == 499


def test_a_binary_frame_closes_the_socket_with_1003() -> None:
    async def run() -> FakeSocket:
        ws = FakeSocket()
        reader = PageReader(FakeConsole(), "1")  # type: ignore[arg-type]
        ws.queue.put_nowait({"type": "websocket.receive", "bytes": b"\x00\x01"})
        await reader.read(ws)  # type: ignore[arg-type]
        reader.close()
        return ws

    assert asyncio.run(run()).closed == 1003
