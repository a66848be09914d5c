"""ramp-shell's pure parts: catalog from describe, tables, errors, help, completion, hints."""

from __future__ import annotations

import io
import re
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from prompt_toolkit.history import FileHistory, InMemoryHistory

from ramp.mcp.messages import Request, Response
from ramp.mcp.protocol import parse_response_line
from ramp.shell.cli import (
    Shell,
    UsageError,
    accepted_motion,
    heartbeat_period,
    history_path,
    open_history,
    parse_requests,
    split_trailing_number,
    stop_message,
    watchdog_timeout,
)
from ramp.shell.complete import complete, current_fragment, param_hint, split_command
from ramp.shell.render import (
    Catalog,
    build_catalog,
    error_text,
    modules_listed,
    render_help,
    render_responses,
    render_value,
    wrap_items,
)

# Answers as a MARTE supervisor gives them (captured from `ramp run --sim`).
ROBOT_DESCRIBE = (
    b"robot:robot.module=(base)robot:robot.module=(ble)robot:robot.function=(get)"
    b"robot:robot.function=(stop)robot:robot.function=(describe)robot:robot.function=(modules)"
    b"robot:watchdog.function=(timeout,float >0..60)robot:control.function=(acquire,name)"
    b"robot:control.function=(release)")
BASE_DESCRIBE = (
    b"base:base.function=(get)base:base.function=(stop)base:base.function=(describe)"
    b"base:base.function=(drive,int -100..100,float)base:lf_wheel.function=(vel,int -100..100)"
    b"base:lb_wheel.function=(vel,int -100..100)base:rf_wheel.function=(vel,int -100..100)"
    b"base:rb_wheel.function=(vel,int -100..100)base:user_led.function=(on,int 0..1)"
    b"base:lf_wheel.property=(vel,int)base:l_button.property=(press,int)"
    b"base:battery.property=(volt,float,V)base:user_led.property=(on,int)")
BLE_NOT_ATTACHED = b"ble:ble.error=(not_attached,ble is detached)"


def catalog() -> Catalog:
    return build_catalog(parse_response_line(ROBOT_DESCRIBE),
                         {"base": parse_response_line(BASE_DESCRIBE),
                          "ble": parse_response_line(BLE_NOT_ATTACHED)})


# --------------------------------------------------------------------------- catalog


def test_catalog_lists_modules_devices_functions_and_units_from_describe() -> None:
    cat = catalog()
    assert cat.modules == ["robot", "base", "ble"]
    assert cat.devices("base") == ["base", "lf_wheel", "lb_wheel", "rf_wheel", "rb_wheel",
                                   "user_led"]
    assert cat.devices("robot") == ["robot", "watchdog", "control"]
    drive = cat.function("base", "base", "drive")
    assert drive is not None and drive.params == ("int -100..100", "float")
    assert drive.usage == "base:base.drive=(int -100..100, float)"
    assert cat.unit("base", "battery", "volt") == "V"
    assert cat.unit("base", "lf_wheel", "vel") == ""
    assert cat.unit("nope", "battery", "volt") == ""
    assert cat.problems == {"ble": "not_attached: ble is detached"}
    assert cat.devices("ble") == []


def test_catalog_skips_rows_it_does_not_understand() -> None:
    rows = parse_response_line(b"base:x.function=()base:y.wobble=(1)base:z.property=(p)")
    cat = build_catalog([], {"base": rows})
    assert cat.functions["base"] == []
    assert [(p.device, p.name, p.type, p.unit) for p in cat.properties["base"]] == [
        ("z", "p", "", "")]


# --------------------------------------------------------------------------- rendering


def test_get_renders_as_an_aligned_table_with_units() -> None:
    rows = parse_response_line(b"base:lf_wheel.vel=(60)base:battery.volt=(19.512)"
                               b"base:user_led.on=(0)")
    assert render_responses(rows, catalog()).split("\n") == [
        "module  device    property  value",
        "base    lf_wheel  vel       60",
        "base    battery   volt      19.512 V",
        "base    user_led  on        0",
    ]


def test_several_values_are_joined_and_floats_print_as_mcp_does() -> None:
    assert render_value((140, 9258, 25326)) == "140, 9258, 25326"
    assert render_value((0.1 + 0.2,), "kg") == "0.3 kg"
    assert render_value(("base", "ble")) == "base, ble"
    assert render_value((), "V") == ""


