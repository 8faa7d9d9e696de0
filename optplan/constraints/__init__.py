"""Constraints shared by the planners, the NLPs and the paper methods, each defined once:
:mod:`.closed_chain` (two hands holding one rigid object)."""
