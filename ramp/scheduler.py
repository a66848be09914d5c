"""The one loop: a fixed-rate tick scheduler that services sockets and ports between ticks.

Why this shape (see shared/reference/platform-limits.md): an absolute-deadline loop waiting in
`select.select` (microsecond timeout) matches C `clock_nanosleep`, while epoll, poll and
asyncio round their timeouts up to whole milliseconds (about 0.6 ms late every tick). But
select cannot watch a descriptor numbered 1024 or more, and a server with many clients has
some. So while every descriptor is below 1024 (the usual case) the wait is one `select` with
a microsecond timeout, one wake-up per tick as in the bare loop; with a descriptor past it,
the wait is `poll` (no such limit) for the whole milliseconds, rounded down, then a
microsecond `select` for the rest on the descriptors below 1024 (the others are looked at
again right after). Input is dispatched the
moment it arrives during the wait, so a request is answered on arrival, not at the next tick.
Missed ticks are skipped, never replayed in a burst, and every overrun names the task that ate
the budget.

With a virtual clock the wait polls I/O once without blocking and jumps the clock to the next
deadline, so simulated minutes pass in seconds and runs repeat exactly.

Idle ticks: while nothing moves or is about to (the owner's `idle` predicate: the watchdog not
armed, every bus at rest), the next tick comes `idle_stride` base periods later instead of one,
the way a tickless kernel idles: fewer wake-ups of a robot that only waits, the same rate the
moment it moves. Tasks keep their grid (a 10 Hz task still runs every tenth base slot), see the
real time since their last run as `dt`, and I/O is served the moment it arrives as always; a
request that arms the watchdog calls `hurry()`, which brings the tick back to the next base slot.
The stride never reaches the stall limit (at most half of it).

Stalls (SPEC 2.2, *Stalls and freezes*): before every unit of work (a task, an I/O callback,
the wait) the loop compares the clock with the start of the last tick. More than
`stall_limit` since then means the loop did not run (a stuck task, a blocked call, the process
stopped by the kernel or a debugger, a clock jump): `on_stall` runs first, before anything
else can reach a wire, and the HAL asks `on_time()` before motion output, so a write computed
before the gap is dropped even when the gap fell in the middle of a task.
"""

from __future__ import annotations

import bisect
import contextlib
import logging
import math
import select
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

from ramp.clock import Clock, VirtualClock

log = logging.getLogger("ramp.scheduler")

#: select() cannot watch a descriptor from this number up (FD_SETSIZE).
SELECT_FD_LIMIT = 1024
_IN = select.POLLIN | select.POLLPRI
_OUT = select.POLLOUT
_GONE = select.POLLHUP | select.POLLERR  # the callback reads or writes, and learns why

TaskFn = Callable[[float, float], None]
IoCallback = Callable[[], None]
#: Called with (gap in s, the unit of work during which the time went) when the loop stalled.
StallHandler = Callable[[float, str], None]
#: Called with (now, how late the tick started, s) as each tick starts.
TickHook = Callable[[float, float], None]
#: The unit of work a gap is blamed on when it fell between ticks.
WAIT = "the wait between ticks"


@dataclass
class ScheduledTask:
    """A periodic task: runs every `divisor` base ticks with `(now, dt)`."""

    name: str
    divisor: int
    fn: TaskFn
    next_index: int = 0  # the first base tick (on the grid) at which it runs again
    last_run: float | None = None
    runs: int = 0
    errors: int = 0
    total_s: float = 0.0
    max_s: float = 0.0
    enabled: bool = True


