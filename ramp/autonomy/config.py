"""`autonomy.yaml` -> validated, frozen configuration of the autonomy and its own hardware.

The autonomy's file, not the backend's: the backend's address, the LIDAR's address and
mount, the IMU board and mount, the pan/tilt servo board and its two axes, and the mission's
tunable numbers. Like `ramp.yaml`'s loader, every error names the file, the line, the key path
and what was expected (`autonomy.yaml:14: gimbal.tilt.max_deg: 200 is not an angle in
degrees (-180-180)`), and all of them are collected in one pass so `ramp-autonomy check`
shows everything to fix at once.

Blocks are field tables (`ramp.schema.Field`): a later feature adds a key by adding one entry
(`MISSION_FIELDS` is meant to grow with the mission). Nothing here touches hardware.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ramp.autonomy.hal import DRIVERS
from ramp.autonomy.mount import Mount
from ramp.common.hostport import format_hostport, parse_hostport, valid_host
from ramp.common.phidget22 import MAX_HUB_PORT, MAX_SERIAL
from ramp.common.yamlload import LinedMap, YamlError, kind_of, parse_mapping, read_text
from ramp.errors import ConfigError, ConfigErrors
from ramp.schema import Field, shorten

DEFAULT_BACKEND = ("127.0.0.1", 5577)
DEFAULT_LIDAR_HOST = "192.168.0.10"  # the UTM-30LX-EW's factory address (SPEC 6.2)
DEFAULT_LIDAR_PORT = 10940

#: Pulse widths an RC servo accepts safely; Hitec's digital servos run about 550-2450 us.
PULSE_MIN_US = 500.0
PULSE_MAX_US = 2500.0

MOUNT_FIELDS = {
    "x": Field(float, 0.0, lo=-5.0, hi=5.0, what="metres in the chassis frame"),
    "y": Field(float, 0.0, lo=-5.0, hi=5.0, what="metres in the chassis frame"),
    "z": Field(float, 0.0, lo=-5.0, hi=5.0, what="metres in the chassis frame"),
    "roll": Field(float, 0.0, lo=-180.0, hi=180.0, what="degrees"),
    "pitch": Field(float, 0.0, lo=-90.0, hi=90.0, what="degrees"),
    "yaw": Field(float, 0.0, lo=-180.0, hi=180.0, what="degrees"),
}
PIVOT_FIELDS = {k: MOUNT_FIELDS[k] for k in ("x", "y", "z")}

LIDAR_FIELDS = {
    "host": Field(str, DEFAULT_LIDAR_HOST, what="a host name or IP address"),
    "port": Field(int, DEFAULT_LIDAR_PORT, lo=1, hi=65535, what="a TCP port"),
}

_SERIAL = Field(int, -1, lo=-1, hi=MAX_SERIAL, what="a Phidget serial number or -1 for any")
_HUB_PORT = Field(int, -1, lo=-1, hi=MAX_HUB_PORT, what="a VINT hub port or -1 for any")
_ATTACH = Field(float, 2.0, lo=0.05, hi=60.0, what="a time in s")

IMU_FIELDS = {
    "driver": Field(str, "phidget", choices=tuple(DRIVERS["imu"]), what="an IMU driver"),
    "serial": _SERIAL,
    "hub_port": _HUB_PORT,
    "channel": Field(int, 0, lo=0, hi=7, what="a Spatial channel"),
    "data_interval_ms": Field(int, 8, lo=1, hi=1000, what="a sample interval in ms"),
    "attach_timeout_s": _ATTACH,
}

GIMBAL_FIELDS = {
    "driver": Field(str, "phidget", choices=tuple(DRIVERS["gimbal"]), what="a gimbal driver"),
    "serial": _SERIAL,
    "hub_port": _HUB_PORT,
    "attach_timeout_s": _ATTACH,
}

SERVO_FIELDS = {
    "channel": Field(int, lo=0, hi=15, what="a servo channel"),
    "min_deg": Field(float, lo=-180.0, hi=180.0, what="an angle in degrees"),
    "max_deg": Field(float, lo=-180.0, hi=180.0, what="an angle in degrees"),
    "velocity_dps": Field(float, 90.0, lo=1.0, hi=2000.0, what="a speed in deg/s"),
    "acceleration_dps2": Field(float, 720.0, lo=1.0, hi=100000.0,
                               what="an acceleration in deg/s^2"),
    "neutral_us": Field(float, 1500.0, lo=PULSE_MIN_US, hi=PULSE_MAX_US,
                        what="a pulse width in us"),
    "us_per_deg": Field(float, 10.0, lo=1.0, hi=50.0, what="microseconds per degree"),
    "reversed": Field(bool, False),
}

#: The mission's tunables (SPEC 6.3). Any named number is accepted in `mission:`; the names
#: listed here are also range-checked and get their default when absent.
MISSION_FIELDS: dict[str, Field] = {
    "duration_s": Field(float, 600.0, lo=1.0, hi=86400.0, what="a run length in s"),
    "end_margin_s": Field(float, 30.0, lo=0.0, hi=3600.0,
                          what="seconds before the end when no new cycle starts"),
    "max_relocalize_tries": Field(int, 3, lo=0, hi=100, what="a number of tries"),
    # Perception (issue "Perception"): one localization's scans, the 3D scan's sweep.
    "localize_scans": Field(int, 10, lo=1, hi=400, what="a number of scans"),
    "sweep_spacing_m": Field(float, 0.04, lo=0.005, hi=0.5,
                             what="a ground line spacing in m"),
    "sweep_far_m": Field(float, 3.85, lo=0.5, hi=30.0, what="a distance in m"),
    # the state machine's (ramp/statemachine/settings.py MissionConfig; a test keeps both equal)
    "max_step_retries": Field(int, 3, lo=0, hi=100, what="a number of tries"),
    "min_pose_confidence": Field(float, 0.5, lo=0.0, hi=1.0, what="a confidence (0-1)"),
    "min_return_load_kg": Field(float, 1.0, lo=0.0, hi=1000.0, what="a load in kg"),
    "trip_estimate_s": Field(float, 60.0, lo=0.0, hi=3600.0, what="a time in s"),
    "dock_deposit_estimate_s": Field(float, 60.0, lo=0.0, hi=3600.0, what="a time in s"),
    "min_dig_s": Field(float, 30.0, lo=0.0, hi=3600.0, what="a time in s"),
    "stop_settle_s": Field(float, 1.0, lo=0.0, hi=60.0, what="a time in s"),
    # the executive's (ramp/autonomy/executive/settings.py ExecutiveSettings; a test keeps
    # both equal)
    "still_s": Field(float, 0.3, lo=0.0, hi=10.0, what="a time in s"),
    "vantage_x_m": Field(float, 0.80, lo=0.6, hi=0.9, what="an x in the start region in m"),
    "drive_speed_pct": Field(float, 60.0, lo=5.0, hi=100.0, what="a speed in %"),
    "relocalize_every_m": Field(float, 1.2, lo=0.1, hi=20.0, what="a distance in m"),
    "pose_decay_m": Field(float, 5.0, lo=0.1, hi=1000.0, what="a distance in m"),
    "obstacle_margin_m": Field(float, 0.03, lo=0.0, hi=1.0, what="a distance in m"),
    "partial_margin_m": Field(float, 0.10, lo=0.0, hi=1.0, what="a distance in m"),
    "max_replans": Field(int, 4, lo=0, hi=100, what="a number of re-plans"),
    "dig_target_kg": Field(float, 36.0, lo=0.1, hi=1000.0, what="a load in kg"),
    "dig_rate_kg_s": Field(float, 0.3, lo=0.01, hi=100.0, what="a rate in kg/s"),
    "dig_max_s": Field(float, 150.0, lo=1.0, hi=3600.0, what="a time in s"),
    "chain_speed_pct": Field(float, 100.0, lo=1.0, hi=100.0, what="a speed in %"),
    "creep_speed_pct": Field(float, 3.0, lo=0.0, hi=30.0, what="a speed in %"),
    "dock_speed_pct": Field(float, 12.0, lo=1.0, hi=50.0, what="a speed in %"),
    "dump_done_kg": Field(float, 0.5, lo=0.0, hi=100.0, what="a load in kg"),
}

TOP_KEYS = ("backend", "estimation_hz", "lidar", "imu", "gimbal", "mission")

#: The rate of state estimation: the IMU driver, the AHRS and wheel odometry. Every IMU sample
#: is taken in, in batches, whatever the rate; the attitude and the odometry pose are read by
#: the 20 Hz mission. The LIDAR driver, scan collection and the gimbal stay at the loop rate: a
#: 3D sweep waits on them at every tilt. It must divide the 100 Hz loop.
ESTIMATION_HZ = 50.0
LOOP_HZ = 100.0
#: The mission's rate (ramp/autonomy/executive/autonomy.py MISSION_HZ): estimation no slower.
MISSION_READS_HZ = 20.0


@dataclass(frozen=True)
class LidarConfig:
    host: str = DEFAULT_LIDAR_HOST
    port: int = DEFAULT_LIDAR_PORT
    mount: Mount = Mount()  # optical centre with the gimbal at pan = tilt = 0


@dataclass(frozen=True)
class ImuConfig:
    driver: str = "phidget"
    serial: int = -1
    hub_port: int = -1
    channel: int = 0
    data_interval_ms: int = 8
    attach_timeout_s: float = 2.0
    mount: Mount = Mount()  # the board's axes on the chassis


@dataclass(frozen=True)
class ServoConfig:
    """One axis of the gimbal. Angles are the gimbal's, 0 = straight ahead / level."""

    name: str
    channel: int
    min_deg: float
    max_deg: float
    velocity_dps: float = 90.0
    acceleration_dps2: float = 720.0
    neutral_us: float = 1500.0  # pulse width at 0 deg
    us_per_deg: float = 10.0
    reversed: bool = False  # a larger pulse turns the axis the negative way

    def pulse_us(self, deg: float) -> float:
        """The pulse width that puts this axis at `deg`."""
        sign = -1.0 if self.reversed else 1.0
        return self.neutral_us + sign * self.us_per_deg * deg


