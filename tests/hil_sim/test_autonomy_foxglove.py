"""The autonomy's view live in Foxglove, as real processes on the wall clock, watched by a real
Foxglove WebSocket client (`websockets`, subprotocol `foxglove.websocket.v1`).

- `ramp-autonomy --foxglove-port 0` against `ramp run --sim` (no autonomy sensors on this
  machine, so the mission waits in Initial Localization without a pose): the channels are
  advertised with their JSON Schemas, the state, the numbers at 10 Hz and the map arrive and
  validate, and no pose is sent while there is none; SIGTERM still ends it with status 0.
- A port already in use is an error naming it, exit 2, before any device is touched.
- `ramp sim mission --realtime --foxglove-port 0` (the simulated sensors localize within
  seconds): the estimated pose arrives, valid, beside the simulator's truth.

About 12 s of wall time together.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import select
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from websockets.asyncio.client import connect

from ramp.cli import main
from tests.harness import REPO, end_process, start_ramp

pytestmark = pytest.mark.timeout(90)

SUBPROTOCOL = "foxglove.websocket.v1"
VIEW_TOPICS = {"/mission/state", "/pose/estimated", "/mission/numbers", "/lidar/scan", "/map"}
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}


def sensorless_config(tmp_path: Path) -> Path:
    """The repository's autonomy.yaml with the LIDAR at a loopback port nobody serves."""
    config = tmp_path / "autonomy.yaml"
    text = (REPO / "autonomy.yaml").read_text()
    config.write_text(text.replace("host: 192.168.0.10", "host: 127.0.0.1")
                      .replace("port: 10940", "port: 9"))
    return config


def wait_for_line(proc: subprocess.Popen[str], pattern: str, timeout: float) -> re.Match[str]:
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        r, _, _ = select.select([proc.stdout], [], [], 0.5)
        if r:
            line = proc.stdout.readline()
            seen.append(line)
            m = re.search(pattern, line)
            if m:
                return m
            if not line and proc.poll() is not None:
                break
    proc.kill()
    raise AssertionError(f"no line matching {pattern!r}; stdout {seen}, "
                         f"stderr {proc.communicate()[1][-2000:]}")


