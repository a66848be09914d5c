"""The emulated UTM-30LX-EW as a state machine, with bytes in and bytes out, in virtual time.

Replies are read back with the driver's codec, so these tests also hold the two independent
encoders to one format.
"""

from __future__ import annotations

import numpy as np
import pytest

from firmware_like.hokuyo import (
    BOOTING,
    ERROR,
    IDLE,
    MULTI_SCAN,
    SINGLE_SCAN,
    TIME_ADJUST,
    HokuyoSensor,
    SensorModel,
    synthetic_room,
)
from ramp.autonomy.hal import scip


def talk(sensor: HokuyoSensor, t: float, data: bytes, until: float | None = None
         ) -> list[scip.Reply]:
    sensor.feed(t, data)
    sensor.service(t if until is None else until)
    out = scip.ScipDecoder().feed(sensor.take_output())
    assert all(isinstance(r, scip.Reply) for r in out), out
    return [r for r in out if isinstance(r, scip.Reply)]


def statuses(replies: list[scip.Reply]) -> list[tuple[str, str]]:
    return [(r.echo, r.status) for r in replies]


def test_laser_on_off_and_the_spec_statuses_of_bm_qt_and_gd() -> None:
    s = HokuyoSensor()
    assert statuses(talk(s, 0.0, b"GD0000108001\n")) == [("GD0000108001", "10")]
    assert statuses(talk(s, 0.0, b"BM\nBM\n")) == [("BM", "00"), ("BM", "02")]
    assert s.state == SINGLE_SCAN and s.laser_on
    assert statuses(talk(s, 0.0, b"QT\n")) == [("QT", "00")]
    assert s.state == IDLE and not s.laser_on


def test_gd_waits_for_the_next_whole_scan_and_stamps_it_at_step_zero() -> None:
    s = HokuyoSensor(now=10.0)
    talk(s, 10.0, b"BM\n")
    s.feed(10.010, b"GD0000108001\nVV\n")  # VV waits behind the GD: replies stay in order
    s.service(10.040)
    assert s.take_output() == b""  # the scan started at 10.000 began before the GD
    replies = talk(s, 10.060, b"")
    assert [r.command for r in replies] == ["GD", "VV"]
    gd = replies[0]
    assert gd.timestamp_ms == 25 and gd.values is not None  # scan 1 starts at 10.025 s
    assert np.array_equal(gd.values, np.asarray(synthetic_room()(10.025)))


def test_md_streams_every_scan_with_the_remaining_count_then_turns_the_laser_off() -> None:
    s = HokuyoSensor()
    replies = talk(s, 0.001, b"MD0000108001003;x\n", until=0.2)
    assert statuses(replies) == [("MD0000108001003;x", "00"), ("MD0000108001002;x", "99"),
                                 ("MD0000108001001;x", "99"), ("MD0000108001000;x", "99")]
    assert [r.timestamp_ms for r in replies[1:]] == [25, 50, 75]
    assert s.state == IDLE and not s.laser_on


def test_md_with_an_interval_skips_scans_and_00_streams_until_qt() -> None:
    s = HokuyoSensor()
    replies = talk(s, 0.0, b"MD0000108001200\n", until=0.3)
    scans = [r for r in replies if r.is_scan]
    assert [r.timestamp_ms for r in scans] == [50, 125, 200, 275]  # every third scan
    assert all(r.echo == "MD0000108001200" for r in scans)  # 00: the count stays 00
    assert s.state == MULTI_SCAN
    assert statuses(talk(s, 0.3, b"QT\n", until=1.0)) == [("QT", "00")]
    assert s.state == IDLE


def test_clusters_give_the_nearest_real_range_of_each_group() -> None:
    ranges = np.full(1081, 5000)
    ranges[3:6] = [1, 900, 800]  # an error code, then two ranges
    ranges[6:9] = [1, 2, 3]  # only error codes
    s = HokuyoSensor(lambda t: ranges)
    replies = talk(s, 0.0, b"BM\nGD0003001003\n", until=0.1)
    gd = replies[1]
    assert gd.values is not None and gd.values.tolist() == [800, 1, 5000]  # 3..5, 6..8, 9..10


def test_malformed_commands_get_the_spec_error_statuses() -> None:
    s = HokuyoSensor()
    replies = talk(s, 0.0, b"XX\nVVV\nGD00001080\nGD0000108001x\nGDa000108001\n"
                   b"GD0000x08001\nGD00001080zz\nGD0000200001\nGD0500010001\n"
                   b"MD0000108001x00\nMD000010800100y\nVV;" + b"t" * 17 + b"\n")
    assert [r.status for r in replies] == ["0E", "0D", "0C", "0D", "01", "02", "03", "04",
                                           "05", "06", "07", "0G"]


def test_commands_may_end_in_cr_or_lf() -> None:
    s = HokuyoSensor()
    assert statuses(talk(s, 0.0, b"BM\rQT\r\nVV\n"))[:2] == [("BM", "00"), ("QT", "00")]
    assert s.received == ["BM", "QT", "VV"]


