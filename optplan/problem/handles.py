"""The binding of a term to a problem: :class:`TermHandle` (a leaf module, so that the modules
that read handles — evaluation, solutions — need not import the problem)."""
from __future__ import annotations

from dataclasses import dataclass

from .terms import Term

__all__ = ["TermHandle"]


@dataclass(frozen=True)
class TermHandle:
    """Named handle returned by ``add_cost`` / ``add_constraint`` (the binding of a term to a
    problem): pass it to ``Solution.value/violation/dual/sample`` and ``OptProblem.term_data``."""

    name: str
    term: Term
    role: str  # "cost" | "constraint"
    weight: float = 1.0
