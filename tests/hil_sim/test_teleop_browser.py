"""The teleop console in headless Chromium, against `ramp run --sim` and a real `ramp-teleop`.

The browser is Debian's chromium driven by Playwright's Python package (no `playwright
install`); it finds the page's elements only through SPEC 7's hooks (`value:`, `call:`,
`stop`), as the acceptance tests do, and checks every effect on the robot over MCP from a
separate client. A fake gamepad is injected by an init script overriding
`navigator.getGamepads`, then announced with a `gamepadconnected` event.

One supervisor, one console and one browser serve the module; each test opens its own page
and leaves the robot stopped and control free.
"""

from __future__ import annotations

import os
import re
import select
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.mcp.client import McpClient
from tests.harness import start_ramp, stop_process

REPO = Path(__file__).resolve().parents[2]
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync"]
#: The README's picture. Every run takes it (so the page can always be drawn); it lands in
#: docs/img/ with `make screenshots` (RAMP_UPDATE_DOCS=1), so a plain test run leaves the
#: working tree as it was.
SCREENSHOT = (REPO / "docs" / "img" / "teleop.png" if os.environ.get("RAMP_UPDATE_DOCS") == "1"
              else Path(tempfile.gettempdir()) / f"ramp-teleop-{os.getpid()}.png")
OPERATOR = "tester"
WHEELS = ("lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel")

if not Path(CHROMIUM).exists():
    if os.environ.get("CI"):
        raise RuntimeError(f"{CHROMIUM} is missing: .ci/run installs Debian's chromium")
    pytest.skip(f"{CHROMIUM} is not installed (apt-get install chromium)", allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api")

# A standard-mapping pad at rest. Tests move it with `pad(page, ...)`.
FAKE_PAD = """
(() => {
  const buttons = Array.from({length: 17}, () => ({pressed: false, touched: false, value: 0}));
  const pad = {id: "Fake pad (STANDARD GAMEPAD)", index: 0, connected: true,
               mapping: "standard", timestamp: 0, axes: [0, 0, 0, 0], buttons};
  window.__pad = pad;
  Object.defineProperty(navigator, "getGamepads",
                        {value: () => [pad, null, null, null], configurable: true});
  window.addEventListener("load", () => window.dispatchEvent(new Event("gamepadconnected")));
})();
"""


# --------------------------------------------------------------------------- processes


class Teleop:
    """`ramp-teleop` as a process, once it printed its open line."""

    def __init__(self, backend: str, config_home: Path) -> None:
        env = {**os.environ, "XDG_CONFIG_HOME": str(config_home)}
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ramp.teleop", "--backend", backend, "--http-port", "0",
             "--name", OPERATOR],
            cwd=REPO, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        assert self.proc.stdout is not None
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            r, _, _ = select.select([self.proc.stdout], [], [], 0.5)
            if r:
                line = self.proc.stdout.readline()
                m = re.match(r"ramp-teleop: open (http://127\.0\.0\.1:\d+/)$", line.strip())
                if m:
                    self.url = m.group(1)
                    return
                if not line and self.proc.poll() is not None:
                    break
        self.proc.kill()
        raise AssertionError(f"no open line; stderr: {self.proc.communicate()[1]}")

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.proc.wait(timeout=10)
        for f in (self.proc.stdout, self.proc.stderr):
            if f is not None:
                f.close()


@pytest.fixture(scope="module")
def robot() -> Iterator[tuple[str, int]]:
    proc, host, port = start_ramp(["--sim", "--host", "127.0.0.1", "--port", "0"],
                                  stderr=subprocess.DEVNULL)
    try:
        yield host, port
    finally:
        stop_process(proc)


