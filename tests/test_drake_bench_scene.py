"""The Drake benchmark's closed-chain problems need a held object: a scene without one is a clear
ValueError (not an AttributeError on None). Runs without Drake installed."""
import pytest

from optplan.bench import drake_bench as DB
from optplan.scene import Scene


def test_closed_chain_of_a_scene_without_an_object_is_a_clear_error():
    scene = Scene.load("splinerrt_capture")
    assert scene.object is None
    with pytest.raises(ValueError, match="no held object"):
        DB._closed_chain(scene)


def test_closed_chain_of_the_transport_scene_pairs_its_two_grasps():
    scene = Scene.load("transport")
    assert scene.object is not None
    cc = DB._closed_chain(scene)
    assert {cc.arm_a, cc.arm_b} == set(scene.object.grasps)
