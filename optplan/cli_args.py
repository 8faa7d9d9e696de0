"""Checks of the ``optplan`` command's arguments, done before any long run.

Every check raises :class:`optplan.errors.UsageError` (or, inside argparse, ``ArgumentTypeError``)
with a one-line message that names the argument, the value given and what was expected; the
command prints that line and exits with status 2, without a traceback.
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from .errors import UsageError
from .limits import check_path

__all__ = ["positive_int", "nonnegative_int", "positive_float", "int_list", "check_output_file",
           "check_output_dir", "check_scene", "check_planner", "check_root"]


def _int(text: str) -> int:
    try:
        return int(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def positive_int(text: str) -> int:
    """argparse type: an integer ≥ 1."""
    v = _int(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text!r}")
    return v


def nonnegative_int(text: str) -> int:
    """argparse type: an integer ≥ 0 (trial indices, seeds)."""
    v = _int(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}")
    return v


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0 (durations, time limits [s])."""
    try:
        v = float(str(text).strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return v


def int_list(minimum: int):
    """argparse type: comma-separated integers, each ≥ ``minimum`` (e.g. knot counts ``25,50``)."""
    def parse(text: str) -> list[int]:
        parts = [p.strip() for p in str(text).split(",") if p.strip()]
        if not parts:
            raise argparse.ArgumentTypeError(f"expected comma-separated integers >= {minimum}, got {text!r}")
        out = []
        for p in parts:
            try:
                v = int(p)
            except ValueError:
                raise argparse.ArgumentTypeError(f"expected comma-separated integers >= {minimum}, got {p!r} "
                                                 f"in {text!r}") from None
            if v < minimum:
                raise argparse.ArgumentTypeError(f"expected integers >= {minimum}, got {v} in {text!r}")
            out.append(v)
        return out
    parse.__name__ = f"integers >= {minimum}"
    return parse


def check_output_file(path: str | None, option: str) -> None:
    """The file ``path`` can be written: its folder exists and takes a new file, and the path is not
    a folder. Tried by opening the file for appending (removed again when it did not exist), so
    read-only file systems and missing folders are found before a long run, also as root."""
    if path is None:
        return
    p = check_path(path, option, UsageError)   # names > 255 bytes, paths > 4096 characters
    if p.is_dir():
        raise UsageError(f"{option} {path}: is a directory; expected a file path to write")
    if not p.parent.is_dir():
        raise UsageError(f"{option} {path}: the folder {str(p.parent)!r} does not exist")
    existed = p.exists()
    try:
        with open(p, "a"):
            pass
    except OSError as exc:
        raise UsageError(f"{option} {path}: cannot be written ({exc.strerror or exc})") from None
    if not existed:
        try:
            p.unlink()
        except OSError:
            pass


def check_output_dir(path: str | None, option: str) -> None:
    """The folder ``path`` exists and takes new files, or can be created."""
    if path is None:
        return
    p = check_path(path, option, UsageError)
    if p.exists() and not p.is_dir():
        raise UsageError(f"{option} {path}: exists and is not a directory")
    probe = p
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise UsageError(f"{option} {path}: {str(probe)!r} is not a directory")
    try:
        import tempfile

        with tempfile.NamedTemporaryFile(dir=probe, prefix=".optplan-write-test-"):
            pass
    except OSError as exc:
        raise UsageError(f"{option} {path}: cannot create files in {str(probe)!r} ({exc.strerror or exc})") from None


def check_scene(text: str, option: str = "--scene", *, needs_task: bool = True) -> str:
    """A scene name (or 1, 2, 3, or a ``.toml`` path) that loads; with ``needs_task`` it has an object,
    a start and a goal. Returns the name or path to pass to :meth:`Scene.load`."""
    from .errors import OptplanError
    from .scene import Scene, available_scenes, scene_name

    name = scene_name(str(text).strip())
    if not name.endswith(".toml") and name not in available_scenes():
        raise UsageError(f"{option} {text!r}: unknown scene; expected one of {', '.join(available_scenes())} "
                         "(1, 2, 3 = ssps_scene1..3) or a .toml path")
    try:
        scene = Scene.load(name)
    except OptplanError as exc:
        raise UsageError(f"{option} {text!r}: {exc}") from None
    if needs_task and (scene.object is None or scene.start is None or scene.goal is None):
        raise UsageError(f"{option} {text!r}: the scene has no [object], [start] and [goal] to plan between")
    return name


def check_planner(name: str, option: str = "--planner") -> str:
    from .planners import planner_names

    key = str(name).strip().lower()
    if key not in planner_names() and not key.startswith("ompl-"):
        raise UsageError(f"{option} {name!r}: unknown planner; expected one of {', '.join(planner_names())}")
    return key


def check_root() -> None:
    """``OPTPLAN_ROOT``, when set, is a folder with ``models/robots`` and ``models/scenes``."""
    env = os.environ.get("OPTPLAN_ROOT")
    if not env:   # unset or empty: the installed package's models (as optplan.model.description.repo_root)
        return
    p = Path(env)
    if not (p / "models").is_dir():
        raise UsageError(f"OPTPLAN_ROOT={env!r}: expected a directory that contains models/robots and "
                         "models/scenes (an optplan checkout); unset it to use the installed package's")
