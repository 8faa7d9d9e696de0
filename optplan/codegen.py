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
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from .cache import memo_dir, memo_name, quarantine, read_memo, record, usable, write_memo
from .errors import CacheError

__all__ = ["CompiledFunction", "FastFunction", "MemoFunctions", "build_library", "c_compiler", "compile_function",
           "cache_dir", "call_dense", "memo_functions"]
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

    def __init__(self, f: ca.Function | None, lib_path: Path, signature: dict | None = None,
                 loader: Callable[[], ca.Function] | None = None):
        """``f``: the function; or None with its :func:`signature` and a ``loader`` that gives it
        when :attr:`f` is first read (a library found through a set-up memo needs no function)."""
        if signature is None:
            if f is None:
                raise ValueError("CompiledFunction: give the function, or its signature and a loader")
            signature = _signature(f)
        elif f is None and loader is None:
            raise ValueError("CompiledFunction: a signature without the function needs a loader")
        sig = signature
        self._f, self._loader = f, loader
        self.name = str(sig["name"])
        self.lib = ctypes.CDLL(str(lib_path))
        self._fn = getattr(self.lib, self.name)
        sz_arg, sz_res, sz_iw, sz_w = (ctypes.c_longlong() for _ in range(4))
        getattr(self.lib, f"{self.name}_work")(ctypes.byref(sz_arg), ctypes.byref(sz_res),
                                                ctypes.byref(sz_iw), ctypes.byref(sz_w))
        self._iw = np.zeros(max(sz_iw.value, 1), dtype=np.int64)
        self._w = np.zeros(max(sz_w.value, 1), dtype=np.float64)
        ins, outs = sig["in"], sig["out"]
        self.n_in, self.n_out = len(ins), len(outs)
        self._in_shapes = [(int(r), int(c)) for r, c, _, _ in ins]
        self._in_bufs = [np.zeros(int(nnz)) for _, _, nnz, _ in ins]
        for i, (_, _, _, dense) in enumerate(ins):
            if not dense:
                raise ValueError(f"{self.name}: input {i} must be dense")
        self._out_bufs = [np.zeros(max(len(rows), 1)) for _, _, rows, _ in outs]
        self._out_map = [((int(r), int(c)), np.array(rows, dtype=np.intp), np.array(cols, dtype=np.intp))
                         for r, c, rows, cols in outs]
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

    @property
    def f(self) -> ca.Function:
        """The interpreted function (same values)."""
        if self._f is None:
            assert self._loader is not None
            self._f = self._loader()
        return self._f

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


def _signature(f: ca.Function) -> dict:
    """What :class:`CompiledFunction` needs of ``f`` besides its library (JSON): name, inputs
    ``[rows, cols, nnz, dense]``, outputs ``[rows, cols, row indices, column indices]``."""
    ins = [[*f.size_in(i), int(f.nnz_in(i)), bool(f.sparsity_in(i).is_dense())] for i in range(f.n_in())]
    outs = []
    for i in range(f.n_out()):
        sp = f.sparsity_out(i)
        rows, cols = sp.get_triplet()
        outs.append([*sp.shape, [int(r) for r in rows], [int(c) for c in cols]])
    return {"name": f.name(), "in": ins, "out": outs}


