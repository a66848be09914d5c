"""The console's view of the autonomy (SPEC 7.1) in headless Chromium, on a realtime mission.

`ramp sim mission --realtime --foxglove-port 0` runs the robot, its emulators and the
autonomy on the wall clock; a real `ramp-teleop --autonomy` watches both its links; the page
is found only through SPEC 7.1's hooks, and every effect on the robot is checked over MCP from
a separate client. One test walks the issue's scenario (state, map and confidence appear; the
LIDAR blinded by `sim:lidar.blind=(1)` raises an error alert; its Take control takes control
and stops the robot; Hand back gives control back to the autonomy), one checks a console
whose view is unreachable.
"""

from __future__ import annotations

import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.mcp.client import McpClient

REPO = Path(__file__).resolve().parents[2]
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync"]
SCREENSHOT = (REPO / "docs" / "img" / "console-autonomy.png"
              if os.environ.get("RAMP_UPDATE_DOCS") == "1"
              else Path(tempfile.gettempdir()) / f"ramp-console-autonomy-{os.getpid()}.png")
OPERATOR = "tester"
SEED = "5"
WHEELS = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")
#: The mission machine's states (`python -m ramp.statemachine --states`).
STATES = re.compile(r"idle|acquire_control|initial_localization|prepare_for_scan|"
                    r"scan_for_obstacles|detect_obstacles|plan_path_to_dig|cross_to_dig|"
                    r"excavate|plan_path_home|cross_home|dock|deposit|decouple|stop|relevel|"
                    r"rescan|relocalize|paused|waiting_for_operator|done")

