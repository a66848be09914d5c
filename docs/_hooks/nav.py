"""The site's one build hook: the nav as the pages on disk make it.

Several people write pages at once, each on a branch of their own. Listing a page in the
nav before it exists would fail the strict build, and a placeholder in its place would
collide with the real page at merge. So pages still to come are named in mkdocs.yml under
`extra.pending_pages`: while one is missing it is left out of the nav and the build log
says so (at INFO, so --strict still passes). A missing page that is not pending still
fails the build, as mkdocs has it. And every `developing/fixed-*.md` (one "Found and fixed"
page per branch) is listed under Developing without anyone editing the nav.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

log = logging.getLogger("mkdocs.hooks.nav")

FIXED_SECTION = "Found and fixed"


def _prune(items: list[Any], missing: set[str]) -> list[Any]:
    """The nav without the entries whose file is in `missing` (empty sections dropped)."""
    kept: list[Any] = []
    for item in items:
        if isinstance(item, str):
            if item not in missing:
                kept.append(item)
            continue
        if not isinstance(item, dict):
            kept.append(item)
            continue
        entry: dict[str, Any] = {}
        for title, target in item.items():
            if isinstance(target, list):
                children = _prune(target, missing)
                if children:
                    entry[title] = children
            elif target not in missing:
                entry[title] = target
        if entry:
            kept.append(entry)
    return kept


def _title(page: Path) -> str:
    """A fixed page's nav title: its first heading, else its file name."""
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return page.stem


def on_config(config: Any) -> Any:
    docs = Path(config["docs_dir"])
    pending = list(config["extra"].get("pending_pages", []))
    missing = {p for p in pending if not (docs / p).is_file()}
    for page in sorted(missing):
        log.info("nav: %s is not written yet; left out of the nav", page)
    nav = _prune(config["nav"], missing)
    fixed = sorted((docs / "developing").glob("fixed-*.md"))
    if fixed:
        entries = [{_title(p): p.relative_to(docs).as_posix()} for p in fixed]
        for section in nav:
            if isinstance(section, dict) and "Developing" in section:
                section["Developing"].append({FIXED_SECTION: entries})
                break
    config["nav"] = nav
    return config