class FastFunction:
    """A CasADi function with dense inputs and ONE dense vector output for hot loops: compiled
    (:func:`compile_function`) and called with the inputs copied into preallocated buffers and no
    shape checks (inputs already flat, column-major); falls back to the interpreted function.
    :meth:`of` makes one from a set-up memo (:func:`memo_functions`)."""

    def __init__(self, f: ca.Function, opt: str = "-O2", memo: str | None = None):
        if not f.sparsity_out(0).is_dense():
            raise ValueError(f"{f.name()}: the output must be dense")
        self._f: ca.Function | None = f
        self.n_out = int(f.nnz_out(0))
        cf = compile_function(f, opt, memo=memo)
        self.compiled = isinstance(cf, CompiledFunction)
        self._cf = cf if self.compiled else None

    @classmethod
    def of(cls, functions: MemoFunctions, key: str, opt: str = "-O2") -> FastFunction:
        """The function ``key`` of a set-up memo, compiled. When an earlier process compiled it, its
        library is loaded through the memo's record and the function itself is read from disk only if
        :attr:`f` is used (the interpreted fallback)."""
        memo = f"{functions.name}/{key}"
        if c_compiler() is not None:
            got = _memo_library(memo, opt, lambda: functions[key])
            if got is not None and len(got._out_map) == 1 and len(got._out_map[0][1]) == np.prod(got._out_map[0][0]):
                self = cls.__new__(cls)
                self._f, self._cf, self.compiled = None, got, True
                self.n_out = len(got._out_map[0][1])
                return self
        return cls(functions[key], opt, memo=memo)

    @property
    def f(self) -> ca.Function:
        """The interpreted function."""
        if self._f is None:
            assert self._cf is not None
            self._f = self._cf.f
        return self._f

    def __call__(self, *inputs) -> np.ndarray:
        cf = self._cf
        if cf is None:
            return np.asarray(self.f(*inputs), dtype=float).ravel(order="F")
        for b, x in zip(cf._in_bufs, inputs):
            b[:] = x
        if cf._fn(cf._arg, cf._res, cf._iw_p, cf._w_p, 0) != 0:
            raise RuntimeError(f"{cf.name}: evaluation failed")
        return cf._out_bufs[0][:self.n_out].copy()


