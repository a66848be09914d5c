"""Scout in the operator console (SPEC 10): the arm plugin's module appears and is driven
from the page with no code of its own, in Debian's chromium (as test_teleop_browser.py)."""

from __future__ import annotations

import os
import re
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.mcp.client import McpClient
from tests.harness import start_ramp, stop_process
from tests.hil_sim.test_teleop_browser import (
    CHROMIUM,
    CHROMIUM_FLAGS,
    REPO,
    Teleop,
    sync_api,
    wait_for,
)

#: The docs' picture (docs/extending/scout.md): written there by `make screenshots`.
SCREENSHOT = (REPO / "docs" / "img" / "console-scout.png"
              if os.environ.get("RAMP_UPDATE_DOCS") == "1"
              else Path(tempfile.gettempdir()) / f"ramp-scout-{os.getpid()}.png")


@pytest.fixture(scope="module")
def scout() -> Iterator[tuple[str, int]]:
    proc, host, port = start_ramp(["--sim", "--config", "examples/robots/scout.yaml",
                                   "--host", "127.0.0.1", "--port", "0"],
                                  stderr=subprocess.DEVNULL)
    try:
        yield host, port
    finally:
        stop_process(proc)


def test_the_arm_plugin_is_on_the_console_and_moves_from_it(
        scout: tuple[str, int], tmp_path: Path) -> None:
    teleop = Teleop(f"{scout[0]}:{scout[1]}", tmp_path)
    try:
        with sync_api.sync_playwright() as p:
            context = p.chromium.launch_persistent_context(
                str(tmp_path / "profile"), executable_path=CHROMIUM, headless=True,
                args=CHROMIUM_FLAGS, viewport={"width": 1400, "height": 1000})
            try:
                page = context.new_page()
                page.goto(teleop.url)
                expect: Any = sync_api.expect
                expect(page.get_by_test_id("tree:arm")).to_contain_text("shoulder", timeout=5000)
                expect(page.get_by_test_id("tree:base")).to_contain_text("bumper_left")
                expect(page.get_by_test_id("value:arm:arm.stowed")).to_have_text("1",
                                                                                 timeout=5000)
                # Issue 35: Scout's fresh 3S pack read "12.57 V · 0 %" against MARTE's
                # 17-21 V; the gauge now shows the robot's own charge (its YAML model).
                gauge = page.locator('[data-gauge="base:battery.volt"] .gauge-volts')
                expect(gauge).to_have_text(re.compile(r"^12\.\d\d V · (9\d|100) %$"),
                                           timeout=5000)
                alerts = page.get_by_test_id("alert")
                try:
                    expect(alerts).to_have_count(0)
                except AssertionError as exc:  # say which alert it was
                    raise AssertionError(f"alerts on a robot at rest: "
                                         f"{alerts.all_inner_texts()}") from exc
                with McpClient(*scout, timeout=5.0) as mcp:
                    box = page.get_by_test_id("call:arm:shoulder.pos")
                    box.fill("45")
                    box.press("Enter")

                    def at_45() -> bool:
                        rows = mcp.request("arm:arm.get=()")
                        return any(r.device == "shoulder" and r.prop == "pos"
                                   and r.values[0] == 45.0 for r in rows)

                    wait_for(at_45, 5.0, "the shoulder at 45 deg")
                    expect(page.get_by_test_id("value:arm:shoulder.pos")).to_have_text("45.0")
                    expect(page.get_by_test_id("value:arm:arm.stowed")).to_have_text("0")
                    time.sleep(0.3)
                    page.screenshot(path=str(SCREENSHOT))
                    mcp.request("robot:robot.stop=()")
            finally:
                context.close()
    finally:
        teleop.close()