@dataclass(frozen=True)
class GimbalConfig:
    driver: str = "phidget"
    serial: int = -1
    hub_port: int = -1
    attach_timeout_s: float = 2.0
    pivot: tuple[float, float, float] = (0.0, 0.0, 0.0)  # where pan and tilt axes cross
    pan: ServoConfig = ServoConfig("pan", 0, -90.0, 90.0)
    tilt: ServoConfig = ServoConfig("tilt", 1, -30.0, 45.0)


@dataclass(frozen=True)
class AutonomyConfig:
    file: str = ""
    backend_host: str = DEFAULT_BACKEND[0]
    backend_port: int = DEFAULT_BACKEND[1]
    estimation_hz: float = ESTIMATION_HZ
    lidar: LidarConfig = LidarConfig()
    imu: ImuConfig = ImuConfig()
    gimbal: GimbalConfig = GimbalConfig()
    mission: Mapping[str, float] = field(default_factory=lambda: MappingProxyType(
        {k: f.default for k, f in MISSION_FIELDS.items()}))

    @property
    def backend(self) -> str:
        return format_hostport(self.backend_host, self.backend_port)


def tunable_notes(cfg: AutonomyConfig) -> list[str]:
    """`mission.NAME is not a tunable this version reads (did you mean …?)` for each name in
    `mission:` that no code reads. They are accepted (a later mission may read more), but a
    misspelt `drive_speed_pcnt: 20` left the robot at the default 60 % without a word."""
    notes = []
    for name in cfg.mission:
        if name not in MISSION_FIELDS and not _state_timeout(name):
            near = difflib.get_close_matches(name, MISSION_FIELDS, n=1)
            hint = f" (did you mean {near[0]}?)" if near else ""
            notes.append(f"mission.{name} is not a tunable this version reads{hint}; "
                         "it is ignored")
    return notes