@pytest.fixture(scope="module")
def config_home(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The operator's config dir: a copy of the default profile and a broken one."""
    home = tmp_path_factory.mktemp("xdg")
    profiles = home / "ramp" / "profiles"
    profiles.mkdir(parents=True)
    default = (REPO / "ramp" / "teleop" / "profiles" / "default.yaml").read_text()
    (profiles / "slow.yaml").write_text(default.replace("scale: 0.5", "scale: 0.2"))
    (profiles / "broken.yaml").write_text("deadman: 4\nbindings:\n  - request: base:base.drive\n"
                                          "    stick: {forward: {axis: 9}, turn: {axis: 0}}\n")
    return home


@pytest.fixture(scope="module")
def teleop(robot: tuple[str, int], config_home: Path) -> Iterator[Teleop]:
    t = Teleop(f"{robot[0]}:{robot[1]}", config_home)
    try:
        yield t
    finally:
        t.close()


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with sync_api.sync_playwright() as p, tempfile.TemporaryDirectory() as profile_dir:
        context = p.chromium.launch_persistent_context(
            profile_dir, executable_path=CHROMIUM, headless=True, args=CHROMIUM_FLAGS,
            viewport={"width": 1400, "height": 1000})
        context.add_init_script(FAKE_PAD)
        try:
            yield context
        finally:
            context.close()


@pytest.fixture()
def mcp(robot: tuple[str, int]) -> Iterator[McpClient]:
    """A monitoring client; it also leaves the robot stopped after the test."""
    client = McpClient(*robot, timeout=5.0)
    try:
        yield client
    finally:
        client.request("robot:robot.stop=()")
        client.close()


def open_page(browser: Any, url: str) -> Any:
    page = browser.new_page()
    page.goto(url)
    # The live values arrive with the first poll after the describe.
    sync_api.expect(page.get_by_test_id("value:base:lf_wheel.vel")).not_to_have_text("",
                                                                                    timeout=5000)
    return page


@pytest.fixture()
def page(browser: Any, teleop: Teleop) -> Iterator[Any]:
    p = open_page(browser, teleop.url)
    try:
        yield p
    finally:
        if not p.is_closed():
            p.close()


# --------------------------------------------------------------------------- helpers


def robot_state(client: McpClient) -> dict[str, Any]:
    """`module:device.property` -> first value, from base.get and ble.get."""
    rows = client.request("base:base.get=()ble:ble.get=()robot:robot.get=()")
    return {f"{r.module}:{r.device}.{r.prop}": r.values[0] for r in rows if r.values}


def wheels(client: McpClient) -> list[Any]:
    s = robot_state(client)
    return [s[f"base:{w}.vel"] for w in WHEELS]


def wait_for(check: Callable[[], bool], timeout: float, what: str) -> float:
    """Seconds until `check()` holds; fails after `timeout`."""
    start = time.monotonic()
    while True:
        if check():
            return time.monotonic() - start
        if time.monotonic() - start > timeout:
            raise AssertionError(f"not within {timeout} s: {what}")
        time.sleep(0.005)


def pad(page: Any, *, axes: list[float] | None = None, **buttons: float) -> None:
    """Set the fake pad: `pad(page, axes=[0, -1, 0, 0], b4=1, b7=0.8)`."""
    values = {int(name[1:]): v for name, v in buttons.items()}
    page.evaluate("""([axes, values]) => {
        const p = window.__pad;
        if (axes !== null) p.axes = axes;
        for (const [i, v] of Object.entries(values))
            p.buttons[Number(i)] = {pressed: v >= 0.5, touched: v > 0, value: v};
        p.timestamp += 1;
    }""", [axes, values])


def all_stopped(client: McpClient) -> bool:
    s = robot_state(client)
    return all(s[f"base:{w}.vel"] == 0 for w in WHEELS) and s["ble:chain.vel"] == 0 \
        and s["ble:lift.vel"] == 0


# --------------------------------------------------------------------------- the tests


def test_tree_lists_the_modules_and_a_wheel_moved_by_another_client_shows_within_a_second(
        page: Any, mcp: McpClient) -> None:
    sync_api.expect(page.get_by_test_id("tree:base")).to_contain_text("lf_wheel")
    sync_api.expect(page.get_by_test_id("tree:ble")).to_contain_text("chain")
    sync_api.expect(page.get_by_test_id("value:ble:lift.pos")).not_to_have_text("")
    with McpClient(*mcp_address(mcp)) as other:
        assert other.request("base:lb_wheel.vel=(37)") == []
        sent = time.monotonic()
        value = page.get_by_test_id("value:base:lb_wheel.vel")
        while value.text_content() != "37":
            other.heartbeat()  # keep it turning while we look
            assert time.monotonic() - sent < 1.0, "the page did not show 37 within 1 s"
            time.sleep(0.02)
        other.request("base:base.stop=()")


def mcp_address(client: McpClient) -> tuple[str, int]:
    return client.host, client.port


def test_a_value_typed_into_a_call_input_moves_the_robot_and_keeps_it_moving(
        page: Any, mcp: McpClient) -> None:
    box = page.get_by_test_id("call:base:rf_wheel.vel")
    box.fill("-25")
    box.press("Enter")
    wait_for(lambda: robot_state(mcp)["base:rf_wheel.vel"] == -25, 2.0, "rf_wheel at -25")
    # Past the watchdog timeout (1 s): the live page keeps it fed.
    time.sleep(1.3)
    assert robot_state(mcp)["base:rf_wheel.vel"] == -25
    lift = page.get_by_test_id("call:ble:lift.pos")
    lift.fill("0.2")
    lift.press("Enter")
    wait_for(lambda: robot_state(mcp)["ble:lift.vel"] != 0, 2.0, "lift moving to 0.2")
    page.get_by_test_id("stop").click()
    wait_for(lambda: all_stopped(mcp), 1.0, "everything stopped")


def test_stop_by_click_and_by_space_zeroes_every_motion(page: Any, mcp: McpClient) -> None:
    for how in ("click", "space"):
        drive = page.get_by_test_id("call:base:base.drive")
        drive.fill("40,0")
        drive.press("Enter")
        chain = page.get_by_test_id("call:ble:chain.vel")
        chain.fill("60")
        chain.press("Enter")
        page.get_by_test_id("call:ble:lift.extend").click()
        wait_for(lambda: not all_stopped(mcp) and robot_state(mcp)["ble:chain.vel"] == 60
                 and robot_state(mcp)["ble:lift.vel"] != 0, 2.0, "robot moving")
        if how == "click":
            page.get_by_test_id("stop").click()
        else:
            # Focus in a text box: Space is still STOP, not a character.
            page.get_by_test_id("call:base:lf_wheel.vel").focus()
            page.keyboard.press("Space")
        wait_for(lambda: all_stopped(mcp), 1.0, f"STOP by {how}")
        assert robot_state(mcp)["robot:watchdog.state"] == "idle"
    assert page.get_by_test_id("call:base:lf_wheel.vel").input_value() == ""


def test_gamepad_drives_only_while_lb_is_held_and_release_stops_within_0_3_s(
        page: Any, mcp: McpClient) -> None:
    sync_api.expect(page.get_by_test_id("gamepad")).to_contain_text("standard mapping")
    # Stick forward without the dead-man: nothing moves.
    pad(page, axes=[0, -1, 0, 0], b7=1.0)
    time.sleep(0.4)
    assert all_stopped(mcp)
    # LB held: all four wheels forward, the chain runs on the right trigger.
    pad(page, b4=1.0)
    wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "four wheels forward")
    wait_for(lambda: robot_state(mcp)["ble:chain.vel"] > 0, 1.0, "chain running")
    sync_api.expect(page.get_by_test_id("value:base:lf_wheel.vel")).not_to_have_text("0")
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SCREENSHOT))
    # Trigger released while LB is held: the chain stops, the wheels keep going.
    pad(page, b7=0.0)
    wait_for(lambda: robot_state(mcp)["ble:chain.vel"] == 0, 1.0, "chain stopped")
    assert all(v > 0 for v in wheels(mcp))
    time.sleep(1.2)  # past the watchdog timeout: the held dead-man keeps it fed
    assert all(v > 0 for v in wheels(mcp))
    # Release LB: stopped within 0.3 s ...
    pad(page, b4=0.0)
    took = wait_for(lambda: all_stopped(mcp), 0.3, "stopped after LB release")
    assert took <= 0.3
    # ... then silence: the console does not fight another client with zeros.
    pad(page, b7=1.0)
    with McpClient(*mcp_address(mcp)) as other:
        other.request("base:lf_wheel.vel=(30)")
        for _ in range(10):
            time.sleep(0.05)
            other.heartbeat()
        assert robot_state(mcp)["base:lf_wheel.vel"] == 30
        assert robot_state(mcp)["ble:chain.vel"] == 0  # trigger without LB does nothing
        other.request("base:base.stop=()")


