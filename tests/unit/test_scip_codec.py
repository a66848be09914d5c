"""The SCIP 2.0 codec with byte strings: every command, every status family, real-format
replies, sums, cut-short and garbled replies, and the 24-bit timestamp's wrap.

Reference vectors come from Hokuyo's SCIP 2.0 specification (C-42-03320B): its encoding
examples ("CB" = 1234, "1Dh" = 5432, "m2@0" = 16000000) and its VV/PP/II example lines of a
URG-04LX, whose sums the vendor printed. The UTM-30LX-EW replies are built to that format.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from firmware_like.hokuyo import HokuyoSensor, synthetic_room
from ramp.autonomy.hal import scip

PP_UTM = (b"PP\n00P\n"
          b"MODL:UTM-30LX-EW;I\nDMIN:23;7\nDMAX:60000;J\nARES:1440;^\n"
          b"AMIN:0;?\nAMAX:1080;Z\nAFRT:540;0\nSCAN:2400;U\n\n")
VV_URG = (b"VV\n00P\nVEND:Hokuyo Automatic Co.,Ltd.;[\nPROD:SOKUIKI Sensor URG-04LX;[\n"
          b"FIRM:3.1.00(18/Jan./2007);`\nPROT:SCIP 2.0;N\nSERI:H0614967;V\n\n")
PP_URG = (b"PP\n00P\nMODL:URG-04LX(Hokuyo Automatic Co.,Ltd.);N\nDMIN:20;4\nDMAX:5600;_\n"
          b"ARES:1024;\\\nAMIN:44;7\nAMAX:725;o\nAFRT:384;6\nSCAN:600;e\n\n")
II_URG = (b"II\n00P\nMODL:URG-04LX(Hokuyo Automatic Co.,Ltd.);N\nLASR:OFF;7\n"
          b"SCSP:Initial(600[rpm])<-Default setting by user;A\nMESM:IDLE;:\n"
          b"SBPS:19200[bps]<-Default setting by user;A\nTIME:081615;N\n"
          b"STAT:Sensor works well.;8\n\n")
# Steps 0..2 of a GD: 1000 mm, 5432 mm and error code 1 ("no object in range"), t = 1000 ms.
GD_SMALL = b"GD0000000201\n00P\n00?Xg\n0?X1Dh001e\n\n"
# The same steps streamed: DMIN, 30 m and DMAX, stamped at the last ms before the wrap.
MD_SMALL = b"MD0000000201000\n99b\nooool\n00G7D`>YPY\n\n"
MD_TAGGED = b"MD0000000201001;lidar\n99b\n018dm\n01T03804\\@\n\n"


def one(data: bytes) -> scip.Decoded:
    out = scip.ScipDecoder().feed(data)
    assert len(out) == 1, out
    return out[0]


def ok(data: bytes) -> scip.Reply:
    reply = one(data)
    assert isinstance(reply, scip.Reply), reply
    return reply


def bad(data: bytes) -> scip.BadReply:
    reply = one(data)
    assert isinstance(reply, scip.BadReply), reply
    return reply


# -- commands ----------------------------------------------------------------------------------
@pytest.mark.parametrize(("encoded", "wire"), [
    (scip.vv(), b"VV\n"),
    (scip.pp(), b"PP\n"),
    (scip.ii(), b"II\n"),
    (scip.bm(), b"BM\n"),
    (scip.qt(), b"QT\n"),
    (scip.rs(), b"RS\n"),
    (scip.rb(), b"RB\n"),
    (scip.tm(0), b"TM0\n"),
    (scip.tm(1), b"TM1\n"),
    (scip.tm(2), b"TM2\n"),
    (scip.gd(), b"GD0000108001\n"),
    (scip.gd(180, 900, 3), b"GD0180090003\n"),
    (scip.gs(0, 1080, 0), b"GS0000108000\n"),
    (scip.md(), b"MD0000108001000\n"),
    (scip.md(0, 1080, 1, interval=2, scans=5), b"MD0000108001205\n"),
    (scip.ms(44, 725, 10, 9, 99), b"MS0044072510999\n"),
    (scip.vv(tag="abc"), b"VV;abc\n"),
    (scip.md(tag="0123456789ABCDEF"), b"MD0000108001000;0123456789ABCDEF\n"),
])
def test_every_command_encodes_to_the_bytes_the_sensor_expects(encoded: bytes,
                                                                wire: bytes) -> None:
    assert encoded == wire


@pytest.mark.parametrize(("call", "match"), [
    (lambda: scip.gd(0, 10000), "end step"),
    (lambda: scip.gd(-1, 10), "starting step"),
    (lambda: scip.gd(500, 100), "smaller than the starting step"),
    (lambda: scip.gd(0, 1080, 100), "cluster count"),
    (lambda: scip.md(interval=10), "scan interval"),
    (lambda: scip.md(scans=100), "number of scans"),
    (lambda: scip.gd(0, 1080, True), "cluster count"),
    (lambda: scip.vv(tag="x" * 17), "at most 16"),
    (lambda: scip.vv(tag="a;b"), "without ';'"),
    (lambda: scip.vv(tag="a\nb"), "printable"),
    (lambda: scip.tm(3), "0, 1 or 2"),
    (lambda: scip.command("vv"), "two upper-case letters"),
    (lambda: scip.command("VVV"), "two upper-case letters"),
])
def test_encoders_refuse_commands_the_sensor_would_refuse(call: object, match: str) -> None:
    with pytest.raises(scip.ScipError, match=match):
        call()  # type: ignore[operator]


# -- encodings and sums ------------------------------------------------------------------------
def test_the_specs_encoding_examples_decode_and_encode() -> None:
    assert scip.decode_int(b"CB") == 1234
    assert scip.decode_int(b"1Dh") == 5432
    assert scip.decode_int(b"m2@0") == 16_000_000
    assert scip.encode_int(1234, 2) == b"CB"
    assert scip.encode_int(5432, 3) == b"1Dh"
    assert scip.encode_int(16_000_000, 4) == b"m2@0"
    assert scip.encode_int(0, 3) == b"000" and scip.encode_int(262_143, 3) == b"ooo"


def test_encodings_refuse_values_that_do_not_fit_and_foreign_characters() -> None:
    with pytest.raises(scip.ScipError, match="does not fit"):
        scip.encode_int(4096, 2)
    with pytest.raises(scip.ScipError, match="2, 3 or 4"):
        scip.encode_int(1, 5)
    with pytest.raises(scip.ScipError, match="not a SCIP data character"):
        scip.decode_int(b"0p")
    with pytest.raises(scip.ScipError, match="outside 0x30-0x6F"):
        scip.decode_values(b"00/", 3)
    with pytest.raises(scip.ScipError, match="whole number"):
        scip.decode_values(b"0000", 3)
    with pytest.raises(scip.ScipError, match="values must be"):
        scip.encode_values([262_144], 3)


@given(st.sampled_from([2, 3, 4]).flatmap(
    lambda w: st.tuples(st.just(w), st.integers(0, (1 << 6 * w) - 1))))
def test_single_values_round_trip_through_every_width(case: tuple[int, int]) -> None:
    width, value = case
    chars = scip.encode_int(value, width)
    assert len(chars) == width and all(0x30 <= c <= 0x6F for c in chars)
    assert scip.decode_int(chars) == value


@given(st.sampled_from([2, 3, 4]).flatmap(
    lambda w: st.tuples(st.just(w), st.lists(st.integers(0, (1 << 6 * w) - 1), max_size=300))))
def test_arrays_round_trip_and_match_the_scalar_encoding(case: tuple[int, list[int]]) -> None:
    width, values = case
    body = scip.encode_values(values, width)
    assert body == b"".join(scip.encode_int(v, width) for v in values)
    assert scip.decode_values(body, width).tolist() == values


def test_line_sums_match_the_vendors_printed_examples() -> None:
    for reply in (VV_URG, PP_URG, II_URG):
        for line in reply.split(b"\n")[2:-2]:
            assert scip.line_sum_ok(line, key_value=True), line
            assert line[-1] == scip.checksum(line[:-2])  # the ';' is outside the sum
    assert scip.with_sum(b"00") == b"00P\n" and scip.with_sum(b"99") == b"99b\n"


def test_key_value_lines_pass_with_the_semicolon_inside_or_outside_the_sum() -> None:
    outside = scip.key_value_lines([("DMIN", "23")])[0].rstrip(b"\n")
    inside = scip.key_value_lines([("DMIN", "23")], semicolon_in_sum=True)[0].rstrip(b"\n")
    assert outside == b"DMIN:23;7" and inside == b"DMIN:23;2"
    assert scip.line_sum_ok(outside, key_value=True)
    assert scip.line_sum_ok(inside, key_value=True)
    assert not scip.line_sum_ok(b"DMIN:23;8", key_value=True)
    # Scan data is checked strictly: ';' is an ordinary data character there.
    assert not scip.line_sum_ok(outside, key_value=False)
    both = ok(PP_UTM.replace(b"DMIN:23;7", b"DMIN:23;2"))
    assert scip.parse_params(both).dmin_mm == 23


# -- parameter replies -------------------------------------------------------------------------
def test_pp_of_a_utm_30lx_ew_gives_its_geometry() -> None:
    p = scip.parse_params(ok(PP_UTM))
    assert (p.model, p.dmin_mm, p.dmax_mm, p.ares, p.amin, p.amax, p.afrt, p.scan_rpm) == (
        "UTM-30LX-EW", 23, 60000, 1440, 0, 1080, 540, 2400)
    assert p.steps == 1081 and p.scan_period_s == pytest.approx(0.025)
    assert p.angle(540) == 0.0
    assert math.degrees(p.angle(0)) == pytest.approx(-135.0)
    assert math.degrees(p.angle(1080)) == pytest.approx(135.0)
    assert math.degrees(p.step_rad) == pytest.approx(0.25)


def test_vv_and_ii_of_the_specs_urg_04lx_decode() -> None:
    v = scip.parse_version(ok(VV_URG))
    assert v.vendor == "Hokuyo Automatic Co.,Ltd." and v.protocol == "SCIP 2.0"
    assert v.product == "SOKUIKI Sensor URG-04LX" and v.serial == "H0614967"
    p = scip.parse_params(ok(PP_URG))
    assert (p.amin, p.amax, p.afrt, p.ares, p.scan_rpm) == (44, 725, 384, 1024, 600)
    info = scip.parse_status(ok(II_URG))
    assert not info.laser_on and info.stat == "Sensor works well."
    assert info.time_ms == 0x081615  # six hex digits on this model
    four = ok(scip.encode_reply("II", "00", scip.key_value_lines(
        [("LASR", "ON"), ("TIME", scip.encode_int(4660, 4).decode())])))
    assert scip.parse_status(four).laser_on and scip.parse_status(four).time_ms == 4660


@pytest.mark.parametrize(("reply", "match"), [
    (PP_UTM.replace(b"SCAN:2400;U\n", b""), "lacks SCAN"),
    (scip.encode_reply("PP", "00", scip.key_value_lines(
        [("MODL", "X"), ("DMIN", "23"), ("DMAX", "lots"), ("ARES", "1440"), ("AMIN", "0"),
         ("AMAX", "1080"), ("AFRT", "540"), ("SCAN", "2400")])), "DMAX:'lots' is not"),
    (scip.encode_reply("PP", "00", scip.key_value_lines(
        [("MODL", "X"), ("DMIN", "23"), ("DMAX", "60000"), ("ARES", "1440"), ("AMIN", "0"),
         ("AMAX", "1080"), ("AFRT", "1200"), ("SCAN", "2400")])), "make no sense"),
    (scip.encode_reply("PP", "0E"), "PP answered 0E: undefined command"),
    (VV_URG, "expected a PP reply"),
])
def test_pp_that_cannot_describe_a_scanner_is_refused(reply: bytes, match: str) -> None:
    with pytest.raises(scip.ScipError, match=match):
        scip.parse_params(ok(reply))


# -- statuses ----------------------------------------------------------------------------------
@pytest.mark.parametrize(("wire", "command", "status", "meaning"), [
    (b"BM\n00P\n\n", "BM", "00", "without error"),
    (b"BM\n01Q\n\n", "BM", "01", "laser malfunction"),
    (b"BM\n02R\n\n", "BM", "02", "already on"),
    (b"QT\n00P\n\n", "QT", "00", "without error"),
    (b"RS\n00P\n\n", "RS", "00", "without error"),
    (b"RB\n01Q\n\n", "RB", "01", "send RB again within 1 s"),
    (b"TM0\n02R\n\n", "TM", "02", "already on"),
    (b"TM2\n03S\n\n", "TM", "03", "already off"),
    (b"TM9\n01Q\n\n", "TM", "01", "invalid control code"),
    (b"GD0000108001\n10Q\n\n", "GD", "10", "laser is off"),
    (b"GD0000128001\n04T\n\n", "GD", "04", "out of range"),
    (b"MD0000108001000\n00P\n\n", "MD", "00", "without error"),
    (b"MDxx\n01Q\n\n", "MD", "01", "starting step"),
    (b"MD0000108001x00\n06V\n\n", "MD", "06", "scan interval"),
    (b"MD000010800100y\n07W\n\n", "MD", "07", "number of scans"),
    (b"MD0000108001000\n98a\n\n", "MD", "98", "resumption"),
    (b"XX\n0Ee\n\n", "XX", "0E", "undefined command"),
])
def test_statuses_decode_with_their_meaning(wire: bytes, command: str, status: str,
                                            meaning: str) -> None:
    reply = ok(wire)
    assert (reply.command, reply.status) == (command, status)
    assert meaning in reply.meaning
    assert not reply.hardware_error


@pytest.mark.parametrize("code", ["0A", "0B", "0C", "0D", "0E", "0F", "0G", "0H", "0I", "0J",
                                  "0K", "0L"])
def test_the_command_errors_0a_to_0l_all_have_a_meaning(code: str) -> None:
    reply = ok(scip.encode_reply("VV", code))
    assert reply.status == code and "unknown" not in reply.meaning
    assert not reply.hardware_error


@pytest.mark.parametrize("code", [50, 52, 75, 97, 98])
def test_statuses_50_to_98_are_hardware_faults(code: int) -> None:
    gd = ok(scip.encode_reply("GD0000108001", f"{code:02d}"))
    assert gd.hardware_error and "hardware trouble" in gd.meaning and not gd.is_scan
    md = ok(scip.encode_reply("MD0000108001000", f"{code:02d}"))
    assert md.hardware_error == (code != 98)  # MD 98: measuring resumed after an error
    assert not scip.is_hardware_error("49") and not scip.is_hardware_error("99")
    assert not scip.is_hardware_error("0L") and scip.is_hardware_error("98", "GD")


# -- scans ------------------------------------------------------------------------------------
def test_a_small_gd_reply_gives_its_timestamp_and_ranges() -> None:
    reply = ok(GD_SMALL)
    assert reply.is_scan and reply.status == "00" and reply.timestamp_ms == 1000
    assert reply.values is not None and reply.values.tolist() == [1000, 5432, 1]
    assert reply.request == scip.ScanRequest("GD", 0, 2, 1)


def test_md_scans_carry_the_remaining_count_and_the_tag_in_their_echo() -> None:
    scan = ok(MD_SMALL)
    assert scan.status == "99" and scan.timestamp_ms == scip.TIMESTAMP_MODULUS - 1
    assert scan.values is not None and scan.values.tolist() == [23, 30000, 60000]
    tagged = ok(MD_TAGGED)
    assert tagged.request == scip.ScanRequest("MD", 0, 2, 1, interval=0, scans=1, tag="lidar")
    assert tagged.tag == "lidar" and tagged.timestamp_ms == 4660
    ack = ok(b"MD0000108001000\n00P\n\n")
    assert ack.status == "00" and not ack.is_scan and ack.request is not None


def test_a_full_1081_step_reply_is_cut_every_64_characters_regardless_of_steps() -> None:
    source = synthetic_room()
    values = np.asarray(source(0.0))
    wire = scip.encode_scan_reply("GD0000108001", "00", 123_456, values)
    lines = wire.split(b"\n")
    data = lines[3:-2]
    assert len(data) == 51  # 1081 * 3 = 3243 characters = 50 * 64 + 43
    assert all(len(line) == 65 for line in data[:-1]) and len(data[-1]) == 44
    reply = ok(wire)
    assert reply.values is not None and np.array_equal(reply.values, values)
    assert reply.timestamp_ms == 123_456


def test_the_emulators_independent_encoder_produces_what_the_codec_reads() -> None:
    sensor = HokuyoSensor(now=0.0)
    sensor.feed(0.0, b"BM\nGD0000108001\nGS0180090003;t\n")
    sensor.service(0.2)
    replies = scip.ScipDecoder().feed(sensor.take_output())
    assert [type(r) for r in replies] == [scip.Reply] * 3
    bm, gd, gs = replies
    assert isinstance(gd, scip.Reply) and isinstance(gs, scip.Reply)
    room = np.asarray(synthetic_room()(0.0))
    assert gd.values is not None and np.array_equal(gd.values, room)
    assert gs.request == scip.ScanRequest("GS", 180, 900, 3, tag="t")
    assert gs.values is not None and len(gs.values) == 241
    clusters = np.minimum(room[180:901], 4095)
    expect = [clusters[i:i + 3].min() for i in range(0, 721, 3)]
    assert gs.values.tolist() == expect


# -- bad replies ------------------------------------------------------------------------------
@pytest.mark.parametrize(("wire", "line"), [
    (b"GD0000000201\n00Q\n00?Xg\n0?X1Dh001e\n\n", 1),  # status sum
    (b"GD0000000201\n00P\n00?Xh\n0?X1Dh001e\n\n", 2),  # timestamp sum
    (b"GD0000000201\n00P\n00?Xg\n0?X1Dh001f\n\n", 3),  # data sum
    (b"GD0000000201\n00P\n00?Xg\n0?X1Dh002e\n\n", 3),  # a flipped data character
    (PP_UTM.replace(b"DMAX:60000;J", b"DMAX:60001;J"), 4),  # a parameter line
])
def test_a_line_failing_its_sum_is_reported_with_the_line(wire: bytes, line: int) -> None:
    reply = bad(wire)
    assert reply.kind == "checksum" and reply.line == line
    assert "fails its sum" in str(reply) and reply.echo == wire.split(b"\n")[0].decode()


def test_replies_cut_short_are_reported_as_truncated() -> None:
    full = scip.encode_scan_reply("GD0000108001", "00", 5, np.full(1081, 1500))
    lines = full.split(b"\n")
    missing_line = b"\n".join(lines[:10] + lines[11:])
    r = bad(missing_line)
    assert r.kind == "truncated" and "3179 data characters, 3243 expected" in r.reason
    assert bad(b"GD0000108001\n00P\n\n").kind == "truncated"  # no timestamp
    assert bad(b"QT\n\n").kind == "truncated"  # no status line
    dec = scip.ScipDecoder()
    assert dec.feed(full[:1000]) == [] and dec.pending == 1000
    cut = dec.close()
    assert cut is not None and cut.kind == "truncated" and cut.echo == "GD0000108001"
    assert "ended after 1000 bytes" in cut.reason and dec.pending == 0
    assert dec.close() is None


@pytest.mark.parametrize(("wire", "reason"), [
    (b"\x01\x02\n00P\n\n", "printable command echo"),
    (b"BM\n0P\n\n", "not 2 characters and a sum"),
    (b"GD0000000201\n00P\n00?Xg\n0?X1Dh\n001e\n\n", "cut every 64"),
    (b"GD00000002\n00P\n00?Xg\n0?X1Dh001e\n\n", "10 digits of parameters"),
    (b"MD0000000201000\n00P\n00?Xg\n\n", "carries data"),
    (b"GD0000000201\n99b\n00?Xg\n0?X1Dh001e\n\n", "cannot carry GD data"),
    (b"PP\n00P\nMODL UTM;\x1b\n\n", "fails its sum"),
])
def test_garbled_replies_say_what_is_wrong(wire: bytes, reason: str) -> None:
    reply = bad(wire)
    assert reason in str(reply)


def test_the_streaming_decoder_gives_the_same_replies_whatever_the_chunking() -> None:
    stream = GD_SMALL + b"BM\n02R\n\n" + MD_SMALL + b"GD0000000201\n00Q\n\n" + PP_UTM
    whole = scip.ScipDecoder().feed(stream)
    dec = scip.ScipDecoder()
    bytewise = [r for i in range(len(stream)) for r in dec.feed(stream[i:i + 1])]
    assert dec.pending == 0
    assert [(type(r).__name__, r.echo) for r in whole] == \
           [(type(r).__name__, r.echo) for r in bytewise] == [
        ("Reply", "GD0000000201"), ("Reply", "BM"), ("Reply", "MD0000000201000"),
        ("BadReply", "GD0000000201"), ("Reply", "PP")]  # and it carries on past a bad one


def test_bytes_that_never_end_a_reply_are_dropped_as_an_overflow() -> None:
    dec = scip.ScipDecoder(max_reply=1000)
    out = dec.feed(b"GD0000108001\n" + b"0" * 2000)
    assert len(out) == 1 and isinstance(out[0], scip.BadReply)
    assert out[0].kind == "overflow" and out[0].echo == "GD0000108001"
    assert dec.pending == 0
    assert [type(r) for r in dec.feed(GD_SMALL)] == [scip.Reply]


def test_stray_empty_lines_between_replies_are_ignored() -> None:
    out = scip.ScipDecoder().feed(b"\n\n\n" + GD_SMALL + b"\n" + b"QT\n00P\n\n")
    assert [r.echo for r in out] == ["GD0000000201", "QT"]


# -- time ---------------------------------------------------------------------------------------
def test_tm1_gives_the_sensors_time() -> None:
    reply = ok(b"TM1\n00P\n0N90W\n\n")
    assert reply.timestamp_ms == 123_456
    assert bad(b"TM1\n00P\n0N90X\n\n").kind == "checksum"
    assert bad(b"TM1\n00P\n\n").kind == "truncated"
    assert ok(b"TM0\n00P\n\n").timestamp_ms is None


def test_the_24_bit_timestamp_unwraps_across_the_wrap() -> None:
    assert scip.TIMESTAMP_MODULUS == 16_777_216  # ms: 4 h 39 min 37 s
    u = scip.TimestampUnwrapper()
    raws = [16_777_100, 16_777_125, 16_777_150, 16_777_175, 16_777_200, 9, 34, 59]
    total = [u.unwrap(r) for r in raws]
    assert np.all(np.diff(total) == 25) and total[-1] == 16_777_216 + 59
    assert scip.unwrap_delta(16_777_215, 0) == 1
    assert scip.unwrap_delta(0, 16_777_215) == -1
    assert u.unwrap(20) == total[-1] - 39  # a small step back stays a step back
    u.reset()
    assert u.unwrap(500) == 500
    with pytest.raises(scip.ScipError, match="24-bit"):
        u.unwrap(1 << 24)
    stamp = ok(MD_SMALL).timestamp_ms
    assert stamp is not None and scip.unwrap_delta(stamp, 24) == 25