def _dense_input(a: Any, shape: tuple[int, int]) -> np.ndarray | None:
    """``a`` as the column-major numbers of an input of ``shape``: an array of that shape (or
    its numbers already in column-major order), a narrower block of rows repeated across (as
    CasADi repeats it for a mapped function) or one number; None otherwise."""
    x = np.asarray(a, dtype=float)
    r, c = shape
    if x.ndim == 2 and x.shape == (r, c):
        return np.ascontiguousarray(x.reshape(-1, order="F"))
    if x.ndim <= 1 and x.size == r * c:
        return np.ascontiguousarray(x.reshape(-1))
    if x.ndim <= 1 and x.size == r and c > 1:
        return np.tile(x, c)
    if x.ndim == 2 and x.shape[0] == r and 0 < x.shape[1] < c and c % x.shape[1] == 0:
        return np.tile(x.reshape(-1, order="F"), c // x.shape[1])
    if x.size == 1:
        return np.full(r * c, float(x.reshape(-1)[0]))
    return None


def call_dense(f: ca.Function, *inputs: Any) -> list[np.ndarray]:
    """``f`` evaluated at numeric ``inputs`` (arrays of each input's shape, a column a mapped
    input repeats, or a number), its outputs as dense arrays of their shapes.

    The numbers go to CasADi through its function buffer (the arrays' memory, no matrix objects):
    converting an array to and from CasADi's ``DM`` costs ~0.1 µs per number, several times the
    evaluation of a mapped kernel over a few hundred points. Functions with a sparse input or
    output, or inputs of another size, take CasADi's ordinary call (same results)."""
    outs: list[np.ndarray] = []
    args: list[np.ndarray] = []
    if len(inputs) == f.n_in() and all(f.sparsity_in(i).is_dense() for i in range(f.n_in())) \
            and all(f.sparsity_out(i).is_dense() for i in range(f.n_out())):
        for i, a in enumerate(inputs):
            x = _dense_input(a, f.size_in(i))
            if x is None:
                break
            args.append(x)
    if len(args) == f.n_in():
        buf: Any
        try:
            buf, run = f.buffer()
        except (AttributeError, NotImplementedError, RuntimeError):   # a CasADi without buffers
            buf = None
        if buf is not None:
            outs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
            try:
                for i, x in enumerate(args):
                    buf.set_arg(i, x.data)
                for i, o in enumerate(outs):
                    buf.set_res(i, o.data)
            except (NotImplementedError, TypeError):   # another buffer signature: the ordinary call
                buf = None
        if buf is not None:
            run()   # ``args`` and ``outs`` hold the memory the buffer points to until here
            if buf.ret() != 0:
                raise RuntimeError(f"{f.name()}: evaluation failed (return code {buf.ret()})")
            return [o.reshape(f.size_out(i), order="F") for i, o in enumerate(outs)]
    res = f.call([ca.DM(np.asarray(a, dtype=float)) for a in inputs])
    return [np.asarray(ca.DM(r).full(), dtype=float) for r in res]


def c_compiler() -> str | None:
    """The C compiler (``$CC``, else ``cc``, else ``gcc``), or None."""
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


#: the flags of a build for the building machine (:func:`build_library` with ``native=True``): its instruction set
#: (AVX and the like where the CPU has them), without fused multiply-adds, so that every operation rounds as in a
#: portable build (the same results, bit for bit, as the tests' recorded searches)
NATIVE_FLAGS = ("-march=native", "-ffp-contract=off")


def native_builds() -> bool:
    """Whether the planning kernels are built for this machine's CPU (:data:`NATIVE_FLAGS`): yes unless
    ``$OPTPLAN_NATIVE_BUILD`` is ``0`` (portable builds, e.g. for a cache folder that machines whose
    ``/proc/cpuinfo`` cannot be read share) or the CPU cannot be identified."""
    return os.environ.get("OPTPLAN_NATIVE_BUILD", "1").strip() != "0" and cpu_tag() != "generic"


def build_tag() -> str:
    """The part of a planning kernel's cache name that says how it is built: :func:`cpu_tag` for a native
    build, ``"portable"`` otherwise (:func:`native_builds`)."""
    return cpu_tag() if native_builds() else "portable"


def cpu_tag() -> str:
    """A short hash of this machine's CPU (architecture, model and feature flags; ``"generic"`` where they
    cannot be read): part of the cache name of a library built with :data:`NATIVE_FLAGS`, so that a cache
    folder shared by machines of different CPUs never hands one of them an instruction it lacks."""
    if _CPU_TAG:
        return _CPU_TAG[0]
    import platform

    ident = [platform.machine()]
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                key = line.split(":", 1)[0].strip()
                if key in ("vendor_id", "model name", "flags", "Features", "CPU implementer", "CPU part"):
                    ident.append(line.strip())
                elif not line.strip() and len(ident) > 1:
                    break   # the first processor's block
    except OSError:
        pass
    tag = hashlib.sha1("\n".join(ident).encode()).hexdigest()[:8] if len(ident) > 1 else "generic"
    _CPU_TAG.append(tag)
    return tag


_CPU_TAG: list[str] = []


def build_library(c_file: Path, lib: Path, opt: str, *, native: bool = False) -> str | None:
    """Compile the C file into the shared library ``lib``, written atomically (a concurrent
    process never loads half a library). None on success, else why not (no compiler, or the
    compiler's last error lines). ``native``: with :data:`NATIVE_FLAGS` when :func:`native_builds` (the
    caller names ``lib`` with :func:`build_tag`); a compiler that refuses them builds without."""
    if native and native_builds():
        if build_library(c_file, lib, " ".join((opt, *NATIVE_FLAGS))) is None:
            return None
        log.debug("%s: the compiler refused %s; building without", c_file.name, " ".join(NATIVE_FLAGS))
    cc = c_compiler()
    if cc is None:
        return "no C compiler"
    tmp_lib = lib.with_name(f"{lib.name}.{os.getpid()}.tmp")
    # its own process group: an interruption stops the compiler's own children (cc1, as, ld) with it
    proc = subprocess.Popen([cc, *opt.split(), "-fPIC", "-shared", str(c_file), "-o", str(tmp_lib), "-lm"],
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
    if memo is not None:
        got = _memo_library(memo, opt, lambda: f, f)
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
            if memo is not None:
                write_memo(memo_name("library", memo, opt), {"library": lib.name, "signature": _signature(f)})
            return cf
    log.warning("%s: the compiled library does not load; using the interpreted function", f.name())
    return f


def _memo_library(memo: str, opt: str, loader: Callable[[], ca.Function], f: ca.Function | None = None
                  ) -> CompiledFunction | None:
    """The library that the function of ``memo`` compiled to with ``opt``, loaded through the memo's
    record (with its signature: ``f`` need not be given); None when there is no record, or the
    library is missing, damaged (quarantined) or does not load."""
    got = read_memo(memo_name("library", memo, opt))
    name = got.get("library") if got is not None else None
    sig = got.get("signature") if got is not None else None
    if not isinstance(name, str) or os.sep in name or not name.endswith(".so") or not isinstance(sig, dict):
        return None
    lib = cache_dir() / name
    if not usable(lib):
        return None
    try:
        return CompiledFunction(f, lib, signature=sig, loader=loader)
    except (OSError, AttributeError) as exc:
        quarantine(lib, f"does not load: {exc}")
        return None
    except (KeyError, TypeError, ValueError):   # a record of another form: compile as without it
        return None


class MemoFunctions(Mapping):
    """The functions of a set-up memo by key (:func:`memo_functions`), each read from disk when it is
    first used; ``name``: the memo's name."""

    def __init__(self, name: str, files: dict[str, Path], build: Callable[[], dict[str, ca.Function]]):
        self.name = name
        self._files = files
        self._build = build
        self._fns: dict[str, ca.Function] = {}

    def __getitem__(self, key: str) -> ca.Function:
        fn = self._fns.get(key)
        if fn is not None:
            return fn
        path = self._files[key]
        if usable(path):
            try:
                fn = self._fns[key] = ca.Function.load(str(path))
                return fn
            except RuntimeError as exc:   # a damaged file: build them again
                quarantine(path, f"does not load: {str(exc).splitlines()[0] if str(exc) else exc}")
        built = self._build()
        self._fns.update(built)
        _store(self.name, built)
        return self._fns[key]

    def __iter__(self):
        return iter(self._files)

    def __len__(self) -> int:
        return len(self._files)


def _store(name: str, fns: dict[str, ca.Function]) -> dict[str, Path] | None:
    """Save the functions of memo ``name`` and its record; their paths, or None when not stored."""
    try:
        folder = memo_dir()
    except (CacheError, OSError) as exc:   # no usable cache: built every time
        log.info("memo %s not stored (%s)", name, exc)
        return None
    stored: dict[str, Path] = {}
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
            return None
        stored[fname] = path
    write_memo(name, {"functions": {k: p.name for k, p in stored.items()}})
    return stored


def memo_functions(kind: str, key: tuple, build: Callable[[], dict[str, ca.Function]]) -> MemoFunctions:
    """The functions ``build`` returns (by key), stored as a set-up memo (:mod:`optplan.cache`): a
    later process whose ``kind`` and ``key`` (everything the functions depend on: the robot's
    :func:`~optplan.model.digest.kinematics_digest`, settings, bounds) and optplan source are the
    same reads each function from disk when it is first used (``casadi.Function.load``, ~10 ms for a
    kernel that takes ~0.1 s to build) instead of building them; :meth:`FastFunction.of` loads a
    compiled one without reading it at all. A damaged entry is quarantined and the functions built again."""
    name = memo_name(kind, ca.__version__, *key)  # type: ignore[attr-defined]  # casadi's stubs omit __version__
    got = read_memo(name)
    files = got.get("functions") if got is not None else None
    if isinstance(files, dict) and files and all(isinstance(v, str) and os.sep not in v for v in files.values()):
        folder = memo_dir()   # (read_memo found the folder usable)
        return MemoFunctions(name, {str(k): folder / v for k, v in files.items()}, build)
    fns = build()
    stored = _store(name, fns)
    out = MemoFunctions(name, stored or {}, build)
    out._fns.update(fns)
    if stored is None:
        out._files = {k: Path(os.devnull) for k in fns}   # (never read: every function is in memory)
    return out
