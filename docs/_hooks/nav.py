"""The site's one build hook: the nav as the pages on disk make it, and the API reference as
the modules in the tree make it.

Several people write pages at once, each on a branch of their own. Listing a page in the
nav before it exists would fail the strict build, and a placeholder in its place would
collide with the real page at merge. So pages still to come are named in mkdocs.yml under
`extra.pending_pages`: while one is missing it is left out of the nav and the build log
says so (at INFO, so --strict still passes). A missing page that is not pending still
fails the build, as mkdocs has it. And every `developing/fixed-*.md` (one "Found and fixed"
page per branch) is listed under Developing without anyone editing the nav.

The API page names modules that may not be in the tree yet (`ramp.api`, which the plugin
work adds) with a marker, `<!-- api: ramp.api -->`: the hook puts mkdocstrings' `::: ramp.api`
in its place once `ramp/api.py` (or `ramp/api/`) exists, and a line saying it is still to
come until then.
"""

from __future__ import annotations

import logging
import re
from pathlib import Path
from typing import Any

log = logging.getLogger("mkdocs.hooks.nav")

FIXED_SECTION = "Found and fixed"
API_MARKER = re.compile(r"^<!-- api: ([\w.]+) -->$", re.M)


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


def _module_in_tree(root: Path, dotted: str) -> bool:
    path = root.joinpath(*dotted.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def api_markdown(markdown: str, root: Path) -> str:
    """The page with each API marker replaced by its module's reference, or a note."""
    def replace(match: re.Match[str]) -> str:
        dotted = match.group(1)
        if _module_in_tree(root, dotted):
            return f"::: {dotted}"
        log.info("api: %s is not in the tree yet; its reference is left out", dotted)
        return f"*`{dotted}` is not in this version of RAMP yet.*"
    return API_MARKER.sub(replace, markdown)


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    root = Path(config["config_file_path"]).parent
    return api_markdown(markdown, root)
