"""Independent jobs of one context run side by side in forked worker processes.

The pipeline optimizes the segments of a plan one NLP each; they share nothing but the robot and
the scene, so on a machine with several cores they can be solved at the same time. IPOPT holds
Python's global interpreter lock while it runs, so threads do not help; processes do.

:func:`run_jobs` keeps, per context (the robot and scene objects a job needs), a pool of worker
processes created with ``fork``: a worker starts with the parent's memory — the robot, the scene,
the loaded kernels and compiled libraries — so nothing is pickled but a job's arguments and its
result. Jobs go out longest first (by the cost estimate the caller gives), each to the first
process that is free, the calling process included. A job's function must be importable by name (a
module-level function) and deterministic: which process runs a job does not change its result.
Where ``fork`` is not available, with one worker, inside a daemonic process (a worker of a process
pool, which may not have children), or if a worker dies, the jobs run here, in order. A job sent to a
worker that has not started :data:`STALL_S` after this process ran out of jobs is taken back and run here
(a warning is logged).
"""
from __future__ import annotations

import functools
import logging
import multiprocessing as mp
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from . import interrupt

__all__ = ["default_workers", "run_jobs", "send_early", "shutdown", "start_workers", "workers_started"]
log = logging.getLogger(__name__)

#: contexts the forked workers inherit: key -> the context objects (kept alive while a pool uses them)
_CONTEXTS: dict[tuple[int, ...], tuple[Any, ...]] = {}
#: the pools of the most recently used contexts
_POOLS: OrderedDict[tuple[int, ...], ProcessPoolExecutor] = OrderedDict()
#: how many pools (each with its worker processes) stay alive
MAX_POOLS = 2
#: pools shut down without waiting, whose manager thread may still run: joined before the next pool forks. A fork while
#: such a thread holds its pool's lock leaves the child blocked on that lock for ever (the child's garbage collector
#: frees the old pool, whose weakref callback takes the lock; seen as a hung test)
_RETIRED: list[threading.Thread] = []
#: how long a retired pool's thread is waited for before a fork [s] (it ends within milliseconds of its shutdown)
JOIN_S = 10.0
#: a job sent to a worker that has not started after this long once this process has nothing left to do is
#: taken back and run here [s] (a job is handed to a worker's queue within milliseconds of being sent)
STALL_S = 5.0


def default_workers() -> int:
    """Processes a pipeline uses by default: 2 where the machine has at least 2 CPUs available to
    this process, else 1 (more rarely help: a plan has 2-4 segments, one or two of them long)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        n = os.cpu_count() or 1
    return 2 if n >= 2 else 1


def shutdown(wait: bool = False) -> None:
    """Stop every worker process (they are also stopped when the interpreter exits); ``wait``: until
    they and the pools' threads have ended."""
    while _POOLS:
        key, pool = _POOLS.popitem(last=False)
        _retire(pool)
        _CONTEXTS.pop(key, None)
    if wait:
        _join_retired()


def _retire(pool: ProcessPoolExecutor) -> None:
    """Shut ``pool`` down without waiting; its manager thread is joined before the next fork (:func:`_join_retired`)."""
    th = getattr(pool, "_executor_manager_thread", None)   # the executor forgets it in shutdown
    pool.shutdown(wait=False, cancel_futures=True)
    if isinstance(th, threading.Thread):
        _RETIRED.append(th)


def _join_retired() -> None:
    """Wait (up to :data:`JOIN_S` each) for the threads of the pools shut down without waiting, so that no thread of
    theirs holds a lock when a new pool forks."""
    while _RETIRED:
        th = _RETIRED.pop()
        if th.is_alive():
            th.join(JOIN_S)
            if th.is_alive():  # pragma: no cover - a worker still busy with a job it was given before
                log.warning("a stopped worker pool's thread is still running after %.0f s", JOIN_S)


def _kill_all() -> None:
    """On an interruption: end every worker process now (SIGKILL) and forget the pools."""
    while _POOLS:
        key, pool = _POOLS.popitem(last=False)
        for proc in list((getattr(pool, "_processes", None) or {}).values()):
            try:
                proc.kill()
            except (OSError, AttributeError):  # pragma: no cover - already gone
                pass
        _retire(pool)
        _CONTEXTS.pop(key, None)


interrupt.register_stopper(_kill_all)