def test_errors_show_plainly_after_the_rows() -> None:
    line = (b"base:lf_wheel.error=(bad_params,vel takes one parameter: int in -100..100)"
            b"base:battery.volt=(19.5)robot:mcp.error=(syntax,expected ':')")
    text = render_responses(parse_response_line(line), catalog())
    assert text.split("\n") == [
        "module  device   property  value",
        "base    battery  volt      19.5 V",
        "error  base:lf_wheel  bad_params: vel takes one parameter: int in -100..100",
        "error  robot:mcp  syntax: expected ':'",
    ]


def test_empty_answer_is_ok_and_colour_only_on_request() -> None:
    assert render_responses([]) == "ok"
    rows = parse_response_line(b"base:lf_wheel.error=(fault,gone)base:battery.volt=(1.0)")
    plain = render_responses(rows)
    assert "\x1b" not in plain
    coloured = render_responses(rows, color=True)
    assert "\x1b[31merror  base:lf_wheel  fault: gone\x1b[0m" in coloured
    assert coloured.startswith("\x1b[1mmodule")


def test_error_text_without_detail() -> None:
    assert error_text(Response("a", "b", "error", ("busy",))) == "busy"
    assert error_text(Response("a", "b", "error", ())) == "error"


def test_modules_listed() -> None:
    assert modules_listed(parse_response_line(b"robot:robot.modules=(base,ble)")) == [
        "base", "ble"]
    assert modules_listed(parse_response_line(b"robot:robot.modules=()")) == []
    assert modules_listed(parse_response_line(b"base:battery.volt=(1.0)")) is None


def test_help_groups_by_module_and_states_the_safety_rule() -> None:
    text = render_help(catalog(), watchdog_timeout=1.5)
    lines = text.split("\n")
    base = lines.index("base")
    assert lines[base + 1:base + 3] == ["  base:base.get=()", "  base:base.stop=()"]
    assert "  base:lf_wheel.vel=(int -100..100)" in lines
    assert any(line.startswith("  get rows:") and "battery.volt [V]" in line for line in lines)
    assert "  (cannot describe: not_attached: ble is detached)" in lines
    assert lines.index("robot") < base < lines.index("ble") < lines.index("shell commands")
    assert "never keeps motors running by itself" in text
    assert "(timeout 1.5 s)" in text
    assert all(len(line) <= 100 for line in lines)


# --------------------------------------------------------------------------- completion


def texts(before: str) -> list[str]:
    return [c.text for c in complete(before, catalog())]


def test_nothing_typed_offers_modules_then_commands() -> None:
    got = texts("")
    assert got[:3] == ["robot:", "base:", "ble:"]
    assert {"help", "watch ", "hold ", "reload", "quit", "exit"} <= set(got[3:])


def test_module_prefix_replaces_the_word() -> None:
    [c] = complete("ba", catalog())
    assert (c.text, c.start, c.display, c.meta) == ("base:", -2, "base", "module")
    assert texts("w") == ["watch "]


def test_devices_after_module_colon() -> None:
    got = complete("base:", catalog())
    assert [c.text for c in got] == ["base.", "lf_wheel.", "lb_wheel.", "rf_wheel.",
                                     "rb_wheel.", "user_led."]
    assert got[1].meta == "vel" and got[0].meta == "get, stop, describe, drive"
    assert texts("base:r") == ["rf_wheel.", "rb_wheel."]
    assert texts("nope:") == []


def test_functions_after_device_dot_carry_the_parameter_hint() -> None:
    got = complete("base:base.", catalog())
    assert [c.text for c in got] == ["get=()", "stop=()", "describe=()", "drive=("]
    drive = got[-1]
    assert drive.meta == "(int -100..100, float)" and drive.display == "drive"
    [vel] = complete("base:lf_wheel.v", catalog())
    assert (vel.text, vel.start, vel.meta) == ("vel=(", -1, "(int -100..100)")


