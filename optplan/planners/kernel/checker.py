"""The native kernel as a :class:`~optplan.planners.validity.ValidityChecker` backend: one
:class:`~optplan.planners.kernel.native.NativeKernel` over the checker's geometry model and pair list,
and one ``active`` mask per mode (``"held"``, ``"fixed"``, ``"free"``) mirroring the checker's
Pinocchio ``GeometryData`` (the pairs a regrasp exempts are switched off in the mask as well)."""
from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin

from .native import NativeKernel

__all__ = ["NativeValidity"]


class NativeValidity:
    """Batched boolean checks of a validity checker's modes in the native kernel.

    ``gmodel``: the checker's geometry model (its collision pairs, in order, are the kernel's);
    ``gdata``: per mode, the ``GeometryData`` whose active pairs define the mode; ``fixed_id``: the
    geometry of the still object (placed per query in the ``"fixed"`` mode), None without one;
    ``margin`` [m]."""

    def __init__(self, model: pin.Model, gmodel: pin.GeometryModel, gdata: dict[str, Any], fixed_id: int | None,
                 margin: float) -> None:
        pairs = [(int(cp.first), int(cp.second)) for cp in gmodel.collisionPairs]
        self.kernel = NativeKernel(model, gmodel, pairs, margin=margin)
        self.masks = {mode: np.array([bool(x) for x in gd.activeCollisionPairs], np.uint8) for mode, gd in gdata.items()}
        self._mask_p = {mode: int(m.ctypes.data) for mode, m in self.masks.items()}   # the arrays live as long
        self.fixed_id = fixed_id

    def _override(self, mode: str, object_pose: pin.SE3 | None) -> tuple[int, pin.SE3] | None:
        if mode == "fixed" and self.fixed_id is not None and object_pose is not None:
            return self.fixed_id, object_pose
        return None

    def first_invalid(self, Q: np.ndarray, mode: str, object_pose: pin.SE3 | None = None) -> int:
        """Index of the first row of ``Q`` in collision in ``mode``, −1 if none."""
        return self.kernel.first_invalid(Q, self._mask_p[mode], self._override(mode, object_pose))

    def collides(self, q: np.ndarray, mode: str, object_pose: pin.SE3 | None = None) -> bool:
        """One configuration ``q`` in collision in ``mode``."""
        return self.kernel.collides(q, self._mask_p[mode], self._override(mode, object_pose))

    def valid(self, Q: np.ndarray, mode: str, object_pose: pin.SE3 | None = None) -> np.ndarray:
        """Validity of every row of ``Q`` in ``mode`` (booleans)."""
        return self.kernel.valid(Q, self.masks[mode], self._override(mode, object_pose))

    def edge_first_invalid(self, a: np.ndarray, b: np.ndarray, fractions: np.ndarray, mode: str,
                           object_pose: pin.SE3 | None = None) -> int:
        """The points ``a + f (b − a)``, ``f`` in ``fractions`` in order: index of the first in
        collision, −1 if none."""
        return self.kernel.edge_first_invalid(a, b, fractions, self.masks[mode], self._override(mode, object_pose))

    def edge_first_invalid_skip(self, a: np.ndarray, b: np.ndarray, fractions: np.ndarray, mode: str,
                                object_pose: pin.SE3 | None = None) -> tuple[int, int]:
        """The points ``a + f (b − a)``, ``f`` in ``fractions`` (ascending) in order: (index of the first in
        collision or −1, points checked); see :meth:`.NativeKernel.edge_first_invalid_skip`."""
        return self.kernel.edge_first_invalid_skip(a, b, fractions, self.masks[mode], self._override(mode, object_pose))

    def uniform_edge_first_invalid(self, a: np.ndarray, b: np.ndarray, n: int, mode: str,
                                   object_pose: pin.SE3 | None = None) -> tuple[int, int]:
        """The points ``a + (k/n)(b − a)``, ``k = 1 … n − 1``: (index of the first in collision or −1,
        points checked); see :meth:`.NativeKernel.uniform_edge_first_invalid`."""
        return self.kernel.uniform_edge_first_invalid(a, b, n, self.masks[mode], self._override(mode, object_pose))

    def set_active(self, mode: str, pairs: list[int], on: bool) -> None:
        """Switch the pairs ``pairs`` (indices) of ``mode`` on or off."""
        self.masks[mode][list(pairs)] = 1 if on else 0
