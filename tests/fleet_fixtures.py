"""Fixtures for the fleet's tests: a real Mosquitto on loopback, and an MQTT client that
collects what the robots publish. Import the fixtures into a conftest (tests/fleet/conftest.py
does) or a test module."""

from __future__ import annotations

import contextlib
import json
import os
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from ramp.fleet.broker import LocalBroker, find_mosquitto

if TYPE_CHECKING:
    from ramp.fleet.init import FleetFiles


def need_mosquitto() -> None:
    """Skip without mosquitto on a workstation; fail on CI, which installs it (.ci/run)."""
    if find_mosquitto() is None:
        if os.environ.get("CI"):
            pytest.fail("mosquitto is not installed; .ci/run installs it")
        pytest.skip("mosquitto is not installed (apt-get install mosquitto)")


@pytest.fixture
def mosquitto() -> Iterator[LocalBroker]:
    """A plain anonymous Mosquitto on a free loopback port, stopped after the test."""
    need_mosquitto()
    with LocalBroker() as broker:
        yield broker


@contextlib.contextmanager
def tls_fleet(directory: Path, robots: list[str],
              supervisors: list[str]) -> Iterator[tuple[FleetFiles, LocalBroker]]:
    """`ramp fleet init`'s files for these robots and supervisors in `directory`, and a
    Mosquitto serving them over mutual TLS with its ACL, stopped on exit."""
    need_mosquitto()
    pytest.importorskip("ramp.certs.authority")  # ramp certs: the one certificate authority
    from ramp.fleet.init import write_fleet

    files = write_fleet(directory, robots, supervisors, hosts=["localhost", "127.0.0.1"],
                        manufacturer="RAMP")
    broker = LocalBroker(tls=files.tls).start()
    try:
        yield files, broker
    finally:
        broker.close()


def tls_of(files: FleetFiles, name: str) -> dict[str, str]:
    """A client's TLS files from the set-up, as `Collector` and the agents take them."""
    crt, key = files.clients[name]
    return {"ca": str(files.tls.ca), "cert": str(crt), "key": str(key)}


class Collector:
    """An MQTT client subscribed to `topics`, keeping every message it receives."""

    def __init__(self, host: str, port: int, topics: list[str], *,
                 client_id: str = "", tls: dict[str, str] | None = None) -> None:
        import paho.mqtt.client as mqtt

        self.messages: list[tuple[str, bytes, bool]] = []
        self.lock = threading.Lock()
        self.subscribed = threading.Event()
        self.client = mqtt.Client(mqtt.CallbackAPIVersion.VERSION2, client_id=client_id)
        if tls is not None:
            self.client.tls_set(ca_certs=tls["ca"], certfile=tls["cert"], keyfile=tls["key"])
        self.topics = topics

        def on_connect(client: Any, _u: Any, _f: Any, rc: Any, _p: Any = None) -> None:
            if not rc.is_failure:
                client.subscribe([(t, 1) for t in topics])

        def on_subscribe(*_: Any) -> None:
            self.subscribed.set()

        def on_message(_c: Any, _u: Any, msg: Any) -> None:
            with self.lock:
                self.messages.append((msg.topic, msg.payload, bool(msg.retain)))

        self.client.on_connect = on_connect
        self.client.on_subscribe = on_subscribe
        self.client.on_message = on_message
        self.client.connect(host, port, keepalive=10)
        self.client.loop_start()
        assert self.subscribed.wait(10), "the collector never subscribed"

    def json(self, suffix: str) -> list[dict[str, Any]]:
        """Every message on a topic ending with `suffix`, decoded."""
        with self.lock:
            return [json.loads(p) for t, p, _ in self.messages if t.endswith(suffix)]

    def wait_for(self, suffix: str, pred: Callable[[dict[str, Any]], bool],
                 timeout: float = 10.0) -> dict[str, Any]:
        """The first message on `...suffix` for which `pred` holds, waiting up to `timeout`."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for msg in self.json(suffix):
                if pred(msg):
                    return msg
            time.sleep(0.02)
        raise AssertionError(f"no {suffix} message as expected in {timeout} s; "
                             f"last: {self.json(suffix)[-1:]}")

    def close(self) -> None:
        self.client.loop_stop()
        self.client.disconnect()


def start_agent(config: str, backend: str, broker: str, serial: str, state_dir: str,
                *extra: str) -> Any:
    """`ramp-fleet-agent` as a process, once it printed its start line."""
    import select
    import subprocess
    import sys

    from tests.harness import REPO

    log = open(f"{state_dir}/agent-{serial}.log", "a")  # noqa: SIM115 (the process's)
    proc = subprocess.Popen(
        [sys.executable, "-m", "ramp.fleet.cli", "--config", config, "--backend", backend,
         "--broker", broker, "--serial", serial, "--state-dir", state_dir, *extra],
        cwd=REPO, text=True, stdout=subprocess.PIPE, stderr=log)
    log.close()
    assert proc.stdout is not None
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        r, _, _ = select.select([proc.stdout], [], [], 0.5)
        if r:
            line = proc.stdout.readline()
            if line.startswith("ramp-fleet-agent:"):
                return proc
            if not line and proc.poll() is not None:
                break
    proc.kill()
    proc.communicate()
    with open(f"{state_dir}/agent-{serial}.log") as f:
        raise AssertionError("the agent did not start: " + f.read()[-3000:])
