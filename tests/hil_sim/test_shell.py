"""`ramp-shell` in a real terminal (pexpect pty) and in `-c` mode, against `ramp run --sim`.

prompt_toolkit asks the terminal for the cursor position (CPR, `ESC[6n`) at every prompt.
PROMPT_TOOLKIT_NO_CPR=1 would silence it, but prompt_toolkit then never learns the screen
height and hides the bottom toolbar (where the parameter hint lives), so `expect` below
answers each query the way a terminal would, with the cursor on row 1.
"""

from __future__ import annotations

import os
import re
import select
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pexpect
import pytest

from tests.harness import ask_line, start_ramp

REPO = Path(__file__).resolve().parents[2]
_SCRIPT = Path(sys.executable).parent / "ramp-shell"
SHELL = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-m", "ramp.shell"]
# prompt_toolkit draws "ramp>" and moves the cursor over the space rather than print it.
PROMPT = "ramp>"


class Server:
    """`ramp run --sim` as a process; `close()` kills it whatever state it is in."""

    def __init__(self, port: int = 0) -> None:
        self.proc, host, bound = start_ramp(
            ["--sim", "--host", "127.0.0.1", "--port", str(port)], stderr=subprocess.DEVNULL)
        self.address = f"{host}:{bound}"

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()  # SIGTERM: the supervisor cleans its sim ptys up
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.proc.wait(timeout=10)
        if self.proc.stdout is not None:
            self.proc.stdout.close()


@pytest.fixture(scope="module")
def server() -> Iterator[str]:
    srv = Server()
    try:
        yield srv.address
    finally:
        srv.close()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
    return port


@pytest.fixture()
def term_env(tmp_path: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NO_COLOR", "XDG_DATA_HOME")}
    env.update(TERM="xterm", HOME=str(tmp_path / "home"), XDG_DATA_HOME=str(tmp_path / "xdg"),
               COLUMNS="120", LINES="40")
    (tmp_path / "home").mkdir()
    return env


@pytest.fixture()
def shell(server: str, term_env: dict[str, str]) -> Iterator[pexpect.spawn]:
    child = pexpect.spawn(SHELL[0], [*SHELL[1:], server], env=term_env, cwd=str(REPO),
                          dimensions=(40, 120), encoding="utf-8", timeout=10)
    try:
        expect_exact(child, PROMPT)
        yield child
    finally:
        if child.isalive():
            child.terminate(force=True)
        child.close()


_CPR = re.compile(re.escape("\x1b[6n"))


def expect(child: pexpect.spawn, pattern: str) -> None:
    """child.expect(pattern), answering cursor position requests on the way."""
    wanted = re.compile(pattern)
    while child.expect([_CPR, wanted]) == 0:
        child.send("\x1b[1;1R")


def expect_exact(child: pexpect.spawn, text: str) -> None:
    expect(child, re.escape(text))


def ask(address: str, text: str) -> str:
    host, port = address.split(":")
    with socket.create_connection((host, int(port)), timeout=5) as s:
        return ask_line(s, text)


def heading(name: str) -> str:
    """A line holding only `name`, bold on a terminal."""
    return rf"(?:\n|\x1b\[1m){name}(?:\x1b\[0m)?\r\n"


def run_c(*args: str, timeout: float = 15) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*SHELL, *args], cwd=REPO, text=True, capture_output=True,
                          timeout=timeout)


# --------------------------------------------------------------------------- in a terminal


def test_tab_after_module_offers_its_devices(shell: pexpect.spawn) -> None:
    shell.send("base:")
    shell.send("\t")
    expect_exact(shell, "lf_wheel")
    expect_exact(shell, "rb_wheel")
    shell.send("\x03")  # Ctrl-C at the prompt clears the line
    expect_exact(shell, PROMPT)
    shell.send("ble:lift.")
    shell.send("\t")
    expect_exact(shell, "retract")  # functions after module:device.
    shell.send("\x03")
    expect_exact(shell, PROMPT)
    shell.send("base:lf_wheel.vel=(")  # the toolbar shows what goes in the parentheses
    expect_exact(shell, "base:lf_wheel.vel (int -100..100)")


def test_tab_after_sim_offers_the_sim_module_s_devices(shell: pexpect.spawn) -> None:
    """Issue 35: `sim:` (SPEC 12, not listed by robot.describe) completed nothing."""
    shell.send("sim:")
    shell.send("\t")
    expect_exact(shell, "input")
    shell.send("\x03")
    expect_exact(shell, PROMPT)
    shell.send("sim:bus.")
    shell.send("\t")
    expect_exact(shell, "unplug")
    shell.send("\x03")
    expect_exact(shell, PROMPT)


