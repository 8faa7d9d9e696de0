"""TCBiRRT's task-space sampler and object lead path in native code, with a random stream of their own.

:class:`NativeRandom` is a xoshiro256** generator (C in :mod:`.sampler_csource`) seeded with one 64-bit
integer drawn from a NumPy Generator: the same Generator state gives the same stream, but not NumPy's
draws. :class:`NativeTaskSampler` is :class:`optplan.planners.task_sampling.TaskSampler` in C (the same
probabilities, filter, bridge test and orientation draws; one call per sample, the nearest node of the
tree being extended included), and :func:`native_lead_path` the search of
:func:`~optplan.planners.task_sampling.object_lead_path` (RRT-Connect of the object alone in ξ, then
shortcuts) in one call. Both need the filter's native pose test
(:class:`~optplan.planners.kernel.extend.NativePoseFilter`); the library is the extension library
(:func:`~optplan.planners.kernel.extend.load_extend_library`).
"""
from __future__ import annotations

import ctypes
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from .addresses import AddressCache
from .native import KernelUnavailable
from .sampler_csource import SAMPLER_STATS

if TYPE_CHECKING:
    from ..base import Deadline
    from ..task_sampling import ObjectPoseFilter

__all__ = ["NativeRandom", "NativeTaskSampler", "native_lead_path"]

_P = ctypes.c_void_p
_LL = ctypes.c_longlong
_D = ctypes.c_double


class _Rng(ctypes.Structure):
    _fields_ = [("s", ctypes.c_ulonglong * 4), ("spare", _D), ("has_spare", ctypes.c_int)]


class NativeRandom:
    """A xoshiro256** stream in C, seeded by ``seed`` (an int in [0, 2⁶⁴)) or by one draw of a NumPy
    ``Generator``. :meth:`uniform` and :meth:`normal` draw single values (for tests)."""

    def __init__(self, seed: int | np.random.Generator) -> None:
        from .extend import load_extend_library

        self.lib = load_extend_library()
        if isinstance(seed, np.random.Generator):
            seed = int(seed.integers(0, 2**64, dtype=np.uint64))
        if not isinstance(seed, (int, np.integer)) or not 0 <= int(seed) < 2**64:
            raise ValueError(f"NativeRandom: expected a seed in [0, 2**64) or a numpy Generator, got {seed!r}")
        self._r = _Rng()
        #: the address of the generator's state (for the C code that draws from it)
        self.address = ctypes.addressof(self._r)
        self.lib.tcb_rng_seed(self.address, int(seed))

    def uniform(self) -> float:
        """One draw in [0, 1)."""
        return float(self.lib.tcb_rng_uniform(self.address))

    def normal(self) -> float:
        """One standard normal draw."""
        return float(self.lib.tcb_rng_normal(self.address))


class _Sampler(ctypes.Structure):
    _fields_ = [("rng", _P), ("f", _P), ("lo", _D * 6), ("span", _D * 6), ("filter_tries", ctypes.c_int),
                ("bridge_tries", ctypes.c_int), ("p_bridge", _D), ("sigma", _D * 6), ("goal_bias", _D), ("p_guide", _D),
                ("gsigma", _D * 6), ("p_geo", _D), ("geo_sigma", _D), ("p_lead", _D), ("guide", _P), ("nguide", _LL),
                ("has_ends", ctypes.c_int), ("R0", _D * 9), ("w", _D * 3), ("stats", _LL * len(SAMPLER_STATS))]


def _pose_filter(filt: ObjectPoseFilter | None) -> Any:
    if filt is None:
        return None
    nf = getattr(filt, "_xi_native", None)
    if nf is None:
        raise KernelUnavailable("the task-space filter has no native pose test")
    return nf


