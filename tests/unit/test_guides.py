"""The extending guides show the example package as it is: every code block titled with a
file of examples/ramp-winch/ is that file, byte for byte (the package itself is installed and
run by tests/hil_sim/test_plugin_examples.py), so a newcomer copying the guide gets code that
works."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "ramp-winch"
GUIDES = ("writing-a-module.md", "writing-a-driver.md")
BLOCK = re.compile(r'^```\w+ title="([^"]+)"\n(.*?)^```$', re.M | re.S)


@pytest.mark.parametrize("guide", GUIDES)
def test_every_file_a_guide_shows_is_the_example_s_file(guide: str) -> None:
    text = (REPO / "docs" / "extending" / guide).read_text()
    blocks = BLOCK.findall(text)
    assert len(blocks) >= 3
    for path, body in blocks:
        assert body == (EXAMPLE / path).read_text(), f"{guide}: {path} differs"


def test_the_guides_together_show_every_file_of_the_example() -> None:
    shown = {path for guide in GUIDES
             for path, _ in BLOCK.findall((REPO / "docs" / "extending" / guide).read_text())}
    files = {str(p.relative_to(EXAMPLE)) for p in EXAMPLE.rglob("*")
             if p.is_file() and p.suffix in (".py", ".toml", ".yaml")
             and p.name != "__init__.py" and "egg-info" not in str(p)}
    assert files == shown
