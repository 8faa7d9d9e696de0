"""Compile a ``casadi.Function`` to C and call it through ctypes with preallocated buffers.

CasADi's Python call path costs ~20 µs per call whatever the function; a compiled function called
through ctypes costs ~1-3 µs plus the work itself, which is what hot loops (IK, collision checks,
planners) need. The shared library is cached under ``$OPTPLAN_CACHE`` (default
``~/.cache/optplan``), keyed by a hash of the generated C code; a C compiler (``cc``) is needed the
first time. Each library is checked against the size and SHA-256 recorded when it was written
before it is loaded; a damaged one is quarantined and rebuilt (:mod:`optplan.cache`). :func:`compile_function` falls back to the plain CasADi function, with a logged
warning, when no compiler is available.

Building the symbolic functions and generating their C code to find the library costs ~0.1 s per
kernel at every start. :func:`memo_functions` stores the built functions as set-up memos
(:mod:`optplan.cache`: keyed by the caller's inputs and the optplan source), and
``compile_function(..., memo=...)`` remembers which library a memo's function compiled to, so a
later process loads both without building or generating anything.
"""
from __future__ import annotations

import contextlib
import ctypes
import hashlib
import logging
import os
import shutil
import signal
import subprocess
import tempfile
from collections.abc import Callable
from pathlib import Path

import casadi as ca
import numpy as np

from .cache import memo_dir, memo_name, quarantine, read_memo, record, usable, write_memo
from .errors import CacheError

__all__ = ["CompiledFunction", "FastFunction", "build_library", "c_compiler", "compile_function", "cache_dir",
           "memo_functions"]
log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """The kernel cache folder (:func:`optplan.cache.cache_dir`: ``$OPTPLAN_CACHE``, default
    ``~/.cache/optplan``; :class:`optplan.errors.CacheError` when it is not a usable folder)."""
    from .cache import cache_dir as _cache_dir

    return _cache_dir()


class CompiledFunction:
    """A compiled CasADi function: ``f(*inputs) -> tuple of dense numpy arrays``.

    Inputs are dense vectors/matrices (column-major as CasADi); outputs are returned as fresh
    dense arrays (vectors as 1-D, matrices as 2-D). Not thread-safe (shared work buffers).
    """

    def __init__(self, f: ca.Function, lib_path: Path):
        self.f = f  # the interpreted function (same values)
        self.name = f.name()
        self.lib = ctypes.CDLL(str(lib_path))
        self._fn = getattr(self.lib, self.name)
        sz_arg, sz_res, sz_iw, sz_w = (ctypes.c_longlong() for _ in range(4))
        getattr(self.lib, f"{self.name}_work")(ctypes.byref(sz_arg), ctypes.byref(sz_res),
                                                ctypes.byref(sz_iw), ctypes.byref(sz_w))
        self._iw = np.zeros(max(sz_iw.value, 1), dtype=np.int64)
        self._w = np.zeros(max(sz_w.value, 1), dtype=np.float64)
        self.n_in, self.n_out = f.n_in(), f.n_out()
        self._in_shapes = [f.size_in(i) for i in range(self.n_in)]
        self._in_bufs = [np.zeros(f.nnz_in(i)) for i in range(self.n_in)]
        for i in range(self.n_in):
            if not f.sparsity_in(i).is_dense():
                raise ValueError(f"{self.name}: input {i} must be dense")
        self._out_bufs = [np.zeros(max(f.nnz_out(i), 1)) for i in range(self.n_out)]
        self._out_map = []
        for i in range(self.n_out):
            sp = f.sparsity_out(i)
            rows, cols = sp.get_triplet()
            self._out_map.append((sp.shape, np.array(rows, dtype=np.intp), np.array(cols, dtype=np.intp)))
        self._arg = (ctypes.c_void_p * max(sz_arg.value, self.n_in))()
        self._res = (ctypes.c_void_p * max(sz_res.value, self.n_out))()
        for i, b in enumerate(self._in_bufs):
            self._arg[i] = b.ctypes.data
        for i, b in enumerate(self._out_bufs):
            self._res[i] = b.ctypes.data
        self._iw_p = self._iw.ctypes.data_as(ctypes.c_void_p)
        self._w_p = self._w.ctypes.data_as(ctypes.c_void_p)
        self._fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int]
        self._fn.restype = ctypes.c_int

    def __call__(self, *inputs):
        if len(inputs) != self.n_in:
            raise TypeError(f"{self.name}: expected {self.n_in} inputs, got {len(inputs)}")
        for buf, x, shp in zip(self._in_bufs, inputs, self._in_shapes):
            a = np.asarray(x, dtype=np.float64)
            if a.size != buf.size:
                raise ValueError(f"{self.name}: input of shape {a.shape}, expected {shp}")
            buf[:] = a.reshape(-1, order="F")
        if self._fn(self._arg, self._res, self._iw_p, self._w_p, 0) != 0:
            raise RuntimeError(f"{self.name}: evaluation failed")
        outs = []
        for buf, (shape, rows, cols) in zip(self._out_bufs, self._out_map):
            out = np.zeros(shape)
            out[rows, cols] = buf[:rows.size]
            outs.append(out[:, 0] if shape[1] == 1 else out)
        return tuple(outs)


