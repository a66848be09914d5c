"""Repeated log lines are rate-limited (issue 35: a connect/close flood wrote 1,140 WARNING
lines in 10 s): the same logger and template pass `burst` times a window, the rest are
counted and the count is said on the next line of that kind."""

from __future__ import annotations

import io
import logging

from ramp.common.logthrottle import RepeatFilter


def _logger(f: RepeatFilter) -> tuple[logging.Logger, io.StringIO]:
    out = io.StringIO()
    handler = logging.StreamHandler(out)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    handler.addFilter(f)
    log = logging.getLogger(f"test.throttle.{id(f)}")
    log.propagate = False
    log.handlers = [handler]
    log.setLevel(logging.INFO)
    return log, out


def _at(log: logging.Logger, t: float, level: int, msg: str, *args: object) -> None:
    record = log.makeRecord(log.name, level, __file__, 1, msg, args, None)
    record.created = t
    log.handle(record)


def test_a_flood_of_one_kind_is_a_burst_then_a_count() -> None:
    f = RepeatFilter(burst=5, window=10.0)
    log, out = _logger(f)
    for i in range(1140):
        _at(log, 100.0 + i * 0.0087, logging.WARNING, "refused %s: already %d clients",
            f"127.0.0.1:{40000 + i}", 8)
    assert out.getvalue().count("WARNING") == 5
    assert f.suppressed == 1135
    _at(log, 111.0, logging.WARNING, "refused %s: already %d clients", "127.0.0.1:1", 8)
    last = out.getvalue().splitlines()[-1]
    assert last == (f"WARNING test.throttle.{id(f)}: refused 127.0.0.1:1: already 8 clients "
                    "(1,135 more like this in the last 10 s not shown)")


def test_other_kinds_and_levels_pass_and_critical_is_never_held() -> None:
    f = RepeatFilter(burst=2, window=10.0)
    log, out = _logger(f)
    for i in range(5):
        _at(log, 1.0 + i * 0.01, logging.WARNING, "client %s gone", i)
        _at(log, 1.0 + i * 0.01, logging.ERROR, "bus %s fault", i)
        _at(log, 1.0 + i * 0.01, logging.CRITICAL, "stall %s", i)
    text = out.getvalue()
    assert text.count("WARNING") == 2 and text.count("ERROR") == 2
    assert text.count("CRITICAL") == 5
