"""The conditional variational autoencoder of the latent baselines (the TCBiRRT paper's Section 5.2
item 4: Acar & Tee, ICRA 2021; the latent space of LCBiRRT, Park et al. 2024): configurations on the closed-chain manifold ↔ an 8-dimensional latent
space whose standard normal prior, decoded and projected, samples near the manifold.

Data: :func:`~optplan.planners.manifold_samples.manifold_samples` of the scene (10,000 valid
configurations, projection + collision check, cached) plus **tangent-space augmentation**: every
configuration moved by ``N(0, tangent_sigma²)`` inside the tangent space of the manifold
(``(I − J⁺J) v``), projected back and collision-checked, so the set doubles with neighbours that
are on the manifold too. A random ``val_fraction`` is held out.

Network: encoder ``[q̂, c] → 2×512 → (μ, log σ²)`` and decoder ``[z, c] → 2×512 → q̂`` with ``q̂`` the
configuration standardised by the data's mean and standard deviation and ``c`` the condition: the
relative pose of the two hands (position, rotation vector), constant within a scene — with one
scene per model the CVAE acts as a VAE, as in the paper's per-scene training. Loss: squared
reconstruction error summed over joints + ``kl_weight`` · KL(q(z|q) ‖ N(0, I)); Adam, batch 512,
learning rate 1e-3 (the paper's). Hidden activation: ``"relu"`` by default; the paper writes
"linear activation functions", which makes the decoder an affine map whose image is an
8-dimensional plane — it cannot follow the curved manifold (``activation="linear"`` reproduces it).

Validation (:func:`validate_cvae`): the held-out reconstruction error, and for prior samples
``z ~ N(0, I)`` decoded: the closed-chain residual before and after the projection, the share that
projects, and the share valid after projection (limits and collisions), next to the same figures
for uniform joint samples.
"""
from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...constraints.closed_chain import ClosedChainKinematics, closure_error
from ...errors import ConfigurationError
from ...model.robot import RobotModel
from ...scene import Scene
from ..manifold_samples import ManifoldSampleSettings, manifold_samples, project_onto_chain, scene_digest
from ..validity import ValidityChecker
from .nets import ACTIVATIONS, flatten_params, init_mlp, mlp_jax, mlp_numpy, require_jax, to_numpy, unflatten_params

__all__ = ["CVAESettings", "CVAE", "train_cvae", "load_or_train_cvae", "tangent_augment", "validate_cvae",
           "hand_condition"]
