"""The recorder's configuration: `ramp.yaml`'s `recorder: {dir, max_mb, keep}` block.

The fields are declared once, in the style of `ramp.config.SERVER_FIELDS`, so the config
loader can check the block with its usual file:line: key.path errors; `RecorderConfig` checks
itself too, so a recorder built directly (tests, `ramp run --record DIR`) cannot take a bad
value either.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ramp.errors import ConfigError
from ramp.schema import Field, FieldError, apply_fields

#: The keys of the `recorder:` block. The block is optional: without it nothing is recorded.
RECORDER_FIELDS = {
    "dir": Field(str, what="a directory for the MCAP files"),
    "max_mb": Field(float, 100.0, lo=0.01, hi=1e6,
                    what="a file size in MB (10^6 bytes) at which a new file is started"),
    "keep": Field(int, 20, lo=1, hi=100_000,
                  what="how many files to keep (the oldest beyond it are deleted)"),
}


@dataclass(frozen=True)
class RecorderConfig:
    """Where and how much to record. 100 MB x 20 files bounds the recorder at 2 GB."""

    dir: str
    max_mb: float = 100.0
    keep: int = 20

    def __post_init__(self) -> None:
        values = {"dir": self.dir, "max_mb": self.max_mb, "keep": self.keep}
        try:
            checked = apply_fields(RECORDER_FIELDS, values)
        except FieldError as exc:
            raise ConfigError(exc.message, key=f"recorder.{exc.key}") from None
        if not checked["dir"].strip():
            raise ConfigError("'' is not a directory for the MCAP files", key="recorder.dir")
        if "\x00" in checked["dir"]:  # no file system takes it: the writer could never open
            raise ConfigError(f"{checked['dir']!r} holds a NUL byte; expected a directory path",
                              key="recorder.dir")
        for key, value in checked.items():  # as checked: 5 -> 5.0 for max_mb, and so on
            object.__setattr__(self, key, value)

    @property
    def max_bytes(self) -> int:
        return int(self.max_mb * 1_000_000)

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> RecorderConfig:
        """Build from a YAML block; raises ConfigError naming `recorder.KEY`."""
        try:
            checked = apply_fields(RECORDER_FIELDS, dict(values))
        except FieldError as exc:
            raise ConfigError(exc.message, key=f"recorder.{exc.key}") from None
        return cls(**checked)