def test_stop_latches_a_held_dead_man_until_it_is_released(page: Any, mcp: McpClient) -> None:
    pad(page, axes=[0, -1, 0, 0], b4=1.0)
    wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "driving")
    page.keyboard.press("Space")
    wait_for(lambda: all_stopped(mcp), 0.5, "STOP")
    sync_api.expect(page.get_by_test_id("drive-state")).to_contain_text("LATCHED")
    time.sleep(0.3)
    assert all_stopped(mcp)  # the stick is still forward and LB still held
    pad(page, b4=0.0)
    time.sleep(0.15)
    pad(page, b4=1.0)
    wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "driving again after re-press")
    pad(page, axes=[0, 0, 0, 0], b4=0.0)
    wait_for(lambda: all_stopped(mcp), 0.5, "stopped")


def test_keyboard_drives_while_w_is_held(page: Any, mcp: McpClient) -> None:
    page.keyboard.down("w")
    wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "W drives forward")
    page.keyboard.up("w")
    wait_for(lambda: all_stopped(mcp), 0.3, "released W stops")


def test_closing_the_page_while_driving_stops_the_robot(browser: Any, teleop: Teleop,
                                                        mcp: McpClient) -> None:
    page = open_page(browser, teleop.url)
    pad(page, axes=[0, -1, 0, 0], b4=1.0)
    wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "driving")
    page.close()
    wait_for(lambda: all_stopped(mcp), 1.0, "stopped within the watchdog timeout")