log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CVAESettings:
    """Data and training settings of the CVAE (the paper's values unless said)."""

    #: Valid on-manifold configurations of the scene [count] (the paper: 10,000).
    n_data: int = 10_000
    #: Seed of the data set [-].
    data_seed: int = 0
    #: Share of the data drawn by constrained random walks in the task's start and goal regions [-]
    #: (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.region_fraction`; 0: as the paper).
    data_region_fraction: float = 0.0
    #: Share of the data drawn as the nodes of a task-space exploration over the object's whole workspace [-]
    #: (:attr:`~optplan.planners.manifold_samples.ManifoldSampleSettings.task_fraction`; 0: projected joint draws).
    data_task_fraction: float = 0.0
    #: Tangent-space augmentation: one projected, valid neighbour per configuration [-].
    augment: bool = True
    #: Standard deviation of the tangent-space step of the augmentation [rad].
    tangent_sigma: float = 0.15
    #: Latent dimension [-] (the paper: 8).
    latent_dim: int = 8
    #: Hidden layer width of encoder and decoder (two layers each) [count] (the paper: 512).
    hidden: int = 512
    #: Hidden activation: relu, leaky_relu, elu or linear (the paper writes linear; see the module docstring) [-].
    activation: str = "relu"
    #: Batch size [count] (the paper: 512).
    batch_size: int = 512
    #: Adam learning rate [-] (the paper: 1e-3).
    learning_rate: float = 1e-3
    #: Training epochs [count] (the paper: 1000, about 8 min on its workstation; reduced for 2 CPU cores).
    epochs: int = 100
    #: Weight of the KL term against the summed squared reconstruction error [-].
    kl_weight: float = 0.05
    #: Share of the data held out for validation [-].
    val_fraction: float = 0.1
    #: Seed of the weights, the split and the batches [-].
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("n_data", "latent_dim", "hidden", "batch_size", "epochs"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"CVAESettings.{name}: expected an integer >= 1, got {v!r}")
        for name in ("data_seed", "seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"CVAESettings.{name}: expected an integer >= 0, got {v!r}")
        for name in ("tangent_sigma", "learning_rate"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"CVAESettings.{name}: expected a positive number, got {v!r}")
        if not (isinstance(self.kl_weight, (int, float)) and math.isfinite(self.kl_weight) and self.kl_weight >= 0):
            raise ValueError(f"CVAESettings.kl_weight: expected a number >= 0, got {self.kl_weight!r}")
        if not (isinstance(self.val_fraction, (int, float)) and 0 < self.val_fraction < 0.5):
            raise ValueError(f"CVAESettings.val_fraction: expected a number in (0, 0.5), got {self.val_fraction!r}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"CVAESettings.activation: expected one of {', '.join(ACTIVATIONS)}, got {self.activation!r}")
        for name in ("data_region_fraction", "data_task_fraction"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v <= 1):
                raise ValueError(f"CVAESettings.{name}: expected a number in [0, 1], got {v!r}")
        if not isinstance(self.augment, bool):
            raise ValueError(f"CVAESettings.augment: expected True/False, got {self.augment!r}")


def hand_condition(kin: ClosedChainKinematics) -> np.ndarray:
    """The CVAE's condition: hand 2 in hand 1 (position [m], rotation vector [rad])."""
    import pinocchio as pin

    T = kin.T21
    return np.concatenate([np.asarray(T.translation), np.asarray(pin.log3(T.rotation))])


class CVAE:
    """A trained CVAE in numpy: :meth:`encode` (mean), :meth:`decode`, the data statistics and the
    training record (``history``: loss per epoch; ``metrics``: :func:`validate_cvae`)."""

    def __init__(self, enc: list[Any], dec: list[Any], mean: np.ndarray, std: np.ndarray, cond: np.ndarray, settings: CVAESettings,
                 history: dict[str, list[float]] | None = None, metrics: dict[str, Any] | None = None,
                 path: Path | None = None, data_digest: str = "") -> None:
        self.enc, self.dec = enc, dec
        self.mean, self.std, self.cond = mean, std, cond
        self.settings = settings
        self.history = history or {}
        self.metrics = metrics or {}
        self.path = path
        self.data_digest = data_digest

    @property
    def latent_dim(self) -> int:
        return self.settings.latent_dim

    def encode(self, q: np.ndarray) -> np.ndarray:
        """Latent mean of ``q`` (``nq`` or ``batch × nq``)."""
        x = (np.asarray(q, float) - self.mean) / self.std
        c = np.broadcast_to(self.cond, x.shape[:-1] + self.cond.shape)
        out = mlp_numpy(self.enc, np.concatenate([x, c], axis=-1), self.settings.activation)
        return out[..., :self.latent_dim]

    def decode(self, z: np.ndarray) -> np.ndarray:
        """Configuration(s) [rad] of latent ``z`` (``latent_dim`` or ``batch × latent_dim``)."""
        z = np.asarray(z, float)
        c = np.broadcast_to(self.cond, z.shape[:-1] + self.cond.shape)
        x = mlp_numpy(self.dec, np.concatenate([z, c], axis=-1), self.settings.activation)
        return x * self.std + self.mean

    def save(self, path: Path) -> None:
        arrays: dict[str, Any] = {**flatten_params("enc", self.enc), **flatten_params("dec", self.dec), "mean": self.mean,
                  "std": self.std, "cond": self.cond,
                  "meta": json.dumps({"settings": asdict(self.settings), "history": self.history,
                                      "metrics": self.metrics, "data_digest": self.data_digest})}
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, **arrays)
        tmp.replace(path)
        self.path = path

    @classmethod
    def load(cls, path: Path) -> CVAE:
        with np.load(path) as z:
            meta = json.loads(str(z["meta"]))
            return cls(unflatten_params("enc", z), unflatten_params("dec", z), np.asarray(z["mean"]),
                       np.asarray(z["std"]), np.asarray(z["cond"]), CVAESettings(**meta["settings"]),
                       meta.get("history"), meta.get("metrics"), path, meta.get("data_digest", ""))


def tangent_augment(Q: np.ndarray, kin: Any, checker: ValidityChecker, robot: RobotModel, grasps: dict[str, Any],
                    sigma: float, rng: np.random.Generator) -> np.ndarray:
    """One neighbour per configuration: a step ``(I − J⁺J) v``, ``v ~ N(0, sigma²)``, in the tangent
    space, projected back onto the manifold, kept when it projects, closes the chain (independent
    check), stays in the limits and is collision-free."""
    out = []
    lo, hi = robot.lower, robot.upper
    data = robot.model.createData()
    for q in Q:
        _, J = kin.h_jacobian(q)
        v = rng.normal(0.0, sigma, robot.nq)
        v = v - np.linalg.pinv(J) @ (J @ v)
        x = project_onto_chain(kin, q + v, lo, hi)
        if x is not None and max(closure_error(robot, grasps, x, data)) < 1e-6 and checker.is_valid(x):
            out.append(x)
    return np.array(out).reshape(-1, robot.nq)


def train_cvae(X: np.ndarray, cond: np.ndarray, s: CVAESettings, progress: bool = False) -> tuple[list[Any], list[Any], np.ndarray, np.ndarray, dict[str, Any]]:
    """Train on configurations ``X`` (rows); returns ``(enc, dec, mean, std, history)`` with the
    training and validation loss per epoch (history ``train_loss``, ``val_loss``, ``val_recon_rms_rad``)."""
    jax = require_jax()
    import jax.numpy as jnp
    import optax

    rng = np.random.default_rng(s.seed)
    perm = rng.permutation(len(X))
    n_val = max(1, int(round(s.val_fraction * len(X))))
    Xv, Xt = X[perm[:n_val]], X[perm[n_val:]]
    mean, std = Xt.mean(0), Xt.std(0) + 1e-6
    nq, L, nc = X.shape[1], s.latent_dim, len(cond)
    enc = init_mlp([nq + nc, s.hidden, s.hidden, 2 * L], s.seed)
    dec = init_mlp([L + nc, s.hidden, s.hidden, nq], s.seed + 1)
    params = {"enc": enc, "dec": dec}
    c = jnp.asarray(cond, jnp.float32)
    act = s.activation

    def loss_fn(p: Any, x: Any, eps: Any) -> Any:
        cc = jnp.broadcast_to(c, (x.shape[0], nc))
        h = mlp_jax(p["enc"], jnp.concatenate([x, cc], 1), act)
        mu, logvar = h[:, :L], jnp.clip(h[:, L:], -10.0, 10.0)
        z = mu + jnp.exp(0.5 * logvar) * eps
        xr = mlp_jax(p["dec"], jnp.concatenate([z, cc], 1), act)
        rec = jnp.mean(jnp.sum((xr - x) ** 2, 1))
        kl = jnp.mean(-0.5 * jnp.sum(1 + logvar - mu ** 2 - jnp.exp(logvar), 1))
        return rec + s.kl_weight * kl, rec

    opt = optax.adam(s.learning_rate)
    state = opt.init(params)

    @jax.jit   # type: ignore[untyped-decorator]  # jax.jit is untyped here
    def step(p: Any, st: Any, x: Any, eps: Any) -> Any:
        (loss, _), g = jax.value_and_grad(loss_fn, has_aux=True)(p, x, eps)
        upd, st = opt.update(g, st, p)
        return optax.apply_updates(p, upd), st, loss

    eval_fn = jax.jit(loss_fn)
    xt = ((Xt - mean) / std).astype(np.float32)
    xv = ((Xv - mean) / std).astype(np.float32)
    hist: dict[str, list[float]] = {"train_loss": [], "val_loss": [], "val_recon_rms_rad": []}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=s.epochs, desc="CVAE", unit="epoch")
    for _ in range(s.epochs):
        order = rng.permutation(len(xt))
        tot, nb = 0.0, 0
        for k in range(0, len(xt), s.batch_size):
            xb = xt[order[k:k + s.batch_size]]
            eps = rng.standard_normal((len(xb), L)).astype(np.float32)
            params, state, loss = step(params, state, xb, eps)
            tot += float(loss)
            nb += 1
        vl, _ = eval_fn(params, xv, np.zeros((len(xv), L), np.float32))
        pn = to_numpy(params)
        zv = mlp_numpy(pn["enc"], np.concatenate([xv, np.broadcast_to(cond, (len(xv), nc))], 1), act)[:, :L]
        xr = mlp_numpy(pn["dec"], np.concatenate([zv, np.broadcast_to(cond, (len(xv), nc))], 1), act)
        rms = float(np.sqrt(np.mean(((xr - xv) * std) ** 2)))
        hist["train_loss"].append(tot / nb)
        hist["val_loss"].append(float(vl))
        hist["val_recon_rms_rad"].append(rms)
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"train {tot / nb:.3f} val {float(vl):.3f} rms {rms:.3f} rad")
    if bar is not None:
        bar.close()
    pn = to_numpy(params)
    return pn["enc"], pn["dec"], mean, std, hist


