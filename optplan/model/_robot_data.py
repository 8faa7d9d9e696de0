"""Where the optional ``example-robot-data`` package keeps its robots (shared by
:mod:`.example_robots` and :mod:`.dual_panda`)."""
from __future__ import annotations

from pathlib import Path

from ..errors import ModelError


def example_robot_data_dir() -> Path | None:
    """``.../share/example-robot-data`` of the installed ``example-robot-data`` wheel, or None."""
    import site
    import sys

    roots = list(site.getsitepackages()) + [site.getusersitepackages()] + list(sys.path)
    for r in roots:
        p = Path(r) / "cmeel.prefix" / "share" / "example-robot-data"
        if (p / "robots").is_dir():
            return p
    return None


def _require_dir() -> Path:
    d = example_robot_data_dir()
    if d is None:
        raise ModelError("PR2 and Baxter need the `example-robot-data` package: pip install \"optplan[robots]\" "
                         "(or pip install example-robot-data)")
    return d