class FastFunction:
    """A CasADi function with dense inputs and ONE dense vector output for hot loops: compiled
    (:func:`compile_function`) and called with the inputs copied into preallocated buffers and no
    shape checks (inputs already flat, column-major); falls back to the interpreted function."""

    def __init__(self, f: ca.Function, opt: str = "-O2", memo: str | None = None):
        if not f.sparsity_out(0).is_dense():
            raise ValueError(f"{f.name()}: the output must be dense")
        self.f = f
        self.n_out = int(f.nnz_out(0))
        cf = compile_function(f, opt, memo=memo)
        self.compiled = isinstance(cf, CompiledFunction)
        self._cf = cf if self.compiled else None

    def __call__(self, *inputs) -> np.ndarray:
        cf = self._cf
        if cf is None:
            return np.asarray(self.f(*inputs), dtype=float).ravel(order="F")
        for b, x in zip(cf._in_bufs, inputs):
            b[:] = x
        if cf._fn(cf._arg, cf._res, cf._iw_p, cf._w_p, 0) != 0:
            raise RuntimeError(f"{self.f.name()}: evaluation failed")
        return cf._out_bufs[0][:self.n_out].copy()


def c_compiler() -> str | None:
    """The C compiler (``$CC``, else ``cc``, else ``gcc``), or None."""
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


