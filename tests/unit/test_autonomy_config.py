"""`autonomy.yaml`: the example loads, and every error names file:line: key.path."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from ramp.autonomy.cli import main
from ramp.autonomy.config import (
    MISSION_FIELDS,
    MISSION_READS_HZ,
    AutonomyConfig,
    check_config,
    load_config,
    parse_address,
    parse_config,
)
from ramp.autonomy.executive.autonomy import MISSION_HZ
from ramp.autonomy.mount import Mount, euler_zyx, lidar_pose, mat_vec, rotation_zyx
from ramp.errors import ConfigErrors

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "autonomy.yaml"


def errors_of(text: str) -> list[str]:
    cfg, errors = parse_config(textwrap.dedent(text), "a.yaml")
    assert cfg is None or not errors
    return [str(e) for e in errors]


def test_the_example_for_marte_loads() -> None:
    cfg = load_config(EXAMPLE)
    assert cfg.backend == "192.168.0.20:5577"
    assert (cfg.lidar.host, cfg.lidar.port) == ("192.168.0.10", 10940)
    assert cfg.imu.driver == "phidget" and cfg.imu.data_interval_ms == 8
    assert cfg.imu.mount == Mount(x=0.0, y=0.10, z=0.35)
    g = cfg.gimbal
    assert (g.pan.channel, g.tilt.channel) == (0, 1) and g.tilt.reversed
    assert (g.tilt.min_deg, g.tilt.max_deg) == (-30.0, 80.0)
    assert g.pivot == (0.40, 0.0, 0.70)
    assert cfg.mission["duration_s"] == 600.0 and cfg.mission["max_relocalize_tries"] == 3
    assert cfg.estimation_hz == 50.0


def test_an_empty_file_gives_the_defaults() -> None:
    cfg, errors = parse_config("", "a.yaml")
    assert errors == [] and cfg is not None
    assert cfg.backend == "127.0.0.1:5577" and cfg.lidar.port == 10940
    assert dict(cfg.mission) == {k: f.default for k, f in MISSION_FIELDS.items()}
    assert isinstance(cfg, AutonomyConfig) and cfg.imu.driver == "phidget"


def test_every_error_is_reported_at_once_with_file_line_and_key() -> None:
    errs = errors_of("""\
        backend: robot
        lidar: {host: 192.168.0.10, port: 70000}
        imu:
          driver: xsens
          data_interval_ms: 0
          mount: {x: 0.1, pich: 3}
        gimbal:
          pan: {channel: 0, min_deg: -90, max_deg: 90}
          tilt: {channel: 0, min_deg: -30, max_deg: 45, velocity_dps: fast}
        mission:
          duration_s: -5
          crater_margin_m: 0.2
          name: fred
        radar: {}
        """)
    assert errs == [
        "a.yaml:14: radar: unknown section (expected one of: backend, estimation_hz, lidar, imu, "
        "gimbal, mission)",
        "a.yaml:1: backend: 'robot': no port; expected HOST:PORT (for example "
        "192.168.1.10:5577)",
        "a.yaml:2: lidar.port: 70000 is not a TCP port (1-65535)",
        "a.yaml:4: imu.driver: 'xsens' is not an IMU driver (one of phidget, sim)",
        "a.yaml:5: imu.data_interval_ms: 0 is not a sample interval in ms (1-1000)",
        "a.yaml:6: imu.mount.pich: unknown key (expected one of: pitch, roll, x, y, yaw, z)",
        "a.yaml:9: gimbal.tilt.velocity_dps: 'fast' is not a speed in deg/s (1-2000)",
        "a.yaml:9: gimbal.tilt.channel: channel 0 is already the pan servo's",
        "a.yaml:11: mission.duration_s: -5 is not a run length in s (1-86400)",
        "a.yaml:13: mission.name: 'fred' is not a number",
    ]


@pytest.mark.parametrize(("tilt", "message"), [
    ("{channel: 1, min_deg: 40, max_deg: 10}", "a.yaml:4: gimbal.tilt.max_deg: 10 must be "
     "above min_deg (40)"),
    ("{channel: 1, min_deg: 5, max_deg: 40}", "a.yaml:4: gimbal.tilt.min_deg: the range "
     "5..40 must include 0"),
    ("{channel: 1, min_deg: -30, max_deg: 150}", "a.yaml:4: gimbal.tilt.max_deg: 150 deg "
     "needs a 3000 us pulse"),
    ("{channel: 1, min_deg: -30}", "a.yaml:4: gimbal.tilt.max_deg: missing; expected an "
     "angle in degrees (-180-180)"),
    ("{channel: 1, min_deg: -30, max_deg: 30, speed: 3}", "a.yaml:4: gimbal.tilt.speed: "
     "unknown key"),
    ("[1, 2]", "a.yaml:4: gimbal.tilt: expected a mapping, got a list"),
])
def test_servo_blocks_are_checked_across_their_keys(tilt: str, message: str) -> None:
    errs = errors_of(f"""\
        gimbal:
          driver: sim
          pan: {{channel: 0, min_deg: -90, max_deg: 90}}
          tilt: {tilt}
        """)
    assert len(errs) == 1 and errs[0].startswith(message), errs


def test_a_gimbal_without_its_axes_says_which_is_missing() -> None:
    errs = errors_of("""\
        gimbal:
          driver: phidget
          pan: {channel: 0, min_deg: -90, max_deg: 90}
        """)
    assert errs == ["a.yaml:2: gimbal.tilt: missing; expected the tilt servo's mapping "
                    "(channel, min_deg, max_deg, ...)"]


def test_keys_given_twice_and_broken_yaml_are_located() -> None:
    errs = errors_of("""\
        imu:
          serial: 1
          serial: 2
        """)
    assert errs == ["a.yaml:3: imu.serial: key given twice"]
    errs = errors_of("imu: {serial: [1, 2}\n")
    assert len(errs) == 1 and errs[0].startswith("a.yaml:1: not valid YAML")
    assert errors_of("- 1\n- 2\n") == ["a.yaml:1: expected a mapping of sections at the top, "
                                       "got a list"]


def test_mission_accepts_any_named_number_and_checks_the_known_ones() -> None:
    cfg, errors = parse_config("mission: {duration_s: 300, scan_step_deg: 2.5, tries: 4}\n")
    assert errors == [] and cfg is not None
    assert cfg.mission["duration_s"] == 300.0 and cfg.mission["scan_step_deg"] == 2.5
    assert cfg.mission["end_margin_s"] == 30.0  # known names get their default
    errs = errors_of("mission: {max_relocalize_tries: 2.5, x: .nan, ok: true}\n")
    assert errs == [
        "a.yaml:1: mission.max_relocalize_tries: 2.5 is not a number of tries (0-100)",
        "a.yaml:1: mission.x: nan is not a number",
        "a.yaml:1: mission.ok: True is not a number",
    ]


@pytest.mark.parametrize(("text", "expected"), [
    ("10.0.0.2:5577", ("10.0.0.2", 5577)),
    ("marte.local:1", ("marte.local", 1)),
    ("[::1]:5577", ("::1", 5577)),
])
def test_backend_addresses_parse(text: str, expected: tuple[str, int]) -> None:
    assert parse_address(text) == expected


@pytest.mark.parametrize(("value", "hz"), [("100", 100.0), ("50", 50.0), ("25.0", 25.0),
                                           ("20", 20.0)])
def test_estimation_rates_that_divide_the_loop_are_taken(value: str, hz: float) -> None:
    cfg, errors = parse_config(f"backend: 10.0.0.2:5577\nestimation_hz: {value}\n", "a.yaml")
    assert errors == [] and cfg is not None and cfg.estimation_hz == hz


EXPECTED_RATES = ("expected 100, 50, 25 or 20 (a rate that divides the autonomy's 100 Hz loop, "
                  "no slower than the 20 Hz mission)")


@pytest.mark.parametrize(("value", "says"), [
    ("30", "30 Hz: "), ("200", "200 Hz: "), ("0", "0 Hz: "), ("-50", "-50 Hz: "),
    ("0.5", "0.5 Hz: "), ("10", "10 Hz: "), ("1", "1 Hz: "), ("12.5", "12.5 Hz: "),
    ("fast", "'fast' is not a number; "), ("true", "True is not a number; "),
    (".nan", "nan is not a number; "), (str(10 ** 400), "is not a number; "),
])
def test_an_estimation_rate_that_does_not_divide_the_loop_or_is_slower_than_the_mission_is_refused(
        value: str, says: str) -> None:
    """Below the 20 Hz mission, the attitude and pose it reads are stale (at 1 Hz seed 0 lost
    its localization twice and delivered nothing); a 400-digit integer once raised
    OverflowError out of the check."""
    (error,) = errors_of(f"backend: 10.0.0.2:5577\nestimation_hz: {value}\n")
    assert error.startswith("a.yaml:2: estimation_hz: ")
    assert says in error and error.endswith(EXPECTED_RATES)


def test_the_slowest_estimation_rate_is_the_missions() -> None:
    assert MISSION_READS_HZ == MISSION_HZ


def test_a_mission_number_no_float_holds_is_an_error_not_a_traceback() -> None:
    huge = str(10 ** 400)
    (error,) = errors_of(f"mission:\n  duration_s: {huge}\n")
    assert error.startswith("a.yaml:2: mission.duration_s: ") and "is not a run length" in error
    (error,) = errors_of(f"mission:\n  my_gain: {huge}\n")
    assert error.startswith("a.yaml:2: mission.my_gain: ") and error.endswith("is not a number")


@pytest.mark.parametrize("text", ["5577", ":5577", "host:", "host:0", "host:99999", "a b:1"])
def test_bad_backend_addresses_are_refused(text: str) -> None:
    with pytest.raises(ValueError):
        parse_address(text)


@pytest.mark.parametrize("host", ["", "ü☃", "a..b", "999.1.1.1", "10", "h:5", "-x", "x" * 300])
def test_a_host_that_is_no_address_is_refused_at_its_line(host: str) -> None:
    """`lidar: {host: ""}` connected to this computer, not to the scanner; a backend named
    `ü☃:5577` failed only once the robot was on the field."""
    (error,) = errors_of(f"lidar:\n  host: '{host}'\n")
    assert error.startswith("a.yaml:2: lidar.host: ")
    assert "is not an IP address or host name" in error and "192.168.0.10" in error
    if host and ":" not in host:
        (error,) = errors_of(f"backend: '{host}:5577'\n")
        assert error.startswith("a.yaml:1: backend: ")
        assert "is not an IP address or host name; expected HOST:PORT" in error


def test_a_phidget_serial_past_32_bits_is_refused() -> None:
    """Phidget22 cuts a serial to 32 bits: 4294967296 + N would match board N."""
    found = errors_of("imu: {serial: 4295267297}\ngimbal: {serial: 2147483648}\n")
    assert "a.yaml:1: imu.serial: 4295267297 is not a Phidget serial number or -1 for any " \
        "(-1-2147483647)" in found
    assert "a.yaml:2: gimbal.serial: 2147483648 is not a Phidget serial number or -1 for " \
        "any (-1-2147483647)" in found


def test_an_unreadable_file_is_one_error_naming_it(tmp_path: Path) -> None:
    cfg, errors = check_config(tmp_path / "nope.yaml")
    assert cfg is None and len(errors) == 1 and "nope.yaml: cannot read" in str(errors[0])
    with pytest.raises(ConfigErrors):
        load_config(tmp_path / "nope.yaml")


# -- the command line ---------------------------------------------------------------------------
def test_check_prints_ok_for_the_example(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", str(EXAMPLE)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"{EXAMPLE}: ok") and "pan channel 0 -90..90 deg" in out
    assert "state estimation (IMU, AHRS, odometry) at 50 Hz" in out


def test_a_state_timeout_is_checked_with_the_file() -> None:
    """`timeout_nosuch_s: 5` passed `ramp-autonomy check`; the state machine refused it only
    when the mission was built (`ramp sim mission --config` ended in a traceback)."""
    cfg, errors = parse_config("mission: {timeout_excavate_s: 240}\n")
    assert errors == [] and cfg is not None and cfg.mission["timeout_excavate_s"] == 240
    found = errors_of("mission:\n  timeout_nosuch_s: 5\n  timeout_stop_s: -1\n")
    assert found[0].startswith("a.yaml:2: mission.timeout_nosuch_s: no state named 'nosuch' "
                               "has a timeout (states: acquire_control, ")
    assert found[1] == "a.yaml:3: mission.timeout_stop_s: -1 is not a time in s (> 0)"


def test_check_notes_a_tunable_no_code_reads(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    """A misspelt tunable is accepted (a later mission may read more names), but it was
    silently ignored: `drive_speed_pcnt: 20` left the robot at 60 %."""
    path = tmp_path / "a.yaml"
    path.write_text("mission: {drive_speed_pcnt: 20, duration_s: 300, zzz: 1, "
                    "timeout_dock_s: 90}\n")
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "  note: mission.drive_speed_pcnt is not a tunable this version reads (did you " \
        "mean drive_speed_pct?); it is ignored\n" in out
    assert "  note: mission.zzz is not a tunable this version reads; it is ignored" in out
    assert "duration_s" not in out and "timeout_dock_s" not in out
    assert main(["check", str(EXAMPLE)]) == 0
    assert "note:" not in capsys.readouterr().out


@pytest.mark.parametrize("origin", ["*", "not a url", "https://app.foxglove.dev/studio",
                                    "javascript:alert(1)", "", "http://h:99999"])
def test_a_foxglove_origin_no_browser_sends_is_a_usage_error(
        origin: str, capsys: pytest.CaptureFixture[str]) -> None:
    """`--foxglove-origin '*'` or a page's address with a path never matched any browser's
    Origin: the page was refused while the operator thought it allowed."""
    with pytest.raises(SystemExit) as exc:
        main(["--backend", "127.0.0.1:1", "--foxglove-origin", origin])
    assert exc.value.code == 2
    assert "is not a web page's origin; expected http(s)://HOST[:PORT]" in \
        capsys.readouterr().err


def test_a_foxglove_origin_is_kept_as_a_browser_sends_it() -> None:
    from ramp.autonomy.cli import build_parser

    args = build_parser().parse_args(["--foxglove-origin", "https://App.Foxglove.dev/",
                                      "--foxglove-origin", "http://[::1]:8080"])
    assert args.foxglove_origin == ["https://app.foxglove.dev", "http://[::1]:8080"]


def test_check_lists_every_error_and_fails(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "autonomy.yaml"
    bad.write_text("backend: x\nimu: {serial: -7}\n")
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"{bad}:1: backend: 'x': no port; expected HOST:PORT (for " \
                     "example 192.168.1.10:5577)"
    assert err[1].startswith(f"{bad}:2: imu.serial: -7 is not a Phidget serial number")
    assert err[-1] == f"ramp-autonomy: 2 error(s) in {bad}"


def test_without_a_command_it_says_what_is_available(capsys: pytest.CaptureFixture[str]
                                                     ) -> None:
    assert main([]) == 2
    assert "ramp-autonomy check FILE" in capsys.readouterr().err


# -- mounts -------------------------------------------------------------------------------------
def test_euler_angles_round_trip() -> None:
    for angles in [(0.1, -0.3, 2.5), (-1.0, 0.7, -3.0), (0.0, 0.0, 0.0)]:
        assert euler_zyx(rotation_zyx(*angles)) == pytest.approx(angles)


def test_pan_turns_the_lidar_left_and_tilt_points_it_down() -> None:
    lidar = Mount(x=0.5, y=0.0, z=0.6)
    pivot = (0.45, 0.0, 0.55)
    pos, rot = lidar_pose(lidar, pivot, 0.0, 0.0)
    assert pos == pytest.approx((0.5, 0.0, 0.6)) and mat_vec(rot, (1, 0, 0)) == pytest.approx(
        (1, 0, 0))
    pos, rot = lidar_pose(lidar, pivot, 90.0, 0.0)
    assert pos == pytest.approx((0.45, 0.05, 0.6))  # swung about the pivot to the left
    assert mat_vec(rot, (1, 0, 0)) == pytest.approx((0, 1, 0), abs=1e-12)
    _pos, rot = lidar_pose(lidar, pivot, 0.0, 30.0)
    beam = mat_vec(rot, (1, 0, 0))
    assert beam[2] == pytest.approx(-math.sin(math.radians(30)))  # nose down


# -- isolation ----------------------------------------------------------------------------------
def test_the_autonomy_hardware_modules_do_not_import_the_backend() -> None:
    code = textwrap.dedent("""\
        import sys
        import ramp.autonomy.cli, ramp.autonomy.config, ramp.autonomy.mount
        import ramp.autonomy.hal.interfaces, ramp.autonomy.hal.sim
        import ramp.autonomy.hal.phidget_spatial, ramp.autonomy.hal.phidget_servo
        banned = ("ramp.layers", "ramp.modules", "ramp.hal", "ramp.runtime", "ramp.config",
                  "ramp.simulation.backplane", "firmware_like")
        bad = sorted(m for m in sys.modules if m.split(".")[0] == "firmware_like"
                     or any(m == b or m.startswith(b + ".") for b in banned))
        print(bad)
        """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=REPO)
    assert out.stdout.strip() == "[]"
