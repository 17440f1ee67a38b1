"""Where a command's time goes: named stages, timed where they run, gathered by whoever asks.

A library function marks its stages with :func:`stage` (``with stage("migrate"): ...``); nothing
is timed or kept unless someone is collecting. A caller that wants the figures opens :func:`collect`
around the work and reads the seconds per stage from it afterwards; collections may nest (``gpr3d
--timings`` around ``gpr3d demo``, which keeps its own), and each sees every stage run inside it.
Stages may nest: a stage's seconds are its own, less those of the stages inside it, so the rows add
up to the time collected (the rest is ``other``). Numba's compilations, where they happen (the kernels
are cached on disk after the first run), are counted in a ``compile`` row of their own and taken
out of the stage that triggered them.
"""

from __future__ import annotations

import contextvars
import os
import time
from contextlib import contextmanager

__all__ = ["StageTimes", "stage", "collect", "process_age_s", "age_from_proc", "format_table"]

_ACTIVE: contextvars.ContextVar = contextvars.ContextVar("gpr3d_stage_times", default=())


class StageTimes:
    """Seconds per stage, in the order the stages were first entered.

    Attributes
    ----------
    seconds : dict
        ``{stage name: seconds}``, each a stage's own time (its inner stages taken out).
    counts : dict
        ``{stage name: times entered}``.
    wall_s : float or None
        Seconds from :func:`collect`'s start to its end (None while it runs).
    """

    def __init__(self, clock=time.perf_counter):
        self.seconds: dict = {}
        self.counts: dict = {}
        self.wall_s: float | None = None
        self._clock = clock
        self._open: list = []  # [name, start, seconds of inner stages]

    def _enter(self, name: str) -> None:
        self.seconds.setdefault(name, 0.0)  # rows in the order first entered
        self._open.append([name, self._clock(), 0.0])

    def _leave(self) -> None:
        name, start, inner = self._open.pop()
        took = self._clock() - start
        self.add(name, took - inner)
        if self._open:
            self._open[-1][2] += took

    def add(self, name: str, seconds: float) -> None:
        """Count ``seconds`` to stage ``name`` (e.g. a compilation measured elsewhere)."""
        self.seconds[name] = self.seconds.get(name, 0.0) + float(seconds)
        self.counts[name] = self.counts.get(name, 0) + 1

    def take_from_open(self, seconds: float) -> None:
        """Move ``seconds`` out of the innermost open stage (where a compilation happened inside it)."""
        if self._open:
            self._open[-1][2] += float(seconds)

    def rows(self) -> list:
        """``[(stage, seconds)]`` in order, then ``other`` (the collected time no stage claimed) when positive."""
        out = list(self.seconds.items())
        if self.wall_s is not None:
            rest = self.wall_s - sum(self.seconds.values())
            if rest > 0:
                out.append(("other", rest))
        return out

    def to_dict(self) -> dict:
        """``{"stages": {name: seconds}, "wall_s": ...}`` for a JSON file."""
        return {"stages": {k: round(v, 6) for k, v in self.rows()},
                "wall_s": None if self.wall_s is None else round(self.wall_s, 6)}


@contextmanager
def stage(name: str):
    """Time the block as stage ``name`` for whoever is collecting (nothing is kept when no one is)."""
    active = _ACTIVE.get()
    for times in active:
        times._enter(name)
    try:
        yield
    finally:
        for times in reversed(active):
            times._leave()


class _CompileCounter:
    """Numba's outermost ``numba:compile`` events, their seconds moved into the ``compile`` row."""

    def __init__(self, times: StageTimes, clock):
        self.times, self.clock, self.depth, self.start = times, clock, 0, None

    def on_start(self, event):
        if self.depth == 0:
            self.start = self.clock()
        self.depth += 1

    def on_end(self, event):
        self.depth -= 1
        if self.depth == 0:
            took = self.clock() - self.start
            self.times.add("compile", took)
            self.times.take_from_open(took)


def _compile_listener(times: StageTimes, clock):
    """A numba listener (its own base class) counting into ``times``; None without numba."""
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - numba is a dependency
        return None, None
    listener = type("_Listener", (_CompileCounter, event.Listener), {})(times, clock)
    event.register("numba:compile", listener)
    return event, listener


@contextmanager
def collect(*, compile_times: bool = True, clock=time.perf_counter):
    """Collect the stages run inside the block: ``with collect() as t: ...; t.rows()``.

    ``compile_times``: count numba's compilations in their own row (imports numba when it is installed).
    """
    times = StageTimes(clock)
    token = _ACTIVE.set(_ACTIVE.get() + (times,))
    event, listener = _compile_listener(times, clock) if compile_times else (None, None)
    t0 = clock()
    try:
        yield times
    finally:
        try:
            times.wall_s = clock() - t0
            while times._open:  # a stage left open by an exception still counts
                times._leave()
        finally:  # whatever the clock did, the collection ends here
            if listener is not None:
                event.unregister("numba:compile", listener)
            _ACTIVE.reset(token)


def age_from_proc(stat: str, uptime: str, ticks_per_s: float) -> float:
    """A process's age (s) from its ``/proc/PID/stat`` line, ``/proc/uptime`` and the clock ticks per second:
    the machine's uptime less the process's start (field 22, in ticks since boot). The process's name, in
    parentheses, may itself hold spaces and parentheses: the fields are counted after its last ``)``."""
    start_ticks = int(stat.rsplit(")", 1)[1].split()[19])  # fields 3.. after the name: field 22 is the 20th
    return float(uptime.split()[0]) - start_ticks / ticks_per_s


def process_age_s() -> float | None:
    """Seconds since this process started (Linux's ``/proc``; None elsewhere): the interpreter's and the
    imports' share of a command's time when asked at its start."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            stat = f.read()
        with open("/proc/uptime", encoding="ascii") as f:
            uptime = f.read()
        return age_from_proc(stat, uptime, os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError, AttributeError):
        return None


def format_table(rows, *, title: str = "where the time went") -> str:
    """A plain text table of ``[(stage, seconds)]`` with each stage's share of the total."""
    total = sum(s for _, s in rows) or 1.0
    width = max([len(n) for n, _ in rows] + [5])
    lines = [title, f"  {'stage':<{width}}  {'s':>8}  {'share':>6}"]
    lines += [f"  {n:<{width}}  {s:8.3f}  {100 * s / total:5.1f} %" for n, s in rows]
    lines.append(f"  {'total':<{width}}  {sum(s for _, s in rows):8.3f}  100.0 %")
    return "\n".join(lines)