def build_library(c_file: Path, lib: Path, opt: str) -> str | None:
    """Compile the C file into the shared library ``lib``, written atomically (a concurrent
    process never loads half a library). None on success, else why not (no compiler, or the
    compiler's last error lines)."""
    cc = c_compiler()
    if cc is None:
        return "no C compiler"
    tmp_lib = lib.with_name(f"{lib.name}.{os.getpid()}.tmp")
    # its own process group: an interruption stops the compiler's own children (cc1, as, ld) with it
    proc = subprocess.Popen([cc, opt, "-fPIC", "-shared", str(c_file), "-o", str(tmp_lib), "-lm"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _, stderr = proc.communicate()
    except BaseException:
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        with contextlib.suppress(OSError):
            tmp_lib.unlink()
        raise
    if proc.returncode != 0:
        with contextlib.suppress(OSError):
            tmp_lib.unlink()
        return stderr[-500:]
    from .cache import record

    record(tmp_lib, sidecar_for=lib)   # size + SHA-256, checked before every later load
    os.replace(tmp_lib, lib)
    return None


def compile_function(f: ca.Function, opt: str = "-O2", memo: str | None = None):
    """Compile ``f`` (cached) and return a :class:`CompiledFunction`, or ``f`` itself when no C
    compiler is available (a warning is logged once). ``memo``: the name :func:`memo_functions`
    returned for the memo ``f`` belongs to; the library it compiles to is then remembered, and a
    later call loads it without generating the C code again."""
    if c_compiler() is None:
        log.warning("no C compiler found: %s stays an interpreted casadi.Function", f.name())
        return f
    lib_memo = memo_name("library", memo, f.name(), opt) if memo is not None else None
    if lib_memo is not None:
        got = _memo_library(f, lib_memo)
        if got is not None:
            return got
    with tempfile.TemporaryDirectory() as tmp:
        cname = f"{f.name()}.c"
        cg = ca.CodeGenerator(cname, {"with_header": False, "casadi_int": "long long int"})
        cg.add(f)
        cg.generate(tmp + os.sep)
        code = Path(tmp, cname).read_bytes()
        digest = hashlib.sha1(code + opt.encode()).hexdigest()[:16]
        lib = cache_dir() / f"{f.name()}_{digest}.so"
        for _attempt in range(2):   # a damaged entry is quarantined and built once more
            if not usable(lib):
                err = build_library(Path(tmp, cname), lib, opt)
                if err is not None:
                    log.warning("compiling %s failed (%s); using the interpreted function", f.name(), err)
                    return f
            try:
                cf = CompiledFunction(f, lib)
            except (OSError, AttributeError) as exc:   # dlopen refused it, or a symbol is missing
                quarantine(lib, f"does not load: {exc}")
                continue
            if lib_memo is not None:
                write_memo(lib_memo, {"library": lib.name})
            return cf
    log.warning("%s: the compiled library does not load; using the interpreted function", f.name())
    return f


def _memo_library(f: ca.Function, lib_memo: str) -> CompiledFunction | None:
    """The library a memo says ``f`` compiled to, loaded; None when there is no memo, or the library
    is missing, damaged (quarantined) or does not load."""
    got = read_memo(lib_memo)
    name = got.get("library") if got is not None else None
    if not isinstance(name, str) or os.sep in name or not name.endswith(".so"):
        return None
    lib = cache_dir() / name
    if not usable(lib):
        return None
    try:
        return CompiledFunction(f, lib)
    except (OSError, AttributeError) as exc:
        quarantine(lib, f"does not load: {exc}")
        return None


def memo_functions(kind: str, key: tuple, build: Callable[[], dict[str, ca.Function]]
                   ) -> tuple[dict[str, ca.Function], str]:
    """``(build(), memo name)``, where the functions ``build`` returns are stored as a set-up memo
    (:mod:`optplan.cache`): a later process whose ``kind`` and ``key`` (everything the functions
    depend on: the robot's :func:`~optplan.model.digest.kinematics_digest`, settings, bounds) and
    optplan source are the same loads them (``casadi.Function.load``, ~10 ms for a kernel that
    takes ~0.1 s to build) instead of building them. Pass the memo name on to
    :class:`FastFunction` / :func:`compile_function` to skip the code generation too. A damaged
    entry is quarantined and the functions built again."""
    name = memo_name(kind, ca.__version__, *key)  # type: ignore[attr-defined]  # casadi's stubs omit __version__
    got = read_memo(name)
    files = got.get("functions") if got is not None else None
    if isinstance(files, dict) and files:
        fns: dict[str, ca.Function] = {}
        for fname, file in files.items():
            path = memo_dir() / str(file)   # (read_memo found the folder usable)
            if os.sep in str(file) or not usable(path):
                break
            try:
                fns[str(fname)] = ca.Function.load(str(path))
            except RuntimeError as exc:   # a damaged file: build them all again
                quarantine(path, f"does not load: {str(exc).splitlines()[0] if str(exc) else exc}")
                break
        else:
            return fns, name
    fns = build()
    try:
        folder = memo_dir()
    except (CacheError, OSError) as exc:   # no usable cache: built every time
        log.info("memo %s not stored (%s)", name, exc)
        return fns, name
    stored: dict[str, str] = {}
    for fname, fn in fns.items():
        path = folder / f"{name}_{fname}.casadi"
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            fn.save(str(tmp))
            record(tmp, sidecar_for=path)
            os.replace(tmp, path)   # atomic: a concurrent process never reads half a file
        except (OSError, RuntimeError) as exc:
            log.info("memo %s not stored (%s)", path, exc)
            with contextlib.suppress(OSError):
                tmp.unlink()
            return fns, name
        stored[fname] = path.name
    write_memo(name, {"functions": stored})
    return fns, name
