"""Where the benchmarks' units run: in this process, in a local process pool, or on a Dask
cluster (one machine or many).

``map_unordered(fn, units, engine=..., jobs=..., address=...)`` yields ``fn(unit)`` for every unit,
in completion order, **in the calling process**: the caller is the only writer of the results
file, so a resumable JSONL run gets exactly one line per finished unit whatever the engine. Units
carry their own seeds (``SeedSequence(seed, spawn_key=(trial,))``), so a unit's result does not
depend on the engine, the number of workers or the order in which units finish.

Engines:

* ``"local"``: ``jobs <= 1`` runs the units one after the other in this process; ``jobs > 1`` in a
  pool of ``jobs`` spawned worker processes.
* ``"dask"`` (optional extra ``dask``: ``pip install "optplan[dask]"``): with ``address=None`` a
  local cluster of ``jobs`` single-threaded worker processes is started and closed again; with
  ``address="tcp://host:8786"`` the units go to that running scheduler (start one with
  ``dask scheduler`` and workers with ``dask worker tcp://host:8786 --nthreads 1`` on machines that
  have optplan installed in the same version). A worker that dies is replaced and its unit re-run
  by the scheduler; the result reaches the writer once.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

__all__ = ["ENGINES", "EngineUnavailable", "validate_engine", "engine_error", "map_unordered"]
log = logging.getLogger(__name__)

ENGINES = ("local", "dask")


class EngineUnavailable(ImportError):
    """The engine's optional dependency is not installed."""


def validate_engine(engine: str, jobs: int, address: str | None) -> None:
    """Raise ``ValueError`` naming the argument when the engine settings do not fit together."""
    if engine not in ENGINES:
        raise ValueError(f"--engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if not isinstance(jobs, int) or isinstance(jobs, bool) or jobs < 1:
        raise ValueError(f"--jobs: expected an integer >= 1, got {jobs!r}")
    if address is not None and engine != "dask":
        raise ValueError(f"--address: only with --engine dask (got --engine {engine} --address {address})")
    if address is not None and not str(address).strip():
        raise ValueError("--address: expected a scheduler address such as tcp://127.0.0.1:8786, got ''")


def engine_error(engine: str, jobs: int, address: str | None) -> str | None:
    """The message of what is wrong with the engine settings (bad values, or the ``dask`` extra
    missing), or None when they are usable — for command lines that report instead of raising."""
    try:
        validate_engine(engine, jobs, address)
    except ValueError as exc:
        return str(exc)
    if engine == "dask":
        try:
            import distributed  # noqa: F401
        except ImportError:
            return "--engine dask needs the optional extra 'dask': pip install \"optplan[dask]\""
    return None


def _run_with_init(fn: Callable, initializer: Callable | None, initargs: tuple, unit):
    """One unit on a worker: the (idempotent) initializer first, then the unit."""
    from ..interrupt import worker_init

    worker_init(initializer, *initargs)
    return fn(unit)


def map_unordered(fn: Callable[[Any], Any], units: Sequence, *, engine: str = "local", jobs: int = 1,
                  address: str | None = None, initializer: Callable | None = None, initargs: tuple = (),
                  serial_initializer: bool = True, client=None, connect_timeout: float = 30.0) -> Iterator:
    """Yield ``fn(u)`` for every ``u`` in ``units`` (completion order) in the calling process.

    ``fn`` and ``initializer`` must be importable module-level functions for process engines.
    ``initializer(*initargs)`` runs once per worker process (before each unit on Dask, where it
    must be idempotent and cheap after the first call); with ``serial_initializer=False`` it is
    not run for the in-process serial engine. ``client``: an existing ``distributed.Client`` to
    use instead of ``address`` (it is left open); ``connect_timeout`` [s]: how long to wait for
    the scheduler at ``address``."""
    validate_engine(engine, jobs, address)
    units = list(units)
    if not units:
        return
    if engine == "local":
        if jobs <= 1 or len(units) == 1:
            if initializer is not None and serial_initializer:
                initializer(*initargs)
            for u in units:
                yield fn(u)
            return
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        from ..interrupt import children_start_deaf, worker_init

        # workers ignore Ctrl-C (the terminal sends it to them too; this process stops them) and die with it;
        # they start with it blocked, so one that is still booting prints nothing either
        with children_start_deaf():
            pool = ctx.Pool(min(jobs, len(units)), initializer=worker_init, initargs=(initializer, *initargs))
        with pool:
            yield from pool.imap_unordered(fn, units, chunksize=1)
        return
    yield from _dask_map(fn, units, jobs=jobs, address=address, initializer=initializer, initargs=initargs,
                         client=client, connect_timeout=connect_timeout)


def _dask_map(fn, units: list, *, jobs: int, address: str | None, initializer, initargs, client,
              connect_timeout: float) -> Iterable:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as exc:
        raise EngineUnavailable("--engine dask needs the optional extra 'dask': pip install \"optplan[dask]\" "
                                f"({exc})") from exc
    if not log.isEnabledFor(logging.INFO):   # distributed logs every connection at INFO by default
        for name in ("distributed", "distributed.scheduler", "distributed.core", "distributed.worker",
                     "distributed.nanny", "distributed.http.proxy"):
            logging.getLogger(name).setLevel(logging.WARNING)
    cluster = None
    own_client = client is None
    if client is None:
        if address is None:
            cluster = LocalCluster(n_workers=min(jobs, len(units)), threads_per_worker=1, processes=True,
                                   dashboard_address=None,
                                   silence_logs=logging.INFO if log.isEnabledFor(logging.INFO) else logging.CRITICAL)
            client = Client(cluster)
        else:
            try:
                client = Client(address, timeout=f"{float(connect_timeout)}s")
            except OSError as exc:
                raise ConnectionError(f"--address: no Dask scheduler answers at {address!r} ({exc})") from exc
    log.info("dask engine: %s", client)
    futures = []
    try:
        futures = [client.submit(_run_with_init, fn, initializer, initargs, u, pure=False) for u in units]
        for fut in as_completed(futures):
            res = fut.result()   # a unit that raised re-raises here; the lines written so far stay
            fut.release()
            yield res
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
        if own_client:
            client.close()
        if cluster is not None:
            cluster.close()


def parse_planner_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``"ompl-atlas:tolerance=1e-4:range=0.5"`` → ``("ompl-atlas", {"tolerance": 1e-4, "range": 0.5})``
    (values: int, float, true/false/none, else string). The whole spec is the planner's label."""
    name, *opts = spec.split(":")
    out: dict[str, Any] = {}
    for o in opts:
        if "=" not in o:
            raise ValueError(f"planner option {o!r} in {spec!r}: expected key=value")
        k, v = o.split("=", 1)
        low = v.lower()
        val: Any
        if low in ("true", "false"):
            val = low == "true"
        elif low == "none":
            val = None
        else:
            try:
                val = int(v)
            except ValueError:
                try:
                    val = float(v)
                except ValueError:
                    val = v
        out[k.strip()] = val
    return name.strip(), out
