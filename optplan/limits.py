"""Size, count and range limits of the files and numbers optplan reads.

A file is measured before it is parsed (a 50 MB scene is refused by its size, in microseconds,
not after minutes of parsing), its nesting depth is measured before a recursive parser sees it
(200,000 nested arrays are one clear error, not a ``RecursionError``), and the numbers in it are
held to physical ranges (a position of 1e308 m is refused with the field's name). The shipped
models are far inside every limit: scenes < 5 kB with ≤ 40 obstacles, URDFs < 100 kB, positions
< 10 m. The limits are module constants; a user with a bigger scene may raise them
(``optplan.limits.MAX_OBSTACLES = 20_000``) before loading it.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

__all__ = ["MAX_SCENE_BYTES", "MAX_ROBOT_BYTES", "MAX_URDF_BYTES", "MAX_RESULT_BYTES", "MAX_OBSTACLES",
           "MAX_NESTING", "MAX_COORDINATE_M", "MAX_SIZE_M", "MAX_NAME_CHARS", "MAX_PATH_CHARS",
           "check_file_size", "check_nesting", "check_path", "check_output_path"]

#: Largest scene TOML file [bytes] (the shipped scenes: < 5 kB).
MAX_SCENE_BYTES = 1_000_000
#: Largest robot description TOML file [bytes] (the shipped ones: < 5 kB).
MAX_ROBOT_BYTES = 1_000_000
#: Largest URDF file [bytes] (meshes are separate files; the shipped URDFs: < 100 kB).
MAX_URDF_BYTES = 20_000_000
#: Largest plan result JSON file [bytes].
MAX_RESULT_BYTES = 500_000_000
#: Most obstacles in one scene [count].
MAX_OBSTACLES = 5_000
#: Deepest nesting of arrays and tables in a TOML or JSON file [levels] (the shipped files: 3).
MAX_NESTING = 64
#: Largest absolute value of a position coordinate in a scene (obstacles, object, grasps,
#: start and goal) [m].
MAX_COORDINATE_M = 1_000.0
#: Largest edge, radius or length of a box, sphere or capsule in a scene [m].
MAX_SIZE_M = 1_000.0
#: Longest component of a file path [characters] (the common file systems' NAME_MAX).
MAX_NAME_CHARS = 255
#: Longest file path [characters] (Linux's PATH_MAX).
MAX_PATH_CHARS = 4096

# strings and comments of TOML (a superset of JSON's strings): their brackets do not nest
_STRINGS_AND_COMMENTS = re.compile(r'"""[\s\S]*?"""|\'\'\'[\s\S]*?\'\'\'|"(?:\\.|[^"\\\n])*"|\'[^\'\n]*\'|#[^\n]*')


def check_path(path: str | Path, what: str, error: type[Exception]) -> Path:
    """``path`` as a Path, or ``error`` when a component is longer than :data:`MAX_NAME_CHARS` or
    the whole path longer than :data:`MAX_PATH_CHARS` (the OS would answer ``File name too long``
    from deep inside a library)."""
    s = os.fspath(path)
    if not isinstance(s, str):
        s = os.fsdecode(s)
    if len(s) > MAX_PATH_CHARS:
        raise error(f"{what}: the path has {len(s)} characters; the limit is {MAX_PATH_CHARS} "
                    f"(starts {s[:60]!r}...)")
    for part in Path(s).parts:
        if len(part.encode("utf-8", "surrogateescape")) > MAX_NAME_CHARS:
            raise error(f"{what}: a file or folder name of {len(part)} characters in the path; the limit is "
                        f"{MAX_NAME_CHARS} bytes (name starts {part[:60]!r}...)")
    return Path(s)


def check_file_size(path: Path, limit: int, what: str, error: type[Exception], limit_name: str) -> int:
    """The size of ``path`` [bytes], or ``error`` when it exceeds ``limit`` (checked with
    ``stat``, before the file is read). ``limit_name`` names the constant a user may raise."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise error(f"{path}: cannot be read ({exc.strerror or exc})") from None
    if size > limit:
        raise error(f"{path}: the {what} file has {size / 1e6:.1f} MB; the limit is {limit / 1e6:g} MB "
                    f"(optplan.limits.{limit_name}); a larger file is refused before parsing")
    return size


def nesting_depth(text: str) -> int:
    """Deepest nesting of ``[ ]`` and ``{ }`` outside strings and comments of a TOML or JSON text."""
    stripped = _STRINGS_AND_COMMENTS.sub("", text)
    a = np.frombuffer(stripped.encode("utf-8", "surrogateescape"), dtype=np.uint8)
    if a.size == 0:
        return 0
    step = ((a == ord("[")) | (a == ord("{"))).astype(np.int32) - ((a == ord("]")) | (a == ord("}"))).astype(np.int32)
    return int(np.max(np.cumsum(step), initial=0))


def check_nesting(text: str, where: str, error: type[Exception]) -> None:
    """``error`` when ``text`` nests arrays/tables deeper than :data:`MAX_NESTING` levels (a
    recursive parser would end in ``RecursionError``)."""
    depth = nesting_depth(text)
    if depth > MAX_NESTING:
        raise error(f"{where}: arrays/tables nested {depth} levels deep; the limit is {MAX_NESTING} "
                    "(optplan.limits.MAX_NESTING)")


def check_output_path(path: str | Path, what: str, error: type[Exception]) -> Path:
    """``path`` as a Path a file can be written to, or ``error`` naming it: a name or path longer
    than the OS allows, a parent folder that does not exist or is a file, a target that is a folder."""
    if not isinstance(path, (str, Path)):
        raise error(f"{what}: expected a file path, got {type(path).__name__} {path!r}")
    p = check_path(path, what, error)
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.exists():
        raise error(f"{what} {str(p)!r}: the folder {str(parent)!r} does not exist; create it first")
    if not parent.is_dir():
        raise error(f"{what} {str(p)!r}: {str(parent)!r} is a file, not a folder")
    if p.is_dir():
        raise error(f"{what} {str(p)!r} is a folder; expected a file name")
    return p