@dataclass
class TickStats:
    """Lateness and overrun accounting, exposed through `robot.get`.

    The window is also kept sorted, one insertion and one removal per tick (a memmove of a
    few thousand floats, microseconds), so reading the percentiles costs the same at any age:
    sorting the whole window on every `robot.get` once took 1-2 ms after a minute of uptime.
    """

    window: int = 6000
    late_us: deque[float] = field(default_factory=deque)
    max_late_us: float = 0.0
    ticks: int = 0
    overruns: int = 0
    skipped: int = 0
    last_overrun_task: str = ""
    _sorted: list[float] = field(default_factory=list)

    def record(self, late_s: float) -> None:
        """A tick ran `late_s` after its deadline."""
        self._add(late_s * 1e6)
        self.ticks += 1

    def record_missed(self, late_s: float) -> None:
        """A deadline passed `late_s` ago while a task still ran; that tick is skipped, but
        how late the loop was shows in the figures (a task stuck for 2 s is a 2 s late tick)."""
        self._add(late_s * 1e6)

    def _add(self, us: float) -> None:
        late_us = self.late_us
        late_us.append(us)
        if len(late_us) > self.window:
            old = late_us.popleft()
            # The value leaving the window equals the one entering (every tick of a virtual
            # clock is 0 µs late): the sorted window is the same, skip the two memmoves.
            if old != us:
                data = self._sorted
                bisect.insort(data, us)
                del data[bisect.bisect_left(data, old)]
        else:
            bisect.insort(self._sorted, us)
        if us > self.max_late_us:
            self.max_late_us = us

    def percentiles(self) -> tuple[float, float, float]:
        """(p50, p99, max) lateness in µs over the recent window; max is since start."""
        if not self._sorted:
            return (0.0, 0.0, self.max_late_us)
        data = self._sorted
        return (_pick(data, 0.50), _pick(data, 0.99), self.max_late_us)


def _pick(data: list[float], q: float) -> float:
    return data[min(len(data) - 1, int(q * len(data)))]


