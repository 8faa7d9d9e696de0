"""The native planning kernel is conservative against coal's own verdicts, not only against exact distances.

coal's GJK stops at a tolerance of 1e-6 m, so coal (with contacts requested, as the validity checker and the
benchmark's sweep check ask) calls a pair colliding up to ~1e-6 m apart. A kernel whose slack is smaller calls
free a configuration that the benchmark's check rejects: on ``hard_window`` (trial 30 of base seed 0) the improved
TCBiRRT returned a path whose regrasp pose had the held box 8e-7 m from the duct's front wall (edge against edge),
free for the kernel and colliding for coal. These tests pin coal's boundary by bisection and require the kernel to
call colliding wherever coal does, then replay that query."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.planners.kernel import KernelUnavailable, NativeKernel
from optplan.planners.kernel.csource import KERNEL_EPS
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene

#: coal's collision tolerance (its GJK's default)
GJK_TOLERANCE = coal.CollisionRequest().gjk_tolerance


def _shape(rng: np.random.Generator, kind: str) -> coal.CollisionGeometry:
    if kind == "sphere":
        return coal.Sphere(rng.uniform(0.02, 0.4))
    if kind == "capsule":
        return coal.Capsule(rng.uniform(0.02, 0.3), rng.uniform(0.0, 1.2))
    return coal.Box(*rng.uniform(0.05, 2.0, 3))


def _coal_collides(ga, Ma: pin.SE3, gb, Mb: pin.SE3) -> bool:
    req = coal.CollisionRequest()
    req.enable_contact = True   # as the validity checker's requests (exact_contact_requests)
    return bool(coal.collide(ga, coal.Transform3s(Ma.rotation, Ma.translation), gb,
                             coal.Transform3s(Mb.rotation, Mb.translation), req, coal.CollisionResult()))


def test_kernel_slack_covers_coal_tolerance():
    assert GJK_TOLERANCE <= 1e-6
    assert 5 * GJK_TOLERANCE <= KERNEL_EPS <= 1e-4   # conservative against coal, still far below any clearance


@pytest.mark.parametrize("kinds", [("box", "box"), ("capsule", "box"), ("sphere", "box"), ("capsule", "capsule")])
def test_kernel_colliding_at_coal_boundary(kinds):
    """Random shapes and orientations; the second shape slides along a random direction from overlap to
    far apart, and bisection on coal's verdict finds the last placement coal calls colliding (to 1e-11 m):
    the kernel calls that placement colliding too, and a placement 1 cm farther out free."""
    rng = np.random.default_rng(29)
    n_checked = 0
    for _ in range(60):
        ga, gb = _shape(rng, kinds[0]), _shape(rng, kinds[1])
        gm = pin.GeometryModel()
        gm.addGeometryObject(pin.GeometryObject("a", 0, 0, pin.SE3(pin.exp3(rng.normal(0, 2, 3)), np.zeros(3)), ga))
        ib = gm.addGeometryObject(pin.GeometryObject("b", 0, 0, pin.SE3.Identity(), gb))
        try:
            k = NativeKernel(pin.Model(), gm, [(0, ib)])
        except KernelUnavailable as e:   # no C compiler on this machine
            pytest.skip(str(e))
        mask = k.all_active()
        Ma = gm.geometryObjects[0].placement
        Rb = pin.exp3(rng.normal(0, 2, 3))
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        lo, hi = 0.0, 10.0   # colliding at lo (same centre), free at hi
        assert _coal_collides(ga, Ma, gb, pin.SE3(Rb, lo * d))
        assert not _coal_collides(ga, Ma, gb, pin.SE3(Rb, hi * d))
        while hi - lo > 1e-11:
            s = 0.5 * (lo + hi)
            if _coal_collides(ga, Ma, gb, pin.SE3(Rb, s * d)):
                lo = s
            else:
                hi = s
        assert not k.pose_free(ib, Rb, lo * d, mask), f"{kinds}: coal collides at s = {lo!r}, the kernel says free"
        assert k.pose_free(ib, Rb, (hi + 0.01) * d, mask) or _coal_collides(ga, Ma, gb, pin.SE3(Rb, (hi + 0.01) * d))
        n_checked += 1
    assert n_checked == 60


#: the configuration the improved TCBiRRT returned on hard_window (trial 30, base seed 0) where a regrasp starts:
#: both hands on the box, the box 8e-7 m from the duct's front wall
Q_TOUCH = np.array([0.2303338749861791, -2.54371492263577, -2.3048518881584643, -1.7234137383254557, -1.019150855691728,
                    -1.485636369260019, 1.0808763043410976, 0.8830413983099772, -1.3633971301289292, 0.4916178287896808,
                    1.9144029124748476, -0.730647599967749, -3.7324417841417437, -2.289287999538081])


def test_recorded_touching_configuration(tcb):
    """The recorded configuration: coal calls it colliding (object against duct_front), and so must the kernel."""
    scene = Scene.load("hard_window")
    ref = ValidityChecker(tcb, scene, kernel="coal")
    assert ref.colliding_pairs(Q_TOUCH, "held") == [("obstacle/duct_front", "object/held")]
    nat = ValidityChecker(tcb, scene)
    if nat.kernel != "native":
        pytest.skip("no native kernel here")
    assert not nat.is_valid(Q_TOUCH)
    assert nat.first_invalid(Q_TOUCH[None, :], "held") == 0


def test_hard_window_query_passes_the_bench_sweep():
    """The query itself (improved variant, hard_window trial 30 of base seed 0, 10 s CPU): the returned path
    passes the benchmark's independent checks (closed chain by Pinocchio FK, coal at the 1 cm sweep)."""
    from optplan.bench.tcbirrt import _W, _path_checks, _worker_setup

    spec = "tcbirrt:variant=improved"
    _worker_setup("tcbirrt_dual_arm", ["hard_window"], [spec])
    w = _W["hard_window"]
    t = w["gen"].generate(30, 0)
    res = w["planners"][spec].plan(t.q_start, t.q_goal, time_limit=10, seed=t.seed, clock="cpu")
    assert res.success, res.message
    checks = _path_checks(w["robot"], w["scene"], w["checker"], res)
    assert checks["swept_invalid_edges"] == 0 and checks["dense_invalid_edges"] == 0
    assert checks["max_closed_chain_residual"] < 1e-6
