"""Background kernel compiles: what "auto" evaluated symbolically is queued, compiled by the
background compiler into the cache, and loaded from C by the next NLP — with the same values."""
import os

import casadi as ca
import numpy as np
import pytest

from optplan.problem import kernel_compiler as kc_mod
from optplan.problem.kernels import KernelCache


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch, tcb):
    monkeypatch.setenv("OPTPLAN_CACHE", str(tmp_path))
    monkeypatch.setattr(kc_mod, "_QUEUE", {})
    return KernelCache(tcb)


def _closed_chain_kernel(kc, tcb):
    import pinocchio as pin

    from optplan.problem import ClosedChain

    return kc.closed_chain(ClosedChain("A", "B", relative=pin.SE3(np.eye(3), np.array([0.0, 0.5, 0.0]))))


def test_auto_queues_then_background_compiles_then_loads_c(fresh_cache, tcb, tmp_path, monkeypatch, rng):
    from optplan.codegen import c_compiler

    if c_compiler() is None:
        pytest.skip("no C compiler")
    kc = fresh_cache
    fn = _closed_chain_kernel(kc, tcb)
    fns, compiled = kc.evaluators(fn, "auto")
    assert not compiled
    queued = kc_mod._QUEUE[kc._dir]
    assert len(queued) == 3                      # the kernel, its Jacobian and its Hessian
    monkeypatch.setenv("OPTPLAN_BACKGROUND_COMPILE", "0")
    assert kc_mod.launch() == 0                  # off: nothing started, the queue kept
    monkeypatch.setenv("OPTPLAN_BACKGROUND_COMPILE", "1")
    monkeypatch.setattr(kc_mod, "_running", lambda lock: True)   # "a compiler is running": only the list is written
    assert kc_mod.launch() == 3
    lists = list(kc._dir.glob(".pending-*.txt"))
    assert len(lists) == 1
    monkeypatch.setattr(kc_mod.os, "nice", lambda inc: 0)   # in-process: the test run keeps its priority
    assert kc_mod.main([str(kc._dir)]) == 0      # what the background process runs, here in-process
    assert not list(kc._dir.glob(".pending-*.txt"))
    kc2 = KernelCache(tcb)                       # a later process: the same cache directory
    fns2, compiled2 = kc2.evaluators(_closed_chain_kernel(kc2, tcb), "auto")
    assert compiled2
    q = rng.uniform(-1, 1, tcb.nj)
    n, s = np.zeros(3), 0.0
    np.testing.assert_allclose(np.array(fns2[0](q, n, s)), np.array(fns[0](q, n, s)), rtol=0, atol=1e-12)
    lam = rng.normal(size=fn.size1_out(0))
    np.testing.assert_allclose(np.array(ca.densify(fns2[2](q, n, s, lam))), np.array(ca.densify(fns[2](q, n, s, lam))),
                               rtol=0, atol=1e-10)


def test_launch_starts_one_detached_compiler_and_respects_its_lock(fresh_cache, tcb, monkeypatch):
    kc = fresh_cache
    kc.evaluators(_closed_chain_kernel(kc, tcb), "auto")
    monkeypatch.setenv("OPTPLAN_BACKGROUND_COMPILE", "1")
    lock = kc._dir / kc_mod._LOCK
    lock.write_text(str(os.getpid()))            # a compiler "running" (this process is alive)
    started = []
    monkeypatch.setattr(kc_mod.subprocess, "Popen",
                        lambda cmd, **kw: started.append(cmd) or type("P", (), {"pid": 4242})())
    assert kc_mod.launch() == 3 and not started  # listed for the running compiler, none started
    kc.evaluators(_closed_chain_kernel(kc, tcb), "auto")   # queued again (nothing compiled yet)
    lock.write_text("999999999")                 # a stale lock: no such process
    assert kc_mod.launch() == 3
    assert started and started[0][1:] == ["-m", "optplan.problem.kernel_compiler", str(kc._dir)]
    assert lock.read_text() == "4242"
    assert len(list(kc._dir.glob(".pending-*.txt"))) == 2     # one list per launch, both for the compiler
    assert kc_mod.launch() == 0                  # the queue was handed over