def validate_cvae(model: CVAE, robot: RobotModel, scene: Scene, kin: Any, checker: ValidityChecker, n: int = 500,
                  seed: int = 1) -> dict[str, Any]:
    """Decoded prior samples against uniform joint samples (module docstring): median max |h| before
    and after projection, projection and validity rates."""
    assert scene.object is not None
    grasps = scene.object.grasps
    rng = np.random.default_rng(seed)
    lo, hi = robot.lower, robot.upper
    data = robot.model.createData()

    def stats(Q: np.ndarray) -> dict[str, float]:
        before, after, proj, valid = [], [], 0, 0
        for q in Q:
            qc = np.clip(q, lo, hi)
            before.append(float(np.abs(kin.h(qc)).max()))
            x = project_onto_chain(kin, qc, lo, hi)
            if x is None or max(closure_error(robot, grasps, x, data)) > 1e-6:
                continue
            proj += 1
            after.append(float(np.abs(kin.h(x)).max()))
            valid += bool(checker.is_valid(x))
        return {"median_residual_before": float(np.median(before)),
                "median_residual_after": float(np.median(after)) if after else float("nan"),
                "projection_rate": proj / len(Q), "valid_rate": valid / len(Q)}

    Zs = rng.standard_normal((n, model.latent_dim))
    return {"n": n, "decoded_prior": stats(model.decode(Zs)), "uniform_joints": stats(rng.uniform(lo, hi, (n, robot.nq)))}