def test_completion_restarts_after_each_request_and_after_commands() -> None:
    assert texts("base:base.get=()ble") == ["ble:"]
    assert texts("base:base.get=() base:lf") == ["lf_wheel."]
    assert "help" not in texts("base:base.get=() ")  # commands only start a line
    assert texts("hold base:lf_wheel.") == ["vel=("]
    # watch offers only reads
    assert texts("watch base:base.") == ["get=()", "describe=()"]
    assert texts("watch base:") == ["base."]
    assert texts("base:lf_wheel.vel=(") == []


def test_fragment_and_command_split() -> None:
    assert current_fragment("a:b.c=(1)  d:e") == "d:e"
    assert split_command("  watch  base:base.get=()") == ("watch", "base:base.get=()")
    assert split_command("watcher:x.y=()") == (None, "watcher:x.y=()")


def test_param_hint_inside_parentheses_marks_the_current_parameter() -> None:
    cat = catalog()
    hint = param_hint("base:lf_wheel.vel=(", cat)
    assert hint is not None and hint.text() == "base:lf_wheel.vel (int -100..100)"
    hint = param_hint("hold base:base.drive=(40, ", cat)
    assert hint is not None and hint.index == 1
    assert hint.text() == "base:base.drive (int -100..100, [float])"
    hint = param_hint("base:base.get=(", cat)
    assert hint is not None and hint.text() == "base:base.get (no parameters)"
    assert param_hint("base:base.drive=(1,2)", cat) is None
    assert param_hint("base:base.fly=(", cat) is None
    assert param_hint("base:base.", cat) is None


# --------------------------------------------------------------------------- shell helpers


def test_history_path_honours_xdg_data_home() -> None:
    assert str(history_path({"XDG_DATA_HOME": "/x", "HOME": "/h"})) == (
        "/x/ramp/shell_history")
    assert str(history_path({"XDG_DATA_HOME": "", "HOME": "/h"})) == (
        "/h/.local/share/ramp/shell_history")


