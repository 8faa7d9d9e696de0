"""Kernels compiled to C in the background, for the next process.

The segment NLP's kernels are evaluated from C when a library for them is in the disk cache
(:meth:`optplan.problem.kernels.KernelCache.evaluators`, ``compile_kernels="auto"``), else by
CasADi's SX virtual machine. Compiling a kernel takes the C compiler about a second, and a new
scene needs tens of them, so a run does not wait for it: the kernels it had to evaluate
symbolically are queued (:func:`queue`) and, after the NLP is built, handed to ONE detached,
lowest-priority (``nice 19``) process (:func:`launch`) that compiles them into the cache; later
NLPs and processes load the libraries. At most one such process runs per cache directory (a lock
file holds its pid). ``OPTPLAN_BACKGROUND_COMPILE=0`` turns it off (the test-suite does).

Run as ``python -m optplan.problem.kernel_compiler DIR`` (what :func:`launch` starts): it compiles
the kernels listed in ``DIR/.pending-*.txt`` (lines ``<kernel .casadi file> <optimisation flag>``)
until no list is left.
"""
from __future__ import annotations

import logging
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import casadi as ca

from ..codegen import build_library

__all__ = ["compile_library", "launch", "queue"]
log = logging.getLogger(__name__)

#: (kernel .casadi file, optimisation flag) waiting for :func:`launch`, per cache directory
_QUEUE: dict[Path, set[tuple[str, str]]] = {}
_LOCK = ".background-compile.pid"


def compile_library(fn: ca.Function, lib: Path, opt: str = "-O1") -> bool:
    """Generate C for ``fn`` and compile it into the shared library ``lib``
    (:func:`optplan.codegen.build_library`). False, logged, without a C compiler or when compiling
    fails."""
    with tempfile.TemporaryDirectory() as tmp:
        cname = f"{fn.name()}.c"
        cg = ca.CodeGenerator(cname, {"with_header": False})
        cg.add(fn)
        cg.generate(tmp + os.sep)
        err = build_library(Path(tmp, cname), lib, opt)
    if err is not None:
        log.info("kernel %s not compiled (%s)", fn.name(), err)
        return False
    return True


def enabled() -> bool:
    """Background compiles are on unless ``OPTPLAN_BACKGROUND_COMPILE=0``."""
    return os.environ.get("OPTPLAN_BACKGROUND_COMPILE", "1") != "0"


def queue(directory: Path, name: str, opt: str) -> None:
    """Queue kernel ``name`` (saved as ``directory/name.casadi``) for a background compile."""
    src = directory / f"{name}.casadi"
    if src.exists() and not (directory / f"{name}{opt}.so").exists():
        _QUEUE.setdefault(directory, set()).add((str(src), opt))


def _running(lock: Path) -> bool:
    try:
        pid = int(lock.read_text().strip() or 0)
    except (OSError, ValueError):
        return False
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - another user's process
        return True
    return True


def launch() -> int:
    """Hand every queued kernel to the background compiler of its cache directory: the list is
    written to a ``.pending-*.txt`` file there, and a compiler is started unless one is running
    (it takes up every pending file, also those written while it runs). Returns how many kernels
    were handed over (0 when off or nothing is queued)."""
    if not enabled() or not _QUEUE:
        return 0
    handed = 0
    for directory, items in list(_QUEUE.items()):
        if not items:
            continue
        pending = directory / f".pending-{os.getpid()}-{time.time_ns()}.txt"
        try:
            tmp = pending.with_suffix(".tmp")
            tmp.write_text("".join(f"{src} {opt}\n" for src, opt in sorted(items)))
            os.replace(tmp, pending)               # the compiler never reads half a list
        except OSError as exc:  # pragma: no cover - a read-only cache
            log.info("background kernel compile not queued (%s)", exc)
            continue
        handed += len(items)
        _QUEUE[directory] = set()
        lock = directory / _LOCK
        if _running(lock):
            continue
        try:
            proc = subprocess.Popen([sys.executable, "-m", "optplan.problem.kernel_compiler", str(directory)],
                                    stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                    start_new_session=True, close_fds=True)
        except OSError as exc:  # pragma: no cover - no process to spare
            log.info("background kernel compile not started (%s)", exc)
            continue
        lock.write_text(str(proc.pid))
        log.info("compiling kernels in the background (pid %d)", proc.pid)
    return handed


def main(argv: list[str]) -> int:
    """Compile, at the lowest priority, the kernels of every pending list in the cache directory
    ``argv[0]`` until none is left (see the module docstring)."""
    try:
        os.nice(19)
    except OSError:  # pragma: no cover
        pass
    directory = Path(argv[0])
    lock = directory / _LOCK
    t0, n = time.perf_counter(), 0
    try:
        while True:
            lists = sorted(directory.glob(".pending-*.txt"))
            if not lists:
                break
            for listfile in lists:
                try:
                    items = [line.split() for line in listfile.read_text().splitlines() if line.strip()]
                    listfile.unlink()
                except OSError:
                    continue
                for src, opt in items:
                    path = Path(src)
                    lib = path.parent / f"{path.stem}{opt}.so"
                    if lib.exists() or not path.exists():
                        continue
                    n += compile_library(ca.Function.load(str(path)), lib, opt)
    finally:
        try:
            if lock.read_text().strip() == str(os.getpid()):
                lock.unlink()
        except OSError:
            pass
    log.info("compiled %d kernels in %.1f s", n, time.perf_counter() - t0)
    return 0


if __name__ == "__main__":  # pragma: no cover - the background process
    sys.exit(main(sys.argv[1:]))
