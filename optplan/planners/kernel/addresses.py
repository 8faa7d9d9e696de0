"""The data addresses of the arrays a native call is given, remembered between calls.

``ndarray.ctypes.data`` builds a ctypes helper object at every access (~1-3 µs, several per TCBiRRT
iteration); :class:`AddressCache` looks an array up by identity instead. It holds a reference to each array
it remembers (so an address is never reused by another array while remembered) and forgets them all once it
holds ``size``. An array whose buffer is reallocated in place (``ndarray.resize``) must not be passed to it.
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["AddressCache"]


class AddressCache:
    """``cache(a)`` is ``a.ctypes.data`` of the array ``a`` (None for None)."""

    __slots__ = ("_d", "_size")

    def __init__(self, size: int = 8) -> None:
        if size < 1:
            raise ValueError(f"AddressCache: size must be at least 1, got {size}")
        self._d: dict[int, tuple[np.ndarray, int]] = {}
        self._size = size

    def __call__(self, a: np.ndarray | None) -> Any:
        if a is None:
            return None
        e = self._d.get(id(a))
        if e is not None and e[0] is a:
            return e[1]
        if len(self._d) >= self._size:
            self._d.clear()
        p = a.ctypes.data
        self._d[id(a)] = (a, p)
        return p

    def __len__(self) -> int:
        return len(self._d)
