"""Every command block of ours in the README and the docs that is not marked illustrative
runs, from the repository's root with this venv's commands, and succeeds; a `ramp-shell`
without an address talks to a `ramp run --sim` this test starts. Where a page shows what a
block prints (`<!-- output -->`), it must print exactly that."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.docs_pages import OUTPUT, REPO, Block, blocks, pages, runnable
from tests.harness import start_ramp

BIN = Path(sys.executable).parent

RUN = [b for page in pages() for b in blocks(page) if b.ours() and not b.illustrative]


def _output_after(block: Block) -> Block | None:
    """The `<!-- output -->` block that follows `block` on its page, if any."""
    found = blocks(block.path)
    at = found.index(block)
    if at + 1 < len(found) and found[at + 1].before.strip() == OUTPUT:
        return found[at + 1]
    return None


@pytest.fixture(scope="module")
def robot() -> Iterator[str]:
    """A simulated MARTE on a free port, for the blocks that use ramp-shell."""
    proc, host, port = start_ramp(["--sim", "--config", "ramp.yaml", "--host", "127.0.0.1",
                                   "--port", "0", "--log-level", "warning"],
                                  stderr=subprocess.DEVNULL)
    try:
        yield f"{host}:{port}"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.communicate(timeout=10)


def script(block: Block, address: str | None) -> str:
    """The block as a bash script: `.venv/bin/` is this venv's, and a `ramp-shell` given no
    address is given the test's robot."""
    lines = []
    for command in block.commands():
        command = command.replace(".venv/bin/", f"{BIN}/")
        if address is not None:
            command = re.sub(r"\bramp-shell(?=\s+-)", f"ramp-shell {address}", command)
        lines.append(command)
    return "\n".join(lines)


@pytest.mark.parametrize("block", RUN, ids=lambda b: b.where)
def test_the_block_runs(block: Block, request: pytest.FixtureRequest) -> None:
    # A block that would install, serve for ever or run for minutes is not run at all.
    why = runnable(block)
    assert why is None, f"{block.where}: {why}; mark it <!-- illustrative: REASON -->"
    address = request.getfixturevalue("robot") if "ramp-shell" in "\n".join(block.lines) \
        else None
    done = subprocess.run(
        ["bash", "-e", "-o", "pipefail", "-c", script(block, address)], cwd=REPO,
        capture_output=True, text=True, timeout=60,
        env={**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}",
             "NO_COLOR": "1"})
    assert done.returncode == 0, (
        f"{block.where} exited {done.returncode}\n--- stdout\n{done.stdout[-2000:]}"
        f"\n--- stderr\n{done.stderr[-2000:]}")
    shown = _output_after(block)
    if shown is not None:
        assert done.stdout.rstrip("\n").split("\n") == list(shown.lines), \
            f"{shown.where} is not what {block.where} prints now"


def test_the_run_blocks_include_the_shell_against_the_robot() -> None:
    # The address rewriting is used (the README's and ramp-shell's page's -c examples), and
    # it leaves an explicit address alone.
    assert any("ramp-shell" in "\n".join(b.lines) for b in RUN)
    probe = Block(REPO / "README.md", 1, "sh",
                  ("ramp-shell -c 'x'", "ramp-shell 10.0.0.1:5577 -c 'x'"), "")
    assert script(probe, "127.0.0.1:1").split("\n") == [
        "ramp-shell 127.0.0.1:1 -c 'x'", "ramp-shell 10.0.0.1:5577 -c 'x'"]


def test_the_api_pages_example_talks_to_a_robot(robot: str) -> None:
    # The Python example of the API reference, pointed at the test's robot.
    page = REPO / "docs" / "extending" / "api.md"
    example = next(b for b in blocks(page) if b.lang == "python")
    host, port = robot.split(":")
    code = "\n".join(example.lines).replace('"127.0.0.1", 5577', f'"{host}", {port}')
    assert code != "\n".join(example.lines), "the example no longer names 127.0.0.1:5577"
    done = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                          text=True, timeout=30)
    assert done.returncode == 0, done.stderr
    assert "base lf_wheel vel" in done.stdout
    assert "('bad_params', 'vel takes one int in -100..100')" in done.stdout
