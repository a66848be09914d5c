"""The README and the documentation site: the README stays a front door, every link and
picture resolves, every block has a language, every command block of ours is run or marked
illustrative, the nav hook keeps the site building while pages land, and the site builds
with --strict. The run blocks themselves run in tests/hil_sim/test_docs_commands.py."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import Any
from urllib.parse import unquote

import pytest

from tests.docs_pages import (
    DOCS,
    ILLUSTRATIVE,
    OURS,
    OUTPUT,
    REPO,
    Block,
    anchors,
    blocks,
    links,
    name,
    pages,
    runnable,
    slug,
)

README = REPO / "README.md"
PAGES = pages()


# -- the README as a newcomer reads it ---------------------------------------------------------
def test_the_readme_is_a_front_door_of_at_most_250_lines() -> None:
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines; move material to docs/"


def test_the_two_set_up_commands_are_in_the_readmes_first_30_lines() -> None:
    head = "\n".join(README.read_text(encoding="utf-8").splitlines()[:30])
    for command in ("make run", "make test"):
        assert re.search(rf"^{command}\b", head, re.M), f"`{command}` not in the first 30 lines"


def test_the_readme_says_where_the_docs_are_and_has_the_tour() -> None:
    text = README.read_text(encoding="utf-8")
    for needed in ("make docs", "make teleop", "make mission", "ramp-shell", "docs/index.md"):
        assert needed in text, needed


# -- links, anchors and pictures ---------------------------------------------------------------
def _external(target: str) -> bool:
    return re.match(r"^[a-z][a-z0-9+.-]*:", target) is not None


@pytest.mark.parametrize("page", PAGES, ids=name)
def test_every_relative_link_and_picture_resolves(page: Path) -> None:
    broken = []
    for target in links(page):
        if _external(target):
            continue
        path_part, _, anchor = target.partition("#")
        dest = (page.parent / unquote(path_part)).resolve() if path_part else page
        if not dest.exists():
            broken.append(f"{target}: no such file")
            continue
        if REPO not in dest.parents and dest != REPO:
            broken.append(f"{target}: outside the repository")
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            broken.append(f"{target}: no heading with that anchor in {name(dest)}")
        if page.is_relative_to(DOCS) and not dest.is_relative_to(DOCS):
            broken.append(f"{target}: a page of the site links outside docs/ (the site "
                          "would not have it; name the file in code instead)")
    assert not broken, f"{name(page)}: " + "; ".join(broken)


def test_links_are_found_where_they_are_and_not_in_code(tmp_path: Path) -> None:
    # The link reader itself: a link in prose is seen, one in inline code or a block is not.
    page = tmp_path / "probe.md"
    page.write_text("See [a](x.md#b) and ![p](img/p.png).\n`[c](no.md)`\n\n"
                    "```text\n[d](no.md)\n```\n", encoding="utf-8")
    assert links(page) == ["x.md#b", "img/p.png"]


def test_anchors_are_made_as_the_site_makes_them() -> None:
    assert slug("Frozen, flooded or full: what you see (SPEC 2.2)") == \
        "frozen-flooded-or-full-what-you-see-spec-22"
    assert slug("Configuration: `ramp.yaml`") == "configuration-rampyaml"
    assert slug("Observer points (for the flight recorder)") == \
        "observer-points-for-the-flight-recorder"


# -- fenced blocks -----------------------------------------------------------------------------
@pytest.mark.parametrize("page", PAGES, ids=name)
def test_a_block_holding_one_of_our_commands_names_its_language(page: Path) -> None:
    # Without a language a block of commands would be neither run nor checked for a marker:
    # say `sh` (run it or mark it) or `text` (a transcript, as a ramp-shell session).
    bare = [b.where for b in blocks(page)
            if not b.lang and any(OURS.match(line.strip().removeprefix("$ "))
                                  for line in b.lines)]
    assert not bare, f"blocks of commands without a language (sh, or text): {bare}"


@pytest.mark.parametrize("page", PAGES, ids=name)
def test_every_marker_stands_just_before_a_block(page: Path) -> None:
    found = blocks(page)
    marked = {b.line - 1 for b in found if b.before.strip()}
    inside = {b.line + k for b in found for k in range(1, len(b.lines) + 1)}
    lines = page.read_text(encoding="utf-8").split("\n")
    stray = []
    for n, line in enumerate(lines, start=1):
        if n in inside:
            continue
        text = line.strip()
        if text.startswith("<!-- illustrative") or text == OUTPUT:
            if ILLUSTRATIVE.fullmatch(text) is None and text != OUTPUT:
                stray.append(f"{n}: an illustrative marker needs a reason")
            elif n not in marked:
                stray.append(f"{n}: not on the line just before a fence")
    assert not stray, f"{name(page)}: " + "; ".join(stray)


def test_command_blocks_of_ours_are_either_run_or_marked() -> None:
    # What the command test will run: every unmarked shell block running one of our
    # commands. There must be some (the README's and the pages' cheap ones), and each must be
    # fit to run: only our commands, none that serves or runs for minutes.
    run = [b for page in PAGES for b in blocks(page) if b.ours() and not b.illustrative]
    assert len(run) >= 5, [b.where for b in run]
    bad = [f"{b.where}: {why}" for b in run if (why := runnable(b)) is not None]
    assert not bad, "mark these blocks illustrative (or run only our own, quick commands): " \
        + "; ".join(bad)


def test_what_counts_as_a_command_of_ours() -> None:
    ours = ["ramp check ramp.yaml", ".venv/bin/ramp-shell -c 'x'", "make docs",
            "python -m bench --quick", ".venv/bin/python -m firmware_like.hokuyo",
            "RAMP_FUZZ_EXAMPLES=2000 .venv/bin/python -m pytest tests/fuzz -q",
            "sudo scripts/install-service.sh", "ramp-autonomy check autonomy.yaml"]
    theirs = ["journalctl -u ramp -f", "ramp> hold base:base.drive=(40,0) 3",
              "pip install '.[teleop]'", "ssh -N -L 8765:127.0.0.1:8765 marte@robot",
              "systemctl status ramp", "python -m http.server"]
    assert [c for c in ours if not OURS.match(c)] == []
    assert [c for c in theirs if OURS.match(c)] == []


def test_a_block_is_fit_to_run_only_with_our_own_commands_that_end() -> None:
    def block(*lines: str) -> Block:
        return Block(README, 1, "sh", lines, "")
    assert runnable(block("ramp check ramp.yaml", "ramp-shell -c 'x' || echo refused")) is None
    assert "not a command of ours" in str(runnable(block("pip install '.[teleop]'")))
    assert "does not end" in str(runnable(block("ramp-teleop --backend 10.0.0.1:5577")))
    assert "does not end" in str(runnable(block("make run")))
    # the venv's own path to a server is a server too (one ran on for ever after its test)
    assert "does not end" in str(runnable(block(".venv/bin/ramp run --sim --config x.yaml")))
    assert "does not end" in str(runnable(block(".venv/bin/ramp-teleop --backend h:1")))


def test_a_console_block_runs_only_its_prompt_lines() -> None:
    block = Block(README, 1, "console", ("$ ramp check ramp.yaml", "ramp: ok"), "")
    assert block.commands() == ["ramp check ramp.yaml"]
    assert Block(README, 1, "text", ("ramp check ramp.yaml",), "").commands() == []


@pytest.mark.parametrize("page", PAGES, ids=name)
def test_an_output_block_follows_a_block_that_is_run(page: Path) -> None:
    found = blocks(page)
    for before, block in zip([None, *found], found, strict=False):
        if block.before.strip() != OUTPUT:
            continue
        assert block.lang == "text", f"{block.where}: an output block is `text`"
        assert before is not None and before.ours() and not before.illustrative, \
            f"{block.where}: no run block of ours before this output"


# -- the site ----------------------------------------------------------------------------------
def _hook() -> Any:
    spec = importlib.util.spec_from_file_location("docs_nav_hook", DOCS / "_hooks" / "nav.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_nav_hook_leaves_out_pending_pages_until_they_exist(tmp_path: Path) -> None:
    (tmp_path / "operating").mkdir()
    (tmp_path / "developing").mkdir()
    for page in ("index.md", "operating/mcp.md", "operating/safety.md"):
        (tmp_path / page).write_text("# x\n")
    (tmp_path / "developing" / "fixed-b.md").write_text("# Found and fixed: b\n")
    (tmp_path / "developing" / "fixed-a.md").write_text("no heading\n")
    config = {
        "docs_dir": str(tmp_path),
        "extra": {"pending_pages": ["operating/safety.md", "operating/interlocks.md",
                                    "extending/scout.md"]},
        "nav": [{"Home": "index.md"},
                {"Operating": [{"MCP": "operating/mcp.md"},
                               {"Safety": "operating/safety.md"},
                               {"Interlocks": "operating/interlocks.md"},
                               {"Typo": "operating/typo.md"}]},
                {"Extending": [{"Scout": "extending/scout.md"}]},
                {"Developing": [{"Testing": "developing/testing.md"}]}],
    }
    nav = _hook().on_config(config)["nav"]
    assert nav == [
        {"Home": "index.md"},
        # A pending page that exists stays; one that does not is left out; a missing page
        # that is not pending stays, so the strict build still fails on it.
        {"Operating": [{"MCP": "operating/mcp.md"}, {"Safety": "operating/safety.md"},
                       {"Typo": "operating/typo.md"}]},
        # A section left empty goes.
        {"Developing": [{"Testing": "developing/testing.md"},
                        {"Found and fixed": [{"fixed-a": "developing/fixed-a.md"},
                                             {"Found and fixed: b": "developing/fixed-b.md"}]}]},
    ]


def test_the_site_builds_strictly(tmp_path: Path) -> None:
    if importlib.util.find_spec("mkdocs") is None:
        if os.environ.get("CI"):
            pytest.fail("mkdocs is missing: the `docs` extra is part of `dev`")
        pytest.skip("mkdocs is not installed (pip install -e '.[docs]')")
    site = tmp_path / "site"
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=REPO, capture_output=True, text=True, timeout=180,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert done.returncode == 0, done.stderr[-4000:]
    # Every page of docs/ is a page of the site, and the README's pictures are there.
    for page in PAGES[1:]:
        rel = page.relative_to(DOCS)
        html = site / (rel.parent if rel.name == "index.md" else rel.with_suffix("")) \
            / "index.html"
        assert html.is_file(), f"{name(page)} was not built"
    api = (site / "extending" / "api" / "index.html").read_text(encoding="utf-8")
    assert "McpClient" in api and "parse_response_line" in api, "the API reference is empty"
    # Offline: the diagrams' script is served with the site (with its licence), so the
    # theme never fetches it from a CDN (issue 35); no page loads a script from the network.
    vendored = site / "assets" / "vendor" / "mermaid"
    assert (vendored / "mermaid.min.js").stat().st_size > 1_000_000
    assert "MIT License" in (vendored / "LICENSE").read_text(encoding="utf-8")
    machine = (site / "autonomy" / "state-machine" / "index.html").read_text(encoding="utf-8")
    assert 'class="mermaid"' in machine
    assert re.search(r'<script src="[./]*assets/vendor/mermaid/mermaid\.min\.js"', machine)
    for html in site.rglob("*.html"):
        text = html.read_text(encoding="utf-8")
        assert not re.search(r'<script[^>]+src="(?:https?:)?//', text), html


def test_the_api_page_documents_a_module_once_it_is_in_the_tree(tmp_path: Path) -> None:
    hook = _hook()
    page = "Intro\n\n<!-- api: ramp.api -->\n\n<!-- api: ramp.mcp -->\n"
    (tmp_path / "ramp" / "mcp").mkdir(parents=True)
    (tmp_path / "ramp" / "mcp" / "__init__.py").write_text("")
    before = hook.api_markdown(page, tmp_path)
    assert "::: ramp.api" not in before and "`ramp.api` is not in this version" in before
    assert "::: ramp.mcp\n" in before
    (tmp_path / "ramp" / "api.py").write_text('"""The plugin API."""\n')
    assert "::: ramp.api\n" in hook.api_markdown(page, tmp_path)
    # The real page carries the marker, so the reference appears when ramp/api.py lands.
    assert "<!-- api: ramp.api -->" in (DOCS / "extending" / "api.md").read_text()


def test_code_points_at_the_docs_page_holding_a_text_not_at_the_readme() -> None:
    """Issue 35: comments said "see the README" for text that had moved to docs/ pages."""
    stale = [f"{path.relative_to(REPO)}:{n}" for top in ("ramp", "firmware_like", "bench")
             for path in sorted((REPO / top).rglob("*.py"))
             for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if "README" in line]
    assert stale == [], stale
    for page in ("docs/autonomy/state-machine.md", "docs/operating/mcp.md",
                 "docs/operating/configuration.md"):
        assert (REPO / page).is_file(), page


def test_the_readme_s_simulated_robots_listen_on_loopback_only() -> None:
    """Issue 35: the README's Scout command served on every interface (scout.yaml's server
    host is the real rover's 0.0.0.0): a simulated robot a reader starts is theirs alone."""
    runs = [line for line in (REPO / "README.md").read_text(encoding="utf-8").splitlines()
            if re.match(r"\s*(\.venv/bin/)?ramp run ", line)]
    assert runs, "the README shows no ramp run command"
    for line in runs:
        assert "--host 127.0.0.1" in line, line