def test_history_file_is_created_or_falls_back_to_memory(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "deep" / "ramp" / "shell_history"
    history = open_history(path)
    assert isinstance(history, FileHistory) and path.is_file()
    history.append_string("base:base.get=()")
    assert "+base:base.get=()" in path.read_text()
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert isinstance(open_history(blocker / "ramp" / "shell_history"), InMemoryHistory)
    assert "history not saved" in capsys.readouterr().err


def test_trailing_number_of_watch_and_hold() -> None:
    assert split_trailing_number("base:base.get=() 5", "HZ", 0, 50) == ("base:base.get=()", 5.0)
    assert split_trailing_number(" base:base.get=()", "HZ", 0, 50) == ("base:base.get=()", None)
    assert split_trailing_number("base:base.drive=(30, 0)", "S", 0, 60) == (
        "base:base.drive=(30, 0)", None)
    with pytest.raises(UsageError, match="HZ must be in"):
        split_trailing_number("base:base.get=() 500", "HZ", 0, 50)
    with pytest.raises(UsageError):
        split_trailing_number("base:base.get=() nan", "HZ", 0, 50)
    assert split_trailing_number("a:b.get=() 0.01", "HZ", 0.01, 50, lo_open=False) == (
        "a:b.get=()", 0.01)
    with pytest.raises(UsageError, match="HZ must be in 0.01 <= HZ <= 50, not 1e-10"):
        split_trailing_number("a:b.get=() 1e-10", "HZ", 0.01, 50, lo_open=False)


def test_parse_requests_reports_syntax_in_the_parsers_words() -> None:
    assert parse_requests("base:base.get=()ble:ble.get=()") == [
        Request("base", "base", "get"), Request("ble", "ble", "get")]
    with pytest.raises(UsageError, match="syntax: expected"):
        parse_requests("base:base")


def test_hold_stops_only_what_the_robot_accepted() -> None:
    reqs = parse_requests("base:base.drive=(30,0)ble:chain.vel=(300)ble:ble.get=()")
    answer = parse_response_line(b"ble:chain.error=(bad_params,x)ble:lift.vel=(0)")
    moving = accepted_motion(reqs, answer)
    assert moving == [Request("base", "base", "drive", ("30", "0"))]
    assert stop_message(moving, ["robot", "base", "ble"]) == "base:base.stop=()"
    both = parse_requests("robot:watchdog.timeout=(2)base:lf_wheel.vel=(5)base:rf_wheel.vel=(5)")
    assert stop_message(both, ["robot", "base"]) == "robot:robot.stop=()base:base.stop=()"
    refused = parse_response_line(b"base:base.error=(not_owner,autonomy owns control)")
    assert stop_message(accepted_motion(reqs[:1], refused), ["base"]) == ""


def test_heartbeat_period_is_a_quarter_of_the_watchdog_bounded() -> None:
    rows = parse_response_line(b"robot:robot.uptime=(1.0)robot:watchdog.timeout=(0.4)")
    assert watchdog_timeout(rows) == 0.4
    assert heartbeat_period(0.4) == pytest.approx(0.1)
    assert heartbeat_period(None) == 0.25
    assert heartbeat_period(60) == 0.25
    assert heartbeat_period(0.01) == 0.02


def test_wrap_items_never_splits_an_item() -> None:
    items = ["battery.volt [V]", "lf_wheel.vel", "load.kg [kg]", "x"]
    assert wrap_items("  rows: ", items, "    ", 34) == [
        "  rows: battery.volt [V],",
        "    lf_wheel.vel, load.kg [kg], x",
    ]
    assert wrap_items("> ", [], "  ", 10) == ["> "]


# --------------------------------------------------------------------------- Shell, scripted robot
# A loopback server answering from canned describe rows, logging which connection sent
# what: the shell's safety rule is about which connection carries which message.


class ScriptedRobot:
    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port: int = self.listener.getsockname()[1]
        self.log: list[tuple[int, str]] = []
        self.known = "base"  # robot.describe lists every known module
        self.modules = "base"  # robot.modules only those in state ok
        self.base_fault = False
        self.watchdog_timeout = "1.0"
        #: robot.get says `tripped` once this is true of the log (else `armed`)
        self.trip_when: Callable[[list[tuple[int, str]]], bool] = lambda log: False
        self.interrupt_when: Callable[[list[tuple[int, str]]], bool] = lambda log: False
        self._interrupted = False  # Ctrl-C once: a second one would hit a later test
        self._conns: list[socket.socket] = []
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self) -> None:
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:
                return
            self._conns.append(conn)
            threading.Thread(target=self._serve, args=(len(self._conns) - 1, conn),
                             daemon=True).start()

    def _serve(self, index: int, conn: socket.socket) -> None:
        buf = b""
        with conn:
            while True:
                try:
                    data = conn.recv(4096)
                except OSError:
                    return
                if not data:
                    return
                buf += data
                while b"\n" in buf:
                    line, buf = buf.split(b"\n", 1)
                    text = line.decode()
                    self.log.append((index, text))
                    conn.sendall(self.answer(text).encode() + b"\n")
                    if not self._interrupted and self.interrupt_when(self.log):
                        self._interrupted = True
                        signal.pthread_kill(threading.main_thread().ident or 0, signal.SIGINT)

    def answer(self, text: str) -> str:
        out = []
        for r in parse_requests(text):
            key = f"{r.module}:{r.device}.{r.function}"
            if key == "robot:robot.describe":
                out.append("".join(f"robot:robot.module=({m})" for m in self.known.split(",")))
                out.append(ROBOT_DESCRIBE.decode().split("robot:robot.function=(get)")[1])
            elif key == "base:base.describe" and self.base_fault:
                out.append("base:base.error=(fault,lost /dev/ttyUSB0)")
            elif key == "base:base.describe":
                out.append(BASE_DESCRIBE.decode())
            elif key == "ble:ble.describe":
                out.append("ble:chain.function=(vel,int -100..100)ble:load.property=(kg,float,kg)")
            elif key == "robot:robot.modules":
                out.append(f"robot:robot.modules=({self.modules})")
            elif key == "robot:robot.get":
                state = "tripped" if self.trip_when(self.log) else "armed"
                out.append(f"robot:watchdog.timeout=({self.watchdog_timeout})"
                           f"robot:watchdog.state=({state})")
            elif key == "base:base.get":
                out.append("base:battery.volt=(12.5)")
        return "".join(out)

    def lines_of(self, index: int) -> list[str]:
        return [text for i, text in self.log if i == index]

    def close(self) -> None:
        self.listener.close()
        for c in self._conns:
            c.close()


