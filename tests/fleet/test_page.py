"""The fleet page (SPEC 14): tiles from what robots publish, and Stop all measured per robot.

A unit part feeds the supervisor VDA 5050 messages by hand; a browser part runs `ramp fleet
sim` (a real Mosquitto, the three simulated robots -- MARTE with the autonomy, MARTE without,
Scout -- their agents, the page) in Debian's chromium: it sends MARTE-with-autonomy its mission
from the page, drives the other two over MCP, and presses STOP ALL while all three drive: every
wheel stops (read over MCP, on the emulated wire), stays stopped, and each tile shows its
measured time to `driving=false`."""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.page.supervisor import FleetSupervisor
from tests.harness import REPO, ask_line, end_process


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def feed(sup: FleetSupervisor, serial: str, name: str, msg: dict[str, Any]) -> None:
    sup.receive(f"uagv/v2/ACME/{serial}/{name}", json.dumps(msg).encode())


def state(headers: v.Headers, *, driving: bool, actions: list[dict[str, Any]] | None = None,
          errors: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    f = v.StateFields()
    f.driving, f.paused = driving, False
    f.operating_mode = "MANUAL"
    f.battery_state = v.battery(76.0, voltage=20.1)
    f.errors = errors or []
    f.action_states = actions or []
    f.information = [v.info("controlOwner", "control is held by ana")]
    return v.state(headers, f)


def test_a_tile_is_what_the_robot_says_and_stop_all_is_timed() -> None:
    clock = FakeClock()
    sup = FleetSupervisor("127.0.0.1", 1, clock=clock)
    sent: list[tuple[str, dict[str, Any]]] = []
    sup.client.publish = lambda topic, payload, qos=0: sent.append(  # type: ignore[method-assign]
        (topic, json.loads(payload)))
    h = v.Headers("ACME", "digger-7")
    feed(sup, "digger-7", "connection", v.connection(h, v.ONLINE))
    assert sent[-1][1]["actions"][0]["actionType"] == "stateRequest"  # a newcomer is asked
    feed(sup, "digger-7", "factsheet", {"typeSpecification": {"seriesName": "Digger"},
                                        "protocolFeatures": {"agvActions": [
                                            {"actionType": "stopPause"},
                                            {"actionType": "rmcMission"}]}})
    feed(sup, "digger-7", "state", state(h, driving=True, errors=[
        v.error("moduleFault", "FATAL", "module ble is in fault")]))
    robot = sup.snapshot()["robots"][0]
    assert (robot["type"], robot["battery"], robot["owner"], robot["mode"]) == \
        ("Digger", 76.0, "ana", "MANUAL")
    assert robot["driving"] is True and robot["can_mission"]
    assert robot["alerts"] == [{"level": "error", "type": "moduleFault",
                                "text": "module ble is in fault"}]
    assert sup.stop_all() == ["digger-7"]
    topic, msg = sent[-1]
    assert topic == "uagv/v2/ACME/digger-7/instantActions"
    action = msg["actions"][0]
    assert action["actionType"] == "stopPause"
    clock.t += 0.030
    feed(sup, "digger-7", "state", state(h, driving=False))  # not yet about our action
    assert sup.snapshot()["robots"][0]["stopping"]
    clock.t += 0.020
    feed(sup, "digger-7", "state", state(h, driving=False, actions=[
        v.action_state(action["actionId"], "stopPause", "FINISHED")]))
    assert sup.snapshot()["robots"][0]["stop_ms"] == 50.0
    assert sup.mission("ACME/digger-7") is None
    order = sent[-1][1]
    assert order["nodes"][0]["actions"][0]["actionType"] == "rmcMission"
    clock.t += 10
    feed(sup, "digger-7", "connection", v.connection(h, v.CONNECTIONBROKEN))
    robot = sup.snapshot()["robots"][0]
    assert robot["alerts"][0]["type"] == "connection" and robot["alerts"][0]["level"] == "error"


def test_a_robot_without_rmc_mission_gets_none() -> None:
    sup = FleetSupervisor("127.0.0.1", 1)
    sup.client.publish = lambda *a, **k: None  # type: ignore[method-assign]
    feed(sup, "scout-1", "factsheet", {"protocolFeatures": {"agvActions": [
        {"actionType": "stopPause"}]}})
    assert "no autonomy" in (sup.mission("ACME/scout-1") or "")
    assert sup.mission("ACME/nobody") == "no such robot"


CHROMIUM = "/usr/bin/chromium"


@pytest.fixture(scope="module")
def fleet() -> Iterator[dict[str, Any]]:
    if not Path(CHROMIUM).exists():
        if os.environ.get("CI"):
            raise RuntimeError(f"{CHROMIUM} is missing: .ci/run installs Debian's chromium")
        pytest.skip("chromium is not installed")
    from tests.fleet_fixtures import need_mosquitto

    need_mosquitto()
    proc = subprocess.Popen([sys.executable, "-m", "ramp.cli", "fleet", "sim", "--robots",
                             "marte,marte-noauto,scout", "--http-port", "0", "--consoles"],
                            cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.stdout is not None
    out: dict[str, Any] = {"robots": {}, "consoles": {}}
    deadline = time.monotonic() + 150
    while "page" not in out and time.monotonic() < deadline:
        r, _, _ = select.select([proc.stdout], [], [], 0.5)
        if r:
            line = proc.stdout.readline()
            m = re.search(r"robot (\S+) \((\S+)\) MCP on ([\d.]+):(\d+)", line)
            if m:
                out["robots"][m.group(1)] = (m.group(3), int(m.group(4)))
            m = re.search(r"console for (\S+) on (http://\S+)", line)
            if m:
                out["consoles"][m.group(1)] = m.group(2)
            m = re.search(r"page on (http://\S+)", line)
            if m:
                out["page"] = m.group(1)
    try:
        assert "page" in out, "ramp fleet sim never served its page"
        yield out
    finally:
        end_process(proc, signal.SIGINT, 30)


@pytest.mark.timeout(300)
def test_stop_all_in_the_browser_stops_every_robot(fleet: dict[str, Any]) -> None:
    import socket

    sync_api = pytest.importorskip("playwright.sync_api")
    assert sorted(fleet["robots"]) == ["marte-1", "marte-noauto-1", "scout-1"]
    wires = {serial: socket.create_connection(addr) for serial, addr in fleet["robots"].items()}
    shot = (REPO / "docs" / "img" / "fleet.png" if os.environ.get("RAMP_UPDATE_DOCS") == "1"
            else Path(tempfile.gettempdir()) / f"ramp-fleet-{os.getpid()}.png")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                    args=["--no-sandbox", "--disable-gpu"])
        try:
            page = browser.new_page(viewport={"width": 1300, "height": 420})
            page.goto(fleet["page"])
            tiles = {s: page.get_by_test_id(f"robot-{s}") for s in wires}
            assert sorted(fleet["consoles"]) == sorted(wires)
            for serial, url in fleet["consoles"].items():  # each tile links its own console
                sync_api.expect(tiles[serial].get_by_test_id("console")).to_have_attribute(
                    "href", url, timeout=40_000)
            for serial in ("marte-noauto-1", "scout-1"):  # their factsheets list no rmcMission
                sync_api.expect(tiles[serial].get_by_test_id("send-mission")).to_be_disabled(
                    timeout=40_000)
            mission = tiles["marte-1"].get_by_test_id("send-mission")
            sync_api.expect(mission).to_be_enabled(timeout=40_000)
            mission.click()  # an order with rmcMission: its autonomy drives it
            sync_api.expect(tiles["marte-1"].get_by_test_id("motion")).to_have_text(
                "driving", timeout=60_000)
            for serial in ("marte-noauto-1", "scout-1"):  # no autonomy: driven over MCP
                assert ask_line(wires[serial],
                                "robot:watchdog.timeout=(30)base:base.drive=(40,0)") == ""
            for tile in tiles.values():
                sync_api.expect(tile.get_by_test_id("motion")).to_have_text("driving",
                                                                             timeout=60_000)
            page.get_by_test_id("stop-all").click()
            for tile in tiles.values():
                sync_api.expect(tile.get_by_test_id("stop-time")).to_contain_text(
                    "ms to driving=false", timeout=15_000)
                sync_api.expect(tile.get_by_test_id("motion")).to_have_text("paused")
            sync_api.expect(tiles["marte-1"].get_by_test_id("mission")).to_contain_text(
                "paused")
            # Every stop confirmed: no alert says one is late.
            assert page.locator('[data-alert$=":stop-late"]').count() == 0
            page.screenshot(path=str(shot), full_page=True)
            for serial, s in wires.items():  # on the emulated wire, and it stays so
                for _ in range(2):
                    got = ask_line(s, "base:base.get=()")
                    speeds = [int(x) for x in re.findall(r"_wheel\.vel=\((-?\d+)\)", got)]
                    assert speeds and all(x == 0 for x in speeds), (serial, got)
                    time.sleep(1.0)  # the paused autonomy must not drive again
            sync_api.expect(tiles["marte-1"].get_by_test_id("motion")).to_have_text("paused")
        finally:
            browser.close()
            for s in wires.values():
                s.close()
