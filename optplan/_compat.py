"""Old import paths kept for one release: each emits a :class:`DeprecationWarning` naming the new
path and resolves to the very same object.

* :data:`MOVED_MODULES` — modules that moved: a finder on ``sys.meta_path`` (installed by
  ``optplan/__init__``) answers an import of the old name with the new module itself, so
  ``import optplan.robot`` and ``from optplan.robot import RobotModel`` give the new module's
  objects (private names too);
* :func:`moved` — one name that moved out of a module that still exists (called from that
  module's ``__getattr__``).
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

__all__ = ["MOVED_MODULES", "moved", "install"]

#: old module → new module (removed in the next release)
MOVED_MODULES = {
    "optplan.spatial": "optplan.geometry.spatial",
    "optplan.distance": "optplan.geometry.distance",
    "optplan._distance_smooth": "optplan.geometry._distance_smooth",
    "optplan.splines": "optplan.geometry.splines",
    "optplan.robot": "optplan.model.robot",
    "optplan.description": "optplan.model.description",
    "optplan.urdf_writer": "optplan.model.urdf_writer",
    "optplan.kinematics": "optplan.model.kinematics",
    "optplan.symbolic": "optplan.model.symbolic",
    "optplan.floating": "optplan.model.floating",
    "optplan.modelinfo": "optplan.model.modelinfo",
    "optplan.example_robots": "optplan.model.example_robots",
    "optplan.dual_panda": "optplan.model.dual_panda",
    "optplan.ik": "optplan.model.ik",
    "optplan.ik_analytic": "optplan.model.ik_analytic",
    "optplan.warmstart": "optplan.constraints.closed_chain",
    "optplan.planners.closed_chain": "optplan.constraints.closed_chain",
    "optplan.bench.trials": "optplan.trials",
    "optplan.verify": "optplan.verification",
    "optplan.methods": "optplan.papers",
    "optplan.methods.eba": "optplan.papers.eba",
    "optplan.methods.eba_core": "optplan.papers.eba.core",
    "optplan.methods.eba_ba": "optplan.papers.eba.ba",
    "optplan.methods.eba_baselines": "optplan.papers.eba.baselines",
    "optplan.methods.eba_nlp": "optplan.papers.eba.nlp",
    "optplan.methods.eba_plots": "optplan.papers.eba.plots",
    "optplan.methods.dshdasr": "optplan.papers.dshdasr",
    "optplan.methods.dshdasr_task": "optplan.papers.dshdasr.task",
    "optplan.methods.dshdasr_nlp": "optplan.papers.dshdasr.nlp",
    "optplan.methods.dshdasr_eval": "optplan.papers.dshdasr.evaluate",
    "optplan.methods.dshdasr_baseline": "optplan.papers.dshdasr.baseline",
    "optplan.methods.arcs": "optplan.papers.dshdasr.arcs",
    "optplan.methods.arcs_arms": "optplan.papers.dshdasr.arc_models",
    "optplan.methods.spline_rrt": "optplan.papers.spline_rrt",
    "optplan.methods.spline_rrt_plots": "optplan.papers.spline_rrt.plots",
}


def _warn(old: str, new: str, stacklevel: int) -> None:
    warnings.warn(f"{old} moved to {new}; the old path goes away in the next release",
                  DeprecationWarning, stacklevel=stacklevel)


def moved(old_module: str, name: str, new_module: str, stacklevel: int = 3):
    """``new_module.name``, with a DeprecationWarning that ``old_module.name`` moved there."""
    _warn(f"{old_module}.{name}", f"{new_module}.{name}", stacklevel)
    return getattr(importlib.import_module(new_module), name)


class _MovedModuleFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Answers imports of the old module names of :data:`MOVED_MODULES` with the new modules."""

    def find_spec(self, fullname, path=None, target=None):
        if fullname in MOVED_MODULES:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        new = MOVED_MODULES[spec.name]
        # the frames of importlib's machinery sit between the warning and the importing line
        _warn(spec.name, new, stacklevel=2)
        return importlib.import_module(new)

    def exec_module(self, module):
        """Nothing to run: :meth:`create_module` returned the new module, already executed."""


_FINDER = _MovedModuleFinder()


def install() -> None:
    """Put the finder of the old module names first on ``sys.meta_path`` (idempotent)."""
    if _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)
