"""The native planning kernel: forward kinematics and a primitive collision model (spheres, capsules,
boxes) compiled to C, checking a BATCH of configurations — or the checkpoints of an edge — in one
call. :class:`~optplan.planners.validity.ValidityChecker` routes its boolean checks through it with
``kernel="native"`` (see :mod:`optplan.planners.kernel.native`)."""
from __future__ import annotations

from .native import KernelUnavailable, NativeKernel, load_library

__all__ = ["KernelUnavailable", "NativeKernel", "load_library"]
