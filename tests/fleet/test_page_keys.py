"""The fleet page's Space key is Stop all wherever the focus is (as the console's Space is its
STOP), in Debian's chromium on `ramp-fleet` and a real Mosquitto, with one robot written by
hand: a Space while its Resume button has the focus stops every robot and resumes none."""

from __future__ import annotations

import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import paho.mqtt.client as mqtt
import pytest

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import LocalBroker
from tests.fleet_fixtures import Collector
from tests.harness import REPO, end_process

CHROMIUM = "/usr/bin/chromium"


def start_page(broker: LocalBroker) -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen([sys.executable, "-m", "ramp.fleet.page.cli", "--broker",
                             broker.address, "--http-port", "0"], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert proc.stdout is not None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if select.select([proc.stdout], [], [], 0.5)[0]:
            m = re.search(r"ramp-fleet: page on (http://\S+)", proc.stdout.readline())
            if m:
                return proc, m.group(1)
    proc.kill()
    raise AssertionError("ramp-fleet never printed its address")


def paused_robot(broker: LocalBroker) -> mqtt.Client:
    """`digger-7`, paused by the fleet earlier: its tile offers Resume."""
    h = v.Headers("ACME", "digger-7")
    c = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id="digger-7")
    c.connect(broker.host, broker.port)
    c.loop_start()
    f = v.StateFields()
    f.paused = True
    for name, msg in (("connection", v.connection(h, v.ONLINE)), ("state", v.state(h, f))):
        c.publish(h.topic(name), json.dumps(msg), qos=1, retain=True).wait_for_publish(5)
    return c


def test_space_is_stop_all_even_on_a_focused_resume_button(mosquitto: LocalBroker) -> None:
    if not Path(CHROMIUM).exists():
        if os.environ.get("CI"):
            raise RuntimeError(f"{CHROMIUM} is missing: .ci/run installs Debian's chromium")
        pytest.skip("chromium is not installed")
    sync_api = pytest.importorskip("playwright.sync_api")
    heard = Collector(mosquitto.host, mosquitto.port, ["uagv/v2/ACME/digger-7/instantActions"])
    robot = paused_robot(mosquitto)
    proc, url = start_page(mosquitto)
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                        args=["--no-sandbox", "--disable-gpu"])
            try:
                page = browser.new_page()
                page.goto(url)
                resume = page.get_by_test_id("robot-digger-7").get_by_test_id("pause")
                sync_api.expect(resume).to_have_text("Resume", timeout=20_000)
                resume.focus()
                page.keyboard.press("Space")
                heard.wait_for("/instantActions", lambda m: any(
                    a["actionType"] == "stopPause" for a in m["actions"]))
                time.sleep(0.5)  # a Space that also pressed Resume would have sent it by now
                kinds = [a["actionType"] for m in heard.json("/instantActions")
                         for a in m["actions"]]
                assert "startPause" not in kinds, kinds
                sync_api.expect(page.get_by_test_id("robot-digger-7").get_by_test_id(
                    "stop-time")).to_have_text("stopping…")
            finally:
                browser.close()
    finally:
        end_process(proc, signal.SIGINT)
        robot.loop_stop()
        robot.disconnect()
        heard.close()
