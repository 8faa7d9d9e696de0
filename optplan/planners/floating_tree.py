"""The trees of :class:`~optplan.planners.floating_tcbirrt.FloatingTCBiRRT`: joints, the held
object's pose in the base frame and the base's world pose per node."""
from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["FloatingTree"]


class FloatingTree:
    """One tree: per node the joints [rad], the object's pose in the base frame, the base's world
    pose (exact for the start tree, relative to the root's estimate for the goal tree) and the parent
    index (−1 at a root; the goal tree may have several roots: joint solutions of the same goal pose)."""

    def __init__(self, joints: np.ndarray, obj: pin.SE3, base: pin.SE3) -> None:
        self.joints: list[np.ndarray] = [np.array(joints, float)]
        self.objs: list[pin.SE3] = [obj]
        self.bases: list[pin.SE3] = [base]
        self.parent: list[int] = [-1]
        self._p = [np.array(obj.translation)]
        self._R = [np.array(obj.rotation)]

    def __len__(self) -> int:
        return len(self.joints)

    @property
    def roots(self) -> list[int]:
        return [k for k, p in enumerate(self.parent) if p < 0]

    def add(self, joints: np.ndarray, obj: pin.SE3, base: pin.SE3, parent: int) -> int:
        """A node (``parent`` −1: another root)."""
        self.joints.append(np.array(joints, float))
        self.objs.append(obj)
        self.bases.append(base)
        self.parent.append(int(parent))
        self._p.append(np.array(obj.translation))
        self._R.append(np.array(obj.rotation))
        return len(self.joints) - 1

    def nearest(self, M: pin.SE3, w_rot: float) -> int:
        """The node whose object pose is nearest ``M``: position distance + ``w_rot`` × rotation angle."""
        P, R = np.asarray(self._p), np.asarray(self._R)
        dp = np.linalg.norm(P - M.translation, axis=1)
        c = np.clip((np.einsum("nij,ij->n", R, M.rotation) - 1.0) / 2.0, -1.0, 1.0)
        return int(np.argmin(dp + w_rot * np.arccos(c)))

    def path_to_root(self, k: int) -> list[int]:
        out = [k]
        while self.parent[out[-1]] >= 0:
            out.append(self.parent[out[-1]])
        return out