def _state_timeout(name: str) -> bool:
    """`timeout_<state>_s`: a state's timeout, which the state machine checks and reads."""
    return name.startswith("timeout_") and name.endswith("_s")


def parse_address(text: str) -> tuple[str, int]:
    """`HOST:PORT` (or `[v6]:PORT`) -> (host, port); ValueError says what was expected."""
    if not isinstance(text, str):
        raise ValueError(f"{text!r} is not an address; expected HOST:PORT (for example "
                         "192.168.1.10:5577)")
    host, port = parse_hostport(text, example="192.168.1.10:5577")
    if not valid_host(host):
        raise ValueError(f"{shorten(repr(text))}: {shorten(repr(host))} is not an IP address "
                         "or host name; expected HOST:PORT (for example 192.168.1.10:5577)")
    return host, port


class _Checker:
    """Walks the YAML tree collecting every error instead of stopping at the first."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.errors: list[ConfigError] = []

    def err(self, key: str, line: int, message: str) -> None:
        self.errors.append(ConfigError(message, file=self.file, line=line, key=key))

    def mapping(self, parent: LinedMap, key: str, path: str) -> LinedMap | None:
        """`parent[key]` as a mapping; an empty one when absent, None (and an error) when
        it is something else."""
        raw = parent.get(key)
        if raw is None:
            empty = LinedMap()
            empty.line = parent.line_of(key)
            return empty
        if not isinstance(raw, LinedMap):
            self.err(path, parent.line_of(key), f"expected a mapping, got {kind_of(raw)}")
            return None
        return raw

    def values(self, raw: LinedMap, path: str, fields: Mapping[str, Field],
               nested: frozenset[str] = frozenset()) -> dict[str, Any]:
        """Check `raw` against `fields`; keys in `nested` are left for the caller. Returns
        checked values, defaults for absent keys and for bad ones (None if required)."""
        for dup, line in raw.duplicates:
            self.err(f"{path}.{dup}", line, "key given twice")
        for k in raw:
            if k not in fields and k not in nested:
                known = ", ".join(sorted([*fields, *nested])) or "none"
                self.err(f"{path}.{k}", raw.line_of(k),
                         f"unknown key (expected one of: {known})")
        out: dict[str, Any] = {}
        for k, f in fields.items():
            if k in raw:
                try:
                    out[k] = f.check(raw[k])
                    continue
                except ValueError as exc:
                    self.err(f"{path}.{k}", raw.line_of(k), str(exc))
            elif f.required:
                self.err(f"{path}.{k}", raw.line, f"missing; expected {f.expected()}")
            out[k] = None if f.required else f.default
        return out

    def mount(self, parent: LinedMap, key: str, path: str) -> Mount:
        raw = self.mapping(parent, key, path)
        if raw is None:
            return Mount()
        return Mount(**self.values(raw, path, MOUNT_FIELDS))


def load_config(path: str | Path) -> AutonomyConfig:
    """Load and check `autonomy.yaml`; raises ConfigErrors listing every problem."""
    config, errors = check_config(path)
    if errors or config is None:
        raise ConfigErrors(errors)
    return config


def check_config(path: str | Path) -> tuple[AutonomyConfig | None, list[ConfigError]]:
    """(config or None, every error found), without touching any hardware."""
    name = str(path)
    try:
        text = read_text(path, what="an autonomy config")
    except YamlError as exc:
        return None, [ConfigError(exc.problem, file=name, line=exc.line)]
    return parse_config(text, name)


def parse_config(text: str, name: str = "autonomy.yaml"
                 ) -> tuple[AutonomyConfig | None, list[ConfigError]]:
    try:
        root = parse_mapping(text, "a mapping of sections")
    except YamlError as exc:
        return None, [ConfigError(exc.problem, file=name, line=exc.line)]
    c = _Checker(name)
    for k in root:
        if k not in TOP_KEYS:
            c.err(str(k), root.line_of(k),
                  f"unknown section (expected one of: {', '.join(TOP_KEYS)})")
    for dup, line in root.duplicates:
        c.err(str(dup), line, "section given twice")

    backend = DEFAULT_BACKEND
    if "backend" in root:
        try:
            backend = parse_address(root["backend"])
        except ValueError as exc:
            c.err("backend", root.line_of("backend"), str(exc))
    estimation_hz = _estimation_hz(c, root)
    lidar = _lidar(c, root)
    imu = _imu(c, root)
    gimbal = _gimbal(c, root)
    mission = _mission(c, root)
    if c.errors:
        return None, c.errors
    return AutonomyConfig(file=name, backend_host=backend[0], backend_port=backend[1],
                          estimation_hz=estimation_hz, lidar=lidar, imu=imu, gimbal=gimbal,
                          mission=MappingProxyType(mission)), []


def _finite_number(value: Any) -> bool:
    """An int or float that is finite as a float (a 400-digit integer is not: no float holds
    it, and `math.isfinite` raises on it)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _estimation_hz(c: _Checker, root: LinedMap) -> float:
    """`estimation_hz`: 100, 50, 25 or 20: a rate that divides the 100 Hz loop and is no
    slower than the 20 Hz mission that reads the attitude and the pose (at 1 Hz a run lost
    its localization twice and delivered nothing)."""
    if "estimation_hz" not in root:
        return ESTIMATION_HZ
    value, line = root["estimation_hz"], root.line_of("estimation_hz")
    expected = ("expected 100, 50, 25 or 20 (a rate that divides the autonomy's 100 Hz loop, no "
                f"slower than the {MISSION_READS_HZ:g} Hz mission)")
    if not _finite_number(value):
        c.err("estimation_hz", line, f"{shorten(repr(value))} is not a number; {expected}")
        return ESTIMATION_HZ
    ratio = LOOP_HZ / value if value > 0 else math.inf
    if not (MISSION_READS_HZ <= value <= LOOP_HZ and abs(ratio - round(ratio)) < 1e-9):
        c.err("estimation_hz", line, f"{value:g} Hz: {expected}")
        return ESTIMATION_HZ
    return float(value)