def test_pp_vv_and_ii_describe_a_utm_30lx_ew() -> None:
    s = HokuyoSensor(timestamp_offset_ms=1000)
    vv, pp, ii = talk(s, 2.5, b"VV\nPP\nII\n")
    assert "UTM-30LX-EW" in scip.parse_version(vv).product
    p = scip.parse_params(pp)
    assert (p.model, p.dmin_mm, p.dmax_mm, p.ares, p.amin, p.amax, p.afrt, p.scan_rpm) == (
        "UTM-30LX-EW", 23, 60000, 1440, 0, 1080, 540, 2400)
    info = scip.parse_status(ii)
    assert not info.laser_on and info.time_ms == 3500 and info.stat.startswith("Stable")


def test_key_value_sums_can_include_the_semicolon_as_some_firmware_does() -> None:
    s = HokuyoSensor(semicolon_in_sum=True)
    s.feed(0.0, b"PP\n")
    wire = s.take_output()
    assert b"DMIN:23;2\n" in wire  # the ';' counted in the sum
    assert scip.parse_params(scip.ScipDecoder().feed(wire)[0]).dmin_mm == 23  # type: ignore[arg-type]


def test_tm_adjust_mode_follows_the_spec() -> None:
    s = HokuyoSensor()
    talk(s, 0.0, b"BM\n")
    replies = talk(s, 1.2345, b"TM0\nTM0\nBM\nTM1\nTM2\nTM2\nTM7\n")
    assert statuses(replies) == [("TM0", "00"), ("TM0", "02"), ("BM", "10"), ("TM1", "00"),
                                 ("TM2", "00"), ("TM2", "03"), ("TM7", "01")]
    assert replies[3].timestamp_ms == 1234
    assert s.state == IDLE
    talk(s, 2.0, b"TM0\n")
    assert s.state == TIME_ADJUST and statuses(talk(s, 2.0, b"QT\n")) == [("QT", "10")]


def test_the_timestamp_wraps_after_24_bits_of_milliseconds() -> None:
    s = HokuyoSensor(timestamp_offset_ms=(1 << 24) - 60)
    replies = talk(s, 0.001, b"MD0000108001004\n", until=0.2)
    assert [r.timestamp_ms for r in replies[1:]] == [16_777_181, 16_777_206, 15, 40]


def test_rs_resets_the_timer_and_switches_the_laser_off() -> None:
    s = HokuyoSensor()
    talk(s, 0.0, b"BM\n")
    assert statuses(talk(s, 100.0, b"RS\n")) == [("RS", "00")]
    assert s.state == IDLE and s.timestamp(100.5) == 500


def test_rb_reboots_only_on_the_second_rb_within_a_second() -> None:
    s = HokuyoSensor(boot_time=2.0)
    assert statuses(talk(s, 0.0, b"RB\n")) == [("RB", "01")]
    assert statuses(talk(s, 1.5, b"RB\n")) == [("RB", "01")]  # too late: armed again
    assert statuses(talk(s, 2.0, b"RB\n")) == [("RB", "00")]
    assert s.hangup and s.state == BOOTING and s.counters.reboots == 1
    s.feed(2.5, b"VV\n")  # during the boot: answered once booted
    s.service(3.9)
    assert s.take_output() == b""
    replies = talk(s, 4.0, b"")
    assert statuses(replies) == [("VV", "00")] and s.state == IDLE
    assert s.timestamp(4.0) == 2000  # the counter restarted with the reboot


def test_an_injected_hardware_error_stops_the_stream_and_answers_every_scan_command() -> None:
    s = HokuyoSensor()
    talk(s, 0.0, b"MD0000108001000\n", until=0.06)
    s.inject_error(52, now=0.07)
    out = scip.ScipDecoder().feed(s.take_output())
    assert [(r.echo, getattr(r, "status", "")) for r in out] == [("MD0000108001000", "52")]
    assert s.state == ERROR
    replies = talk(s, 0.1, b"GD0000108001\nMD0000108001000\nBM\nQT\nRS\nTM0\nII\nVV\n",
                   until=0.5)
    assert [r.status for r in replies] == ["52", "52", "01", "0L", "0L", "0L", "00", "00"]
    assert "Error 052" in scip.parse_status(replies[6]).stat
    s.clear_error()
    assert statuses(talk(s, 0.6, b"BM\n")) == [("BM", "00")]
    with pytest.raises(ValueError, match="50-98"):
        s.inject_error(12)


def test_a_closed_connection_stops_measuring() -> None:
    s = HokuyoSensor()
    talk(s, 0.0, b"MD0000108001000\n", until=0.1)
    s.disconnected(0.1)
    assert s.state == IDLE and not s.laser_on
    s.service(1.0)
    assert s.take_output() == b""


def test_a_range_source_of_the_wrong_shape_is_a_clear_error() -> None:
    s = HokuyoSensor(lambda t: np.zeros(100))
    with pytest.raises(ValueError, match=r"shape \(100,\), expected \(1081,\)"):
        talk(s, 0.0, b"BM\nGD0000108001\n", until=0.1)


def test_a_long_pause_catches_up_a_bounded_number_of_scans() -> None:
    s = HokuyoSensor()
    talk(s, 0.0, b"MD0000108001000\n")
    s.service(3600.0)
    assert 1 <= s.counters.scans_sent <= 41 and s.counters.scans_skipped > 100_000
    assert s.timestamp(3600.0) == 3_600_000


def test_a_slower_model_keeps_its_own_period() -> None:
    s = HokuyoSensor(model=SensorModel(model="UTM-30LX", scan_rpm=1200))
    replies = talk(s, 0.001, b"MD0000108001002\n", until=0.2)
    assert [r.timestamp_ms for r in replies[1:]] == [50, 100]
