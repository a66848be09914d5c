"""`ramp-fleet-agent --config ramp.yaml [--backend HOST:PORT] [--serial SERIAL] ...`

Reads the robot's `ramp.yaml` for its `fleet:` block (SPEC 14) and its server port (the
backend is on loopback at that port unless `--backend` says otherwise); command-line options
override the block's keys and are checked by the same rules. Exit status 2 on a usage or
config error (`file:line: key: what was expected`), 0 after SIGINT/SIGTERM, when it has
published OFFLINE.
"""

from __future__ import annotations

import argparse
import logging
import signal
import ssl
import sys
from pathlib import Path
from types import FrameType
from typing import Any

from ramp import fleetconf
from ramp.common.endpoint import add_tls_arguments, context_for, split_scheme
from ramp.common.hostport import parse_hostport
from ramp.common.yamlload import LinedMap, YamlError, load_file

DEFAULT_BACKEND_PORT = 5577


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="ramp-fleet-agent",
        description="Bridge this robot's backend (MCP) to the fleet's MQTT broker, speaking "
                    "VDA 5050 2.1.0 (SPEC 14).")
    p.add_argument("--config", default="ramp.yaml", help="the robot's ramp.yaml (its fleet: "
                   "block; default ./ramp.yaml)")
    p.add_argument("--backend", help="the backend's HOST:PORT (default 127.0.0.1 and the "
                   "config's server.port); mcps://HOST:PORT for mutual TLS with "
                   "--cert/--key/--ca or --identity")
    p.add_argument("--serial", help="the robot's serial (overrides fleet.serial)")
    p.add_argument("--manufacturer", help="overrides fleet.manufacturer")
    p.add_argument("--broker", help="the broker's HOST:PORT (overrides fleet.broker)")
    p.add_argument("--autonomy", help="the autonomy's command endpoint HOST:PORT (overrides "
                   "fleet.autonomy): a robot with the autonomy runs orders")
    p.add_argument("--state-dir", help="where the fleet's pause is kept (default: "
                   "fleet.state_dir, $STATE_DIRECTORY, ~/.local/state/ramp)")
    p.add_argument("--log-level", default="info",
                   choices=["debug", "info", "warning", "error"])
    add_tls_arguments(p, "the backend")
    return p


def load(args: argparse.Namespace) -> tuple[fleetconf.FleetConfig, tuple[str, int], Any]:
    """(fleet config, backend address, the YAML root); ValueError with the words to print."""
    path = Path(args.config)
    try:
        root = load_file(path)
    except YamlError as exc:
        raise ValueError(str(exc.in_file(str(path)))) from None
    if not isinstance(root, dict):
        raise ValueError(f"{path}: expected a mapping of sections")
    raw = root.get("fleet")
    if raw is None:
        raw = LinedMap(1)
    if isinstance(raw, dict):
        for key, value in (("serial", args.serial), ("manufacturer", args.manufacturer),
                           ("broker", args.broker), ("autonomy", args.autonomy)):
            if value is not None:
                raw[key] = value
    bad = fleetconf.problems(raw)
    if bad:
        raise ValueError("\n".join(f"{path}:{line}: {key}: {msg}" for key, line, msg in bad))
    cfg = fleetconf.parse(raw, path.resolve().parent)
    if args.backend:
        try:
            _, address = split_scheme(args.backend)
            backend = parse_hostport(address, default_host="127.0.0.1")
        except ValueError as exc:
            raise ValueError(f"--backend: {exc}") from None
    else:
        server = root.get("server") if isinstance(root.get("server"), dict) else {}
        port = server.get("port", DEFAULT_BACKEND_PORT) if isinstance(server, dict) else 0
        if not isinstance(port, int) or not 0 < port < 65536:
            raise ValueError(f"{path}: server.port {port!r} is not a port the agent can reach; "
                             "give --backend HOST:PORT")
        backend = ("127.0.0.1", port)
    return cfg, backend, root


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        cfg, backend, root = load(args)
        backend_tls = context_for(split_scheme(args.backend or "")[0], args)
    except ValueError as exc:
        print(f"ramp-fleet-agent: {exc}", file=sys.stderr)
        return 2
    logging.basicConfig(level=args.log_level.upper(), stream=sys.stderr,
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    return run(cfg, backend, state_dir=Path(args.state_dir) if args.state_dir else None,
               backend_tls=backend_tls)


def run(cfg: fleetconf.FleetConfig, backend: tuple[str, int], *,
        state_dir: Path | None = None, backend_tls: ssl.SSLContext | None = None) -> int:
    """The agent on the wall clock until SIGINT/SIGTERM."""
    from ramp import __version__
    from ramp.clock import MonotonicClock
    from ramp.common.hostport import format_hostport
    from ramp.common.state_files import default_state_dir
    from ramp.fleet import vda5050 as v
    from ramp.fleet.agent import Agent, Identity
    from ramp.fleet.mcplink import FleetMcpLink
    from ramp.fleet.mqtt import MqttLink
    from ramp.fleet.pause import PauseStore
    from ramp.scheduler import Scheduler

    log = logging.getLogger("ramp.fleet")
    clock = MonotonicClock()
    scheduler = Scheduler(clock, 50.0)
    headers = v.Headers(cfg.manufacturer, cfg.serial)
    link = FleetMcpLink(*backend, clock=clock, loop=scheduler, ssl_context=backend_tls)
    mqtt = MqttLink(headers, *cfg.broker, tls=cfg.tls)
    pause = PauseStore(state_dir or cfg.state_dir or default_state_dir(), cfg.serial)
    identity = Identity(cfg.series, cfg.speed_max, *cfg.size, versions={"ramp": __version__})
    autonomy = None
    if cfg.autonomy is not None:
        from ramp.fleet.autonomy_link import AutonomyLink
        autonomy = AutonomyLink(*cfg.autonomy, clock=clock, loop=scheduler)
    agent = Agent(link, mqtt, pause, now=clock.now, autonomy=autonomy, identity=identity)
    if autonomy is not None:
        from ramp.fleet.orders import Orders
        agent.orders = Orders(agent, autonomy)
        autonomy.on_connect = agent.on_autonomy
    agent.add_tasks(scheduler)
    stopping: list[str] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stopping.append(signal.Signals(signum).name)

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    link.start()
    if autonomy is not None:
        autonomy.start()
    mqtt.start()
    print(f"ramp-fleet-agent: {cfg.serial} on broker {format_hostport(*cfg.broker)}, backend "
          f"{format_hostport(*backend)}"
          + (f", autonomy {format_hostport(*cfg.autonomy)}" if cfg.autonomy else ""),
          flush=True)
    try:
        scheduler.run(lambda: bool(stopping))
        log.info("%s: publishing OFFLINE and leaving", stopping[0] if stopping else "exit")
    finally:
        mqtt.close(offline=True)
        if autonomy is not None:
            autonomy.close()
        link.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
