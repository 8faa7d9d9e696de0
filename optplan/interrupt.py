"""Interruption (Ctrl-C, SIGTERM, SIGHUP) as an ordinary way for a command to end.

:func:`handling` installs one handler for SIGINT, SIGTERM and SIGHUP around a command. The first
signal raises :class:`Interrupted` in the main thread (a ``BaseException``: no ``except Exception``
swallows it), so the command unwinds through its ``finally`` blocks; the files it writes are
atomic (:mod:`optplan._io`), so each is complete or absent. :func:`finish` then stops the worker
processes (SIGTERM, SIGKILL after :data:`STOP_S`), prints ONE line — ``interrupted by SIGINT after
N of M trials; resume with the same command`` — and returns the exit status 128 + signal number
(130 SIGINT, 143 SIGTERM, 129 SIGHUP). Further signals during that clean-up are ignored; if the
clean-up does not end within :data:`GRACE_S`, a watchdog stops the workers, removes partial files
and ends the process with the same line and status.

Worker processes (the pipeline's forked pool, the benchmarks' process pools) run
:func:`worker_init`: they ignore SIGINT and SIGHUP (the terminal sends Ctrl-C to the whole process
group; the main process decides) and die with their parent (``PR_SET_PDEATHSIG``), so no worker
outlives the command.
"""
from __future__ import annotations

import contextlib
import ctypes
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator

__all__ = ["Interrupted", "handling", "received", "check", "progress", "finish", "stop_children",
           "worker_init", "SIGNALS", "GRACE_S", "STOP_S"]

#: the signals handled
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: time a worker process gets to end after SIGTERM before it is killed [s]
STOP_S = 1.0
#: time the main process gets to unwind after a signal before the watchdog ends it [s]
GRACE_S = 5.0


class Interrupted(BaseException):
    """Raised in the main thread by the first SIGINT/SIGTERM/SIGHUP a command receives."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


class _State:
    signum: int | None = None
    done: int | None = None
    total: int | None = None
    unit = "trials"
    prog = "optplan"
    watchdog: threading.Timer | None = None


_state = _State()
_stoppers: list[Callable[[], None]] = []


def register_stopper(fn: Callable[[], None]) -> None:
    """Call ``fn()`` (which stops some worker processes without waiting) on an interruption."""
    if fn not in _stoppers:
        _stoppers.append(fn)


def progress(done: int, total: int, unit: str = "trials") -> None:
    """Record how far the command is, for the interruption's line (``after done of total unit``)."""
    _state.done, _state.total, _state.unit = int(done), int(total), unit


def received() -> int | None:
    """The signal number received since :func:`handling` began, or None."""
    return _state.signum


def check() -> None:
    """Raise :class:`Interrupted` if a signal arrived (also one a library turned into another error)."""
    if _state.signum is not None:
        raise Interrupted(_state.signum)


def message() -> str:
    """The one line an interrupted command prints."""
    name = signal.Signals(_state.signum).name if _state.signum is not None else "a signal"
    where = (f" after {_state.done} of {_state.total} {_state.unit}" if _state.total is not None else "")
    return f"{_state.prog}: interrupted by {name}{where}; resume with the same command"


def exit_code() -> int:
    """128 + the signal number (130 SIGINT, 143 SIGTERM, 129 SIGHUP)."""
    return 128 + int(_state.signum or signal.SIGINT)


def stop_children(timeout: float = STOP_S) -> int:
    """Stop every worker process of this process: SIGTERM, then SIGKILL for those alive after
    ``timeout`` [s]. Returns how many were stopped."""
    for fn in list(_stoppers):
        with contextlib.suppress(Exception):
            fn()
    kids = mp.active_children()
    for p in kids:
        with contextlib.suppress(Exception):
            p.terminate()
    deadline = time.monotonic() + timeout
    for p in kids:
        with contextlib.suppress(Exception):
            p.join(max(0.0, deadline - time.monotonic()))
    for p in kids:
        with contextlib.suppress(Exception):
            if p.is_alive():
                p.kill()
                p.join(0.5)
    return len(kids)


def _hard_exit() -> None:  # pragma: no cover - runs only when the main thread does not unwind in time
    from ._io import remove_partial_files

    stop_children(0.5)
    remove_partial_files()
    with contextlib.suppress(Exception):
        sys.stderr.write(message() + "\n")
        sys.stderr.flush()
    os._exit(exit_code())


def _handler(signum, frame) -> None:
    if _state.signum is not None:   # already unwinding: later signals wait for the clean-up
        return
    _state.signum = signum
    _state.watchdog = threading.Timer(GRACE_S, _hard_exit)
    _state.watchdog.daemon = True
    _state.watchdog.start()
    raise Interrupted(signum)


@contextlib.contextmanager
def handling(prog: str = "optplan") -> Iterator[None]:
    """Handle SIGINT/SIGTERM/SIGHUP while the block runs (main thread only; elsewhere a no-op);
    the previous handlers are restored afterwards. ``prog`` starts the interruption's line."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _state.signum = _state.done = _state.total = None
    _state.unit, _state.prog = "trials", prog
    old = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, _handler)
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        if _state.watchdog is not None:
            _state.watchdog.cancel()
            _state.watchdog = None
        _state.signum = None


def finish() -> int:
    """After an interruption: stop the workers, print the one line, return the exit status."""
    for s in SIGNALS:   # the clean-up is not interrupted again
        signal.signal(s, signal.SIG_IGN)
    stop_children()
    from ._io import remove_partial_files

    remove_partial_files()
    code = exit_code()
    print(message(), file=sys.stderr, flush=True)
    if _state.watchdog is not None:
        _state.watchdog.cancel()
        _state.watchdog = None
    return code


def worker_init(*then) -> None:
    """In a worker process: ignore SIGINT and SIGHUP, end on SIGTERM, die with the parent; then
    ``then[0](*then[1:])`` when given (a pool's own initializer)."""
    if threading.current_thread() is threading.main_thread():   # not in a Dask worker's task thread
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        with contextlib.suppress(Exception):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)   # PR_SET_PDEATHSIG
            if os.getppid() == 1:   # the parent is already gone
                os._exit(0)
    if then and then[0] is not None:
        then[0](*then[1:])
