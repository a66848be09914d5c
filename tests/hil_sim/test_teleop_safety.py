"""The console's safety rules against `ramp run --sim`, with the console in-process (no browser).

The page is played by calling the console as the page reader does; the robot is watched
over MCP from a separate client. Each test is the issue's black-box finding, made to fail on
the old console:
- with LB held and a stick that jitters as real ones do, a stop the operator did not cause
  (another client's `robot.stop`, a supervisor stall) latches driving until the dead-man is
  released and pressed again;
- a page that bursts frames and falls silent stops the robot 0.3 s after its last frame
  arrived.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
from collections.abc import Iterator
from typing import Any

import pytest

from ramp.mcp.aio import AsyncMcpClient
from ramp.teleop.console import Console
from ramp.teleop.profile import DEFAULT_PROFILE, ProfileLibrary
from tests.harness import start_ramp, stop_process

WHEELS = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")


@pytest.fixture(scope="module")
def robot() -> Iterator[tuple[subprocess.Popen[str], str, int]]:
    proc, host, port = start_ramp(["--sim", "--host", "127.0.0.1", "--port", "0"],
                                  stderr=subprocess.DEVNULL)
    try:
        yield proc, host, port
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGCONT)
        stop_process(proc)


def pad_frame(forward: float, lb: bool) -> dict[str, Any]:
    buttons: list[list[Any]] = [[False, 0.0] for _ in range(17)]
    buttons[4] = [lb, 1.0 if lb else 0.0]
    return {"type": "input", "focused": True, "keys": [],
            "pad": {"mapping": "standard", "axes": [0.0, -forward, 0.0, 0.0],
                    "buttons": buttons}}


async def wheel_speeds(client: AsyncMcpClient) -> list[int]:
    rows = await client.request("base:base.get=()", 2.0)
    values = {r.device: r.values[0] for r in rows if r.prop == "vel"}
    return [int(values[w]) for w in WHEELS]


async def console_for(host: str, port: int) -> tuple[Console, str]:
    library = ProfileLibrary()
    console = Console(host, port, name="tester", library=library,
                      profile=library.load(DEFAULT_PROFILE))
    await console.start()
    page = console.open_page(lambda message: None)
    for _ in range(200):
        if console.command_link.up and console.poller.status.polls:
            break
        await asyncio.sleep(0.02)
    return console, page


async def jitter(console: Console, page: str, seconds: float, *, lb: bool = True) -> None:
    """A held stick that reads 0.8 ± 0.005, 20 frames a second, LB as given."""
    end = asyncio.get_running_loop().time() + seconds
    i = 0
    while asyncio.get_running_loop().time() < end:
        console.page_input(page, pad_frame(0.8 + (0.005 if i % 2 else -0.005), lb))
        i += 1
        await asyncio.sleep(0.05)


async def jitter_until_driving(console: Console, page: str, watcher: AsyncMcpClient,
                               timeout: float = 5.0) -> list[int]:
    """Jitter with LB held until all four wheels turn (or `timeout`); their speeds."""
    end = asyncio.get_running_loop().time() + timeout
    while True:
        await jitter(console, page, 0.2)
        speeds = await wheel_speeds(watcher)
        if all(v > 0 for v in speeds) or asyncio.get_running_loop().time() > end:
            return speeds


async def drive_then_stopped_by(robot: tuple[subprocess.Popen[str], str, int], how: str
                                ) -> tuple[list[int], list[list[int]], list[int]]:
    proc, host, port = robot
    console, page = await console_for(host, port)
    watcher = await AsyncMcpClient.connect(host, port, timeout=2.0)
    try:
        driving = await jitter_until_driving(console, page, watcher)
        if how == "another client":
            await watcher.request("robot:robot.stop=()", 2.0)
        else:  # a 0.6 s supervisor stall
            os.kill(proc.pid, signal.SIGSTOP)
            await asyncio.sleep(0.6)
            os.kill(proc.pid, signal.SIGCONT)
        after = []
        for _ in range(8):  # the stick keeps jittering, LB still held
            await jitter(console, page, 0.15)
            after.append(await wheel_speeds(watcher))
        await jitter(console, page, 0.2, lb=False)  # released ...
        again = await jitter_until_driving(console, page, watcher)  # ... and pressed again
        await jitter(console, page, 0.2, lb=False)
        return driving, after, again
    finally:
        await watcher.request("robot:robot.stop=()", 2.0)
        await watcher.close()
        console.close_page(page)
        await console.stop()


@pytest.mark.parametrize("how", ["another client", "a stall"])
def test_a_stop_the_operator_did_not_cause_latches_driving_until_the_dead_man_is_pressed_again(
        robot: tuple[subprocess.Popen[str], str, int], how: str) -> None:
    driving, after, again = asyncio.run(drive_then_stopped_by(robot, how))
    assert all(v > 0 for v in driving)
    assert after == [[0, 0, 0, 0]] * len(after), f"moved again after {how}'s stop: {after}"
    assert all(v > 0 for v in again), "a released and re-pressed dead-man drives again"


async def burst_then_silence(robot: tuple[subprocess.Popen[str], str, int]) -> float:
    from ramp.teleop.pagereader import PageReader

    _, host, port = robot
    console, page = await console_for(host, port)
    watcher = await AsyncMcpClient.connect(host, port, timeout=2.0)
    reader = PageReader(console, page)
    try:
        assert all(v > 0 for v in await jitter_until_driving(console, page, watcher))
        loop = asyncio.get_running_loop()
        # 3,000 frames arrive at once (a page that froze and flushed its buffer), then none.
        frames = [(loop.time(), json.dumps(pad_frame(0.8 + 0.001 * (i % 7), True),
                                           separators=(",", ":"))) for i in range(3000)]
        last = loop.time()
        reader.inbox.extend(frames)
        reader.wake.set()
        while True:
            await asyncio.sleep(0.01)
            if (await wheel_speeds(watcher)) == [0, 0, 0, 0]:
                return loop.time() - last
            if loop.time() - last > 3.0:
                return loop.time() - last
    finally:
        reader.close()
        await watcher.request("robot:robot.stop=()", 2.0)
        await watcher.close()
        console.close_page(page)
        await console.stop()


def test_a_page_that_bursts_frames_then_falls_silent_stops_within_0_3_s_of_its_last_frame(
        robot: tuple[subprocess.Popen[str], str, int]) -> None:
    took = asyncio.run(burst_then_silence(robot))
    # 0.3 s of staleness, then the console's 50 ms tick and the robot's answer.
    assert took < 0.45, f"still moving {took:.2f} s after the last frame arrived"


def test_through_the_real_socket_a_burst_then_silence_stops_within_0_3_s_of_the_last_frame(
        robot: tuple[subprocess.Popen[str], str, int]) -> None:
    """The black-box finding as it was made: `ramp-teleop` as a process, a page's WebSocket
    that drives, then sends 3,000 frames at once and falls silent (it kept moving 1.6-1.85 s)."""
    import re
    import sys
    import time

    from websockets.sync.client import connect

    from ramp.mcp.client import McpClient

    _, host, port = robot
    teleop = subprocess.Popen(
        [sys.executable, "-m", "ramp.teleop", "--backend", f"{host}:{port}", "--http-port", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert teleop.stdout is not None
        m = re.search(r"http://(127\.0\.0\.1:\d+)/", teleop.stdout.readline())
        assert m
        with connect(f"ws://{m.group(1)}/ws", open_timeout=5) as ws, \
                McpClient(host, port, timeout=5.0) as mcp:
            def moving() -> bool:
                rows = mcp.request("base:base.get=()")
                return any(r.prop == "vel" and r.values[0] != 0 for r in rows)

            deadline = time.monotonic() + 5
            while not moving():
                ws.send(json.dumps(pad_frame(0.8, True)))
                time.sleep(0.05)
                assert time.monotonic() < deadline, "never drove"
            burst = "".join(json.dumps(pad_frame(0.8 + 0.001 * (i % 7), True))
                            for i in range(1))  # one frame's text, sent 3,000 times
            for _ in range(3000):
                ws.send(burst)
            last = time.monotonic()
            while moving():
                time.sleep(0.01)
                assert time.monotonic() - last < 3.0
            took = time.monotonic() - last
        assert took < 0.45, f"still moving {took:.2f} s after the last frame was sent"
    finally:
        teleop.terminate()
        teleop.wait(timeout=10)
        if teleop.stdout is not None:
            teleop.stdout.close()
