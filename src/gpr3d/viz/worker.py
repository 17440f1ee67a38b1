"""Figures drawn in a process beside the command: a command that migrates starts :class:`FigureWorker` before it
reads its input, the worker imports matplotlib on the core the reading leaves idle (about 0.3 s), and later draws
the figures while the command writes its volume files. On a 2-core host the figures of ``gpr3d reconstruct`` cost
about 0.75 s in the command itself, a quarter of its time (``benchmarks/results/bench_stages.md``).

Where no ``fork`` is to be had (Windows, or ``GPR3D_FIGURE_WORKER=0``), or the worker has gone (killed, out of
memory), the figures are drawn in the command's own process instead: the same files either way."""

from __future__ import annotations

import os
import sys

__all__ = ["FigureWorker", "fork_job", "in_worker", "wait_job"]

#: the worker's niceness, added to the command's (on a 2-core host it takes the core the reading leaves idle, and its
#: import of matplotlib is over before the migration starts, where 19 spread it into the migration; with one core,
#: the command comes first)
NICE = 5

_IN_WORKER = False  # True in the worker's own process (set by _serve)


def in_worker() -> bool:
    """Whether this process is a :class:`FigureWorker`'s (a process with no thread of its own, safe to fork)."""
    return _IN_WORKER


def fork_job(fn, *args) -> int | None:
    """Run ``fn(*args)`` in a process forked for it (for a job whose result is a file it writes); returns the
    process id for :func:`wait_job`, or None where no process could be forked (nothing was run). Fork only a
    process that runs no thread (:func:`in_worker`); the forked one ends with this one."""
    if not hasattr(os, "fork"):
        return None
    parent = os.getpid()
    try:
        pid = os.fork()
    except OSError:
        return None
    if pid:
        return pid
    code = 1  # pragma: no cover - runs in the forked process (its effects are tested from the parent)
    try:  # pragma: no cover
        _die_with_parent(parent)
        fn(*args)
        code = 0
    finally:  # pragma: no cover - never back into the caller's stack: its exit status says how it went
        os._exit(code)


def wait_job(pid: int) -> bool:
    """Wait for the process of :func:`fork_job`; True where ``fn`` returned, False where it raised or was killed."""
    try:
        _, status = os.waitpid(pid, 0)
    except ChildProcessError:  # (already waited for)
        return False
    return os.waitstatus_to_exitcode(status) == 0


def _die_with_parent(parent: int) -> None:  # pragma: no cover - runs in the forked process
    """Linux: this process is killed when ``parent``, the one that forked it, ends (a worker stopped by its command),
    and ends at once if it has already ended."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        try:
            ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))  # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
    if os.getppid() != parent:  # (ended before the line above took hold)
        os._exit(1)


def _serve(conn, theirs, parent: int) -> None:  # pragma: no cover - runs in the forked child (tested from outside)
    """The worker's loop: matplotlib imported first, then one ``(function, args)`` at a time, each answered with
    ``("ok", value)`` or ``("error", exception)``; ends when the command's end of the pipe closes (``theirs``:
    that end, as the fork copied it, closed here at once), and is killed when the command (``parent``) ends: a
    command killed while its figures are drawn leaves no worker writing into a folder the next run removes."""
    import signal

    global _IN_WORKER
    _IN_WORKER = True
    _die_with_parent(parent)
    theirs.close()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # a Ctrl-C is the command's to handle; it ends this one
    try:
        os.nice(NICE)  # the command's own work first: this one takes what a core leaves idle
    except OSError:
        pass
    from gpr3d.viz._figures import pyplot

    pyplot()
    import mpl_toolkits.mplot3d  # noqa: F401  (the 3D view's axes)

    while True:
        try:
            fn, args = conn.recv()
        except (EOFError, OSError):
            return
        try:
            conn.send(("ok", fn(*args)))
        except BaseException as exc:  # sent back whole: the command raises it
            try:
                conn.send(("error", exc))
            except Exception:  # an exception that does not pickle: its one line
                conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))


def _enabled() -> bool:
    import multiprocessing

    return (os.environ.get("GPR3D_FIGURE_WORKER", "1") != "0" and sys.platform.startswith("linux")
            and "fork" in multiprocessing.get_all_start_methods())


class FigureWorker:
    """A forked process that draws figures: ``with FigureWorker() as w: ...; job = w.submit(fn, *args); ...;
    job()`` gives ``fn(*args)`` as drawn by the worker (or, without one, by this process when ``job`` is called).

    Start it before the command starts any thread (a fork copies only the thread that forks); it is ended when
    the ``with`` block ends, whatever happens in it.

    Parameters
    ----------
    enabled : bool or None
        Fork a worker (None: where ``fork`` is to be had, unless ``GPR3D_FIGURE_WORKER=0``).
    """

    #: how long a job may take in the worker before it is given up and drawn here instead (seconds)
    patience_s = 600.0

    def __init__(self, enabled: bool | None = None):
        self.enabled = _enabled() if enabled is None else bool(enabled)
        self._proc = self._conn = None
        self._busy = False
        self.answered = 0  #: jobs the worker itself answered (the rest ran here)

    def __enter__(self) -> FigureWorker:
        if self.enabled:
            import multiprocessing

            ctx = multiprocessing.get_context("fork")
            mine, theirs = ctx.Pipe()
            self._proc = ctx.Process(target=_serve, args=(theirs, mine, os.getpid()), daemon=True,
                                     name="gpr3d-figures")
            self._proc.start()
            theirs.close()
            self._conn = mine
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def alive(self) -> bool:
        """Whether a worker process is running."""
        return self._proc is not None and self._proc.is_alive()

    def close(self) -> None:
        """End the worker: an idle one at once (it holds nothing unwritten; its own exit, matplotlib loaded, took
        tens of milliseconds of the command's end), one still drawing after a second (its pipe closed)."""
        if self._proc is not None and not self._busy:
            self._proc.kill()  # (before its pipe closes: an idle worker ends here, never by its own exit)
        if self._conn is not None:
            self._conn.close()
            self._conn = None
        if self._proc is not None:
            self._proc.join(timeout=1.0)
            if self._proc.is_alive():
                self._proc.kill()
                self._proc.join()
            self._proc = None

    def submit(self, fn, *args):
        """Hand ``fn(*args)`` to the worker (``fn`` a module-level function, ``args`` what pickles); returns a
        callable that waits for and returns its value, raising what it raised. Without a worker, or one that
        cannot take it, the callable runs ``fn(*args)`` here."""
        if self._conn is not None and not self._busy and self.alive:
            try:
                self._conn.send((fn, args))
                self._busy = True
            except (OSError, ValueError):  # the worker has gone
                self.close()
            except Exception:  # what does not pickle (nothing was sent): drawn here, the worker kept
                pass
            else:
                return lambda: self._wait(fn, args)
        return lambda: fn(*args)

    def _wait(self, fn, args):
        waited = 0.0
        try:
            while not self._conn.poll(0.25):  # a worker that died without a word is noticed within a quarter second
                waited += 0.25
                if not self._proc.is_alive() or waited >= self.patience_s:
                    raise EOFError
            status, value = self._conn.recv()
        except (EOFError, OSError):  # the worker died (or hung) while drawing: drawn here
            self.close()
            self._busy = False
            return fn(*args)
        self._busy = False
        self.answered += 1
        if status == "error":
            raise value
        return value