def _lidar(c: _Checker, root: LinedMap) -> LidarConfig:
    raw = c.mapping(root, "lidar", "lidar")
    if raw is None:
        return LidarConfig()
    v = c.values(raw, "lidar", LIDAR_FIELDS, nested=frozenset({"mount"}))
    if not valid_host(v["host"]):  # "" would reach this computer, not the scanner
        c.err("lidar.host", raw.line_of("host"), f"{shorten(repr(v['host']))} is not an IP "
              f"address or host name (the UTM-30LX-EW's factory one is {DEFAULT_LIDAR_HOST})")
        v["host"] = DEFAULT_LIDAR_HOST
    return LidarConfig(host=v["host"], port=v["port"], mount=c.mount(raw, "mount", "lidar.mount"))


def _imu(c: _Checker, root: LinedMap) -> ImuConfig:
    raw = c.mapping(root, "imu", "imu")
    if raw is None:
        return ImuConfig()
    v = c.values(raw, "imu", IMU_FIELDS, nested=frozenset({"mount"}))
    return ImuConfig(**v, mount=c.mount(raw, "mount", "imu.mount"))


def _gimbal(c: _Checker, root: LinedMap) -> GimbalConfig:
    raw = c.mapping(root, "gimbal", "gimbal")
    if raw is None or "gimbal" not in root:
        return GimbalConfig()
    v = c.values(raw, "gimbal", GIMBAL_FIELDS, nested=frozenset({"pivot", "pan", "tilt"}))
    pivot_raw = c.mapping(raw, "pivot", "gimbal.pivot")
    pivot = (0.0, 0.0, 0.0)
    if pivot_raw is not None:
        p = c.values(pivot_raw, "gimbal.pivot", PIVOT_FIELDS)
        pivot = (p["x"], p["y"], p["z"])
    axes: dict[str, ServoConfig] = {}
    for axis in ("pan", "tilt"):
        servo = _servo(c, raw, axis)
        if servo is not None:
            axes[axis] = servo
    if len(axes) == 2 and axes["pan"].channel == axes["tilt"].channel:
        tilt_raw = raw["tilt"]
        c.err("gimbal.tilt.channel", tilt_raw.line_of("channel"),
              f"channel {axes['tilt'].channel} is already the pan servo's")
    default = GimbalConfig()
    return GimbalConfig(**v, pivot=pivot, pan=axes.get("pan", default.pan),
                        tilt=axes.get("tilt", default.tilt))


