"""Small fully connected networks for the learned baselines: JAX for training (optax's Adam), numpy for
inference (one configuration at a time inside a planner's loop, where a JAX dispatch costs more than
the arithmetic), and ``.npz`` files for the weights.

A network is a list of layers ``(W, b)`` with ``W`` of shape ``in × out``; hidden layers use the
named activation (``"relu"``, ``"leaky_relu"`` with slope 0.01, ``"elu"`` or ``"linear"``), the last
layer none. Everything random comes from an explicit seed.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["ACTIVATIONS", "init_mlp", "mlp_numpy", "mlp_jax", "to_numpy", "flatten_params", "unflatten_params",
           "require_jax"]

ACTIVATIONS = ("relu", "leaky_relu", "elu", "linear")
Params = list[tuple[Any, Any]]


def require_jax() -> Any:
    """Import ``jax`` or raise an ImportError that names the optional extra."""
    try:
        import jax
        import optax  # noqa: F401
    except ImportError as exc:   # pragma: no cover - exercised where the extra is absent
        raise ImportError("the learned planners need the optional extra 'learned': "
                          f"pip install \"optplan[learned]\" ({exc})") from exc
    config: Any = jax.config   # untyped where jax is installed
    config.update("jax_platforms", "cpu")
    return jax


def init_mlp(sizes: Sequence[int], seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """He-uniform weights (numpy float32) for layer widths ``sizes`` (input, hidden..., output)."""
    rng = np.random.default_rng(seed)
    out = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        lim = float(np.sqrt(6.0 / a))
        out.append((rng.uniform(-lim, lim, (a, b)).astype(np.float32), np.zeros(b, np.float32)))
    return out


def _act_np(x: np.ndarray, act: str) -> np.ndarray:
    if act == "relu":
        return np.maximum(x, 0.0)
    if act == "leaky_relu":
        return np.where(x > 0, x, 0.01 * x)
    if act == "elu":
        return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))
    return x


def mlp_numpy(params: Sequence[tuple[np.ndarray, np.ndarray]], x: np.ndarray, act: str) -> np.ndarray:
    """Forward pass in numpy (``x``: ``in`` or ``batch × in``)."""
    for k, (W, b) in enumerate(params):
        x = x @ W + b
        if k < len(params) - 1:
            x = _act_np(x, act)
    return x


def mlp_jax(params: Sequence[tuple[Any, Any]], x: Any, act: str) -> Any:
    """Forward pass in JAX (differentiable)."""
    import jax
    import jax.numpy as jnp

    for k, (W, b) in enumerate(params):
        x = x @ W + b
        if k < len(params) - 1:
            if act == "relu":
                x = jax.nn.relu(x)
            elif act == "leaky_relu":
                x = jax.nn.leaky_relu(x, 0.01)
            elif act == "elu":
                x = jax.nn.elu(x)
            else:
                x = jnp.asarray(x)
    return x


def to_numpy(params: Any) -> Any:
    """JAX arrays (any nesting of lists, tuples and dicts) → float64 numpy arrays."""
    if isinstance(params, dict):
        return {k: to_numpy(v) for k, v in params.items()}
    if isinstance(params, (list, tuple)):
        return type(params)(to_numpy(v) for v in params)
    return np.asarray(params, dtype=np.float64)


def flatten_params(prefix: str, params: Sequence[tuple[Any, Any]]) -> dict[str, np.ndarray]:
    """``{prefix_W0: ..., prefix_b0: ...}`` for ``np.savez``."""
    out = {}
    for k, (W, b) in enumerate(params):
        out[f"{prefix}_W{k}"] = np.asarray(W, np.float32)   # trained in float32: no loss
        out[f"{prefix}_b{k}"] = np.asarray(b, np.float32)
    return out


def unflatten_params(prefix: str, arrays: Any) -> list[tuple[np.ndarray, np.ndarray]]:
    """The inverse of :func:`flatten_params` (float64 numpy)."""
    out = []
    k = 0
    while f"{prefix}_W{k}" in arrays:
        out.append((np.asarray(arrays[f"{prefix}_W{k}"], np.float64), np.asarray(arrays[f"{prefix}_b{k}"], np.float64)))
        k += 1
    if not out:
        raise KeyError(f"no layers named {prefix}_W0, ...")
    return out