def _pool(context: tuple[Any, ...], workers: int) -> tuple[tuple[int, ...], ProcessPoolExecutor] | None:
    if "fork" not in mp.get_all_start_methods():  # pragma: no cover - not on Linux
        return None
    if mp.current_process().daemon:   # a pool's worker (e.g. a benchmark's) may not have children
        return None
    key = (*(id(c) for c in context), workers)
    pool = _POOLS.get(key)
    if pool is not None:
        _POOLS.move_to_end(key)
        return key, pool
    while len(_POOLS) >= MAX_POOLS:      # the least recently used pools make room
        old, p = _POOLS.popitem(last=False)
        _retire(p)
        _CONTEXTS.pop(old, None)
    _join_retired()                      # no earlier pool's thread holds a lock when this one forks
    _CONTEXTS[key] = context             # before the workers fork: they inherit it
    pool = ProcessPoolExecutor(workers, mp_context=mp.get_context("fork"), initializer=interrupt.worker_init)
    _POOLS[key] = pool
    return key, pool


def start_workers(context: tuple[Any, ...], workers: int, warm: Callable[..., Any] | None = None) -> bool:
    """Fork now the ``workers − 1`` worker processes that :func:`run_jobs` will use for this ``context``
    and ``workers`` (the same objects: the pool is found by them), each to run ``warm(*context)`` first,
    so that a worker prepares (imports, loads) while this process goes on with other work — the
    pipeline plans while its worker imports the optimization stack. A worker forked now inherits this
    process's memory as it is now, not as it will be when the jobs come. Returns False (nothing
    started; :func:`run_jobs` works as without it) with ``workers`` < 2, where :func:`run_jobs` would
    run the jobs here, or while another thread runs in this process (a fork copies the locks it holds). ``warm`` runs once per worker process when the pool has one worker (the
    default); with more it is sent ``workers − 1`` times, to whichever workers take it."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if threading.active_count() > 1:
        # another thread (e.g. an earlier pool's, still shutting down) may hold a lock the child would
        # inherit held: fork early only from a process with one thread (a fresh command's); run_jobs
        # forks when the jobs come, as without this call
        return False
    fresh = (*(id(c) for c in context), workers - 1) not in _POOLS
    got = _pool(context, workers - 1) if workers > 1 else None
    if got is None:
        return False
    key, pool = got
    if warm is not None and fresh:   # (a pool already running was prepared when it started)
        for _ in range(workers - 1):
            try:
                with interrupt.children_start_deaf():   # a worker forked here starts with Ctrl-C blocked
                    fut = pool.submit(_run_job, key, warm, ())
            except (BrokenProcessPool, RuntimeError):  # pragma: no cover - the pool is gone: run_jobs copes
                _POOLS.pop(key, None)
                return False
            fut.add_done_callback(_log_warm_failure)
    return True


def workers_started(context: tuple[Any, ...], workers: int) -> bool:
    """Are the worker processes :func:`run_jobs` would use for this ``context`` and ``workers`` already
    running (:func:`start_workers`, or an earlier :func:`run_jobs`)? False with ``workers`` < 2."""
    return workers > 1 and (*(id(c) for c in context), workers - 1) in _POOLS


def _log_warm_failure(fut: Future) -> None:
    """A worker's preparation failed: say so (its jobs still run; they import what they need themselves)."""
    if not fut.cancelled() and fut.exception() is not None:
        log.warning("a worker's preparation failed: %r", fut.exception())


def _run_job(key: tuple[int, ...], fn: Callable[..., Any], args: tuple[Any, ...]
             ) -> tuple[Any, float]:  # pragma: no cover - runs in a worker process
    """In a worker: ``fn(*context, *args)``; its result and CPU time [s]."""
    c0 = time.process_time()
    return fn(*_CONTEXTS[key], *args), time.process_time() - c0


def send_early(context: tuple[Any, ...], workers: int, fn: Callable[..., Any], job: tuple[Any, ...]) -> Future | None:
    """Hand one job to the worker of a pool :func:`start_workers` started for this ``context`` and
    ``workers`` before the other jobs are known: the job the caller knows will be the longest (the
    first :func:`run_jobs` would send a worker). Pass the returned future to :func:`run_jobs` as
    ``early`` with that job's index. None (nothing sent; :func:`run_jobs` sends it as usual) unless
    exactly one worker process is running for them."""
    if workers != 2 or not workers_started(context, workers):
        return None
    key = (*(id(c) for c in context), workers - 1)
    pool = _POOLS[key]
    try:
        with interrupt.children_start_deaf():
            return pool.submit(_run_job, key, fn, tuple(job))
    except (BrokenProcessPool, RuntimeError):  # pragma: no cover - the pool is gone: run_jobs copes
        _POOLS.pop(key, None)
        return None


