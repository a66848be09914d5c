"""SIGHUP reloads `access:` (SPEC 13) without a restart, inside the loop.

The signal handler only writes a byte to a pipe the scheduler watches; the reload itself runs
as that reader's callback, between ticks, like any other I/O: no state changes under a tick's
feet. The file is checked whole first: a file with an error changes nothing (and says why).
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
from types import FrameType

from ramp.config import check_config
from ramp.config.access import server_context
from ramp.errors import PluginError
from ramp.runtime.supervisor import Supervisor

log = logging.getLogger("ramp.access")


class AccessReloader:
    """Owns the self-pipe; `install()` makes SIGHUP reload the access section of `path`."""

    def __init__(self, sup: Supervisor, path: str) -> None:
        self.sup = sup
        self.path = path
        self._r, self._w = os.pipe()
        os.set_blocking(self._r, False)
        os.set_blocking(self._w, False)
        sup.scheduler.add_reader(self._r, self._drain)

    def install(self) -> None:
        signal.signal(signal.SIGHUP, self._on_signal)

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        with contextlib.suppress(BlockingIOError):  # one pending reload is as good as many
            os.write(self._w, b"h")

    def _drain(self) -> None:
        try:
            while os.read(self._r, 64):
                pass
        except BlockingIOError:
            pass
        self.reload()

    def reload(self) -> None:
        config, errors = check_config(self.path)
        # A plugin that cannot load (PluginError) is already in fault: access still reloads.
        if config is None or any(not isinstance(e, PluginError) for e in errors):
            log.error("SIGHUP: %s has %d error(s); access unchanged: %s", self.path,
                      len(errors), "; ".join(str(e) for e in errors[:3]))
            return
        tls = server_context(config.server.tls) if config.server.tls is not None else None
        if (tls is None) != (self.sup.server.tls is None):
            log.error("SIGHUP: server.tls was %s; turning TLS on or off needs a restart "
                      "(access unchanged)", "removed" if tls is None else "added")
            return
        dropped = self.sup.server.reload_access(config.access, tls)
        log.info("SIGHUP: access reloaded from %s (%d identities, %d revoked)%s", self.path,
                 len(config.access.identities), len(config.access.revoked),
                 f"; dropped {', '.join(dropped)}" if dropped else "")

    def close(self) -> None:
        self.sup.scheduler.remove_reader(self._r)
        os.close(self._r)
        os.close(self._w)