def test_get_renders_a_table_with_units_and_history_is_saved(
        shell: pexpect.spawn, term_env: dict[str, str]) -> None:
    shell.sendline("base:base.get=()")
    expect(shell, r"module\s+device\s+property\s+value")
    expect(shell, r"battery\s+volt\s+\d+\.\d+ V")
    expect_exact(shell, PROMPT)
    shell.sendline("base:lf_wheel.vel=(300)")
    expect(shell, r"error  base:lf_wheel  bad_params: vel takes")
    expect_exact(shell, PROMPT)
    shell.sendline("base:user_led.on=(1)")
    expect(shell, r"(?:\n|\?2004l)ok\r\n")  # after the line, or bracketed paste off
    expect_exact(shell, PROMPT)
    shell.sendline("quit")
    shell.expect(pexpect.EOF)
    shell.wait()
    assert shell.exitstatus == 0
    history = Path(term_env["XDG_DATA_HOME"]) / "ramp" / "shell_history"
    text = history.read_text()
    assert "+base:base.get=()" in text and "+base:lf_wheel.vel=(300)" in text


def test_watch_redraws_until_ctrl_c_then_help_lists_modules(shell: pexpect.spawn) -> None:
    shell.sendline("watch base:base.get=() 5")
    expect(shell, r"every 0\.2 s  #1")
    expect(shell, r"battery\s+volt\s+\d+\.\d+ V")
    expect(shell, r"every 0\.2 s  #2")
    expect(shell, r"every 0\.2 s  #3")
    shell.sendintr()
    expect_exact(shell, PROMPT)
    shell.sendline("help")
    expect(shell, heading("robot"))
    expect(shell, heading("base") + r"  base:base.get=\(\)")
    expect_exact(shell, "base:lf_wheel.vel=(int -100..100)")
    expect(shell, heading("ble"))
    expect_exact(shell, "shell commands")
    expect_exact(shell, "never keeps motors running by itself")
    expect_exact(shell, PROMPT)
    shell.sendcontrol("d")
    shell.expect(pexpect.EOF)


def test_connection_loss_is_reported_and_enter_reconnects(term_env: dict[str, str]) -> None:
    port = free_port()
    srv = Server(port)
    child = pexpect.spawn(SHELL[0], [*SHELL[1:], srv.address], env=term_env, cwd=str(REPO),
                          dimensions=(40, 120), encoding="utf-8", timeout=10)
    try:
        expect_exact(child, PROMPT)
        srv.close()
        child.sendline("base:base.get=()")
        expect_exact(child, f"connection to {srv.address} lost")
        expect_exact(child, "Press Enter to reconnect")
        child.sendline("")
        expect_exact(child, f"cannot connect to {srv.address}")
        srv = Server(port)
        child.sendline("")
        expect_exact(child, f"reconnected to {srv.address}")
        child.sendline("base:base.get=()")
        expect(child, r"battery\s+volt\s+\d+\.\d+ V")
        child.sendline("exit")
        child.expect(pexpect.EOF)
        child.wait()
        assert child.exitstatus == 0
    finally:
        if child.isalive():
            child.terminate(force=True)
        child.close()
        srv.close()


# --------------------------------------------------------------------------- -c mode


def test_c_get_prints_a_table_and_exits_0_without_colour(server: str) -> None:
    proc = run_c(server, "-c", "base:base.get=()ble:ble.get=()")
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"base\s+battery\s+volt\s+\d+\.\d+ V\n", proc.stdout)
    assert re.search(r"ble\s+load\s+kg\s+-?\d+\.\d+ kg\n", proc.stdout)
    assert "\x1b" not in proc.stdout


def test_c_error_response_exits_1_and_raw_prints_the_line(server: str) -> None:
    proc = run_c(server, "-c", "base:lf_wheel.vel=(300)")
    assert proc.returncode == 1
    assert proc.stdout.startswith("error  base:lf_wheel  bad_params: vel takes")
    raw = run_c(server, "--raw", "-c", "base:lf_wheel.vel=(300)")
    assert raw.returncode == 1
    assert raw.stdout.startswith("base:lf_wheel.error=(bad_params,vel takes")


def test_c_a_request_refused_by_an_interlock_says_which_are_active(server: str) -> None:
    """MARTE's shipped chain_needs_ladder_down: the bin raised (the pot says 0.8)."""
    assert run_c(server, "-c", "sim:input.set=(ble,lift_pot,0.8)").returncode == 0
    try:
        proc = run_c(server, "-c", "ble:chain.vel=(30)")
        assert proc.returncode == 1
        assert "interlocked: chain_needs_ladder_down is active" in proc.stdout
        assert "active interlocks: chain_needs_ladder_down, bin_up_slow (" in proc.stdout
        # --raw: stdout is the robot's answer line and nothing else (issue 35); the
        # explanation goes to stderr.
        raw = run_c(server, "--raw", "-c", "ble:chain.vel=(30)")
        assert raw.returncode == 1
        assert raw.stdout.splitlines() == [
            "ble:chain.error=(interlocked,chain_needs_ladder_down is active)"], raw.stdout
        assert "active interlocks: chain_needs_ladder_down" in raw.stderr
    finally:
        assert run_c(server, "-c", "sim:input.clear=(ble,lift_pot)").returncode == 0


