"""Interruption (Ctrl-C, SIGTERM, SIGHUP) as an ordinary way for a command to end.

:func:`handling` installs one handler for SIGINT, SIGTERM and SIGHUP around a command. The first
signal raises :class:`Interrupted` in the main thread (a ``BaseException``: no ``except Exception``
swallows it), so the command unwinds through its ``finally`` blocks; the files it writes are
atomic (:mod:`optplan._io`), so each is complete or absent. :func:`finish` then stops the worker
processes (SIGTERM, SIGKILL after :data:`STOP_S`), prints ONE line — ``interrupted by SIGINT after
N of M trials; resume with the same command`` — and returns the exit status 128 + signal number
(130 SIGINT, 143 SIGTERM, 129 SIGHUP). What the unwinding libraries would print to ``sys.stderr``
after the signal (CasADi's ``KeyboardInterruptException`` warning, a worker pool's broken-pipe
traceback) is dropped, unless ``quiet=False`` (``optplan -v``). Further signals during that clean-up are ignored; if the
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
import logging
import multiprocessing as mp
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any, NoReturn

__all__ = ["Interrupted", "handling", "received", "check", "progress", "finish", "end_now", "stop_children",
           "stop_process", "die_with_parent", "worker_init", "deferred", "committing", "SIGNALS", "GRACE_S", "STOP_S"]

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
    stream: Any = None   # the stderr the interruption's line goes to
    defer = 0            # > 0 inside :func:`deferred`: a signal is recorded, raised when the block ends
    active = False       # inside :func:`handling` (in the main thread)


class _QuietAfterSignal:
    """``sys.stderr`` while a command runs: passes everything through until a signal arrives, then
    drops what the unwinding code prints (the interruption's own line goes to the real stream)."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        if _state.signum is not None:
            return len(text)
        return self._stream.write(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


_state = _State()
_stoppers: list[Callable[[], None]] = []


def register_stopper(fn: Callable[[], None]) -> None:
    """Call ``fn()`` (which stops some worker processes without waiting) on an interruption."""
    if fn not in _stoppers:
        _stoppers.append(fn)


def progress(done: int, total: int, unit: str = "trials") -> None:
    """Record how far the command is, for the interruption's line (``after done of total unit``)."""
    _state.done, _state.total, _state.unit = int(done), int(total), unit


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """A block a signal does not cut: one arriving inside is recorded and raised as
    :class:`Interrupted` when the block ends (writing a result line and counting it in
    :func:`progress`, so that the interruption's line counts exactly the lines written)."""
    _state.defer += 1
    try:
        yield
    finally:
        _state.defer -= 1
    if _state.defer == 0:
        check()


@contextlib.contextmanager
def committing() -> Iterator[None]:
    """The block that writes a command's last output — the record that says it succeeded and names its files. A
    signal that arrived before the block is the interruption it always was (raised on entry); from the block's start
    on, SIGINT, SIGTERM and SIGHUP are ignored until :func:`handling` ends: the command is complete once the block
    has written, and ends with its own exit status. (Without it a signal in the last instants — after the record,
    while the idle workers are stopped — ended the command as interrupted beside a record saying success.) Outside
    :func:`handling` it only checks."""
    check()
    if _state.active and threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            signal.signal(s, signal.SIG_IGN)
    yield


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
        stream = _state.stream if _state.stream is not None else sys.__stderr__
        if stream is not None:
            stream.write(message() + "\n")
            stream.flush()
    os._exit(exit_code())


def _handler(signum, frame) -> None:
    if _state.signum is not None:   # already unwinding: later signals wait for the clean-up
        return
    _state.signum = signum
    _state.watchdog = threading.Timer(GRACE_S, _hard_exit)
    _state.watchdog.daemon = True
    _state.watchdog.start()
    if _state.defer:   # inside deferred(): raised when that block ends
        return
    raise Interrupted(signum)


def before_start(prog: str = "optplan") -> None:
    """Until :func:`handling` begins (the command's arguments are parsed, its modules imported):
    a signal ends the process at once with one line (nothing has been written yet)."""
    def stop(signum, frame):  # pragma: no cover - only in that short window
        with contextlib.suppress(Exception):
            sys.stderr.write(f"{prog}: interrupted by {signal.Signals(signum).name} before the command started\n")
            sys.stderr.flush()
        os._exit(128 + signum)

    if threading.current_thread() is threading.main_thread():
        for s in SIGNALS:
            signal.signal(s, stop)


def _no_record_after_signal(record: logging.LogRecord) -> bool:
    return _state.signum is None


@contextlib.contextmanager
def handling(prog: str = "optplan", quiet: bool = True, ignore_after: bool = False) -> Iterator[None]:
    """Handle SIGINT/SIGTERM/SIGHUP while the block runs (main thread only; elsewhere a no-op);
    the previous handlers are restored afterwards. ``prog`` starts the interruption's line;
    ``quiet``: drop what is printed to ``sys.stderr`` after the signal (see the module docstring);
    ``ignore_after``: ignore the signals after the block instead (the command-line process: its
    work is done and written, and the interpreter's shutdown, joining worker pools, is not
    interrupted into a signal death without a message)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _state.signum = _state.done = _state.total = None
    _state.unit, _state.prog = "trials", prog
    old = {s: signal.getsignal(s) for s in SIGNALS}
    for s in SIGNALS:
        signal.signal(s, _handler)
    _state.stream = sys.stderr
    _state.active = True
    handlers = list(logging.getLogger().handlers) if quiet else []
    if quiet:
        sys.stderr = _QuietAfterSignal(_state.stream)
        for h in handlers:   # log records after the signal are dropped too
            h.addFilter(_no_record_after_signal)
    try:
        yield
    finally:
        _state.active = False
        for h in handlers:
            h.removeFilter(_no_record_after_signal)
        if isinstance(sys.stderr, _QuietAfterSignal):
            sys.stderr = _state.stream
        for s, previous in old.items():
            signal.signal(s, signal.SIG_IGN if ignore_after else previous if previous is not None else signal.SIG_DFL)
        if _state.watchdog is not None:
            _state.watchdog.cancel()
            _state.watchdog = None
        _state.signum = None


def finish(exit_now: bool = False) -> int:
    """After an interruption: stop the workers, print the one line, return the exit status.
    ``exit_now``: end the process here (``os._exit``, after flushing stdout and stderr) instead of
    returning — for the command-line process, whose interpreter shutdown would otherwise join the
    stopped pools' threads and print their broken-pipe errors."""
    for s in SIGNALS:   # the clean-up is not interrupted again
        signal.signal(s, signal.SIG_IGN)
    stop_children()
    from ._io import remove_partial_files

    remove_partial_files()
    code = exit_code()
    print(message(), file=_state.stream or sys.stderr, flush=True)
    if _state.watchdog is not None:
        _state.watchdog.cancel()
        _state.watchdog = None
    if exit_now:
        end_now(code)
    return code


def end_now(code: int) -> NoReturn:
    """End this process with status ``code`` without the interpreter's shutdown: what multiprocessing
    does at exit (its semaphores released), stdout and stderr flushed, then ``os._exit``. For the
    command-line process once its children are stopped (:func:`stop_children`)."""
    with contextlib.suppress(Exception):   # without the thread joins of the interpreter's shutdown
        import multiprocessing.util as mpu

        mpu._exit_function()  # type: ignore[attr-defined]
    for stream in (sys.stdout, _state.stream, sys.stderr):
        with contextlib.suppress(Exception):
            if stream is not None:
                stream.flush()
    os._exit(code)


def ignore_in_spawned_child() -> None:
    """In a process a ``spawn`` pool is starting (it imports the command's module before it runs
    :func:`worker_init`): ignore SIGINT and SIGHUP from here on, so a Ctrl-C while the worker starts
    prints no traceback there (the command's own process handles it). Elsewhere: nothing."""
    if getattr(mp.current_process(), "_inheriting", False) and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGHUP, signal.SIG_IGN)


@contextlib.contextmanager
def children_start_deaf() -> Iterator[None]:
    """Block SIGINT and SIGHUP in this thread while worker processes are created in the block: a
    child (forked, or spawned: the mask survives ``exec``) starts with them blocked, so a Ctrl-C
    while it boots prints no traceback there; :func:`worker_init` then ignores them. A signal
    that arrives meanwhile is delivered to this process when the block ends."""
    sigs = {signal.SIGINT, signal.SIGHUP}
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def die_with_parent() -> None:
    """``preexec_fn`` of a child process: it gets SIGTERM when this process ends (``PR_SET_PDEATHSIG``)."""
    with contextlib.suppress(Exception):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGTERM), 0, 0, 0)


def stop_process(proc, timeout: float = STOP_S) -> None:
    """End the ``subprocess.Popen`` ``proc``: SIGTERM, SIGKILL after ``timeout`` [s]."""
    with contextlib.suppress(Exception):
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout)
            except Exception:   # noqa: BLE001 - still running
                proc.kill()
                proc.wait(1.0)


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
