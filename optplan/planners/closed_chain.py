"""Deprecated path: the closed-chain kinematics live in :mod:`optplan.constraints.closed_chain`."""
from .._compat import alias_module

alias_module(__name__, "optplan.constraints.closed_chain")