class NativeTaskSampler:
    """:class:`~optplan.planners.task_sampling.TaskSampler` in C, drawing from ``rng`` (a :class:`NativeRandom`).

    The arguments are the Python sampler's (``lo``/``hi``: the ξ box; ``bridge_sigma``: position [m], angle
    [rad]; ``guide_sigma`` likewise; ``geodesic_sigma`` [rad]); ``filt`` must have the native pose test
    (else :class:`~optplan.planners.kernel.native.KernelUnavailable`). :attr:`guide` (the lead path, n × 6, or
    None) may be set at any time; counters in :attr:`stats` (``filter_calls`` are also added to the filter's
    ``n_calls`` by :meth:`sync_filter_calls`)."""

    def __init__(self, filt: ObjectPoseFilter | None, lo: Any, hi: Any, rng: NativeRandom, *, filter_tries: int = 30,
                 bridge_probability: float = 0.0, bridge_sigma: tuple[float, float] = (0.3, 0.4),
                 bridge_tries: int = 60, goal_bias: float = 0.0, guide_probability: float = 0.0,
                 guide_sigma: tuple[float, float] = (0.05, 0.05), geodesic_probability: float = 0.0,
                 geodesic_sigma: float = 0.15, endpoints: tuple[np.ndarray, np.ndarray] | None = None,
                 lead_orientation_probability: float = 0.0) -> None:
        self.lib = rng.lib
        nf = _pose_filter(filt)
        self.filt = filt
        self.rng = rng
        lo_a, hi_a = np.asarray(lo, float), np.asarray(hi, float)
        if lo_a.shape != (6,) or hi_a.shape != (6,):
            raise ValueError(f"NativeTaskSampler: expected a ξ box of 6 lower and 6 upper bounds, got {lo_a.shape} and {hi_a.shape}")
        s = _Sampler()
        s.rng, s.f = rng.address, (nf._fp if nf is not None else None)
        s.lo[:], s.span[:] = lo_a.tolist(), (hi_a - lo_a).tolist()
        s.filter_tries, s.bridge_tries = int(filter_tries), int(bridge_tries)
        s.p_bridge = float(bridge_probability)
        s.sigma[:] = [bridge_sigma[0]] * 3 + [bridge_sigma[1]] * 3
        s.goal_bias, s.p_guide = float(goal_bias), float(guide_probability)
        s.gsigma[:] = [guide_sigma[0]] * 3 + [guide_sigma[1]] * 3
        s.p_geo, s.geo_sigma, s.p_lead = float(geodesic_probability), float(geodesic_sigma), float(lead_orientation_probability)
        self._s = s
        self._sp = ctypes.addressof(s)
        self._keep = (nf, rng)
        self._guide: np.ndarray | None = None
        self._out = np.zeros(6)
        self._out_p = self._out.ctypes.data
        self._addr = AddressCache(16)   # the trees' key arrays, masks and k-d indexes, the same at most calls
        self._calls0 = 0
        if endpoints is not None:
            self.set_endpoints(*endpoints)

    @property
    def guide(self) -> np.ndarray | None:
        return self._guide

    @guide.setter
    def guide(self, g: np.ndarray | None) -> None:
        if g is None:
            self._guide, self._s.guide, self._s.nguide = None, None, 0
            return
        g = np.ascontiguousarray(g, dtype=float)
        if g.ndim != 2 or g.shape[1] != 6 or not len(g):
            raise ValueError(f"NativeTaskSampler.guide: expected an (n, 6) array of poses with n >= 1, got shape {g.shape}")
        self._guide = g
        self._s.guide, self._s.nguide = g.ctypes.data, len(g)

    def set_endpoints(self, xi_a: np.ndarray, xi_b: np.ndarray) -> None:
        """Start and goal poses: orientation samples follow their geodesic (``geodesic_probability``)."""
        import pinocchio as pin

        R0 = np.asarray(pin.rpy.rpyToMatrix(*(float(v) for v in xi_a[3:6])))
        R1 = np.asarray(pin.rpy.rpyToMatrix(*(float(v) for v in xi_b[3:6])))
        w = np.asarray(pin.log3(R0.T @ R1))
        self._s.R0[:] = R0.reshape(9).tolist()
        self._s.w[:] = w.tolist()
        self._s.has_ends = 1

    @property
    def stats(self) -> dict[str, int]:
        return {k: int(v) for k, v in zip(SAMPLER_STATS, self._s.stats) if k != "filter_calls"}

    def sync_filter_calls(self) -> None:
        """Add the filter calls made since the last sync to the filter's ``n_calls``."""
        n = int(self._s.stats[len(SAMPLER_STATS) - 1])
        if self.filt is not None:
            self.filt.n_calls += n - self._calls0
        self._calls0 = n

    def sample(self, rng: Any = None, other_xi: np.ndarray | None = None) -> np.ndarray:
        """One ξ_rand (``rng`` is ignored: the draws are the native stream's); ``other_xi``: the other tree's
        node poses (n × 6) for the goal bias."""
        if other_xi is None or not len(other_xi):
            self.lib.tcb_sample(self._sp, None, 0, None, self._out_p)
        else:
            X = np.ascontiguousarray(other_xi, dtype=float)
            self.lib.tcb_sample(self._sp, X.ctypes.data, len(X), None, self._out_p)
        return self._out.copy()

    def sample_near(self, X_a: np.ndarray, n_a: int, alive_a: np.ndarray | None, X_b: np.ndarray, n_b: int,
                    alive_b: np.ndarray | None, index_a: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, int]:
        """One ξ_rand (goal bias toward the live rows of ``X_b[:n_b]``) and the index of the live row of
        ``X_a[:n_a]`` nearest it; ``X_a``, ``X_b``: C-contiguous float64 arrays of 6 columns (a tree's keys);
        ``alive_*``: boolean masks or None; ``index_a``: ``X_a``'s k-d index (:func:`.extend.kd_index`) or None."""
        ad = self._addr
        i = self.lib.tcb_sample_near(self._sp, ad(X_b), n_b, None if alive_b is None else ad(alive_b), ad(X_a), n_a,
                                     None if alive_a is None else ad(alive_a), self._out_p,
                                     None if index_a is None else ad(index_a[0]), None if index_a is None else ad(index_a[1]))
        return self._out.copy(), int(i)


