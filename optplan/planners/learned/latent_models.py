"""The latent-space validity classifier of LCBiRRT and the learned distance of LCBiRRT-LPO (the
TCBiRRT paper's Section 5.2 items 6-7, after Park et al. 2024 and Zhang et al. 2025).

* :func:`scene_grid` — the scene's obstacles on a 32³ grid over the workspace: occupancy (the voxel
  input) or signed distance [m] (the SDF input), exact for box, sphere and capsule obstacles.
* :class:`LatentClassifier` — voxel encoder ``32³ → 2×512 (LeakyReLU) → 4`` and classifier
  ``[z, features] → 3×256 (ReLU) → logit``, trained (binary cross-entropy, Adam, learning
  rate 5e-4, batch 256, at most 150 epochs) on latent samples — half ``z ~ N(0, I)``, half around the
  encodings of the training configurations — labelled by decoding, projecting and collision-checking
  them (up to 1000 valid and 1000 invalid).
* :class:`LatentDistance` — SDF encoder ``32³ → 2×512 (LeakyReLU) → 16`` and distance network
  ``[z, features] → 3×1024 (ReLU) → d`` trained (squared error on the standardised distance, Adam,
  learning rate 3e-3, batch 64, at most 60 epochs) on on-manifold configurations (up to 1000 collision-free and 1000 in
  collision) with ``d`` their smallest robot/object/obstacle distance [m] (exact, coal; clipped to
  [-0.2, 0.5] m), ``z`` their latent mean; :meth:`LatentDistance.value_and_gradient` gives d and ∂d/∂z (JAX).

With one model per scene the encoders' input is the same grid for every sample, as in the paper's
per-scene training, so an encoder's output is one constant feature vector: training it can add
nothing that the head's first-layer bias cannot represent. By default (``train_encoder=False``) the
encoder is kept as a fixed random projection of the grid (scaled to unit RMS) and only the head
trains; ``train_encoder=True`` is the paper's joint training. Measured on scene 1 (docs, planners
page): jointly trained on the raw SDF with the paper's learning rate 3e-3, Adam moves each of the
encoder's 32,768 × 512 first-layer weights by ≈ the learning rate per step in one coherent direction
(the input is the same every step), so a feature moves by up to ``lr · Σ|grid|`` per step — the loss
started at 10⁷ m², spiked again at epoch 14, and the distance net ended uncorrelated with the exact
distance (−0.10, on its own training rows). The distance target is standardised (mean / standard deviation of the training
rows, undone at prediction). Both models keep the weights of the epoch with the lowest loss on a
validation tenth (early stopping, ``patience`` epochs) and report their figures on a further held-out
tenth that neither training nor stopping saw, next to a model-free reference: a 5-nearest-neighbour
predictor in the latent space on the same split.
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

from ...collision.checker import CollisionChecker
from ...constraints.closed_chain import closure_error
from ...model.robot import RobotModel
from ...scene import Scene
from ..manifold_samples import project_onto_chain, scene_digest
from ..tcbirrt_options import PAPER_XI_LOWER, PAPER_XI_UPPER
from ..validity import ValidityChecker
from .cvae import CVAE
from .nets import flatten_params, init_mlp, mlp_jax, mlp_numpy, require_jax, to_numpy, unflatten_params

__all__ = ["GRID", "scene_grid", "LatentModelSettings", "LatentClassifier", "LatentDistance",
           "load_or_train_classifier", "load_or_train_distance"]
log = logging.getLogger(__name__)

GRID = 32   #: voxel / SDF grid resolution per axis (the paper: 32)


def scene_grid(scene: Scene, kind: str = "occupancy", n: int = GRID, margin: float = 1.0) -> np.ndarray:
    """``n³`` values at the cell centres of the box ``TCBiRRT's ξ position box ± margin`` [m]:
    ``"occupancy"`` (1 inside an obstacle, else 0) or ``"sdf"`` (signed distance to the nearest
    obstacle [m], negative inside), flattened in C order."""
    if kind not in ("occupancy", "sdf"):
        raise ValueError(f"kind: expected 'occupancy' or 'sdf', got {kind!r}")
    lo = np.asarray(PAPER_XI_LOWER[:3]) - margin
    hi = np.asarray(PAPER_XI_UPPER[:3]) + margin
    axes = [lo[k] + (np.arange(n) + 0.5) * (hi[k] - lo[k]) / n for k in range(3)]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    d = np.full(len(P), np.inf)
    for o in scene.obstacles:
        M = o.placement
        x = (P - np.asarray(M.translation)) @ np.asarray(M.rotation)     # points in the obstacle frame
        if o.shape == "box":
            q = np.abs(x) - np.asarray(o.size, float) / 2
            di = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(1), 0.0)
        elif o.shape == "sphere":
            di = np.linalg.norm(x, axis=1) - float(o.radius or 0.0)
        else:   # capsule along its local z
            h = float(o.length or 0.0) / 2
            x = x.copy()
            x[:, 2] -= np.clip(x[:, 2], -h, h)
            di = np.linalg.norm(x, axis=1) - float(o.radius or 0.0)
        d = np.minimum(d, di)
    if kind == "occupancy":
        return (d <= 0).astype(np.float32)
    return np.clip(d, -1.0, 5.0).astype(np.float32)


@dataclass(frozen=True)
class LatentModelSettings:
    """Data and training settings of the classifier and the distance network (the paper's values)."""

    #: Valid and invalid latent samples each for the classifier [count] (the paper: 1000 + 1000).
    n_classifier: int = 1000
    #: Classifier learning rate [-] (the paper: 5e-4).
    classifier_lr: float = 5e-4
    #: Classifier batch size [count] (the paper: 256).
    classifier_batch: int = 256
    #: Classifier epochs [count] (the paper: 150).
    classifier_epochs: int = 150
    #: Collision-free and in-collision configurations each for the distance network [count] (the paper: 1000 + 1000).
    n_distance: int = 1000
    #: Distance network learning rate [-] (the paper: 3e-3).
    distance_lr: float = 3e-3
    #: Distance network batch size [count] (the paper: 64).
    distance_batch: int = 64
    #: Distance network epochs [count] (the paper: 60).
    distance_epochs: int = 60
    #: Latent draws (classifier) or candidates (distance) before training on what was found [count].
    max_draws: int = 60_000
    #: Seed of data, weights and batches [-].
    seed: int = 0
    #: Train the grid encoders jointly with the heads (the paper) instead of keeping them as a fixed
    #: random projection of the constant per-scene grid (module docstring) [-].
    train_encoder: bool = False
    #: Stop when the validation loss has not improved for this many epochs, keeping the best
    #: epoch's weights; 0: train every epoch and keep the last [count].
    patience: int = 20

    def __post_init__(self) -> None:
        for name, v in asdict(self).items():
            if name == "train_encoder":
                if not isinstance(v, bool):
                    raise ValueError(f"LatentModelSettings.train_encoder: expected a bool, got {v!r}")
            elif name.endswith("_lr"):
                if not (isinstance(v, (int, float)) and 0 < v < 1):
                    raise ValueError(f"LatentModelSettings.{name}: expected a number in (0, 1), got {v!r}")
            elif isinstance(v, bool) or not isinstance(v, int) or v < (0 if name in ("seed", "patience") else 1):
                raise ValueError(f"LatentModelSettings.{name}: expected a positive integer, got {v!r}")


def _bce(logit: Any, y: Any) -> Any:
    import jax.numpy as jnp

    return jnp.mean(jnp.maximum(logit, 0) - logit * y + jnp.log1p(jnp.exp(-jnp.abs(logit))))


def grid_input(grid: np.ndarray) -> np.ndarray:
    """The encoder's input: the grid scaled to unit root mean square (float64)."""
    g = np.asarray(grid, np.float64)
    rms = float(np.sqrt(np.mean(g ** 2)))
    return g / rms if rms > 0 else g


def _knn_reference(Zt: np.ndarray, yt: np.ndarray, Zq: np.ndarray, k: int = 5) -> np.ndarray:
    """Mean label of the ``k`` nearest training rows (Euclidean, latent space): the model-free reference."""
    out = np.empty(len(Zq))
    for s in range(0, len(Zq), 256):
        D = ((Zq[s:s + 256, None, :] - Zt[None, :, :]) ** 2).sum(-1)
        out[s:s + 256] = yt[np.argsort(D, 1)[:, :k]].mean(1)
    return out


def _scores(loss: str, pred: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """Held-out figures: accuracy (``bce``; ``pred`` a probability) or correlation and RMSE [m] (``mse``)."""
    if loss == "bce":
        return {"accuracy": float(np.mean((pred > 0.5) == (y > 0.5)))}
    corr = float(np.corrcoef(pred, y)[0, 1]) if np.std(pred) > 0 and np.std(y) > 0 else 0.0
    return {"corr": corr, "rmse_m": float(np.sqrt(np.mean((pred - y) ** 2)))}


def _train(grid: np.ndarray, enc_sizes: list[int], head_sizes: list[int], enc_act: str, head_act: str,
           Z: np.ndarray, y: np.ndarray, loss: str, lr: float, batch: int, epochs: int, seed: int,
           desc: str, progress: bool, train_encoder: bool = False,
           patience: int = 0) -> tuple[list[Any], list[Any], dict[str, Any]]:
    """Training of grid encoder (``train_encoder``; else fixed) + head on ``(Z, y)``: 80 % train, 10 %
    validation (loss curve, early stopping), 10 % test (the reported held-out figures). ``mse``
    targets are standardised; returns ``enc, head, record`` (record: history, target_mean,
    target_std, epochs_run, best_epoch, held_out, held_out_knn)."""
    jax = require_jax()
    import jax.numpy as jnp
    import optax

    rng = np.random.default_rng(seed)
    perm = rng.permutation(len(Z))
    nv = max(1, len(Z) // 10)
    iv, ite, itr = perm[:nv], perm[nv:2 * nv], perm[2 * nv:]
    mu, sd = (float(np.mean(y[itr])), float(np.std(y[itr]) or 1.0)) if loss == "mse" else (0.0, 1.0)
    T = ((y - mu) / sd).astype(np.float32)
    Z32 = Z.astype(np.float32)
    enc0 = init_mlp(enc_sizes, seed)
    g_in = grid_input(grid)
    params: dict[str, Any] = {"head": init_mlp(head_sizes, seed + 1)}
    if train_encoder:
        params["enc"] = enc0
    feats = jnp.asarray(mlp_numpy(enc0, g_in, enc_act)[None, :], jnp.float32)
    g = jnp.asarray(g_in[None, :], jnp.float32)

    def forward(p: Any, z: Any) -> Any:
        f = mlp_jax(p["enc"], g, enc_act) if "enc" in p else feats
        return mlp_jax(p["head"], jnp.concatenate([z, jnp.broadcast_to(f, (z.shape[0], f.shape[1]))], 1), head_act)[:, 0]

    def loss_fn(p: Any, z: Any, t: Any) -> Any:
        out = forward(p, z)
        return _bce(out, t) if loss == "bce" else jnp.mean((out - t) ** 2)

    opt = optax.adam(lr)
    state = opt.init(params)

    @jax.jit   # type: ignore[untyped-decorator]  # jax.jit is untyped here
    def step(p: Any, st: Any, z: Any, t: Any) -> Any:
        val, gr = jax.value_and_grad(loss_fn)(p, z, t)
        upd, st = opt.update(gr, st, p)
        return optax.apply_updates(p, upd), st, val

    ev = jax.jit(loss_fn)
    hist: dict[str, list[float]] = {"train_loss": [], "val_loss": []}
    best, best_val, best_epoch = params, math.inf, 0
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=epochs, desc=desc, unit="epoch")
    for ep in range(epochs):
        order = rng.permutation(itr)
        tot, nb = 0.0, 0
        for k in range(0, len(order), batch):
            idx = order[k:k + batch]
            params, state, v = step(params, state, Z32[idx], T[idx])
            tot += float(v)
            nb += 1
        hist["train_loss"].append(tot / max(nb, 1))
        hist["val_loss"].append(float(ev(params, Z32[iv], T[iv])))
        if not patience or hist["val_loss"][-1] < best_val:
            best, best_val, best_epoch = params, hist["val_loss"][-1], ep + 1
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(f"train {hist['train_loss'][-1]:.4f} val {hist['val_loss'][-1]:.4f}")
        if patience and ep + 1 - best_epoch >= patience:
            break
    if bar is not None:
        bar.close()
    pn = to_numpy(best)
    enc = pn.get("enc", to_numpy(enc0))
    raw = np.asarray(forward(best, Z32[ite]), np.float64)
    pred = 1.0 / (1.0 + np.exp(-raw)) if loss == "bce" else raw * sd + mu
    knn = _knn_reference(Z[itr], y[itr], Z[ite])
    record = {"history": hist, "encoder_trained": train_encoder, "target_mean": mu, "target_std": sd, "epochs_run": len(hist["train_loss"]),
              "best_epoch": best_epoch, "n_train": len(itr), "n_val": len(iv), "n_test": len(ite),
              "held_out": _scores(loss, pred, y[ite]), "held_out_knn": _scores(loss, knn, y[ite]),
              "train": _scores(loss, (1.0 / (1.0 + np.exp(-np.asarray(forward(best, Z32[itr]), np.float64)))
                                      if loss == "bce" else np.asarray(forward(best, Z32[itr]), np.float64) * sd + mu),
                               y[itr])}
    return enc, pn["head"], record


class _GridModel:
    kind = "model"
    enc_act, head_act = "leaky_relu", "relu"

    def __init__(self, enc: list[Any] | None, head: list[Any], grid: np.ndarray, meta: dict[str, Any],
                 path: Path | None = None, features: np.ndarray | None = None) -> None:
        self.enc, self.head, self.meta, self.path = enc, head, meta, path
        if features is None:
            assert enc is not None
            features = mlp_numpy(enc, grid_input(grid), self.enc_act)   # constant per scene
        self.features = np.asarray(features, np.float64)
        self.scale = float(meta.get("target_std", 1.0))
        self.offset = float(meta.get("target_mean", 0.0))
        self._vg: Any = None

    def raw(self, z: np.ndarray) -> np.ndarray:
        """The head's output (the classifier's logit; the distance's standardised value)."""
        z = np.asarray(z, float)
        f = np.broadcast_to(self.features, z.shape[:-1] + self.features.shape)
        return mlp_numpy(self.head, np.concatenate([z, f], axis=-1), self.head_act)[..., 0]

    def save(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        # a fixed (untrained) encoder is stored as its constant output only: 16.8 M weights → 4-16 numbers
        enc = flatten_params("enc", self.enc) if self.enc is not None and self.meta.get("encoder_trained") else {}
        arrays: dict[str, Any] = {**enc, **flatten_params("head", self.head), "features": self.features,
                                  "meta": json.dumps(self.meta)}
        np.savez(tmp, **arrays)
        tmp.replace(path)
        self.path = path

    @classmethod
    def load(cls, path: Path, grid: np.ndarray) -> Any:
        with np.load(path) as z:
            enc = unflatten_params("enc", z) if "enc_W0" in z else None
            feats = np.asarray(z["features"], np.float64) if enc is None else None
            return cls(enc, unflatten_params("head", z), grid, json.loads(str(z["meta"])), path, feats)


class LatentClassifier(_GridModel):
    """``p(valid | z)`` of a latent vector (module docstring)."""

    kind = "classifier"

    def probability(self, z: np.ndarray) -> np.ndarray:
        return 1.0 / (1.0 + np.exp(-self.raw(z)))


class LatentDistance(_GridModel):
    """Predicted smallest distance [m] of the configuration a latent vector decodes to, and its
    gradient (module docstring)."""

    kind = "distance"

    def distance(self, z: np.ndarray) -> np.ndarray:
        """Predicted smallest distance [m] (``latent_dim`` or ``batch × latent_dim``)."""
        return self.raw(z) * self.scale + self.offset

    def value_and_gradient(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        """Predicted distance [m] and ∂d/∂z [m per latent unit] at ``z`` (one latent vector), by one
        jitted JAX call: ~1 ms of CPU here, where numpy's float64 forward pass through the 3×1024 head
        took ~12 ms for one vector (measured 2026-11-28, loaded machine)."""
        if self._vg is None:
            jax = require_jax()
            import jax.numpy as jnp

            head = [(jnp.asarray(W, jnp.float32), jnp.asarray(b, jnp.float32)) for W, b in self.head]
            f = jnp.asarray(self.features, jnp.float32)
            act = self.head_act
            self._vg = jax.jit(jax.value_and_grad(lambda x: mlp_jax(head, jnp.concatenate([x, f]), act)[0]))
        v, g = self._vg(np.asarray(z, np.float32))
        return float(v) * self.scale + self.offset, self.scale * np.asarray(g, float)

    def gradient(self, z: np.ndarray) -> np.ndarray:
        """∂d/∂z [m per latent unit] at ``z`` (one latent vector; :meth:`value_and_gradient`)."""
        return self.value_and_gradient(z)[1]


def _decode_valid(cvae: CVAE, z: np.ndarray, robot: RobotModel, kin: Any, checker: ValidityChecker, grasps: dict[str, Any],
                  data: Any) -> np.ndarray | None:
    lo, hi = robot.lower, robot.upper
    x = project_onto_chain(kin, np.clip(cvae.decode(z), lo, hi), lo, hi)
    if x is None or max(closure_error(robot, grasps, x, data)) > 1e-6 or not checker.is_valid(x):
        return None
    return x


def _cache_path(robot: RobotModel, scene: Scene, kind: str, cvae: CVAE, s: LatentModelSettings,
                version: int = 1) -> Path:
    from ...codegen import cache_dir

    digest = scene_digest(robot, scene, {kind: asdict(s), "cvae": cvae.data_digest,
                                         "cvae_settings": asdict(cvae.settings), "version": version})
    return cache_dir() / "learned" / f"{scene.name}_{kind}_{digest}.npz"


def load_or_train_classifier(robot: RobotModel, scene: Scene, cvae: CVAE, kin: Any, checker: ValidityChecker,
                             settings: LatentModelSettings | None = None, *, samples: np.ndarray | None = None,
                             cache: bool = True, progress: bool = False) -> LatentClassifier:
    """The scene's latent validity classifier (cached per scene, hash of the CVAE's data + settings);
    ``samples``: the CVAE's on-manifold training configurations (half the latent draws are taken
    around their encodings, ``N(0, 0.5²)``)."""
    s = settings or LatentModelSettings()
    assert scene.object is not None
    grid = scene_grid(scene, "occupancy")
    path = _cache_path(robot, scene, "classifier", cvae, s, 2 if samples is not None else 1)
    if cache and path.exists():
        try:
            return LatentClassifier.load(path, grid)
        except (OSError, ValueError, KeyError) as exc:
            log.warning("%s: unreadable (%s), training again", path, exc)
    t0 = time.perf_counter()
    rng = np.random.default_rng(s.seed)
    data = robot.model.createData()
    good: list[np.ndarray] = []
    bad: list[np.ndarray] = []
    draws = 0
    # half the draws from the prior (where the planner samples), half around the encodings of the training
    # configurations (where the trials' start and goal encode: prior draws alone left them at p(valid) ~ 1e-4)
    Zd = cvae.encode(samples) if samples is not None and len(samples) else None
    while (len(good) < s.n_classifier or len(bad) < s.n_classifier) and draws < s.max_draws:
        draws += 1
        if Zd is not None and draws % 2 == 0:
            z = Zd[int(rng.integers(len(Zd)))] + rng.normal(0.0, 0.5, cvae.latent_dim)
        else:
            z = rng.standard_normal(cvae.latent_dim)
        ok = _decode_valid(cvae, z, robot, kin, checker, scene.object.grasps, data) is not None
        (good if ok else bad).append(z)
    good, bad = good[:s.n_classifier], bad[:s.n_classifier]
    if not good or not bad:
        raise RuntimeError(f"scene {scene.name!r}: {len(good)} valid and {len(bad)} invalid latent samples in "
                           f"{draws} draws; the classifier needs both")
    Z = np.array(good + bad)
    y = np.r_[np.ones(len(good)), np.zeros(len(bad))]
    t_data = time.perf_counter() - t0
    enc, head, rec = _train(grid, [grid.size, 512, 512, 4], [cvae.latent_dim + 4, 256, 256, 256, 1], "leaky_relu",
                            "relu", Z, y, "bce", s.classifier_lr, s.classifier_batch, s.classifier_epochs, s.seed,
                            f"classifier {scene.name}", progress, s.train_encoder, s.patience)
    meta = {**rec, "n_valid": len(good), "n_invalid": len(bad), "draws": draws, "data_time_s": t_data,
            "train_time_s": time.perf_counter() - t0 - t_data}
    meta["train_accuracy"] = rec["train"]["accuracy"]
    model = LatentClassifier(enc, head, grid, meta)
    if cache:
        model.save(path)
    return model


def load_or_train_distance(robot: RobotModel, scene: Scene, cvae: CVAE, kin: Any, checker: ValidityChecker,
                           samples: np.ndarray, settings: LatentModelSettings | None = None, *, cache: bool = True,
                           progress: bool = False) -> LatentDistance:
    """The scene's learned distance (cached as the classifier). On-manifold candidates are the
    valid ``samples`` perturbed by ``N(0, 0.3²)`` rad and projected (collision-free or not)."""
    s = settings or LatentModelSettings()
    assert scene.object is not None
    grid = scene_grid(scene, "sdf")
    path = _cache_path(robot, scene, "distance", cvae, s)
    if cache and path.exists():
        try:
            return LatentDistance.load(path, grid)
        except (OSError, ValueError, KeyError) as exc:
            log.warning("%s: unreadable (%s), training again", path, exc)
    t0 = time.perf_counter()
    rng = np.random.default_rng(s.seed + 7)
    exact = CollisionChecker(robot, scene)
    data = robot.model.createData()
    lo, hi = robot.lower, robot.upper
    free: list[tuple[np.ndarray, float]] = []
    hit: list[tuple[np.ndarray, float]] = []
    draws = 0
    while (len(free) < s.n_distance or len(hit) < s.n_distance) and draws < s.max_draws:
        draws += 1
        x0 = samples[int(rng.integers(len(samples)))] + rng.normal(0.0, 0.3, robot.nq)
        x = project_onto_chain(kin, np.clip(x0, lo, hi), lo, hi)
        if x is None or max(closure_error(robot, scene.object.grasps, x, data)) > 1e-6:
            continue
        d = float(np.clip(exact.min_distance(x)[0], -0.2, 0.5))
        (free if checker.is_valid(x) else hit).append((x, d))
    rows = free[:s.n_distance] + hit[:s.n_distance]
    if not rows:
        raise RuntimeError(f"scene {scene.name!r}: no on-manifold configuration for the distance network")
    Q = np.array([r[0] for r in rows])
    y = np.array([r[1] for r in rows])
    Z = cvae.encode(Q)
    t_data = time.perf_counter() - t0
    enc, head, rec = _train(grid, [grid.size, 512, 512, 16], [cvae.latent_dim + 16, 1024, 1024, 1024, 1],
                            "leaky_relu", "relu", Z, y, "mse", s.distance_lr, s.distance_batch, s.distance_epochs,
                            s.seed, f"distance {scene.name}", progress, s.train_encoder, s.patience)
    meta = {**rec, "n_free": len(free[:s.n_distance]), "n_collision": len(hit[:s.n_distance]), "draws": draws,
            "data_time_s": t_data, "train_time_s": time.perf_counter() - t0 - t_data}
    meta["train_rmse_m"] = rec["train"]["rmse_m"]
    meta["train_corr"] = rec["train"]["corr"]
    model = LatentDistance(enc, head, grid, meta)
    if cache:
        model.save(path)
    return model
