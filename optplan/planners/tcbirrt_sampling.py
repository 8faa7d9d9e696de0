"""TCBiRRT's samplers and the native loop's layer: the task-space filter, the ξ sampler (NumPy's, or the native one with
its random stream), and with the native sampler the functions the loop takes from the native code in the streaks and
outside them (the target pose of ξ, the ξ of a pose, the twin nearest a configuration), so that both give one search.

:class:`SamplingMixin` holds these methods of :class:`~.tcbirrt.TCBiRRT` (the attributes below are the planner's).
"""
from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import pinocchio as pin

from .task_sampling import ObjectPoseFilter, TaskSampler
from .task_space import pose_from_xi, xi_from_pose
from .tcbirrt_options import TCBiRRTOptions
from .tcbirrt_streak import NativePose, NativeTwin, NativeXi

if TYPE_CHECKING:
    from ..model.robot import RobotModel
    from ..scene import Scene
    from .tcbirrt_tree import _TaskTree

__all__ = ["SamplingMixin"]
log = logging.getLogger("optplan.planners.tcbirrt")


def _xi_of_pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    """ξ of the pose (R, p) by Pinocchio (:func:`.task_space.xi_from_pose`)."""
    return xi_from_pose(pin.SE3(R, p))


def _twin_of(tree: _TaskTree, i: int, q: np.ndarray, rng: np.random.Generator) -> int:
    """Node i's twin nearest ``q`` (:meth:`._TaskTree.twin_nearest`)."""
    return tree.twin_nearest(i, q, rng)


class SamplingMixin:
    """The sampler methods of :class:`~.tcbirrt.TCBiRRT`."""

    options: TCBiRRTOptions
    robot: RobotModel
    scene: Scene
    _ext: Any
    _filter: ObjectPoseFilter | None
    _lo: np.ndarray
    _hi: np.ndarray
    _rng: np.random.Generator
    _nrng: Any
    _pose: Any
    _xi_of: Any
    _twin_of: Any
    _la: Any            # the look-ahead grafts' native candidate loop (:class:`.tcbirrt_lookahead.NativeLookahead`) or None
    kin: Any

    def _make_filter(self, native: bool) -> ObjectPoseFilter:
        """The task-space filter of the samples and the lead path (``filter_robot_body``: the robot's fixed body too)."""
        return ObjectPoseFilter(self.robot, self.scene, native=native, robot_body=bool(self.options.filter_robot_body))

    def _sampler(self) -> Any:
        """The improved variant's ξ sampler (None: the paper's uniform box); with ``extension="loop"`` the
        native sampler (:class:`~optplan.planners.kernel.sampler.NativeTaskSampler`, for the paper's box too)
        when it can be built, and then :attr:`_nrng` is the query's native random stream."""
        o = self.options
        self._nrng, self._pose, self._xi_of, self._twin_of = None, pose_from_xi, _xi_of_pose, _twin_of
        self._la = None
        if self._ext is not None and o.extension == "loop":
            got = self._native_sampler()
            if got is not None:
                return got
        if not (o.sample_filter or cast(float, o.bridge_probability) > 0 or cast(float, o.goal_bias) > 0 or cast(float, o.guide_probability) > 0
                or cast(float, o.geodesic_probability) > 0 or cast(float, o.lead_orientation_probability) > 0):
            return None
        if self._filter is None:
            self._filter = self._make_filter(o.validity_kernel == "native")
            if o.extension == "python":
                self._filter._xi_native = None   # the filter's pose test in Python too (native object check)
        need = o.sample_filter or cast(float, o.bridge_probability) > 0 or cast(float, o.guide_probability) > 0
        return TaskSampler(self._filter if need else None,
                           self._lo, self._hi, bridge_probability=cast(float, o.bridge_probability),
                           bridge_sigma=o.bridge_sigma, goal_bias=cast(float, o.goal_bias),
                           filter_tries=30 if o.sample_filter else 0, guide_probability=cast(float, o.guide_probability),
                           guide_sigma=o.guide_sigma, geodesic_probability=cast(float, o.geodesic_probability),
                           geodesic_sigma=o.geodesic_sigma,
                           lead_orientation_probability=cast(float, o.lead_orientation_probability))

    def _native_sampler(self) -> Any:
        """The native sampler with the options' probabilities, seeded by one draw of the planner's generator
        (None: the filter has no native pose test); the extension's restarts draw from the same stream."""
        from .kernel.native import KernelUnavailable
        from .kernel.sampler import NativeRandom, NativeTaskSampler

        o = self.options
        need = o.sample_filter or cast(float, o.bridge_probability) > 0 or cast(float, o.guide_probability) > 0
        if need and self._filter is None:
            self._filter = self._make_filter(True)
        try:
            nrng = NativeRandom(self._rng)
            smp = NativeTaskSampler(self._filter if need else None, self._lo, self._hi, nrng,
                                    bridge_probability=cast(float, o.bridge_probability), bridge_sigma=o.bridge_sigma,
                                    goal_bias=cast(float, o.goal_bias), filter_tries=30 if o.sample_filter else 0,
                                    guide_probability=cast(float, o.guide_probability), guide_sigma=o.guide_sigma,
                                    geodesic_probability=cast(float, o.geodesic_probability),
                                    geodesic_sigma=o.geodesic_sigma,
                                    lead_orientation_probability=cast(float, o.lead_orientation_probability))
        except KernelUnavailable as e:
            log.info("TCBiRRT samples in Python: %s", e)
            return None
        self._nrng, self._pose, self._xi_of, self._twin_of = nrng, NativePose(), NativeXi(), NativeTwin()
        ext = cast(Any, self._ext)
        ext.restarts_in_c(nrng, cast(int, o.ik_restarts), o.ik_restart_sigma, self.robot.lower - 1e-9,
                          self.robot.upper + 1e-9, cast(int, o.ik_restart_iterations), cast(Any, o.ik_restart_clip))
        if ext.edge_on:   # the look-ahead grafts' candidates in C too
            from .tcbirrt_lookahead import NativeLookahead

            self._la = NativeLookahead(ext, self.robot.lower, self.robot.upper, list(self.kin.idx),
                                       cast(float, o.max_joint_step))
        return smp
