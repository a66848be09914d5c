"""The console's robot links against a scripted asyncio MCP server: polls, describe refresh on
attach and fault, a lost link shown at once and reconnected."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable

from ramp.mcp.describe import Catalog
from ramp.mcp.protocol import parse_message
from ramp.teleop.robot import Link, Status, StatusPoller

DESCRIBE = {
    b"robot:robot.describe=()": b"robot:robot.module=(arm)robot:robot.function=(get)"
                                b"robot:robot.property=(uptime,float,s)"
                                b"robot:arm.property=(state,name)",
    b"arm:arm.describe=()": b"arm:arm.function=(get)arm:arm.function=(stop)"
                            b"arm:motor.function=(vel,int -100..100)"
                            b"arm:motor.property=(vel,int)",
}


class FakeRobot:
    """Answers describe and get; `state` of module arm and its motor velocity are settable."""

    def __init__(self) -> None:
        self.state = "ok"
        self.vel = 0
        self.received: list[bytes] = []
        self.writers: list[asyncio.StreamWriter] = []
        self.mute = False

    async def handle(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.writers.append(writer)
        try:
            while line := await reader.readline():
                msg = line.rstrip(b"\n")
                self.received.append(msg)
                if self.mute:
                    continue
                writer.write(self.answer(msg) + b"\n")
        except ConnectionError:
            pass
        finally:
            writer.close()

    def answer(self, msg: bytes) -> bytes:
        if msg in DESCRIBE:
            if msg.startswith(b"arm:") and self.state != "ok":
                return b"arm:arm.error=(fault,motor bus gone)"
            return DESCRIBE[msg]
        out = b""
        if b"robot:robot.get=()" in msg:
            out += b"robot:robot.uptime=(1.5)robot:arm.state=(" + self.state.encode() + b")"
        if b"arm:arm.get=()" in msg:
            out += b"arm:motor.vel=(" + str(self.vel).encode() + b")"
        return out

    def drop_all(self) -> None:
        for w in self.writers:
            w.close()
        self.writers.clear()


def run(coro: Awaitable[None]) -> None:
    asyncio.run(asyncio.wait_for(coro, 20))  # type: ignore[arg-type]


async def until(check: object, timeout: float = 3.0) -> None:
    loop = asyncio.get_running_loop()
    end = loop.time() + timeout
    while not check():  # type: ignore[operator]
        assert loop.time() < end, "condition not met in time"
        await asyncio.sleep(0.01)


def test_poller_shows_values_refreshes_describe_on_fault_and_survives_a_lost_link() -> None:
    async def main() -> None:
        robot = FakeRobot()
        server = await asyncio.start_server(robot.handle, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        statuses: list[Status] = []
        catalogs: list[Catalog] = []
        link = Link("127.0.0.1", port, "status", retry=0.05, answer_timeout=0.5)
        poller = StatusPoller(link, 50.0, on_status=lambda s: statuses.append(s),
                              on_catalog=lambda c: catalogs.append(c))
        tasks = [asyncio.create_task(link.run()), asyncio.create_task(poller.run())]
        try:
            await until(lambda: poller.status.values.get("arm:motor.vel") == "0")
            assert poller.catalog.modules == ["robot", "arm"]
            assert poller.catalog.function("arm", "motor", "vel") is not None
            assert poller.poll_message() == "robot:robot.get=()arm:arm.get=()"
            robot.vel = 42
            await until(lambda: poller.status.values.get("arm:motor.vel") == "42")
            assert poller.status.reachable and poller.status.rtt_ms is not None
            # Only the poller's own messages were ever sent: gets and describes.
            functions = {r.function for m in robot.received
                         for r in parse_message(m).requests}
            assert functions == {"get", "describe"}

            # A fault: described again; the module keeps its last good describe, is not
            # polled, and its state is shown.
            described = len(catalogs)
            robot.state = "fault"
            await until(lambda: poller.status.states.get("arm") == "fault")
            await until(lambda: len(catalogs) > described)
            assert poller.catalog.function("arm", "motor", "vel") is not None
            assert poller.poll_message() == "robot:robot.get=()"
            robot.state = "ok"
            await until(lambda: poller.poll_message().endswith("arm:arm.get=()"))

            # The connection drops: shown at once, then reconnected by itself.
            seen = len(statuses)
            robot.drop_all()
            await until(lambda: any(not s.reachable for s in statuses[seen:]), 1.0)
            await until(lambda: poller.status.reachable and link.up)

            # A robot that stops answering: shown within the answer timeout.
            robot.mute = True
            await until(lambda: not poller.status.reachable or not link.up, 2.0)
            robot.mute = False
            await until(lambda: poller.status.reachable, 3.0)
        finally:
            for t in tasks:
                t.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await t
            await link.close()
            robot.drop_all()
            server.close()
            await server.wait_closed()

    run(main())