def run_jobs(context: tuple[Any, ...], fn: Callable[..., Any], jobs: Sequence[tuple[Any, ...]],
             cost: Sequence[float], workers: int, early: dict[int, Future] | None = None) -> tuple[list[Any], float]:
    """``[fn(*context, *job) for job in jobs]`` computed by this process and ``workers − 1``
    forked worker processes (see the module docstring). ``cost``: an estimate per job. The jobs are
    handed out longest estimate first, each to the first process that is free (this one takes the
    next job whenever it finishes one; a worker is sent the next as soon as it returns one), so a
    wrong estimate leaves no process idle while jobs wait. ``early``: jobs already sent to the worker
    (:func:`send_early`), by index. Returns the results in job order and the CPU time [s] the workers
    spent (this process's own is its ``process_time``)."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers: expected an integer >= 1, got {workers!r}")
    if len(cost) != len(jobs):
        raise ValueError(f"cost: expected one estimate per job ({len(jobs)}), got {len(cost)}")
    early = dict(early or {})
    n_proc = max(min(workers, len(jobs)), 2 if early else 1)
    got = _pool(context, n_proc - 1) if n_proc > 1 else None
    if got is None:
        return [fn(*context, *job) for job in jobs], 0.0
    key, pool = got
    order = sorted((i for i in range(len(jobs)) if i not in early), key=lambda i: -float(cost[i]))
    lock = threading.Lock()
    nxt, pending, worker_cpu = [0], [0], [0.0]   # next job of ``order``, jobs at the workers, their CPU [s]
    here: list[int] = []                         # jobs a failed worker hands back to this process
    results: list[Any] = [None] * len(jobs)
    errors: list[BaseException] = []
    all_done = threading.Event()
    sent: dict[int, Future] = {}                 # jobs at the workers, by index

    def take(to_worker: bool) -> int | None:
        """The next job; one for a worker is counted as pending in the same step, so that this
        thread never finds a job in neither place."""
        with lock:
            if nxt[0] >= len(order):
                return None
            nxt[0] += 1
            pending[0] += to_worker
            return order[nxt[0] - 1]

    def settle(i: int | None = None) -> None:
        """A worker's job is over (``i``: to be run here instead)."""
        with lock:
            if i is not None:
                here.append(i)
            pending[0] -= 1
            if pending[0] == 0:
                all_done.set()

    def send() -> None:   # runs in this thread or in the pool's callback thread
        i = take(to_worker=True)
        if i is None:
            return
        try:
            with interrupt.children_start_deaf():   # a worker forked here starts with Ctrl-C blocked
                fut = pool.submit(_run_job, key, fn, tuple(jobs[i]))
        except (BrokenProcessPool, RuntimeError):  # pragma: no cover - the pool is gone: run it here
            log.warning("worker processes unavailable; running the remaining jobs here")
            _POOLS.pop(key, None)
            settle(i)
            return
        with lock:
            sent[i] = fut
        fut.add_done_callback(functools.partial(returned, i=i))

    def returned(fut: Future, i: int) -> None:
        with lock:
            sent.pop(i, None)
        try:
            results[i], cpu = fut.result()
        except CancelledError:   # taken back before a worker started it (see the wait below): run here
            settle(i)
            return
        except BrokenProcessPool:  # pragma: no cover - a worker died: its job runs here
            log.warning("a worker process died; running its job here")
            _POOLS.pop(key, None)
            settle(i)
            return
        except BaseException as exc:  # noqa: BLE001 - re-raised in the calling thread
            errors.append(exc)
        else:
            with lock:
                worker_cpu[0] += cpu
            if key in _POOLS:
                send()
        settle()

    for j, fut in early.items():   # sent before: pending at the worker from now on
        with lock:
            pending[0] += 1
            sent[j] = fut
        fut.add_done_callback(functools.partial(returned, i=j))
    for _ in range(n_proc - 1 - len(early)):
        send()
    try:
        while (i := take(to_worker=False)) is not None:
            interrupt.check()   # a signal a solver turned into its own error stops here, not after every job
            results[i] = fn(*context, *jobs[i])
    except BaseException:
        with lock:   # no further job goes to a worker
            nxt[0] = len(order)
        raise
    with lock:
        if pending[0] == 0:
            all_done.set()
    waited = 0.0
    while not all_done.wait(timeout=0.5):
        waited += 0.5
        if waited < STALL_S:
            continue
        with lock:   # a job the pool never handed to its worker is run here instead
            stalled = [f for f in sent.values() if not f.running() and not f.done()]
        for f in stalled:
            if f.cancel():
                log.warning("a job sent to a worker process did not start within %.0f s; running it here", waited)
    if errors:
        raise errors[0]
    for i in here:   # after a worker died, or a job it never started
        results[i] = fn(*context, *jobs[i])
    return results, worker_cpu[0]
