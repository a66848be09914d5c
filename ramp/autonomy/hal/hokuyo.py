"""Hokuyo UTM-30LX-EW over Ethernet (SCIP 2.0 on TCP, default 192.168.0.10:10940).

The driver never blocks the loop that drives it: the TCP connect is non-blocking, bytes are
read when the socket is readable (`on_readable`, registered with the loop's `add_reader`, or
polled from `tick`) and written without waiting, and every wait is a deadline checked in
`tick(now, dt)`. Time comes only from the injected clock.

On connect it sends QT and drains everything up to the QT echo (a previous client may have
left a stream running; a TM adjust mode is left with TM2), then VV, then PP, whose numbers it
checks (model, DMIN/DMAX, ARES, AMIN/AMAX/AFRT, SCAN) and keeps as the scan geometry, then BM
(laser on). From then on it serves scans on demand (GD) or streams them (MD, stopped with QT:
scans already in flight are taken until the QT echo, then BM again).

Failures, each named in `fault`:
- no connection, a refused or timed-out connect, a silent sensor (no reply within
  `reply_timeout`, no scan within `stream_timeout` while streaming), a closed link: the
  socket is closed and the driver reconnects after a back-off that doubles up to
  `backoff_max`;
- a sensor fault (status 50-98, BM 01, 0L): state `fault` with the code and its meaning,
  no scans served, the handshake retried every `fault_retry` seconds;
- a reply that fails its sums or is cut short: dropped (counted in `stats`), never published.

A host name is resolved once in `start()`, which can block on DNS: give the sensor's IP.
The socket, the non-blocking connect, the read budget and the back-off are
`ramp.common.tcpclient.TcpClient`'s, shared with the autonomy's MCP link; the back-off is
reset only once a whole handshake has passed (a sensor that accepts and then fails keeps
backing off).
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ramp.autonomy.hal import scip
from ramp.autonomy.hal.lidar import (
    CONFIGURING,
    CONNECTING,
    DISCONNECTED,
    FAULT,
    READY,
    STOPPED,
    STREAMING,
    Lidar,
    Scan,
    ScanGeometry,
)
from ramp.clock import Clock, MonotonicClock
from ramp.common import tcpclient
from ramp.common.hostport import parse_hostport
from ramp.common.outputs import figure_file, save_figure
from ramp.common.tcpclient import IoLoop, TcpClient, check_seconds
from ramp.scheduler import Scheduler

log = logging.getLogger("ramp.autonomy.hokuyo")

DEFAULT_HOST = "192.168.0.10"
DEFAULT_PORT = 10940
DEFAULT_ADDRESS = f"{DEFAULT_HOST}:{DEFAULT_PORT}"
MAX_BAD_IN_A_ROW = 5  # garbled replies in a row before the link is reset


def parse_address(text: str, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """`host:port`, `host`, `[v6]:port` -> (host, port) (`ramp.common.hostport`, the port
    defaulting to SCIP's); ValueError with the reason."""
    return parse_hostport(text, default_port=default_port, example=DEFAULT_ADDRESS)


@dataclass
class _Pending:
    echo: str  # the command line as the sensor will echo it
    what: str  # for messages
    deadline: float
    on_reply: Callable[[scip.Reply, float], None]


class HokuyoLidar(Lidar):
    """A UTM-30LX-EW (or another SCIP 2.0 scanner) on TCP, driven from one loop.

    `start()`, then `tick(now, dt)` from a scheduler task (and, if `loop` is given, the
    driver registers its socket with `loop.add_reader` so bytes are read on arrival).
    """

    def __init__(self, address: str = DEFAULT_ADDRESS, *, clock: Clock, name: str = "lidar",
                 loop: IoLoop | None = None, stream: bool = False,
                 first_step: int | None = None, last_step: int | None = None,
                 cluster: int = 1, expected_model: str = "UTM-30LX",
                 connect_timeout: float = 2.0, reply_timeout: float = 1.0,
                 stream_timeout: float = 0.5, backoff_min: float = 0.5,
                 backoff_max: float = 8.0, fault_retry: float = 2.0) -> None:
        super().__init__(name)
        host, port = parse_address(address)
        check_seconds(name, connect_timeout=connect_timeout, reply_timeout=reply_timeout,
                      stream_timeout=stream_timeout, backoff_min=backoff_min,
                      backoff_max=backoff_max, fault_retry=fault_retry)
        if not 1 <= cluster <= 99:
            raise ValueError(f"{name}: cluster must be 1-99, got {cluster}")
        if first_step is not None and last_step is not None and last_step < first_step:
            raise ValueError(f"{name}: last_step {last_step} is before first_step {first_step}")
        self.clock = clock
        self.loop = loop
        self.streaming_wanted = stream
        self.first_step = first_step
        self.last_step = last_step
        self.cluster = cluster
        self.expected_model = expected_model
        self.reply_timeout = reply_timeout
        self.stream_timeout = stream_timeout
        self.fault_retry = fault_retry
        #: What the sensor said about itself (VV and PP), once it has.
        self.version: scip.VersionInfo | None = None
        self.params: scip.SensorParams | None = None
        self.geometry: ScanGeometry | None = None
        self.stats = {"connects": 0, "connect_failures": 0, "disconnects": 0, "scans": 0,
                      "bad_replies": 0, "drained": 0, "unexpected": 0, "timeouts": 0,
                      "sensor_faults": 0}
        self.client = TcpClient(host, port, now=clock.now, loop=loop,
                                connect_timeout=connect_timeout, backoff_min=backoff_min,
                                backoff_max=backoff_max, on_connected=self._connected,
                                on_data=self._on_data, on_lost=self._lost, on_eof=self._eof,
                                connect_hint="is the sensor on this network?",
                                stats=self.stats)
        self._connection = 0  # counts losses: the rest of a read from a lost link is dropped
        self._fault_retry_at = math.inf
        self._decoder = scip.ScipDecoder()
        self._pending: deque[_Pending] = deque()
        self._draining = False  # after the connect-time QT: ignore all but its echo
        self._accept_stream = False  # our MD is running: its scans are ours
        self._gd_after_bm = False
        self._bad_in_a_row = 0
        self._last_scan_at = 0.0
        self._unwrapper = scip.TimestampUnwrapper()

    # -- addresses and loop hooks ---------------------------------------------------------------
    @property
    def address(self) -> str:
        return self.client.address

    @property
    def _who(self) -> str:
        return f"{self.name} at {self.address}"

    def fileno(self) -> int:
        """The socket's descriptor, -1 when there is none (for loops that poll themselves)."""
        return self.client.fileno()

    def on_readable(self) -> None:
        """Read what has arrived and act on every whole reply (call when `fileno()` is
        readable; never blocks)."""
        self.client.on_readable()

    def _on_data(self, data: bytes, now: float) -> None:
        connection = self._connection
        for msg in self._decoder.feed(data):
            if self._connection != connection:
                return
            self._handle(msg, now)

    def _eof(self, now: float) -> str:
        cut = self._decoder.close()
        if cut is not None:
            self.stats["bad_replies"] += 1
            log.warning("%s: %s", self.name, cut)
        return "connection closed by the sensor"

    @property
    def pending_commands(self) -> int:
        """Commands sent and not yet answered."""
        return len(self._pending)

    def reboot(self) -> bool:
        """Reboot the sensor (RB twice within a second, as SCIP asks): it closes the link,
        boots, and the driver reconnects. False when there is no link to send it on."""
        if not self.client.connected or self.state in (STOPPED, CONNECTING):
            return False
        self._set_state(CONFIGURING)
        self._send_command(scip.rb(), "RB", self._after_first_rb)
        return True

    def _after_first_rb(self, reply: scip.Reply, now: float) -> None:
        if reply.status not in ("00", "01"):
            self._sensor_fault(now, "RB", reply)
            return
        self._send_command(scip.rb(), "RB", self._after_second_rb)

    def _after_second_rb(self, reply: scip.Reply, now: float) -> None:
        if reply.status != "00":
            self._sensor_fault(now, "RB", reply)
            return
        log.info("%s: sensor rebooting", self._who)  # it closes the link; we reconnect

    # -- lifecycle hooks -----------------------------------------------------------------------
    def _start(self) -> None:
        self.client.start()

    def _tick(self, now: float, dt: float) -> None:
        self.client.tick(now)
        if self.client.state == tcpclient.CONNECTING and self.state == DISCONNECTED:
            self._set_state(CONNECTING)
        if not self.client.connected:
            return
        if self._pending and now > self._pending[0].deadline:
            p = self._pending[0]
            self.stats["timeouts"] += 1
            self._lost_link(now, f"no reply to {p.what} within {self._timeout_for(p.echo):.2f} s")
            return
        if (self.state == STREAMING and self._accept_stream
                and now - self._last_scan_at > self.stream_timeout):
            self.stats["timeouts"] += 1
            self._lost_link(now, f"no scan for {self.stream_timeout:.2f} s while streaming")
            return
        if self.state == FAULT and now >= self._fault_retry_at and not self._pending:
            self._fault_retry_at = math.inf
            self._begin_handshake(now)

    def _stop(self) -> None:
        if self.client.connected and (self._accept_stream or self.state in (READY, STREAMING)):
            self.client.write(scip.qt())  # best effort: stop the stream, laser off
        self.client.close()
        self._reset_protocol()

    # -- scans ----------------------------------------------------------------------------------
    def _request_scan(self) -> bool:
        if any(p.echo.startswith("GD") for p in self._pending):
            return True
        self._send_command(self._gd_command(), "GD", self._after_gd)
        return True

    def _start_stream(self) -> None:
        if self.geometry is None:
            return
        first, last = self._steps()
        self._send_command(scip.md(first, last, self.cluster), "MD", self._after_md)

    def _stop_stream(self) -> None:
        self._set_state(CONFIGURING)
        self._send_command(scip.qt(), "QT (stop stream)", self._after_stream_qt)

    # -- connecting -----------------------------------------------------------------------------
    def _connected(self, now: float) -> None:
        self._decoder.reset()
        self._unwrapper.reset()
        log.info("%s: connected to %s", self.name, self.address)
        self._begin_handshake(now)

    def _begin_handshake(self, now: float) -> None:
        self._set_state(CONFIGURING)
        self._pending.clear()
        self._accept_stream = False
        self._draining = True
        self._send_command(scip.qt(), "QT", self._after_connect_qt)

    # -- the handshake --------------------------------------------------------------------------
    def _after_connect_qt(self, reply: scip.Reply, now: float) -> None:
        self._draining = False
        if reply.status == "00":
            self._send_command(scip.vv(), "VV", self._after_vv)
        elif reply.status in ("0E", "10"):  # refused: most likely left in TM adjust mode
            self._send_command(scip.tm(2), "TM2", self._after_tm2)
        else:
            self._sensor_fault(now, "QT", reply)

    def _after_tm2(self, reply: scip.Reply, now: float) -> None:
        self._send_command(scip.qt(), "QT", self._after_connect_qt)

    def _after_vv(self, reply: scip.Reply, now: float) -> None:
        try:
            self.version = scip.parse_version(reply)
        except scip.ScipError as exc:
            self._sensor_fault(now, "VV", reply, str(exc))
            return
        self._send_command(scip.pp(), "PP", self._after_pp)

    def _after_pp(self, reply: scip.Reply, now: float) -> None:
        try:
            params = scip.parse_params(reply)
        except scip.ScipError as exc:
            self._sensor_fault(now, "PP", reply, str(exc))
            return
        if self.expected_model and not params.model.startswith(self.expected_model):
            self._sensor_fault(now, "PP", reply, f"the sensor is a {params.model!r}, "
                               f"expected a {self.expected_model}")
            return
        first = params.amin if self.first_step is None else self.first_step
        last = params.amax if self.last_step is None else self.last_step
        if not params.amin <= first <= last <= params.amax:
            self._sensor_fault(now, "PP", reply, f"steps {first}..{last} are outside the "
                               f"sensor's {params.amin}..{params.amax}")
            return
        self.params = params
        self.geometry = ScanGeometry(params.ares, params.amin, params.amax, params.afrt,
                                     params.dmin_mm / 1000.0, params.dmax_mm / 1000.0,
                                     params.scan_period_s)
        self._send_command(scip.bm(), "BM", self._after_bm)

    def _after_bm(self, reply: scip.Reply, now: float) -> None:
        if reply.status not in ("00", "02"):
            self._sensor_fault(now, "BM", reply)
            return
        self.client.reset_backoff()  # a whole handshake: the sensor has proven itself
        self._set_state(READY, "")
        if self.streaming_wanted:
            self._start_stream()
        elif self._gd_after_bm:
            self._gd_after_bm = False
            self.request_scan()

    # -- scans on demand ------------------------------------------------------------------------
    def _gd_command(self) -> bytes:
        first, last = self._steps()
        return scip.gd(first, last, self.cluster)

    def _steps(self) -> tuple[int, int]:
        g = self.geometry
        assert g is not None
        first = g.amin if self.first_step is None else self.first_step
        last = g.amax if self.last_step is None else self.last_step
        return first, last

    def _after_gd(self, reply: scip.Reply, now: float) -> None:
        if reply.is_scan:
            self._publish_scan(reply, now)
        elif reply.status == "10":  # the laser went off (someone sent RS or QT): on again
            self._gd_after_bm = True
            self._set_state(CONFIGURING)
            self._send_command(scip.bm(), "BM", self._after_bm)
        else:
            self._sensor_fault(now, "GD", reply)

    # -- streaming ------------------------------------------------------------------------------
    def _after_md(self, reply: scip.Reply, now: float) -> None:
        if reply.status != "00":
            self._sensor_fault(now, "MD", reply)
            return
        self._accept_stream = True
        self._last_scan_at = now
        self._set_state(STREAMING, "")
        if not self.streaming_wanted:  # stop_stream() came while the MD was in flight
            self._stop_stream()

    def _after_stream_qt(self, reply: scip.Reply, now: float) -> None:
        self._accept_stream = False
        if reply.status != "00":
            self._sensor_fault(now, "QT", reply)
            return
        self._send_command(scip.bm(), "BM", self._after_bm)

    def _on_stream_status(self, reply: scip.Reply, now: float) -> None:
        """A status in the MD stream other than 99: a fault, or the sensor recovering."""
        if reply.status == "98":
            log.info("%s: sensor resumed measuring after an error (MD 98)", self.name)
            self._last_scan_at = now
            return
        self._accept_stream = False
        self._sensor_fault(now, "MD stream", reply)

    # -- replies --------------------------------------------------------------------------------
    def _handle(self, msg: scip.Decoded, now: float) -> None:
        if isinstance(msg, scip.BadReply):
            self._bad_reply(msg, now)
            return
        self._bad_in_a_row = 0
        stream_code = msg.command in scip.STREAM_COMMANDS
        if stream_code and msg.status == "99":
            if self._accept_stream and not self._draining:
                self._publish_scan(msg, now)
            else:
                self.stats["drained"] += 1
            return
        if self._pending and msg.echo == self._pending[0].echo:
            p = self._pending.popleft()
            p.on_reply(msg, now)
            return
        if self._draining:
            self.stats["drained"] += 1
            return
        if stream_code and self._accept_stream:
            self._on_stream_status(msg, now)
            return
        self.stats["unexpected"] += 1
        log.warning("%s: unexpected reply %r status %s (%s)", self.name, msg.echo, msg.status,
                    msg.meaning)

    def _bad_reply(self, msg: scip.BadReply, now: float) -> None:
        self.stats["bad_replies"] += 1
        self._bad_in_a_row += 1
        log.warning("%s: dropped a bad reply: %s", self._who, msg)
        if self._bad_in_a_row >= MAX_BAD_IN_A_ROW:
            self._lost_link(now, f"{self._bad_in_a_row} garbled replies in a row (last: {msg})")
            return
        if self._pending and msg.echo == self._pending[0].echo:
            p = self._pending.popleft()
            if p.echo.startswith("GD"):
                return  # that scan is lost; the caller asks again
            self._lost_link(now, f"bad reply to {p.what}: {msg}")

    def _publish_scan(self, reply: scip.Reply, now: float) -> None:
        geometry = self.geometry
        req = reply.request
        if geometry is None or req is None or reply.values is None:
            return
        stamp = reply.timestamp_ms or 0
        total_ms = self._unwrapper.unwrap(stamp)
        self._last_scan_at = now
        self.stats["scans"] += 1
        self._publish(Scan.from_raw(reply.values, geometry, sensor_time=total_ms / 1000.0,
                                    received_at=now, first_step=req.first, last_step=req.last,
                                    cluster=req.cluster, seq=self._next_seq(), sensor_ms=stamp,
                                    tag=req.tag))

    def _sensor_fault(self, now: float, what: str, reply: scip.Reply, detail: str = "") -> None:
        """The sensor refused or reported trouble: no scans until a retry succeeds."""
        self.stats["sensor_faults"] += 1
        if reply.hardware_error:
            text = f"sensor hardware error {reply.status} on {what}: {reply.meaning}"
        elif detail:
            text = f"{what}: {detail}"
        else:
            text = f"{what} answered {reply.status}: {reply.meaning}"
        self._pending.clear()
        self._accept_stream = False
        self._gd_after_bm = False
        self._fault_retry_at = now + self.fault_retry
        self._set_state(FAULT, f"{self._who}: {text}")

    # -- sending --------------------------------------------------------------------------------
    def _timeout_for(self, echo: str) -> float:
        extra = self.geometry.scan_period_s if self.geometry is not None else 0.0
        return self.reply_timeout + (extra if echo[:2] in scip.SCAN_COMMANDS else 0.0)

    def _send_command(self, line: bytes, what: str,
                      on_reply: Callable[[scip.Reply, float], None]) -> None:
        echo = line.rstrip(b"\n").decode("ascii")
        now = self.clock.now()
        self._pending.append(_Pending(echo, what, now + self._timeout_for(echo), on_reply))
        self.client.write(line)

    # -- losing the link ------------------------------------------------------------------------
    def _lost_link(self, now: float, reason: str) -> None:
        self.client.drop(now, reason)

    def _lost(self, now: float, reason: str) -> None:
        """The client has closed the socket (or a connect failed) and will retry."""
        self._reset_protocol()
        delay = self.client.retry_at - now
        self._set_state(DISCONNECTED, f"{self._who}: {reason}; retrying in {delay:.2g} s")

    def _reset_protocol(self) -> None:
        self._connection += 1
        self._pending.clear()
        self._draining = False
        self._accept_stream = False
        self._gd_after_bm = False
        self._fault_retry_at = math.inf
        self._decoder.reset()


# -- command line ---------------------------------------------------------------------------------
def describe_scan(scan: Scan) -> str:
    """One line a person can check against the room: counts, nearest, farthest, ahead."""
    n = len(scan.ranges)
    valid = int(scan.valid.sum())
    parts = [f"{n} steps ({scan.first_step}..{scan.last_step}), {valid} valid"]
    if valid:
        r = np.where(scan.valid, scan.ranges, np.inf)
        i = int(np.argmin(r))
        j = int(np.argmax(np.where(scan.valid, scan.ranges, -np.inf)))
        parts.append(f"nearest {scan.ranges[i]:.3f} m at {np.degrees(scan.angles[i]):+.2f}°")
        parts.append(f"farthest {scan.ranges[j]:.3f} m at {np.degrees(scan.angles[j]):+.2f}°")
    ahead = scan.range_at(0.0)
    parts.append("ahead " + ("no return" if math.isnan(ahead) else f"{ahead:.3f} m"))
    parts.append(f"sensor time {scan.sensor_time:.3f} s")
    return ", ".join(parts)


def plot_scan(scan: Scan, path: str, title: str = "") -> None:
    """Draw `scan` seen from above in the sensor's frame (x ahead, y left) into a PNG.

    Needs matplotlib (`pip install 'ramp[plot]'`)."""
    import matplotlib

    matplotlib.use("Agg")  # files only: no display on the robot
    import matplotlib.pyplot as plt

    g = scan.geometry
    pts = scan.points()
    fig, ax = plt.subplots(figsize=(6.4, 6.4), dpi=100)
    reach = float(np.nanmax(scan.ranges)) * 1.08 if scan.valid.any() else 1.0
    edge = np.array([g.angle(g.amin), g.angle(g.amax)])
    ax.plot([0, reach * np.cos(edge[0])], [0, reach * np.sin(edge[0])], color="0.75", lw=0.8)
    ax.plot([0, reach * np.cos(edge[1])], [0, reach * np.sin(edge[1])], color="0.75", lw=0.8,
            label=f"field of view ({np.degrees(edge[1] - edge[0]):.0f}°)")
    if len(pts):
        ax.plot(pts[:, 0], pts[:, 1], ".", ms=2.5, color="tab:blue",
                label=f"{len(pts)} returns")
    gone = ~scan.valid
    if gone.any():
        a = scan.angles[gone]
        ax.plot(0.3 * np.cos(a), 0.3 * np.sin(a), "x", ms=3, color="tab:red",
                label=f"{int(gone.sum())} no return")
    ax.plot([0], [0], marker=(3, 0, -90), ms=12, color="black", ls="none",
            label="sensor (x ahead)")
    ax.set_aspect("equal")
    ax.set_xlabel("x ahead (m)")
    ax.set_ylabel("y left (m)")
    ax.grid(True, lw=0.4, alpha=0.6)
    ax.legend(loc="lower left", fontsize=8)
    ax.set_title(title or f"scan {scan.seq}: {len(scan.ranges)} steps, "
                 f"sensor time {scan.sensor_time:.3f} s", fontsize=10)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    """`python -m ramp.autonomy.hal.hokuyo [HOST:PORT]`: is the LIDAR there and sane?"""
    parser = argparse.ArgumentParser(
        prog="python -m ramp.autonomy.hal.hokuyo",
        description="Connect to a Hokuyo SCIP 2.0 LIDAR, print VV, PP and one scan.")
    parser.add_argument("address", nargs="?", default=DEFAULT_ADDRESS,
                        help=f"HOST:PORT of the sensor (default {DEFAULT_ADDRESS})")
    parser.add_argument("--timeout", type=float, default=5.0,
                        help="seconds to wait for each step before giving up")
    parser.add_argument("--stream", type=int, default=0, metavar="N",
                        help="also stream N scans (MD) and report their rate")
    parser.add_argument("--model", default="UTM-30LX",
                        help="model PP must report (prefix; '' accepts any)")
    parser.add_argument("--plot", type=figure_file, metavar="FILE.png",
                        help="draw the scan seen from above (needs matplotlib: ramp[plot])")
    args = parser.parse_args(argv)
    if not (math.isfinite(args.timeout) and 0 < args.timeout <= 3600):
        parser.error(f"--timeout: expected seconds, more than 0 and up to 3600, "
                     f"got {args.timeout:g}")
    if not 0 <= args.stream <= 1_000_000:
        parser.error(f"--stream: expected 0-1000000 scans, got {args.stream}")
    if args.plot:
        try:
            import matplotlib  # noqa: F401 - checked before connecting, not after
        except ImportError:
            parser.error("--plot needs matplotlib: pip install 'ramp[plot]'")
    try:
        parse_address(args.address)
    except ValueError as exc:
        parser.error(str(exc))
    logging.basicConfig(level=logging.WARNING, format="%(name)s: %(message)s")
    # The loop pauses between steps (printing, plotting): late ticks here are no news.
    sched_log = logging.getLogger("ramp.scheduler")
    sched_level = sched_log.level
    sched_log.setLevel(logging.ERROR)
    try:
        return _check(args, MonotonicClock())
    finally:
        sched_log.setLevel(sched_level)


def _check(args: argparse.Namespace, clock: Clock) -> int:
    """The check itself: connect, VV/PP, one scan, optionally a stream and a plot."""
    sched = Scheduler(clock, rate_hz=100)
    lidar = HokuyoLidar(args.address, clock=clock, loop=sched, expected_model=args.model,
                        name="hokuyo")
    sched.add_task("lidar", 100, lidar.tick)

    def wait(done: Callable[[], bool], what: str) -> bool:
        deadline = clock.now() + args.timeout
        sched.run(lambda: done() or clock.now() > deadline)
        if done():
            return True
        print(f"hokuyo: no {what} from {lidar.address} within {args.timeout:g} s "
              f"(state {lidar.state}{': ' + lidar.fault if lidar.fault else ''})",
              file=sys.stderr)
        return False

    lidar.start()
    try:
        if not wait(lambda: lidar.state == READY, "answer"):
            return 1
        assert lidar.version is not None and lidar.params is not None
        v, p = lidar.version, lidar.params
        print(f"VV: {v.vendor} | {v.product} | firmware {v.firmware} | {v.protocol} | "
              f"serial {v.serial}")
        print(f"PP: {p.model}, {p.dmin_mm}-{p.dmax_mm} mm, steps {p.amin}..{p.amax} "
              f"(front {p.afrt}, {p.ares} per turn = {360 / p.ares:.3g}°), {p.scan_rpm} rpm "
              f"({p.scan_period_s * 1000:.1f} ms per scan)")
        before = lidar.scans_received
        lidar.request_scan()
        if not wait(lambda: lidar.scans_received > before, "scan"):
            return 1
        assert lidar.latest is not None
        print("scan: " + describe_scan(lidar.latest))
        if args.plot:
            plot_scan(lidar.latest, args.plot, f"{p.model} at {lidar.address}: "
                      f"{describe_scan(lidar.latest).split(', nearest')[0]}")
            print(f"plot: {args.plot}")
        if args.stream > 0:
            start_count, t0 = lidar.scans_received, clock.now()
            lidar.start_stream()
            if not wait(lambda: lidar.scans_received >= start_count + args.stream, "stream"):
                return 1
            took = clock.now() - t0
            print(f"stream: {args.stream} scans in {took:.3f} s "
                  f"({args.stream / took:.1f} scans/s)")
            lidar.stop_stream()
            wait(lambda: lidar.state == READY, "QT")
    finally:
        lidar.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