if not Path(CHROMIUM).exists():
    pytest.skip(f"{CHROMIUM} is not installed (apt-get install chromium)",
                allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api")


def read_line(proc: subprocess.Popen[str], pattern: str, timeout: float) -> re.Match[str]:
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        r, _, _ = select.select([proc.stdout], [], [], 0.5)
        if r:
            line = proc.stdout.readline()
            m = re.search(pattern, line)
            if m:
                return m
            if not line and proc.poll() is not None:
                break
    raise AssertionError(f"no line matching {pattern!r} within {timeout} s")


def stop_process(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=10)
    for f in (proc.stdout, proc.stderr):
        if f is not None:
            f.close()


@pytest.fixture(scope="module")
def mission() -> Iterator[tuple[str, str]]:
    """(MCP address, view address) of a realtime mission."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port", "0",
         "--foxglove-port", "0", "--seed", SEED],
        cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        view = read_line(proc, r"foxglove live on ws://([\d.]+:\d+)", 60).group(1)
        mcp = read_line(proc, r"MCP on ([\d.]+:\d+)", 30).group(1)
        yield mcp, view
    finally:
        stop_process(proc)


def start_teleop(backend: str, autonomy: str) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramp.teleop", "--backend", backend, "--autonomy", autonomy,
         "--http-port", "0", "--name", OPERATOR],
        cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    url = read_line(proc, r"ramp-teleop: open (http://127\.0\.0\.1:\d+/)", 30).group(1)
    return proc, url


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with sync_api.sync_playwright() as p, tempfile.TemporaryDirectory() as profile_dir:
        context = p.chromium.launch_persistent_context(
            profile_dir, executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS,
            viewport={"width": 1400, "height": 1000})
        try:
            yield context
        finally:
            context.close()


def robot(client: McpClient) -> dict[str, Any]:
    rows = client.request("base:base.get=()robot:robot.get=()")
    return {f"{r.module}:{r.device}.{r.prop}": r.values[0] for r in rows if r.values}


def wait_for(check: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"not within {timeout} s: {what}")
        time.sleep(0.1)


@pytest.mark.timeout(240)  # ~20 s; `make screenshots` waits for the crossing (a minute more)
def test_the_operator_sees_the_mission_and_takes_over_from_an_error_alert_then_hands_back(
        mission: tuple[str, str], browser: Any) -> None:
    backend, view = mission
    teleop, url = start_teleop(backend, view)
    host, port = backend.split(":")
    page = browser.new_page()
    try:
        page.goto(url)
        expect = sync_api.expect
        expect(page.get_by_test_id("autonomy-state")).to_have_text(STATES, timeout=20_000)
        expect(page.get_by_test_id("autonomy-map")).to_be_visible()
        expect(page.get_by_test_id("autonomy-confidence")).to_have_text(
            re.compile(r"^\d\.\d\d$"), timeout=20_000)
        expect(page.get_by_test_id("link-bandwidth")).to_contain_text("B/s", timeout=5_000)
        with McpClient(host, int(port), timeout=5.0) as mcp:
            # Past the first fix: the autonomy knows where it is and says so.
            wait_for(lambda: float(page.get_by_test_id("autonomy-confidence").text_content()
                                   or 0) > 0.5, 60, "a localization fix")
            # The view's typed localization, not a reading of state names or reasons.
            expect(page.get_by_test_id("autonomy-localization")).to_have_text(
                "ok", timeout=30_000)
            # Normal work raises no alert (an info interlock such as digging_creep is panel
            # state, SPEC 11): nothing to act on, nothing shown as a problem.
            expect(page.locator('[data-testid="alert"][data-severity="warning"]')).to_have_count(
                0, timeout=5_000)
            if os.environ.get("RAMP_UPDATE_DOCS") == "1":
                # The docs' picture: with the obstacles detected and the plan on the map.
                expect(page.get_by_test_id("autonomy-state")).to_contain_text(
                    "cross_to_dig", timeout=120_000)
                time.sleep(3)
            # Blind the LIDAR, as a trainer would while the autonomy holds control: `sim`
            # requests act on the world and are exempt from control arbitration (SPEC 12).
            assert mcp.request("sim:lidar.blind=(1)") == []
            error = page.locator('[data-testid="alert"][data-severity="error"]').first
            expect(error).to_be_visible(timeout=60_000)
            expect(error).to_contain_text(re.compile("Localization lost|waiting for the "
                                                     "operator"))
            page.screenshot(path=str(SCREENSHOT))
            error.get_by_test_id("alert-takeover").click()
            wait_for(lambda: robot(mcp)["robot:control.owner"] == OPERATOR, 5,
                     "the console owns control")
            wait_for(lambda: all(robot(mcp)[f"base:{w}.vel"] == 0 for w in WHEELS), 2,
                     "the robot stopped")
            expect(page.get_by_test_id("autonomy-state")).to_contain_text("paused",
                                                                          timeout=10_000)
            page.get_by_test_id("hand-back").click()
            wait_for(lambda: robot(mcp)["robot:control.owner"] == "autonomy", 15,
                     "the autonomy took control back")
            expect(page.get_by_test_id("autonomy-state")).not_to_contain_text(
                "paused", timeout=10_000)
    finally:
        page.close()
        stop_process(teleop)


def test_an_unreachable_view_is_said_and_the_console_still_works(
        mission: tuple[str, str], browser: Any) -> None:
    backend, _ = mission
    teleop, url = start_teleop(backend, "127.0.0.1:9")
    page = browser.new_page()
    try:
        page.goto(url)
        expect = sync_api.expect
        expect(page.get_by_test_id("autonomy-status")).to_contain_text("unreachable",
                                                                       timeout=10_000)
        warning = page.locator('[data-testid="alert"][data-severity="warning"]',
                               has_text="Autonomy view unreachable")
        expect(warning).to_be_visible(timeout=10_000)
        expect(page.get_by_test_id("value:base:lf_wheel.vel")).not_to_have_text("",
                                                                               timeout=10_000)
        stops = page.get_by_test_id("event").filter(has_text="STOP sent")
        page.get_by_test_id("stop").click()
        expect(stops).to_have_count(1, timeout=5_000)
        page.get_by_test_id("stop").click()
        expect(stops).to_have_count(2, timeout=5_000)
        # The Events list's STOP entries are plain lines, not copies of the big STOP button
        # (72 px blocks that overlapped into one red smear).
        heights = [stops.nth(i).bounding_box()["height"] for i in range(2)]
        assert max(heights) < 30, heights
    finally:
        page.close()
        stop_process(teleop)
