"""The learned baselines of the TCBiRRT paper's comparison (Section 5.2): CVAE latent sampling,
LCBiRRT and LCBiRRT-LPO, with their data generation, training and on-disk weight cache.

Training needs the optional extra ``learned`` (JAX and optax: ``pip install "optplan[learned]"``;
:doc:`decision 0018 <../decisions/0018-learned-baselines-jax>` says why JAX and not PyTorch). Inference runs
in numpy. Weights are never downloaded: each scene's models are trained here from optplan's own
closed-chain samples and cached under ``$OPTPLAN_CACHE/learned/`` with a hash of the data and the
settings.

* :mod:`.cvae` — data (on-manifold set + tangent-space augmentation), the CVAE, its validation;
* :mod:`.latent_models` — voxel / SDF grids, the latent validity classifier, the learned distance;
* :mod:`.latent_planners` — :class:`LatentSampling`, :class:`LCBiRRT` (``lpo=True``: LCBiRRT-LPO);
* :mod:`.train` — ``python -m optplan.planners.learned.train``: train and report every scene's models.
"""
from __future__ import annotations

import dataclasses
from typing import Any

from ...errors import OptionError

__all__ = ["available", "make_learned_planner", "LEARNED"]

#: planner name → (options class name, fixed options)
LEARNED = {"latent-sampling": ("LatentSamplingOptions", {}), "lcbirrt": ("LCBiRRTOptions", {"lpo": False}),
           "lcbirrt-lpo": ("LCBiRRTOptions", {"lpo": True})}


def available() -> bool:
    """True when the optional extra ``learned`` (JAX, optax) is installed."""
    try:
        import jax  # noqa: F401
        import optax  # noqa: F401
    except ImportError:
        return False
    return True


def make_learned_planner(name: str, robot: Any, scene: Any, *, checker: Any = None, kinematics: Any = None,
                         progress: bool = False, **options: Any) -> Any:
    """Build ``"latent-sampling"``, ``"lcbirrt"`` or ``"lcbirrt-lpo"`` (training the scene's models
    when they are not cached); another option name is an :class:`~optplan.errors.OptionError`."""
    from . import latent_planners as lp
    from .nets import require_jax

    if name not in LEARNED:
        raise ValueError(f"unknown learned planner {name!r}; known: {', '.join(LEARNED)}")
    require_jax()
    cls_name, fixed = LEARNED[name]
    cls = getattr(lp, cls_name)
    known = {f.name for f in dataclasses.fields(cls)} - set(fixed)
    unknown = sorted(set(options) - known)
    if unknown:
        raise OptionError(f"make_planner({name!r}): unknown option(s) {', '.join(unknown)}; "
                          f"{cls_name} has: {', '.join(sorted(known))}")
    opts = cls(**options, **fixed)
    if name == "latent-sampling":
        return lp.LatentSampling(robot, scene, opts, checker=checker, kinematics=kinematics, progress=progress)
    return lp.LCBiRRT(robot, scene, opts, checker=checker, kinematics=kinematics, progress=progress)