def _servo(c: _Checker, gimbal: LinedMap, axis: str) -> ServoConfig | None:
    path = f"gimbal.{axis}"
    if axis not in gimbal:
        c.err(path, gimbal.line, f"missing; expected the {axis} servo's mapping "
              "(channel, min_deg, max_deg, ...)")
        return None
    raw = c.mapping(gimbal, axis, path)
    if raw is None:
        return None
    v = c.values(raw, path, SERVO_FIELDS)
    if any(v[k] is None for k in ("channel", "min_deg", "max_deg")):
        return None
    servo = ServoConfig(name=axis, **v)
    if not servo.min_deg < servo.max_deg:
        c.err(f"{path}.max_deg", raw.line_of("max_deg"),
              f"{servo.max_deg:g} must be above min_deg ({servo.min_deg:g})")
        return None
    if not servo.min_deg <= 0.0 <= servo.max_deg:
        c.err(f"{path}.min_deg", raw.line_of("min_deg"),
              f"the range {servo.min_deg:g}..{servo.max_deg:g} must include 0 "
              "(straight ahead / level)")
        return None
    for key, deg in (("min_deg", servo.min_deg), ("max_deg", servo.max_deg)):
        pulse = servo.pulse_us(deg)
        if not PULSE_MIN_US <= pulse <= PULSE_MAX_US:
            c.err(f"{path}.{key}", raw.line_of(key),
                  f"{deg:g} deg needs a {pulse:.0f} us pulse (neutral_us "
                  f"{servo.neutral_us:g} + {servo.us_per_deg:g} us/deg), outside "
                  f"{PULSE_MIN_US:.0f}-{PULSE_MAX_US:.0f} us")
    return servo