@pytest.fixture()
def robot() -> Iterator[ScriptedRobot]:
    r = ScriptedRobot()
    try:
        yield r
    finally:
        r.close()


def connected(robot: ScriptedRobot, clock: Callable[[], float] | None = None
              ) -> tuple[Shell, io.StringIO]:
    out = io.StringIO()
    shell = Shell("127.0.0.1", robot.port, out, timeout=5, clock=clock or time.monotonic)
    shell.interactive = True
    shell.connect(monitor=True)  # main is connection 0, the read-only one 1
    return shell, out


def test_watch_polls_never_travel_on_the_main_connection(robot: ScriptedRobot) -> None:
    shell, out = connected(robot)
    try:
        assert shell.run_line("base:base.drive=(30,0)") == 0
        robot.interrupt_when = lambda log: sum(
            t == "base:base.get=()" for i, t in log if i == 1) >= 3
        assert shell.run_line("watch base:base.get=() 50") == 0
    finally:
        shell.close()
    assert robot.lines_of(0) == ["base:base.drive=(30,0)"]
    assert robot.lines_of(1).count("base:base.get=()") == 3
    text = out.getvalue()
    assert "#3" in text and "#4" not in text
    assert re.search(r"base\s+battery\s+volt\s+12.5 V", text)


def test_hold_feeds_on_the_main_connection_then_stops(robot: ScriptedRobot) -> None:
    robot.watchdog_timeout = "0.08"  # heartbeats every 20 ms
    shell, out = connected(robot)
    try:
        robot.interrupt_when = lambda log: sum(t == "" for i, t in log if i == 0) >= 3
        assert shell.run_line("hold base:base.drive=(30,0)") == 0
    finally:
        shell.close()
    assert robot.lines_of(0) == ["base:base.drive=(30,0)", "", "", "", "base:base.stop=()"]
    assert "stopped: base:base.stop=()" in out.getvalue()


def test_hold_ends_early_and_exits_1_when_the_watchdog_trips(robot: ScriptedRobot) -> None:
    """The robot stopped the motion under the hold (a stall, a lost feed): the shell says so
    and exits 1 instead of holding on and reporting success."""
    robot.watchdog_timeout = "0.08"  # heartbeats every 20 ms
    robot.trip_when = lambda log: sum(t == "" for i, t in log if i == 0) >= 2
    shell, out = connected(robot)
    try:
        assert shell.run_line("hold base:base.drive=(30,0) 30") == 1
    finally:
        shell.close()
    assert robot.lines_of(0) == ["base:base.drive=(30,0)", "", "", "base:base.stop=()"]
    assert "robot:robot.get=()" in robot.lines_of(1)  # the state is read on the other one
    assert "the watchdog tripped during the hold" in out.getvalue()


def test_a_change_in_attached_modules_re_describes(robot: ScriptedRobot) -> None:
    now = [0.0]
    shell, out = connected(robot, lambda: now[0])
    try:
        assert shell.catalog.modules == ["robot", "base"]
        assert texts_for(shell.catalog, "ble") == []
        robot.known = robot.modules = "base,ble"
        now[0] = 5.0
        shell.run_line("base:base.get=()")
    finally:
        shell.close()
    assert shell.catalog.modules == ["robot", "base", "ble"]
    assert texts_for(shell.catalog, "ble:") == ["chain."]
    assert "(modules changed: now base, ble; completion updated)" in out.getvalue()
    # the check and the re-describe went on the read-only connection
    assert robot.lines_of(0) == ["base:base.get=()"]
    assert "ble:ble.describe=()" in "".join(robot.lines_of(1))


def test_a_module_in_fault_keeps_its_completion(robot: ScriptedRobot) -> None:
    now = [0.0]
    shell, out = connected(robot, lambda: now[0])
    try:
        robot.base_fault = True
        robot.modules = ""  # robot.modules lists only modules in state ok
        now[0] = 5.0
        shell.run_line("base:base.get=()")
    finally:
        shell.close()
    assert shell.catalog.problems == {"base": "fault: lost /dev/ttyUSB0"}
    assert "lf_wheel." in texts_for(shell.catalog, "base:")
    assert "now none" in out.getvalue()


def texts_for(cat: Catalog, before: str) -> list[str]:
    return [c.text for c in complete(before, cat)]
