"""The sources name no path of the machine they were written on."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_no_source_file_names_a_machine_path() -> None:
    """`firmware_like/marte_params.py` cited `/work/shared/...`; a clone elsewhere has
    `../shared/...` at most."""
    found = []
    for folder in ("ramp", "firmware_like", "bench", "scripts"):
        for path in sorted((REPO / folder).rglob("*.py")):
            for number, line in enumerate(path.read_text().splitlines(), 1):
                if re.search(r"(?<![\w.])/(work|home|root)/", line):
                    found.append(f"{path.relative_to(REPO)}:{number}: {line.strip()}")
    assert found == []