def _clock(deadline: Deadline) -> tuple[int, float]:
    """(0 CLOCK_MONOTONIC / 1 CLOCK_PROCESS_CPUTIME_ID, the deadline's end on that clock [s])."""
    if deadline.clock is time.perf_counter:
        return 0, float(deadline.end)
    if deadline.clock is time.process_time:
        return 1, float(deadline.end)
    return 0, time.perf_counter() + float(deadline.remaining())


def native_lead_path(filt: ObjectPoseFilter, xi_start: np.ndarray, xi_goal: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                     rng: NativeRandom, deadline: Deadline, *, resolution: float, range_: float, shortcut_iterations: int,
                     bridge_probability: float, bridge_sigma: tuple[float, float],
                     geodesic_probability: float) -> list[np.ndarray] | None:
    """The search and shortcuts of :func:`~optplan.planners.task_sampling.object_lead_path` in one native call
    (``lo``/``hi`` already include the end poses): the path's poses, or None at the deadline (its time, or its work
    budget in iterations, :meth:`~optplan.planners.base.Deadline.spend`)."""
    sampler = NativeTaskSampler(filt, lo, hi, rng, filter_tries=0, bridge_probability=bridge_probability,
                                bridge_sigma=bridge_sigma, bridge_tries=20, geodesic_probability=geodesic_probability,
                                endpoints=(xi_start, xi_goal))
    a = np.ascontiguousarray(xi_start, dtype=float)
    b = np.ascontiguousarray(xi_goal, dtype=float)
    kind, end = _clock(deadline)
    out = ctypes.POINTER(_D)()
    iters = _LL(0)
    n = sampler.lib.tcb_lead_path(sampler._sp, a.ctypes.data, b.ctypes.data, float(range_), float(resolution),
                                  int(shortcut_iterations), kind, end, deadline.work_cap(), ctypes.byref(out),
                                  ctypes.byref(iters))
    deadline.spend(int(iters.value))
    sampler.sync_filter_calls()
    if n < 0:
        raise MemoryError("the native object lead path ran out of memory")
    if n == 0:
        return None
    try:
        P = np.ctypeslib.as_array(out, shape=(int(n), 6)).copy()
    finally:
        sampler.lib.tcb_free(ctypes.cast(out, _P))
    return list(P)
