"""Deprecated path: warm starts on the closed chain live in :mod:`optplan.constraints.closed_chain`
(``manifold_resample``, ``project_closed_chain``, ``closed_chain_residual``)."""
from ._compat import alias_module

alias_module(__name__, "optplan.constraints.closed_chain")