def test_c_closed_port_exits_2() -> None:
    port = free_port()
    proc = run_c(f"127.0.0.1:{port}", "-c", "base:base.get=()")
    assert proc.returncode == 2
    assert f"cannot connect to 127.0.0.1:{port}" in proc.stderr


@pytest.mark.parametrize("timeout", ["1e308", "nan", "0"])
def test_c_a_timeout_out_of_range_is_a_usage_error(timeout: str) -> None:
    proc = run_c("127.0.0.1:1", "--timeout", timeout, "-c", "base:base.get=()")
    assert proc.returncode == 2  # 1e308 ended in an OverflowError traceback
    assert "--timeout must be a positive number of seconds up to 3600" in proc.stderr
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize("hz", ["1e-10", "0.001"])
def test_c_watch_slower_than_one_poll_in_100_s_is_a_usage_error(server: str, hz: str) -> None:
    """`watch … 1e-10` waited 1e10 s: an OverflowError traceback from select."""
    proc = run_c(server, "-c", f"watch robot:robot.get=() {hz}")
    assert proc.returncode == 1
    assert f"HZ must be in 0.01 <= HZ <= 50, not {hz}" in proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr


def test_c_connection_closed_by_peer_exits_2() -> None:
    listener = socket.create_server(("127.0.0.1", 0))
    port = listener.getsockname()[1]

    def accept_and_close() -> None:
        conn, _ = listener.accept()
        conn.recv(1024)
        conn.close()

    t = threading.Thread(target=accept_and_close, daemon=True)
    t.start()
    try:
        proc = run_c(f"127.0.0.1:{port}", "-c", "base:base.get=()")
    finally:
        t.join(timeout=5)
        listener.close()
    assert proc.returncode == 2
    assert "closed the connection" in proc.stderr


def test_c_hold_keeps_motion_past_the_watchdog_then_stops(server: str) -> None:
    """The watchdog times out after 1 s; hold feeds it for 3 s, then sends base.stop."""
    proc = subprocess.Popen([*SHELL, server, "-c", "hold base:base.drive=(30,0) 3"],
                            cwd=REPO, text=True, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        r, _, _ = select.select([proc.stdout], [], [], 10)
        assert r and proc.stdout.readline().startswith("holding base:base.drive=(30,0)")
        time.sleep(1.5)  # past the 1 s watchdog timeout: only heartbeats keep it moving
        during = ask(server, "base:base.get=()robot:robot.get=()")
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert "base:lf_wheel.vel=(30)" in during
    assert "robot:watchdog.state=(armed)" in during
    assert proc.returncode == 0, err
    assert "stopped: base:base.stop=()" in out
    after = ask(server, "base:base.get=()robot:robot.get=()")
    assert "base:lf_wheel.vel=(0)" in after
    assert "robot:watchdog.state=(idle)" in after


@pytest.mark.timeout(60)
def test_c_hold_exits_1_when_the_watchdog_trips_during_the_hold() -> None:
    """The supervisor is frozen for 0.6 s in the middle of a hold: when it runs again it
    stops every module and the watchdog reads `tripped`. The hold used to go on and exit 0."""
    srv = Server()
    try:
        proc = subprocess.Popen([*SHELL, srv.address, "-c", "hold base:base.drive=(30,0) 20"],
                                cwd=REPO, text=True, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE)
        try:
            assert proc.stdout is not None
            r, _, _ = select.select([proc.stdout], [], [], 10)
            assert r and proc.stdout.readline().startswith("holding base:base.drive=(30,0)")
            time.sleep(0.3)
            srv.proc.send_signal(signal.SIGSTOP)
            time.sleep(0.6)
            srv.proc.send_signal(signal.SIGCONT)
            out, err = proc.communicate(timeout=10)  # long before the 20 s are up
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.communicate()
        assert proc.returncode == 1, (out, err)
        assert "the watchdog tripped during the hold" in out
        assert "stopped: base:base.stop=()" in out
        assert "base:lf_wheel.vel=(0)" in ask(srv.address, "base:base.get=()")
    finally:
        srv.proc.send_signal(signal.SIGCONT)
        srv.close()
