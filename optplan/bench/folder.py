"""A benchmark's output folder has one owner, and its ``results.jsonl`` is read line by line with checks.

:func:`folder_lock` takes an exclusive ``fcntl.flock`` on ``DIR/.optplan.lock`` for the whole run:
a second run writing to the same folder is refused at once with a message naming the folder and
the process that holds it (the lock ends with its process, also when it is killed, so there is
no stale lock to remove). :func:`read_result_lines` reads a results file and skips, with one
warning naming the line number, every line that is not a result line (not JSON, not an object,
no scene name or no integer trial index), so a foreign or damaged line never stops a resume.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import logging
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import FolderBusyError

__all__ = ["LOCK_NAME", "folder_lock", "read_result_lines", "dedupe"]
log = logging.getLogger(__name__)

#: the lock file in a benchmark's output folder
LOCK_NAME = ".optplan.lock"
#: foreign lines reported one by one (the rest are counted)
MAX_REPORTED = 10


@contextlib.contextmanager
def folder_lock(folder: str | Path) -> Iterator[Path]:
    """Hold the output folder ``folder`` (created if missing) for this process while the block runs;
    :class:`~optplan.errors.FolderBusyError` when another process holds it."""
    d = Path(folder)
    d.mkdir(parents=True, exist_ok=True)
    path = d / LOCK_NAME
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
            except OSError:  # pragma: no cover
                holder = "unknown"
            raise FolderBusyError(f"--out {str(d)!r}: another optplan run (pid {holder}) is writing to this "
                                  "folder; wait for it to end or choose another --out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield d
    finally:
        os.close(fd)   # releases the lock


def _problem(obj: Any) -> str | None:
    if not isinstance(obj, dict):
        return f"a JSON {type(obj).__name__}, not an object"
    if not isinstance(obj.get("scene"), str):
        return "no scene name"
    trial = obj.get("trial")
    if isinstance(trial, bool) or not isinstance(trial, int):
        return f"trial {trial!r} is not an integer"
    return None


def read_result_lines(path: str | Path) -> list[dict]:
    """The result lines of ``path`` (a ``results.jsonl``); every other line is skipped with a warning
    that names its line number and what is wrong with it."""
    p = Path(path)
    rows: list[dict] = []
    if not p.exists():
        return rows
    bad = 0
    with open(p, encoding="utf-8", errors="replace") as f:
        for n, line in enumerate(f, start=1):
            text = line.strip()
            if not text:
                continue
            try:
                obj = json.loads(text)
                why = _problem(obj)
            except (json.JSONDecodeError, RecursionError):
                why = "not JSON"
            if why is None:
                rows.append(obj)
                continue
            bad += 1
            if bad <= MAX_REPORTED:
                shown = text if len(text) <= 60 else text[:57] + "..."
                log.warning("%s line %d: not a result line (%s: %s); skipped", p, n, why, shown)
    if bad > MAX_REPORTED:
        log.warning("%s: %d lines that are not result lines skipped in all", p, bad)
    return rows


def dedupe(rows: list[dict], key) -> list[dict]:
    """One row per ``key(row)`` (the last one written wins), in first-seen order of the keys."""
    keep: dict[Any, dict] = {}
    for r in rows:
        keep[key(r)] = r
    return list(keep.values())