def _mission(c: _Checker, root: LinedMap) -> dict[str, float]:
    out: dict[str, float] = {k: f.default for k, f in MISSION_FIELDS.items()}
    raw = c.mapping(root, "mission", "mission")
    if raw is None:
        return out
    for dup, line in raw.duplicates:
        c.err(f"mission.{dup}", line, "key given twice")
    for k, value in raw.items():
        path = f"mission.{k}"
        line = raw.line_of(k)
        if not isinstance(k, str) or not k.isidentifier():
            c.err(path, line, "a tunable's name must be a word (letters, digits, _)")
            continue
        f = MISSION_FIELDS.get(k)
        try:
            if f is not None:
                out[k] = f.check(value)
            elif _finite_number(value):
                out[k] = value
            else:
                raise ValueError(f"{value!r} is not a number")
        except ValueError as exc:
            c.err(path, line, str(exc))
            continue
        if _state_timeout(k):
            # the state machine's own check, here rather than when the mission is built
            # (`timeout_nosuch_s: 5` passed the check and `ramp sim mission` ended in a
            # traceback)
            from ramp.statemachine.settings import MissionConfig

            try:
                MissionConfig.from_mapping({k: out[k]})
            except ConfigError as exc:
                c.err(path, line, exc.detail)
    return out
