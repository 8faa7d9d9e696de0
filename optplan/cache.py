"""The on-disk kernel cache: its folder, and entries that are verified before they are used.

Compiled kernels (``.so``) and saved CasADi functions (``.casadi``) live under ``$OPTPLAN_CACHE``
(default ``~/.cache/optplan``). Loading a damaged shared library can kill the process (a library
cut short is mapped past the end of its file: SIGBUS), so an entry is checked before it is loaded:

* at write, :func:`record` stores the entry's size and SHA-256 in a sidecar ``<entry>.sha256``;
* before use, :func:`usable` compares the entry with its sidecar; an entry without one (written by
  an older optplan) is checked for a complete ELF image (every loadable segment and the section
  table inside the file) and then recorded;
* a bad entry is moved to ``quarantine/`` in the cache folder, with one warning, and the caller
  rebuilds it — a damaged cache never crashes a run and repairs itself.

``OPTPLAN_CACHE`` that is not a usable folder (a file, a folder that cannot be created or written)
is an error, :class:`optplan.errors.CacheError`, whose one line names the setting — no silent
fallback, since a cache elsewhere would be rebuilt (seconds per kernel) on every run.

**Set-up memos.** What a run computes from the robot alone before it plans (an arm's sampled reach,
the symbolic functions behind the compiled planner kernels) is stored as a *memo* under ``memo/``:
:func:`memo_name` keys it by a hash of the caller's inputs (robot kinematics, settings) and of
:func:`source_fingerprint` — the optplan source that computed it — so an edited or upgraded
optplan never reads a value an older one wrote. Memos are written and checked like the other
entries (:func:`write_memo` atomically with a sidecar, :func:`read_memo` quarantines a damaged one).
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import struct
import time
from pathlib import Path

from .errors import CacheError

__all__ = ["cache_dir", "check_cache_setting", "record", "usable", "verify", "quarantine", "SIDECAR",
           "source_fingerprint", "memo_name", "memo_dir", "read_memo", "write_memo"]
log = logging.getLogger(__name__)

#: the sidecar's suffix: ``<entry>.sha256`` holds ``{"size": bytes, "sha256": hex}``
SIDECAR = ".sha256"


def _setting() -> tuple[Path, str]:
    env = os.environ.get("OPTPLAN_CACHE")
    if env:
        return Path(env), f"OPTPLAN_CACHE={env!r}"
    return Path.home() / ".cache" / "optplan", f"the kernel cache {str(Path.home() / '.cache' / 'optplan')!r}"


def check_cache_setting() -> None:
    """Raise :class:`CacheError` if the cache folder is not usable (see the module docstring);
    creates it when missing. Commands call this before a long run."""
    cache_dir()


def cache_dir() -> Path:
    """The kernel cache folder (created if missing); :class:`CacheError` when it is not usable."""
    d, what = _setting()
    if d.exists() and not d.is_dir():
        raise CacheError(f"{what}: is a file, expected a folder for compiled kernels "
                         "(point OPTPLAN_CACHE at a folder, or unset it for ~/.cache/optplan)")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CacheError(f"{what}: cannot be created ({exc.strerror or exc}); point OPTPLAN_CACHE at a "
                         "writable folder") from None
    if not os.access(d, os.W_OK | os.X_OK):
        raise CacheError(f"{what}: is not writable; point OPTPLAN_CACHE at a writable folder")
    return d


def _sidecar(path: Path) -> Path:
    return path.with_name(path.name + SIDECAR)


def _digest(path: Path) -> tuple[int, str]:
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as f:
        while chunk := f.read(1 << 20):
            h.update(chunk)
            size += len(chunk)
    return size, h.hexdigest()


def record(path: str | Path, sidecar_for: str | Path | None = None) -> None:
    """Store the size and SHA-256 of entry ``path`` in its sidecar (atomically). ``sidecar_for``:
    the name the entry will have (a temporary file about to be renamed). Failures are logged only
    (the entry is then checked structurally when used)."""
    from ._io import write_json

    p = Path(path)
    try:
        size, digest = _digest(p)
        write_json(_sidecar(Path(sidecar_for) if sidecar_for is not None else p), {"size": size, "sha256": digest})
    except OSError as exc:
        log.info("kernel cache: no record for %s (%s)", p, exc)


def _elf_problem(path: Path, size: int) -> str | None:
    """Why the shared library ``path`` is not a complete ELF image, or None (64-bit ELF checked
    segment by segment; other classes by their magic only)."""
    with open(path, "rb") as f:
        head = f.read(64)
        if head[:4] != b"\x7fELF":
            return "not an ELF shared library"
        if len(head) < 64 or head[4] != 2:
            return None if head[4] == 1 else "truncated ELF header"
        end = "<" if head[5] == 1 else ">"
        phoff, shoff = struct.unpack_from(end + "QQ", head, 32)
        phentsize, phnum, shentsize, shnum = struct.unpack_from(end + "HHHH", head, 54)
        if shoff + shnum * shentsize > size or phoff + phnum * phentsize > size:
            return f"cut short ({size} B; its tables end past the file)"
        f.seek(phoff)
        table = f.read(phnum * phentsize)
    for i in range(phnum):
        p_type, _, p_offset, _, _, p_filesz = struct.unpack_from(end + "IIQQQQ", table, i * phentsize)
        if p_type == 1 and p_offset + p_filesz > size:   # PT_LOAD past the end: SIGBUS when touched
            return f"cut short ({size} B; a segment ends at {p_offset + p_filesz} B)"
    return None


def verify(path: str | Path) -> str | None:
    """Why cache entry ``path`` must not be used, or None when it matches its record (or, without a
    record, is a complete ELF image — then recorded)."""
    p = Path(path)
    try:
        size = p.stat().st_size
    except OSError as exc:
        return f"unreadable ({exc.strerror or exc})"
    if size == 0:
        return "empty"
    try:
        rec = json.loads(_sidecar(p).read_text())
        want_size, want_hash = int(rec["size"]), str(rec["sha256"])
    except (OSError, ValueError, KeyError, TypeError):
        rec = None
    try:
        if rec is not None:
            if size != want_size:
                return f"{size} B, recorded {want_size} B"
            if _digest(p)[1] != want_hash:
                return "content differs from its recorded SHA-256"
            return None
        if p.suffix == ".so":
            why = _elf_problem(p, size)
            if why is not None:
                return why
    except (OSError, struct.error) as exc:
        return f"unreadable ({exc})"
    record(p)
    return None


def quarantine(path: str | Path, reason: str) -> None:
    """Move the bad entry ``path`` (and its sidecar) to ``quarantine/`` beside the cache folder's
    entries, with one warning; the caller rebuilds it."""
    p = Path(path)
    try:
        root = cache_dir()
    except CacheError:
        root = p.parent
    qdir = root / "quarantine"
    dest = qdir / f"{p.name}.{time.time_ns()}"
    try:
        qdir.mkdir(parents=True, exist_ok=True)
        os.replace(p, dest)
        where = f"moved to {dest}"
    except OSError:
        with contextlib.suppress(OSError):
            p.unlink()
        where = "removed"
    with contextlib.suppress(OSError):
        os.replace(_sidecar(p), dest.with_name(dest.name + SIDECAR))
    log.warning("kernel cache: %s is damaged (%s); %s, rebuilding it", p, reason, where)


def usable(path: str | Path) -> bool:
    """True when entry ``path`` exists and passes :func:`verify`; a bad entry is quarantined
    (False), so the caller builds it again."""
    p = Path(path)
    if not p.exists():
        return False
    why = verify(p)
    if why is None:
        return True
    quarantine(p, why)
    return False


# --------------------------------------------------------------------------- set-up memos
_FINGERPRINT: list[str] = []


def source_fingerprint() -> str:
    """A hash of the optplan package's source files (relative path, size and modification time of
    every ``.py`` file; computed once per process, ~2 ms): a memo written by other source is not read."""
    if not _FINGERPRINT:
        root = Path(__file__).resolve().parent
        h = hashlib.sha256()
        for dirpath, dirs, files in os.walk(root):
            dirs.sort()
            for name in sorted(files):
                if name.endswith(".py"):
                    path = os.path.join(dirpath, name)
                    try:
                        st = os.stat(path)
                    except OSError:   # pragma: no cover - removed while walking
                        continue
                    h.update(f"{os.path.relpath(path, root)}:{st.st_size}:{st.st_mtime_ns};".encode())
        _FINGERPRINT.append(h.hexdigest()[:16])
    return _FINGERPRINT[0]


def memo_name(kind: str, *parts: object) -> str:
    """The memo name of ``kind`` (a short word, e.g. ``"reach"``) for the inputs ``parts`` (bytes,
    or anything whose ``repr`` is exact: strings, ints, floats, tuples of them) and this optplan
    source (:func:`source_fingerprint`): ``<kind>_<hash>``."""
    if not kind.isidentifier():
        raise ValueError(f"memo kind: expected a short identifier, got {kind!r}")
    h = hashlib.sha256(f"{kind}:{source_fingerprint()}".encode())
    for p in parts:
        b = p if isinstance(p, bytes) else repr(p).encode()
        h.update(len(b).to_bytes(8, "little") + b)
    return f"{kind}_{h.hexdigest()[:20]}"


def memo_dir() -> Path:
    """The memo folder ``memo/`` of the cache folder (created if missing)."""
    d = cache_dir() / "memo"
    d.mkdir(exist_ok=True)
    return d


def read_memo(name: str) -> dict | None:
    """The memo ``name`` (:func:`memo_name`) written by :func:`write_memo`, or None when there is none,
    the cache is unusable, or the entry is damaged (then quarantined, with one warning)."""
    try:
        path = memo_dir() / f"{name}.json"
    except (CacheError, OSError):
        return None
    if not usable(path):
        return None
    try:
        value = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        quarantine(path, f"not readable JSON ({exc})")
        return None
    if not isinstance(value, dict):
        quarantine(path, f"expected a JSON object, got {type(value).__name__}")
        return None
    return value


def write_memo(name: str, value: dict) -> None:
    """Store ``value`` (JSON) as memo ``name``: written to a temporary file, recorded (size and
    SHA-256) and renamed, so a concurrent reader sees the whole entry or none. Failures are logged
    only (the value is then computed again next time)."""
    try:
        path = memo_dir() / f"{name}.json"
        text = json.dumps(value)
    except (CacheError, OSError, TypeError, ValueError) as exc:
        log.info("memo %s not stored (%s)", name, exc)
        return
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        record(tmp, sidecar_for=path)
        os.replace(tmp, path)
    except OSError as exc:
        log.info("memo %s not stored (%s)", name, exc)
        with contextlib.suppress(OSError):
            tmp.unlink()
