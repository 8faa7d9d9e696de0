"""Exact collision checking with coal: :class:`CollisionChecker` (distances of every robot, obstacle
and held-object pair, per pair and batched in C++) — the planners' boolean
:class:`~optplan.planners.validity.ValidityChecker` checks the same pair set."""
from .checker import CollisionChecker, Pair

__all__ = ["CollisionChecker", "Pair"]