class Scheduler:
    """Runs tasks at integer divisors of a base rate, and I/O callbacks between ticks."""

    def __init__(self, clock: Clock, rate_hz: float = 100.0,
                 overrun_log_interval: float = 5.0, stall_limit: float = 0.25,
                 idle_rate_hz: float | None = None) -> None:
        if not (math.isfinite(rate_hz) and 0 < rate_hz <= 2000):
            raise ValueError(f"scheduler rate {rate_hz} Hz is outside 0-2000")
        self.clock = clock
        self.rate_hz = float(rate_hz)
        self.period = 1.0 / self.rate_hz
        #: A loop waiting out a long period is not stalled: never less than two periods.
        self.stall_limit = max(stall_limit, 2 * self.period)
        #: Base periods per tick while `idle()` holds (1: every tick, the default).
        self.idle_stride = self.stride_for(idle_rate_hz)
        #: The owner's "nothing moves or is about to" (None: never idle).
        self.idle: Callable[[], bool] | None = None
        #: (deadline, index) of the next base slot while the wait is stretched, else None.
        self._unstretched: tuple[float, int] | None = None
        #: Set by the owner (the supervisor): stops every module. None: stalls are not checked.
        self.on_stall: StallHandler | None = None
        #: Observer hook: (now, lateness in s) as every tick starts. None costs nothing.
        self.on_tick: TickHook | None = None
        #: Observer hook: (now, s the tick's tasks took, bookkeeping included) as it ends.
        self.on_tick_done: TickHook | None = None
        self.stalls = 0
        self._beat: float | None = None  # clock time the last tick started
        self._unit = WAIT  # the unit of work in progress (or last begun)
        self._stall_requested = False  # set from the stall guard's thread ...
        self._stall_lock = threading.Lock()  # ... under this lock, against handling it twice
        self._handled_alive = -1.0  # `alive_at` of the last stall handled
        self.tasks: list[ScheduledTask] = []
        self.stats = TickStats()
        self._readers: dict[int, IoCallback] = {}
        self._poller = select.poll()
        #: Watched descriptors select cannot take (>= SELECT_FD_LIMIT): poll is used then.
        self._high_fds: set[int] = set()
        #: Readers with input already read and not yet handled: served without waiting.
        self._pending: set[int] = set()
        #: Until when the I/O callback now running may work (the next tick's deadline).
        self.io_deadline = math.inf
        self._rotation = 0
        self._writers: dict[int, IoCallback] = {}
        self._unit_names: dict[tuple[int, bool], str] = {}
        self._next: float | None = None
        self._index = 0
        self._stop = False
        self.current_task: str = ""
        #: perf_counter() of the loop's last sign of progress; the stall guard reads it.
        self.alive_at: float = 0.0
        self._overrun_log_interval = overrun_log_interval
        self._last_overrun_log = -math.inf
        self._overruns_unlogged = 0

    def stride_for(self, idle_rate_hz: float | None) -> int:
        """Base periods per idle tick for `idle_rate_hz` (None or the base rate: 1), rounded
        down to a whole number and kept to at most half the stall limit."""
        if idle_rate_hz is None:
            return 1
        if not (math.isfinite(idle_rate_hz) and idle_rate_hz > 0):
            raise ValueError(f"idle tick rate {idle_rate_hz!r} Hz is not a positive number")
        stride = max(1, int(self.rate_hz / idle_rate_hz + 1e-9))
        return max(1, min(stride, int(self.stall_limit / (2 * self.period) + 1e-9)))

    def hurry(self) -> None:
        """Motion is starting (a request armed the watchdog) during a stretched idle wait:
        the next tick comes at the next base slot instead of the end of the stride."""
        slot = self._unstretched
        if slot is None:
            return
        self._unstretched = None
        deadline, index = slot
        late = self.clock.now() - deadline
        skip = math.ceil(late / self.period) if late > 0.0 else 0
        if deadline + skip * self.period < self._next:  # type: ignore[operator]
            self._next = deadline + skip * self.period
            self._index = index + skip

    # -- registration -------------------------------------------------------------------------
    def add_task(self, name: str, rate_hz: float, fn: TaskFn) -> ScheduledTask:
        """Run `fn(now, dt)` at `rate_hz`, which must divide the base rate."""
        ratio = self.rate_hz / rate_hz
        divisor = round(ratio)
        if divisor < 1 or abs(ratio - divisor) > 1e-6:
            raise ValueError(
                f"task {name}: {rate_hz} Hz does not divide the base rate {self.rate_hz:g} Hz")
        task = ScheduledTask(name, divisor, fn, next_index=self._index)
        self.tasks.append(task)
        return task

    def rate_at_most(self, rate_hz: float) -> float:
        """The fastest rate a task can have that is no faster than `rate_hz`: the base rate
        over a whole divisor (50 Hz on a 100 Hz loop stays 50; on a 60 Hz loop it is 30)."""
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"a task rate must be a positive number of Hz, got {rate_hz!r}")
        return self.rate_hz / max(1, math.ceil(self.rate_hz / rate_hz - 1e-9))

    def remove_task(self, task: ScheduledTask) -> None:
        if task in self.tasks:
            self.tasks.remove(task)

    def add_reader(self, fd: int, callback: IoCallback) -> None:
        self._readers[fd] = callback
        self._watch(fd)

    def remove_reader(self, fd: int) -> None:
        self._readers.pop(fd, None)
        self._pending.discard(fd)
        self._watch(fd)

    @property
    def pending(self) -> set[int]:
        """Readers with work left over from their last turn (see `set_pending`)."""
        return self._pending

    def set_pending(self, fd: int, pending: bool) -> None:
        """A reader with work left over from its last turn (input already read) gets another
        turn on the next pass, as if its fd were readable, without the wait blocking."""
        if pending and fd in self._readers:
            self._pending.add(fd)
        else:
            self._pending.discard(fd)

    def add_writer(self, fd: int, callback: IoCallback) -> None:
        self._writers[fd] = callback
        self._watch(fd)

    def remove_writer(self, fd: int) -> None:
        self._writers.pop(fd, None)
        self._watch(fd)

    def _watch(self, fd: int) -> None:
        """Tell the poller what `fd` is watched for now."""
        mask = (_IN if fd in self._readers else 0) | (_OUT if fd in self._writers else 0)
        if mask:
            self._poller.register(fd, mask)  # registers or modifies
            if fd >= SELECT_FD_LIMIT:
                self._high_fds.add(fd)
        else:
            self._high_fds.discard(fd)
            with contextlib.suppress(KeyError):  # it was not watched
                self._poller.unregister(fd)

    # -- running ------------------------------------------------------------------------------
    def stop(self) -> None:
        """Ask `run` to return after the current iteration."""
        self._stop = True

    @property
    def stopping(self) -> bool:
        """True once `stop()` was called (from a signal handler, say)."""
        return self._stop

    # -- stalls -------------------------------------------------------------------------------
    def request_stall_stop(self, alive_mark: float) -> None:
        """From another thread (the stall guard, which sent zeros when the loop had shown no
        progress since `alive_mark`): treat that gap as a stall even if it is shorter than
        this loop's own limit, unless the loop has already handled it."""
        with self._stall_lock:
            if alive_mark != self._handled_alive:
                self._stall_requested = True

    def on_time(self) -> bool:
        """False while a stall has happened and not yet been handled: motion output computed
        now was computed before the gap and must be dropped (the HAL asks before writing)."""
        if self.on_stall is None or self._beat is None:
            return True
        return not self._stall_requested and self.clock.now() - self._beat <= self.stall_limit

    def check_stall(self) -> bool:
        """Handle a stall now if there was one (`on_stall` first, before any other output);
        True when it did."""
        if self.on_stall is None or self._beat is None:
            return False
        now = self.clock.now()
        gap = now - self._beat
        if gap <= self.stall_limit and not self._stall_requested:
            return False
        with self._stall_lock:
            self._beat = now  # the handler's own output (zeros) is on time
            self._stall_requested = False
            self._handled_alive = self.alive_at
        self.stalls += 1
        try:
            self.on_stall(gap, self._unit)
        except Exception:
            log.exception("stall handler raised")
        return True

    def _begin(self, unit: str) -> None:
        """Before each unit of work: a gap is blamed on the unit that was running."""
        beat = self._beat
        if self.on_stall is not None and beat is not None and (
                self._stall_requested or self.clock.now() - beat > self.stall_limit):
            self.check_stall()
        self._unit = unit
        self.current_task = unit
        self.alive_at = time.perf_counter()

    def run(self, until: Callable[[], bool] | None = None) -> None:
        """Tick until `stop()` has been called or `until()` is true.

        A stop is final: a signal that arrives while start-up is still settling must end the
        main run too."""
        while not self._stop and not (until is not None and until()):
            self.run_once()

    def run_for(self, seconds: float) -> None:
        """Run the ticks due in the next `seconds` of clock time (virtual or real)."""
        start = self._next if self._next is not None else self.clock.now()
        end = start + seconds - 1e-9
        self.run(lambda: self._next is not None and self._next >= end)

    def run_once(self) -> None:
        """Exactly one iteration: wait for the next deadline servicing I/O, then tick."""
        if self._next is None:
            self._next = self.clock.now()
        self._wait()
        self._tick(self._next)

    def poll_io(self, timeout: float = 0.0, deadline: float | None = None) -> int:
        """Dispatch ready I/O once; returns how many callbacks ran.

        With a `deadline`, dispatching stops once the clock passes it: the tick comes first,
        and whatever was not served is still readable on the next pass. The order rotates
        each pass so a busy client early in the list cannot starve the ones after it. A
        callback reads `io_deadline` to end its own turn in time.
        """
        if not self._readers and not self._writers:
            return 0
        if self._pending:
            timeout = 0.0
        r, w = self._ready(timeout) if self._high_fds else self._ready_select(timeout)
        if self._pending:
            r = list(set(r) | self._pending)
        if not w and len(r) == 1:  # the usual wake-up: one client's input (as _guard)
            fd = r[0]
            cb = self._readers.get(fd)
            if cb is None:
                return 0
            what = self._unit_names.get((fd, False)) or self._unit_name(fd, False)
            self._begin(what)
            self.io_deadline = math.inf if deadline is None else deadline
            try:
                cb()
            except Exception:
                log.exception("I/O callback (%s) raised; the loop goes on", what)
            finally:
                self.io_deadline = math.inf
                self.current_task = ""
            self.alive_at = time.perf_counter()
            return 1
        self.io_deadline = math.inf if deadline is None else deadline
        ready = [(fd, True) for fd in w] + [(fd, False) for fd in r]  # output first: it frees
        if len(ready) > 1:
            self._rotation = (self._rotation + 1) % len(ready)
            ready = ready[self._rotation:] + ready[:self._rotation]
        ran = 0
        try:
            for fd, writable in ready:
                if ran and deadline is not None and self.clock.now() >= deadline:
                    break
                cb = (self._writers if writable else self._readers).get(fd)
                if cb is not None:
                    self._guard(cb, self._unit_name(fd, writable))
                    ran += 1
        finally:
            self.io_deadline = math.inf
        self.alive_at = time.perf_counter()
        return ran

    def _ready_select(self, timeout: float) -> tuple[list[int], list[int]]:
        """(readable, writable) descriptors while every one is below 1024: one select with a
        microsecond timeout, one wake-up (see the docstring at the top)."""
        try:
            r, w, _ = select.select(self._readers.keys(), self._writers.keys(), [], timeout)
        except (OSError, ValueError):  # a descriptor closed under us: poll says which
            return self._ready(0.0)
        return r, w

    def _ready(self, timeout: float) -> tuple[list[int], list[int]]:
        """(readable, writable) descriptors, waiting at most `timeout`, with a descriptor past
        select's reach (see the docstring at the top: whole milliseconds in poll, the rest in
        a microsecond select)."""
        ms = int(timeout * 1000)  # rounded down: poll rounds up
        events = self._poller.poll(ms)
        if not events and ms == 0 and timeout > 0:
            low_r = [fd for fd in self._readers if fd < SELECT_FD_LIMIT]
            low_w = [fd for fd in self._writers if fd < SELECT_FD_LIMIT]
            with contextlib.suppress(OSError, ValueError):  # closed under us: poll says so
                select.select(low_r, low_w, [], timeout)
            events = self._poller.poll(0)
        r: list[int] = []
        w: list[int] = []
        for fd, ev in events:
            if ev & select.POLLNVAL:
                self._drop_bad_fd(fd)
                continue
            if ev & (_IN | _GONE) and fd in self._readers:
                r.append(fd)
            if ev & (_OUT | _GONE) and fd in self._writers:
                w.append(fd)
        return r, w

    def _wait(self) -> None:
        """Serve I/O until the next tick's deadline (`_next`, which `hurry` may move)."""
        deadline: float = self._next  # type: ignore[assignment]
        if isinstance(self.clock, VirtualClock):
            self.poll_io(0.0, deadline)
            deadline = self._next  # type: ignore[assignment]
            if self.clock.now() < deadline:
                self.clock.set(deadline)
            return
        polled = False
        while True:
            deadline = self._next  # type: ignore[assignment]
            remaining = deadline - self.clock.now()
            if remaining <= 0:
                if not polled:  # a late tick still lets one client's turn through
                    self.alive_at = time.perf_counter()
                    self.poll_io(0.0, deadline)
                return
            polled = True
            self._begin(WAIT)
            if not self._readers and not self._writers:
                # Nothing to watch: sleep the remainder with a µs-precise wait.
                select.select([], [], [], remaining)
                continue
            self.poll_io(remaining, deadline)

    def _tick(self, deadline: float) -> None:
        clock = self.clock
        clock_now = clock.now
        # A plain virtual clock is read as its attribute after each task: the same value as
        # `now()` without a call per task (a subclass may do more in `now`, so not for it).
        virtual = clock if type(clock) is VirtualClock else None
        beat = self._beat  # a gap in the wait is handled before the first task (check_stall)
        if self.on_stall is not None and beat is not None and (
                self._stall_requested or not clock_now() - beat <= self.stall_limit):
            self.check_stall()
        now = clock_now()
        self._beat = now
        late = now - deadline
        if not late > 0.0:  # max(0.0, now - deadline), NaN included
            late = 0.0
        self.stats.record(late)
        if self.on_tick is not None:
            self.on_tick(now, late)
        period = self.period
        missed = int(late // period)
        worst_name, worst_s = "", 0.0
        index, t, stall_limit, perf_counter = self._index, now, self.stall_limit, time.perf_counter
        for task in list(self.tasks):
            # Skipped ticks move the index in jumps; a task runs at the first tick at or past
            # its slot (never twice to catch up), then waits for its next slot on the grid.
            if index < task.next_index or not task.enabled:
                continue
            divisor = task.divisor
            task.next_index = (index // divisor + 1) * divisor
            last_run = task.last_run
            tdt = divisor * period if last_run is None else now - last_run
            task.last_run = now
            # As _begin, with the time the previous task ended (one clock read per task).
            if self.on_stall is not None and (
                    self._stall_requested or t - self._beat > stall_limit):
                self.check_stall()
                t = clock_now()
            name = task.name
            self._unit = self.current_task = name
            self.alive_at = perf_counter()
            try:
                task.fn(now, tdt)
            except Exception:
                task.errors += 1
                log.exception("task %s raised; the loop goes on", name)
            t1 = virtual._now if virtual is not None else clock_now()
            spent, t = t1 - t, t1
            task.runs += 1
            task.total_s += spent
            if spent > task.max_s:
                task.max_s = spent
            if spent > worst_s:
                worst_name, worst_s = name, spent
        self.current_task = ""
        # The next deadline: skip every tick that is already in the past.
        if missed:
            # Late before any task ran: the time went to I/O handling or to the OS.
            self.stats.overruns += 1
            self.stats.skipped += missed
            self.stats.last_overrun_task = "the wait before the tick (I/O handling or the OS)"
            self._log_overrun(late)
        self._index += 1 + missed
        self._next = deadline + (1 + missed) * self.period
        # Tasks that ran past the next deadline: the overrun is this tick's, name its task.
        after = self.clock.now()
        if self.on_tick_done is not None:
            self.on_tick_done(now, after - now)
        if after > self._next:
            self.stats.record_missed(after - self._next)
            extra = int((after - self._next) // self.period) + 1
            self.stats.overruns += 1
            self.stats.skipped += extra
            self.stats.last_overrun_task = self._blame(worst_name, worst_s)
            self._log_overrun(after - deadline)
            self._index += extra
            self._next += extra * self.period
        # Idle: the next tick `idle_stride` slots on (an overrun is still the base period's).
        self._unstretched = None
        stride = self.idle_stride
        if stride > 1 and self.idle is not None and self._is_idle():
            self._unstretched = (self._next, self._index)
            self._index += stride - 1
            self._next += (stride - 1) * self.period

    def _is_idle(self) -> bool:
        """The owner's predicate, guarded: an error in it means "not idle" (every tick)."""
        try:
            return bool(self.idle())  # type: ignore[misc]
        except Exception:
            log.exception("the idle predicate raised; ticking at the base rate")
            return False

    def _blame(self, name: str, spent: float) -> str:
        return f"{name} ({spent * 1e3:.1f} ms)" if name else "no task (the OS)"

    def _log_overrun(self, late: float) -> None:
        """Throttled: one warning per interval, counting the ones it held back."""
        self._overruns_unlogged += 1
        now = time.perf_counter()
        if now - self._last_overrun_log >= self._overrun_log_interval:
            log.warning("tick overrun: %.1f ms late; slowest task %s (%d overruns since last"
                        " report)", late * 1e3, self.stats.last_overrun_task,
                        self._overruns_unlogged)
            self._last_overrun_log = now
            self._overruns_unlogged = 0

    def _unit_name(self, fd: int, writable: bool) -> str:
        """`input on fd 12`: what a stall in an I/O callback is blamed on (made once)."""
        name = self._unit_names.get((fd, writable))
        if name is None:
            name = f"{'output' if writable else 'input'} on fd {fd}"
            self._unit_names[(fd, writable)] = name
        return name

    def _guard(self, cb: IoCallback, what: str) -> None:
        self._begin(what)
        try:
            cb()
        except Exception:
            log.exception("I/O callback (%s) raised; the loop goes on", what)
        finally:
            self.current_task = ""

    def _drop_bad_fd(self, fd: int) -> None:
        """A closed fd left registered would be reported forever: drop it."""
        log.error("dropping closed file descriptor %d from the loop", fd)
        self._readers.pop(fd, None)
        self._writers.pop(fd, None)
        self._pending.discard(fd)
        self._watch(fd)