def test_killing_ramp_teleop_while_driving_stops_the_robot(
        browser: Any, robot: tuple[str, int], config_home: Path, mcp: McpClient) -> None:
    own = Teleop(f"{robot[0]}:{robot[1]}", config_home)
    try:
        page = open_page(browser, own.url)
        pad(page, axes=[0, -1, 0, 0], b4=1.0)
        wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "driving")
        own.proc.kill()
        wait_for(lambda: all_stopped(mcp), 1.0, "stopped within the watchdog timeout")
        sync_api.expect(page.get_by_test_id("link")).to_have_text("console lost")
        page.close()
    finally:
        own.close()


def test_taking_control_shows_the_owner_and_refuses_another_client(
        page: Any, mcp: McpClient) -> None:
    page.get_by_test_id("take-control").click()
    sync_api.expect(page.get_by_test_id("value:robot:control.owner")).to_have_text(OPERATOR)
    sync_api.expect(page.get_by_test_id("control-owner")).to_contain_text(f"{OPERATOR} (you)")
    with McpClient(*mcp_address(mcp)) as other:
        (error,) = other.request("base:base.drive=(40,0)")
        assert error.prop == "error" and error.values[0] == "not_owner"
    # The owner's own console still drives.
    pad(page, axes=[0, -1, 0, 0], b4=1.0)
    wait_for(lambda: all(v > 0 for v in wheels(mcp)), 1.0, "owner drives")
    pad(page, axes=[0, 0, 0, 0], b4=0.0)
    wait_for(lambda: all_stopped(mcp), 0.5, "stopped")
    page.get_by_test_id("hand-back").click()
    sync_api.expect(page.get_by_test_id("value:robot:control.owner")).to_have_text("none")


def test_profiles_switch_from_the_page_and_a_broken_one_shows_file_and_line(
        page: Any, mcp: McpClient) -> None:
    select_ = page.get_by_test_id("profile")
    select_.select_option("broken")
    error = page.get_by_test_id("profile-error")
    sync_api.expect(error).to_contain_text("broken.yaml:4: bindings.0.stick.forward.axis")
    sync_api.expect(select_).to_have_value("default")
    select_.select_option("slow")
    sync_api.expect(error).to_be_hidden()
    pad(page, axes=[0, -1, 0, 0], b4=1.0)
    wait_for(lambda: wheels(mcp) == [20, 20, 20, 20], 1.0, "slow profile: 20 %")
    pad(page, axes=[0, 0, 0, 0], b4=0.0)
    wait_for(lambda: all_stopped(mcp), 0.5, "stopped")
    select_.select_option("default")


def test_chromium_is_the_system_one() -> None:
    assert shutil.which("chromium") or Path(CHROMIUM).exists()


def test_a_lost_robot_shows_at_once_and_the_reconnect_does_not_resume_motion(
        browser: Any, config_home: Path) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    args = ["--sim", "--host", "127.0.0.1", "--port", str(port)]
    proc, host, _ = start_ramp(args, stderr=subprocess.DEVNULL)
    own = Teleop(f"{host}:{port}", config_home)
    page = None
    try:
        page = open_page(browser, own.url)
        page.get_by_test_id("take-control").click()
        sync_api.expect(page.get_by_test_id("value:robot:control.owner")).to_have_text(OPERATOR)
        pad(page, axes=[0, -1, 0, 0], b4=1.0)
        with McpClient(host, port) as first:
            wait_for(lambda: all(v > 0 for v in wheels(first)), 1.0, "driving")
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout is not None:
            proc.stdout.close()
        sync_api.expect(page.get_by_test_id("link")).to_have_text("robot link lost",
                                                                   timeout=1000)
        proc, _, _ = start_ramp(args, stderr=subprocess.DEVNULL)
        sync_api.expect(page.get_by_test_id("link")).to_contain_text("link ok", timeout=5000)
        with McpClient(host, port) as second:
            time.sleep(0.5)  # LB and the stick are still held: nothing resumes
            assert all_stopped(second)
            sync_api.expect(page.get_by_test_id("drive-state")).to_contain_text("LATCHED")
            pad(page, b4=0.0)
            time.sleep(0.15)
            pad(page, b4=1.0)
            wait_for(lambda: all(v > 0 for v in wheels(second)), 1.0, "driving after re-press")
            pad(page, axes=[0, 0, 0, 0], b4=0.0)
            wait_for(lambda: all_stopped(second), 0.5, "stopped")
            # Control, held before the loss, was taken again on the new connection.
            assert robot_state(second)["robot:control.owner"] == OPERATOR
    finally:
        if page is not None:
            page.close()
        own.close()
        proc.kill()
        proc.wait(timeout=5)
        if proc.stdout is not None:
            proc.stdout.close()


