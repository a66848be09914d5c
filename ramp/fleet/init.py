"""`ramp fleet init DIR --robots NAME... --supervisors NAME...`: a broker's TLS set-up.

Writes, in DIR: the certificates (a CA, the broker's server certificate for `--host`s, one
client certificate per robot and per supervisor, CN = the name; made by `ramp.certs`, the
project's one certificate authority, never by hand), `mosquitto.conf` (one TLS listener that
requires a client certificate and takes its CN as the user name; no anonymous access) and
`acl` (VDA 5050's topics, per identity):

- a robot writes only its own `connection`, `state`, `visualization` and `factsheet`, and
  reads only its own `order` and `instantActions`;
- a supervisor writes every robot's `order` and `instantActions` and reads everything.

Mosquitto refuses the rest: with MQTT 3.1.1 and 5 a publish the ACL denies is dropped (a
robot posing as another, or sending orders, reaches nobody), a subscription it denies gets
no messages.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ramp.fleet import vda5050 as v
from ramp.fleet.broker import BrokerTls, mosquitto_conf
from ramp.fleetconf import NAME

RESERVED = {"ca", "broker"}


@dataclass(frozen=True)
class FleetFiles:
    directory: Path
    conf: Path
    acl: Path
    tls: BrokerTls
    clients: dict[str, tuple[Path, Path]]  # name -> (certificate, key)


def check_names(robots: list[str], supervisors: list[str]) -> list[str]:
    """Every problem with the names, in words ([] when they are good)."""
    problems = []
    if not robots and not supervisors:
        problems.append("name at least one robot or supervisor")
    seen: set[str] = set()
    for name in [*robots, *supervisors]:
        if not NAME.fullmatch(name):
            problems.append(f"{name!r} is not a name of 1-64 letters, digits, _ . -")
        elif name in RESERVED:
            problems.append(f"{name!r} is reserved for the fleet's own files")
        elif name in seen:
            problems.append(f"{name!r} is named twice")
        seen.add(name)
    return problems


def acl_text(robots: list[str], supervisors: list[str], manufacturer: str = "+") -> str:
    """Mosquitto's ACL file: each robot its own topics, supervisors the masters' topics."""
    lines = ["# Written by `ramp fleet init` (SPEC 14): VDA 5050 topics per identity (the",
             "# certificate's CN). Anything not granted here is refused by the broker.", ""]
    for robot in robots:
        lines.append(f"user {robot}")
        lines += [f"topic write {v.topic(manufacturer, robot, t)}" for t in v.ROBOT_TOPICS]
        lines += [f"topic read {v.topic(manufacturer, robot, t)}" for t in v.MASTER_TOPICS]
        lines.append("")
    for sup in supervisors:
        lines.append(f"user {sup}")
        lines += [f"topic write {v.topic('+', '+', t)}" for t in v.MASTER_TOPICS]
        lines.append(f"topic read {v.INTERFACE}/{v.MAJOR}/#")
        lines.append("")
    return "\n".join(lines)


def write_fleet(directory: Path, robots: list[str], supervisors: list[str], *,
                hosts: list[str], port: int = 8883, listen: str = "0.0.0.0",
                manufacturer: str = "+") -> FleetFiles:
    """Write the whole set into `directory` (created): certificates that exist are kept,
    `mosquitto.conf` and `acl` are written anew for the names given."""
    from ramp.certs.authority import create_ca, issue_client, issue_server

    problems = check_names(robots, supervisors)
    if problems:
        raise ValueError("; ".join(problems))
    directory.mkdir(parents=True, exist_ok=True)
    d = directory.resolve()
    # Run again with a new robot, it adds that robot: the CA and the identities already
    # issued are kept (ramp.certs never overwrites a certificate); the ACL is rewritten.
    if not (d / "ca.crt").exists():
        create_ca(d, "ramp-fleet-ca")
    if not (d / "broker.crt").exists():
        issue_server(d, "broker", hosts)
    clients = {}
    for name in [*robots, *supervisors]:
        if (d / f"{name}.crt").exists() and (d / f"{name}.key").exists():
            clients[name] = (d / f"{name}.crt", d / f"{name}.key")
            continue
        crt, key = issue_client(d, name)
        clients[name] = (Path(crt), Path(key))
    acl = d / "acl"
    acl.write_text(acl_text(robots, supervisors, manufacturer))
    tls = BrokerTls(d / "ca.crt", d / "broker.crt", d / "broker.key", acl)
    for path in (tls.ca, tls.cert, tls.key):
        if not path.exists():
            raise RuntimeError(f"the certificate authority did not write {path}")
    conf = d / "mosquitto.conf"
    conf.write_text(mosquitto_conf(port, host=listen, tls=tls, run_as_me=False))
    return FleetFiles(d, conf, acl, tls, clients)
