"""Old import paths kept for one release: each emits a :class:`DeprecationWarning` naming the new
path and resolves to the very same object.

* :func:`moved` — one name that moved out of a module that still exists (called from that module's
  ``__getattr__``);
* :func:`alias_module` — a whole module that moved: the old module file calls it, and
  ``sys.modules`` then maps the old name onto the new module, so ``import optplan.old`` and
  ``from optplan.old import x`` give the new module's objects (private names too).
"""
from __future__ import annotations

import importlib
import sys
import warnings

__all__ = ["moved", "alias_module"]


def moved(old_module: str, name: str, new_module: str, stacklevel: int = 3):
    """``new_module.name``, with a DeprecationWarning that ``old_module.name`` moved there."""
    warnings.warn(f"{old_module}.{name} moved to {new_module}.{name}; the old path goes away in the next release",
                  DeprecationWarning, stacklevel=stacklevel)
    return getattr(importlib.import_module(new_module), name)


def alias_module(old: str, new: str) -> None:
    """Make the module ``old`` (being imported) the module ``new``, with a DeprecationWarning."""
    warnings.warn(f"{old} moved to {new}; the old path goes away in the next release",
                  DeprecationWarning, stacklevel=3)
    sys.modules[old] = importlib.import_module(new)