def test_another_sites_page_cannot_open_the_console_socket(teleop: Teleop) -> None:
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    ws_url = teleop.url.replace("http://", "ws://") + "ws"
    with pytest.raises(InvalidStatus), connect(ws_url, origin="http://evil.example"):
        pass
    with connect(ws_url, origin=teleop.url.rstrip("/"), open_timeout=5) as ws:
        assert '"type":"hello"' in str(ws.recv(timeout=5))


def test_at_1500_px_every_ble_control_stays_inside_its_panel(browser: Any,
                                                             teleop: Teleop) -> None:
    """Issue 35: the lift's presets pushed `retract` out of the BLE panel at 1500 px."""
    page = browser.new_page()
    try:
        page.set_viewport_size({"width": 1500, "height": 1000})
        page.goto(teleop.url)
        retract = page.get_by_test_id("call:ble:lift.retract")
        sync_api.expect(retract).to_be_visible(timeout=5000)
        panel = page.locator('[data-module="ble"]').bounding_box()
        for testid in ("call:ble:lift.retract", "call:ble:lift.pos", "call:ble:lift.extend"):
            box = page.get_by_test_id(testid).bounding_box()
            assert box is not None and panel is not None
            assert box["x"] >= panel["x"] and box["x"] + box["width"] <= \
                panel["x"] + panel["width"], (testid, box, panel)
    finally:
        page.close()


def test_a_robot_with_no_autonomy_gets_one_line_not_a_page(page: Any) -> None:
    card = page.get_by_test_id("autonomy")
    sync_api.expect(page.get_by_test_id("autonomy-status")).to_contain_text("No autonomy view")
    sync_api.expect(page.get_by_test_id("autonomy-map")).to_be_hidden()
    sync_api.expect(page.get_by_test_id("autonomy-confidence")).to_be_hidden()
    box = card.bounding_box()
    assert box is not None and box["height"] < 120, box


def test_the_battery_gauge_shows_the_robot_s_own_charge_and_interlocks_are_panel_state(
        page: Any, mcp: McpClient) -> None:
    charge = float(next(r.values[0] for r in mcp.request("base:base.get=()")
                        if r.device == "battery" and r.prop == "charge"))
    gauge = page.locator('[data-gauge="base:battery.volt"] .gauge-volts')
    sync_api.expect(gauge).to_contain_text(f"· {charge:.0f} %", timeout=5000)
    sync_api.expect(page.get_by_test_id("robot-interlocks")).not_to_have_text("")
    # Nothing is wrong with a robot at rest: no alert and no banner.
    sync_api.expect(page.get_by_test_id("alert")).to_have_count(0)
    sync_api.expect(page.locator("#banner")).to_be_hidden()


def test_an_active_interlock_is_an_alert_per_rule_an_events_line_and_panel_state(
        page: Any, mcp: McpClient) -> None:
    """A robot whose describe gives a rule no severity (`rule=(NAME)`) means `warning`: one
    alert per rule with the rule's own advice, never "the lift's position" for any rule."""
    assert mcp.request("sim:input.set=(ble,lift_pot,0.8)") == []
    try:
        alert = page.locator('[data-testid="alert"]'
                             '[data-alert="interlock:chain_needs_ladder_down"]')
        sync_api.expect(alert).to_be_visible(timeout=5000)
        sync_api.expect(alert).to_have_attribute("data-severity", "warning")
        sync_api.expect(alert).not_to_contain_text("lift's position")
        sync_api.expect(page.get_by_test_id("robot-interlocks")).to_contain_text(
            "chain_needs_ladder_down (warning)")
        sync_api.expect(page.get_by_test_id("value:robot:interlock.active")).to_have_attribute(
            "data-severity", "warning")
        sync_api.expect(page.get_by_test_id("event").filter(
            has_text="interlock chain_needs_ladder_down active (warning)")).to_have_count(1)
    finally:
        assert mcp.request("sim:input.clear=(ble,lift_pot)") == []
    sync_api.expect(page.locator('[data-alert^="interlock:"]')).to_have_count(0, timeout=5000)
    sync_api.expect(page.get_by_test_id("event").filter(
        has_text="interlock chain_needs_ladder_down released")).to_have_count(1)