def load_or_train_cvae(robot: RobotModel, scene: Scene, settings: CVAESettings | None = None, *,
                       checker: ValidityChecker | None = None, kinematics: ClosedChainKinematics | None = None,
                       cache: bool = True, progress: bool = False) -> CVAE:
    """The scene's CVAE from the on-disk cache (``$OPTPLAN_CACHE/learned/``, keyed by a hash of the
    data set and the settings), else generated data, training, validation and a new cache file."""
    from ...codegen import cache_dir

    s = settings or CVAESettings()
    if scene.object is None or len(scene.object.grasps) != 2:
        raise ConfigurationError(f"scene {scene.name!r}: the CVAE needs an [object] grasped by two arms")
    kin = kinematics or ClosedChainKinematics(robot, scene.object.grasps)
    ck = checker or ValidityChecker(robot, scene)
    data = manifold_samples(robot, scene, ManifoldSampleSettings(n=s.n_data, seed=s.data_seed,
                                                                 region_fraction=s.data_region_fraction,
                                                                 task_fraction=s.data_task_fraction),
                            checker=ck, kinematics=kin, cache=cache, progress=progress)
    d = asdict(s)
    for k in ("data_region_fraction", "data_task_fraction"):   # models trained before an option existed keep their files
        if not d[k]:
            d.pop(k)
    digest = scene_digest(robot, scene, {"cvae": d, "data": _array_digest(data.Q), "version": 1})
    path = cache_dir() / "learned" / f"{scene.name}_cvae_{digest}.npz"
    if cache and path.exists():
        try:
            return CVAE.load(path)
        except (OSError, ValueError, KeyError) as exc:
            log.warning("%s: unreadable (%s), training again", path, exc)
    t0 = time.perf_counter()
    X = data.Q
    assert scene.object is not None
    if s.augment:
        X = np.concatenate([X, tangent_augment(X, kin, ck, robot, scene.object.grasps, s.tangent_sigma,
                                               np.random.default_rng(s.data_seed + 1))])
    t_data = time.perf_counter() - t0
    enc, dec, mean, std, hist = train_cvae(X, hand_condition(kin), s, progress)
    hist["data_time_s"] = [t_data]
    hist["train_time_s"] = [time.perf_counter() - t0 - t_data]
    hist["n_train_rows"] = [float(len(X))]
    model = CVAE(enc, dec, mean, std, hand_condition(kin), s, hist, None, None, _array_digest(data.Q))
    model.metrics = validate_cvae(model, robot, scene, kin, ck)
    if cache:
        model.save(path)
    return model


def _array_digest(A: np.ndarray) -> str:
    import hashlib

    return hashlib.sha256(np.ascontiguousarray(A, np.float64).tobytes()).hexdigest()[:16]