class Watcher:
    """A Foxglove client: the handshake, subscriptions, and each message decoded and checked
    against the JSON Schema its channel advertised."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.channels: dict[str, dict[str, Any]] = {}
        self.received: dict[str, list[tuple[int, dict[str, Any]]]] = {}
        self._by_sub: dict[int, str] = {}

    async def watch(self, topics: list[str], done: Any, timeout: float) -> None:
        """Connect, wait for `topics` to be advertised, subscribe, and take messages until
        `done(self)` or `timeout` s (then fail)."""
        async with connect(self.url, subprotocols=[SUBPROTOCOL],  # type: ignore[list-item]
                           open_timeout=10) as ws:
            assert ws.subprotocol == SUBPROTOCOL
            deadline = time.monotonic() + timeout
            subscribed = False
            while True:
                left = deadline - time.monotonic()
                assert left > 0, f"timed out: advertised {sorted(self.channels)}, " \
                                 f"received {({t: len(m) for t, m in self.received.items()})}"
                try:
                    msg = await asyncio.wait_for(ws.recv(), left)
                except TimeoutError:
                    continue
                if isinstance(msg, str):
                    self._control(json.loads(msg))
                else:
                    self._data(msg)
                if not subscribed and set(topics) <= set(self.channels):
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                        {"id": i, "channelId": self.channels[t]["id"]}
                        for i, t in enumerate(topics, 1)]}))
                    self._by_sub = dict(enumerate(topics, 1))
                    subscribed = True
                if done(self):
                    return

    def _control(self, doc: dict[str, Any]) -> None:
        if doc["op"] == "serverInfo":
            return
        assert doc["op"] == "advertise", doc
        for ch in doc["channels"]:
            assert ch["encoding"] == "json" and ch["schemaEncoding"] == "jsonschema"
            schema = json.loads(ch["schema"])
            jsonschema.Draft202012Validator.check_schema(schema)
            self.channels[ch["topic"]] = {**ch, "schema": schema}

    def _data(self, frame: bytes) -> None:
        opcode, sub_id, stamp = struct.unpack_from("<BIQ", frame)
        assert opcode == 0x01
        topic = self._by_sub[sub_id]
        payload = json.loads(frame[13:])
        jsonschema.validate(payload, self.channels[topic]["schema"])
        self.received.setdefault(topic, []).append((stamp, payload))

    def on(self, topic: str) -> list[dict[str, Any]]:
        return [p for _, p in self.received.get(topic, [])]


def test_ramp_autonomy_streams_its_view_live_to_a_foxglove_client(tmp_path: Path) -> None:
    backend, host, port = start_ramp(["--sim", "--port", "0"])
    auto = subprocess.Popen(
        [sys.executable, "-m", "ramp.autonomy.cli", "--backend", f"{host}:{port}",
         "--config", str(sensorless_config(tmp_path)), "--foxglove-port", "0"],
        cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    try:
        m = wait_for_line(auto, r"ramp-autonomy: foxglove live on (ws://127\.0\.0\.1:\d+)$", 30)
        watcher = Watcher(m.group(1))

        def done(w: Watcher) -> bool:
            states = [s["state"] for s in w.on("/mission/state")]
            return ("initial_localization" in states and len(w.on("/mission/numbers")) >= 6
                    and bool(w.on("/map")))

        asyncio.run(watcher.watch(["/mission/state", "/pose/estimated", "/mission/numbers",
                                   "/map"], done, timeout=30))
        assert set(watcher.channels) >= VIEW_TOPICS
        assert watcher.channels["/pose/estimated"]["schemaName"] == "foxglove.PoseInFrame"
        assert watcher.channels["/map"]["schemaName"] == "foxglove.SceneUpdate"
        numbers = watcher.received["/mission/numbers"]
        assert all(n["pose_confidence"] == 0.0 for _, n in numbers)
        assert not any(k.startswith("true_") for _, n in numbers for k in n)  # no truth here
        steps = sorted(b[0] - a[0] for a, b in zip(numbers, numbers[1:], strict=False))
        assert 0.08e9 < steps[len(steps) // 2] < 0.12e9  # 10 Hz of the autonomy's clock
        assert abs(numbers[-1][0] - time.time_ns()) < 30e9  # a real date, not 1970
        walls = watcher.on("/map")[-1]["entities"][0]["lines"][0]["points"]
        assert {(p["x"], p["y"]) for p in walls} == {(0, 0), (7.38, 0), (7.38, 3.88),
                                                     (0, 3.88)}
        assert watcher.on("/pose/estimated") == []  # never localized: no pose to show
        _out, err = end_process(auto, timeout=15)
        assert auto.returncode == 0, err
        assert "SIGTERM: stopping the robot" in err
    finally:
        if auto.poll() is None:
            auto.kill()
            auto.communicate()
        backend.send_signal(signal.SIGTERM)
        backend.communicate(timeout=10)


def test_a_foxglove_port_in_use_is_an_error_naming_it_exit_2(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        out = subprocess.run(
            [sys.executable, "-m", "ramp.autonomy.cli", "--backend", "127.0.0.1:9",
             "--config", str(sensorless_config(tmp_path)), "--foxglove-port", str(port)],
            cwd=REPO, capture_output=True, text=True, timeout=30, env=ENV)
    assert out.returncode == 2, out.stderr
    assert f"ramp-autonomy: --foxglove-port: foxglove: cannot listen on 127.0.0.1:{port}" \
        in out.stderr
    assert "foxglove live on" not in out.stdout
    assert "lidar" not in out.stderr.lower()  # no device was touched


def test_a_bad_foxglove_port_on_sim_mission_exits_2_saying_what_was_expected(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sim", "mission", "--foxglove-port", "70000"]) == 2
    assert "--foxglove-port: expected 0-65535, got 70000" in capsys.readouterr().err


def test_a_realtime_sim_mission_streams_the_estimated_pose_beside_the_truth() -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramp.cli", "sim", "mission", "--realtime", "--port", "0",
         "--foxglove-port", "0", "--duration", "30"],
        cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV)
    try:
        m = wait_for_line(proc, r"ramp sim mission: foxglove live on (ws://127\.0\.0\.1:\d+)$",
                          30)
        watcher = Watcher(m.group(1))

        def done(w: Watcher) -> bool:
            return len(w.on("/pose/estimated")) >= 3

        asyncio.run(watcher.watch(["/pose/estimated", "/pose/true", "/mission/state"], done,
                                  timeout=40))
        assert "/pose/true" in watcher.channels  # the simulator's truth, beside the view
        (stamp, est) = watcher.received["/pose/estimated"][-1]
        truth = {s: p for s, p in watcher.received["/pose/true"]}
        assert stamp in truth  # sampled at the same instant
        e, t = est["pose"]["position"], truth[stamp]["pose"]["position"]
        assert abs(e["x"] - t["x"]) < 0.15 and abs(e["y"] - t["y"]) < 0.15
        assert any(s["state"] == "initial_localization" for s in watcher.on("/mission/state"))
    finally:
        end_process(proc, timeout=15)
