"""Training and evaluating MSMR-Net: config, loop, checkpoints, exact resume, DDP, evaluation.

Paper, Sec. "Training": the loss is the L1 distance between predicted and ground-truth mesh
vertices, the vertices translated so that the middle MCP joint (keypoint 9) is at the origin; Adam
with learning rate ``1e-4`` for 200 epochs, halved every 50 epochs; batch size 32; images normalised
with mean 0.5 and standard deviation 1.0; random crops and transformations. Those are the defaults
of [`TrainConfig`][handmesh_tutorial.train.TrainConfig]. Our loss is the mean absolute error over
vertices *and* coordinates, i.e. the paper's per-vertex L1 norm divided by 3 (a constant factor that
Adam ignores).

A notebook trains and evaluates in a few lines::

    cfg = hmt.train.TrainConfig.from_budget(data="runs/intersh", out_dir="runs/train")
    result = hmt.train.train(cfg)                 # tqdm bar, metrics.csv, checkpoints
    report = hmt.train.evaluate(result.checkpoint, "runs/intersh_test", out_dir="runs/eval")
    print(report["table"])                        # scores per visibility-ratio bin

What the loop guarantees:

* **Determinism.** Model initialisation uses ``torch.manual_seed(seed)``; the sample order of epoch
  ``e`` is ``numpy.random.default_rng([seed, e]).permutation``; augmentation draws come from
  ``(seed, epoch, index)`` (see [`handmesh_tutorial.augment`][handmesh_tutorial.augment]). No global
  RNG is touched by the data pipeline.
* **Exact resume.** ``checkpoint_last.pt`` (written atomically after every
  ``checkpoint_every`` epochs) holds the model, optimiser, scheduler, epoch, step, the torch /
  numpy / python RNG states, the history and the config; ``train(cfg, resume=True)`` continues
  from it and ends with the same weights as an uninterrupted run (same threads, CPU).
  Everything is stored as tensors, lists and numbers: ``torch.load(..., weights_only=True)``
  reads it.
* **Batches and DDP.** ``batch_size`` is the *global* batch. Launched with ``torchrun`` (env
  vars ``WORLD_SIZE``, ``RANK``, ``LOCAL_RANK``, ``MASTER_ADDR``, ``MASTER_PORT``), every
  global batch is cut into ``world_size * micro_batches`` equal consecutive chunks; rank ``r``
  processes chunks ``r * micro_batches ... (r + 1) * micro_batches - 1`` (gradient accumulation
  within a rank), each chunk's mean loss counts equally, so DDP on ``W`` processes computes the
  same update as one process with ``micro_batches = W`` (BatchNorm statistics are per chunk in
  both cases). A last, incomplete global batch is filled up with the epoch's first samples, so
  every step sees exactly ``batch_size`` samples. Backend ``gloo`` on CPU, ``nccl`` on CUDA.
  Only rank 0 validates and writes files.
* **Failure.** A NaN or infinite loss stops training with ``FloatingPointError`` naming the epoch
  and step (before the optimiser step, so the last checkpoint stays good).
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import os
import pickle
import random
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
import torch
from torch import nn

from . import augment as A
from . import metrics as M
from ._io import atomic_write_bytes as _atomic_write_bytes
from ._io import leftover_temporaries, write_json
from ._progress import progress_bar
from .dataset import KINDS
from .keypoints import keypoint_loss, normalised_keypoints
from .losses import aligned_joint_loss, edge_length_loss, normal_loss, vertex_loss

__all__ = [
    "TrainConfig", "TrainResult", "EpochBatchSampler", "train", "evaluate", "validate", "predict",
    "load_checkpoint", "save_checkpoint", "build_model_from_config", "make_datasets",
    "resolve_template", "save_template", "template_hash", "vertex_loss", "training_loss",
    "constant_hand_predictions", "constant_hand_scores", "mean_hand", "REST_HAND", "MEAN_HAND",
    "existing_run", "remove_stale_temp_files", "changed_settings",
    "CHECKPOINT_FORMAT", "METRIC_COLUMNS", "RUN_CHECKPOINTS", "RESUMABLE_KEYS",
]

CHECKPOINT_FORMAT = "handmesh_tutorial.checkpoint/1"
"""``format`` entry of every checkpoint written by
[`save_checkpoint`][handmesh_tutorial.train.save_checkpoint]."""
METRIC_COLUMNS = ("epoch", "step", "train_loss", "lr", "seconds", "val_loss", "val_mpjpe",
                  "val_mpvpe", "val_pa_mpjpe", "val_pa_mpvpe", "val_auc_joints", "val_auc_verts",
                  "val_f_at_5mm", "val_f_at_15mm")
"""Columns of ``metrics.csv``, in order (empty cells where a value does not exist)."""
_VAL_KEYS = ("mpjpe", "mpvpe", "pa_mpjpe", "pa_mpvpe", "auc_joints", "auc_verts", "f_at_5mm",
             "f_at_15mm")
# config keys that define the network: they must match when resuming or loading
_ARCH_KEYS = ("encoder", "decoder", "attention", "channels", "latent_channels", "model_kwargs")
RESUMABLE_KEYS = ("epochs", "lr_step", "out_dir", "device", "threads", "num_workers", "cache_data",
                  "val_every", "checkpoint_every", "val_batch_size", "progress", "durable",
                  "skip_bad")
"""[`TrainConfig`][handmesh_tutorial.train.TrainConfig] fields a resumed run may change (how long,
where, how fast, what is logged, whether bad samples are skipped); every other field must equal
the checkpoint's, so a run never silently mixes data, seeds, batch sizes or learning rates.
"""
_PATH_KEYS = ("data", "val_data", "template")


# --------------------------------------------------------------------------------------------
# configuration


@dataclass
class TrainConfig:
    """Everything a training run needs; the defaults are the paper's recipe.

    Attributes:
        data: training data root (INTER-SH root, or FreiHAND root with ``dataset="freihand"``). May
            be ``None`` when datasets are passed to [`train`][handmesh_tutorial.train.train]
            directly.
        dataset: ``"intersh"`` or ``"freihand"``.
        val_data: separate validation root (INTER-SH root; FreiHAND root whose ``evaluation``
            split is used). ``None``: hold out ``val_fraction`` of ``data``.
        val_fraction: share of ``data`` held out for validation (seeded; FreiHAND holds out
            whole unique samples, all their versions). 0 = no validation.
        image_size: network input side, pixels (paper: 224).
        augment: random crop / scale / rotation / colour jitter on training crops.
        cache_data: keep decoded training samples in memory (per process; pays off with
            ``num_workers=0``, since worker processes are restarted every epoch).
        epochs: training epochs (paper: 200).
        batch_size: global batch size (paper: 32); split over ranks and micro-batches.
        lr: Adam learning rate (paper: 1e-4).
        lr_step: epochs between learning-rate decays (paper: 50).
        lr_gamma: decay factor (paper: 0.5).
        weight_decay: Adam weight decay (paper: none).
        micro_batches: gradient-accumulation chunks per rank and step.
        encoder: encoder name (``resnet18``, ``resnet34``, ``resnet50``, ``hrnet18``).
        decoder: ``"multi"`` (MSMR) or ``"single"`` (baseline).
        attention: transformer on the coarse mesh.
        channels: decoder channels per level, finest first (``None``: model defaults).
        latent_channels: channels per coarse-mesh token.
        model_kwargs: further [`build_model`][handmesh_tutorial.model.build_model] arguments
            (``spiral_length``, ``num_blocks``, ``num_heads``, ...).
        template: ``None`` = the open right hand; else a ``.npz`` path written by
            [`save_template`][handmesh_tutorial.train.save_template] (``vertices``, ``faces``,
            ``joint_regressor``).
        out_dir: output folder (checkpoints, ``metrics.csv``, ``steps.csv``, ``config.json``).
        seed: seed of initialisation, data order, split and augmentation.
        device: ``"auto"`` (CUDA when available), ``"cpu"``, ``"cuda"`` or ``"cuda:N"``.
        threads: ``torch.set_num_threads`` value (``None``: leave as is).
        num_workers: DataLoader worker processes.
        val_every: validate every this many epochs (and after the last).
        checkpoint_every: write ``checkpoint_last.pt`` every this many epochs (and after the
            last).
        val_batch_size: batch size of validation (``None``: ``batch_size``).
        box_scale: crop margin around the projected target mesh (INTER-SH).
        progress: show tqdm bars (rank 0).
        durable: fsync checkpoints and logs before renaming them into place.
        keypoint_weight: weight of the 2D keypoint loss (needs ``model_kwargs={"keypoints":
            True}``); 0 = off, as the paper.
        aligned_weight: weight of the L1 loss of Procrustes-aligned joints; 0 = off.
        edge_weight: weight of the edge-length loss; 0 = off.
        normal_weight: weight of the normal loss; 0 = off. (The four terms:
            [`training_loss`][handmesh_tutorial.train.training_loss],
            [`handmesh_tutorial.losses`][handmesh_tutorial.losses].)
        skip_bad: before training, load every training and validation item once and leave out
            those that cannot be read (listed in ``TrainResult.skipped`` and ``skipped.json``);
            ``False``: the first bad sample stops the run with its file named. May change on
            resume (the batches after the resume point then differ; ``skipped.json`` says why).
        precision: ``"float32"`` (default) or ``"bfloat16"``: forward pass and loss under
            ``torch.autocast`` in bfloat16 (weights, gradients and the optimiser stay float32).
            Faster on CPUs with bfloat16 units (AVX-512 BF16 / AMX), at a measured cost in
            accuracy (``benchmarks/train.py``, docs page "Performance").
    """

    data: str | None = None
    dataset: str = "intersh"
    val_data: str | None = None
    val_fraction: float = 0.1
    image_size: int = 224
    augment: bool = True
    cache_data: bool = False
    epochs: int = 200
    batch_size: int = 32
    lr: float = 1e-4
    lr_step: int = 50
    lr_gamma: float = 0.5
    weight_decay: float = 0.0
    micro_batches: int = 1
    encoder: str = "resnet18"
    decoder: str = "multi"
    attention: bool = True
    channels: tuple[int, ...] | None = None
    latent_channels: int = 16
    model_kwargs: dict = field(default_factory=dict)
    template: str | None = None
    out_dir: str = "runs/train"
    seed: int = 0
    device: str = "auto"
    threads: int | None = None
    num_workers: int = 0
    val_every: int = 1
    checkpoint_every: int = 1
    val_batch_size: int | None = None
    box_scale: float = 1.5
    progress: bool = True
    durable: bool = True
    keypoint_weight: float = 0.0
    aligned_weight: float = 0.0
    edge_weight: float = 0.0
    normal_weight: float = 0.0
    skip_bad: bool = False
    precision: str = "float32"

    def __post_init__(self):
        for name in ("data", "val_data", "template"):
            v = getattr(self, name)
            if v is not None:
                setattr(self, name, str(v))
        self.out_dir = str(self.out_dir)
        if self.channels is not None:
            self.channels = tuple(int(c) for c in self.channels)
        self.model_kwargs = dict(self.model_kwargs or {})
        if self.precision not in ("float32", "bfloat16"):
            raise ValueError(f"precision must be 'float32' or 'bfloat16', got {self.precision!r}")
        if self.dataset not in ("intersh", "freihand"):
            raise ValueError(f"dataset must be 'intersh' or 'freihand', got {self.dataset!r}")
        for name in ("epochs", "batch_size", "lr_step", "micro_batches", "image_size",
                     "val_every", "checkpoint_every"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in [0, 1), got {self.val_fraction}")
        if not self.lr > 0:
            raise ValueError(f"lr must be positive, got {self.lr}")
        for name in ("keypoint_weight", "aligned_weight", "edge_weight", "normal_weight"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not v >= 0:
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
            setattr(self, name, float(v))
        if self.keypoint_weight and not self.model_kwargs.get("keypoints", False):
            raise ValueError("keypoint_weight > 0 needs model_kwargs={'keypoints': True} (a "
                             "model with a 2D keypoint head)")
        if self.num_workers < 0:
            raise ValueError(f"num_workers must be >= 0, got {self.num_workers}")

    @classmethod
    def from_budget(cls, budget=None, **overrides) -> TrainConfig:
        """A config sized by a run-size tier.

        ``epochs``, ``batch_size``, ``image_size`` and ``threads`` come from the budget; the
        learning rate decays four times per run (``lr_step = max(1, round(epochs / 4))``: 50 at
        the ``full`` tier's 200 epochs, as in the paper).

        Args:
            budget: a [`Budget`][handmesh_tutorial.budget.Budget] (default ``hmt.budget()``).
            **overrides: any field of [`TrainConfig`][handmesh_tutorial.train.TrainConfig].

        Returns:
            The config.
        """
        if budget is None:
            from .budget import budget as _budget

            budget = _budget()
        sized = {"epochs": budget.epochs, "batch_size": budget.batch_size,
                 "image_size": budget.image_size, "threads": budget.threads,
                 "lr_step": max(1, round(budget.epochs / 4))}
        if "epochs" in overrides and "lr_step" not in overrides:
            sized["lr_step"] = max(1, round(overrides["epochs"] / 4))
        sized.update(overrides)
        return cls(**sized)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (tuples become lists)."""
        d = asdict(self)
        d["channels"] = None if self.channels is None else list(self.channels)
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> TrainConfig:
        """Inverse of [`to_dict`][handmesh_tutorial.train.TrainConfig.to_dict]; unknown keys raise
        ``ValueError``."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise ValueError(f"unknown TrainConfig keys {unknown}")
        return cls(**dict(d))

    def architecture(self) -> dict:
        """The entries that define the network (compared when resuming or loading)."""
        d = self.to_dict()
        return {k: d[k] for k in _ARCH_KEYS}


@dataclass
class TrainResult:
    """What [`train`][handmesh_tutorial.train.train] returns.

    Attributes:
        out_dir: the output folder.
        checkpoint: ``checkpoint_last.pt`` (``None`` on ranks other than 0).
        best_checkpoint: ``checkpoint_best.pt`` (lowest validation PA-MPVPE; model weights
            and config, no optimiser state), or ``None``.
        metrics_csv: ``metrics.csv`` (one row per epoch; columns
            [`METRIC_COLUMNS`][handmesh_tutorial.train.METRIC_COLUMNS]).
        history: the rows of ``metrics.csv`` as dicts (NaN where missing).
        step_losses: training loss of every step so far (mean over ranks), metres.
        final: the last row of ``history``.
        epochs: epochs completed.
        steps: optimiser steps completed.
        seconds: wall time of this call.
        model: the trained network (unwrapped from DDP), on the training device.
        rank: this process's rank.
        world_size: the number of processes.
        skipped: with ``TrainConfig.skip_bad``, the items left out:
            ``[{"split": "train" | "val", "index": reader index, "error": message}, ...]``.
    """

    out_dir: Path
    checkpoint: Path | None
    best_checkpoint: Path | None
    metrics_csv: Path | None
    history: list
    step_losses: list
    final: dict
    epochs: int
    steps: int
    seconds: float
    model: nn.Module
    rank: int = 0
    world_size: int = 1
    skipped: list = field(default_factory=list)


# --------------------------------------------------------------------------------------------
# templates and models


def resolve_template(spec=None):
    """The mesh template of a run.

    Args:
        spec: ``None`` (the open right hand), a path to a ``.npz`` with ``vertices``, ``faces``,
            ``joint_regressor`` (see [`save_template`][handmesh_tutorial.train.save_template]), or
            anything [`as_template`][handmesh_tutorial.model.as_template] accepts.

    Returns:
        A [`MeshTemplate`][handmesh_tutorial.model.MeshTemplate].

    Raises:
        FileNotFoundError: the ``.npz`` does not exist.
        ValueError: it lacks a key or has bad shapes.
    """
    from .model import as_template

    if isinstance(spec, str | os.PathLike):
        path = Path(spec)
        if not path.is_file():
            raise FileNotFoundError(f"template file not found: {path}")
        with np.load(path, allow_pickle=False) as z:
            missing = {"vertices", "faces", "joint_regressor"} - set(z.files)
            if missing:
                raise ValueError(f"{path}: template lacks keys {sorted(missing)}")
            spec = {k: z[k] for k in ("vertices", "faces", "joint_regressor")}
    return as_template(spec)


def save_template(path: str | os.PathLike, template) -> Path:
    """Write a template as ``.npz`` (``vertices`` (V,3) m, ``faces`` (F,3), ``joint_regressor``
    (21,V)) atomically, for ``TrainConfig(template=path)``.

    Args:
        path: output file.
        template: anything [`resolve_template`][handmesh_tutorial.train.resolve_template] accepts.

    Returns:
        The path.
    """
    t = resolve_template(template)
    path = Path(path)
    buf = io.BytesIO()
    np.savez(buf, vertices=t.vertices, faces=t.faces, joint_regressor=t.joint_regressor)
    _atomic_write_bytes(path, buf.getvalue())
    return path


def template_hash(template) -> str:
    """Short SHA-256 of a template's vertices, faces and joint regressor (float64/int64 bytes)."""
    t = resolve_template(template)
    h = hashlib.sha256()
    for a, dt in ((t.vertices, np.float64), (t.faces, np.int64), (t.joint_regressor, np.float64)):
        a = np.ascontiguousarray(a, dtype=dt)
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:16]


def build_model_from_config(config: TrainConfig, template=None) -> nn.Module:
    """The network described by a config (weights freshly initialised from torch's global RNG).

    Args:
        config: the run's [`TrainConfig`][handmesh_tutorial.train.TrainConfig].
        template: overrides ``config.template`` (a template object or path).

    Returns:
        An [`MSMRNet`][handmesh_tutorial.model.MSMRNet] on the CPU.
    """
    from .model import build_model

    tmpl = resolve_template(config.template if template is None else template)
    return build_model(encoder=config.encoder, decoder=config.decoder,
                       attention=config.attention, template=tmpl, channels=config.channels,
                       latent_channels=config.latent_channels, **config.model_kwargs)


# --------------------------------------------------------------------------------------------
# data


class EpochBatchSampler(torch.utils.data.Sampler):
    """Global batches of a seeded permutation per epoch; yields this rank's share of each.

    Epoch ``e`` orders the ``n`` items by ``numpy.random.default_rng([seed, e]).permutation(n)``
    (``shuffle=False``: ``0..n-1``) and cuts that order into global batches of ``batch_size``.
    A shorter last batch is filled up with the first items of the order (wrapping around), so
    every batch has exactly ``batch_size`` items (as ``DistributedSampler`` pads; it also avoids
    a last batch of one sample, which BatchNorm rejects). Rank ``r`` gets the ``r``-th of
    ``world_size`` equal consecutive slices of every global batch.

    Args:
        n: dataset length.
        batch_size: global batch size (a multiple of ``world_size * micro_batches``).
        seed: order seed.
        rank: this process's rank.
        world_size: number of processes.
        micro_batches: accumulation chunks per rank (checked: ``batch_size`` must split).
        shuffle: permute (``False``: keep the dataset order).

    Raises:
        ValueError: ``batch_size`` is not divisible by ``world_size * micro_batches`` or
            ``n`` is 0.
    """

    def __init__(self, n: int, batch_size: int, seed: int = 0, rank: int = 0,
                 world_size: int = 1, micro_batches: int = 1, shuffle: bool = True):
        chunks = world_size * micro_batches
        if n < 1:
            raise ValueError("the training set is empty")
        if batch_size % chunks:
            raise ValueError(f"batch_size {batch_size} must be divisible by world_size x "
                             f"micro_batches = {world_size} x {micro_batches} = {chunks}")
        self.n, self.batch_size, self.seed = n, batch_size, seed
        self.rank, self.world_size, self.chunks = rank, world_size, chunks
        self.shuffle = shuffle
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the order of ``epoch``."""
        self.epoch = int(epoch)

    def global_batches(self, epoch: int | None = None) -> list[list[int]]:
        """All global batches of an epoch (padded), as lists of dataset positions."""
        e = self.epoch if epoch is None else epoch
        order = (np.random.default_rng([self.seed, e]).permutation(self.n) if self.shuffle
                 else np.arange(self.n)).tolist()
        out = []
        for start in range(0, self.n, self.batch_size):
            b = order[start:start + self.batch_size]
            b = b + [order[k % self.n] for k in range(self.batch_size - len(b))]
            out.append(b)
        return out

    def __iter__(self):
        for b in self.global_batches():
            per = len(b) // self.world_size
            yield b[self.rank * per:(self.rank + 1) * per]

    def __len__(self) -> int:
        return math.ceil(self.n / self.batch_size)


def _split(n: int, fraction: float, seed: int) -> tuple[list[int], list[int]]:
    if fraction <= 0 or n < 2:
        return list(range(n)), []
    n_val = min(n - 1, max(1, round(n * fraction)))
    perm = np.random.default_rng([seed, 7919]).permutation(n)  # 7919: its own stream
    return sorted(perm[n_val:].tolist()), sorted(perm[:n_val].tolist())


def make_datasets(config: TrainConfig):
    """Training and validation torch datasets of a config.

    Returns:
        ``(train_dataset, val_dataset or None)``:
        [`InterSHTorchDataset`][handmesh_tutorial.augment.InterSHTorchDataset] or
        [`FreiHANDTorchDataset`][handmesh_tutorial.augment.FreiHANDTorchDataset]; validation without
        augmentation.

    Raises:
        ValueError: ``config.data`` is not set.
    """
    if config.data is None:
        raise ValueError("TrainConfig.data is None: give a data root or pass dataset= to train()")
    common = {"image_size": config.image_size, "seed": config.seed, "cache": config.cache_data}
    if config.dataset == "intersh":
        from .dataset import InterSHDataset

        src = InterSHDataset(config.data)

        def make(source, idx, train):
            return A.InterSHTorchDataset(source, train=train, augment=config.augment and train,
                                         indices=idx, box_scale=config.box_scale, **common)

        if config.val_data is not None:
            return make(src, None, True), make(InterSHDataset(config.val_data), None, False)
        tr, va = _split(len(src), config.val_fraction, config.seed)
        return make(src, tr, True), (make(src, va, False) if va else None)

    from .freihand import FreiHAND

    src = FreiHAND(config.data, "training")

    def make_fh(source, idx, train):
        return A.FreiHANDTorchDataset(source, train=train, augment=config.augment and train,
                                      indices=idx, **common)

    if config.val_data is not None:
        return make_fh(src, None, True), make_fh(FreiHAND(config.val_data, "evaluation"), None,
                                                 False)
    nu = src.num_unique
    tr_u, va_u = _split(nu, config.val_fraction, config.seed)
    reps = len(src) // nu
    tr = [u + nu * r for r in range(reps) for u in tr_u]
    va = [u + nu * r for r in range(reps) for u in va_u]
    return make_fh(src, tr, True), (make_fh(src, va, False) if va else None)


# --------------------------------------------------------------------------------------------
# files


def _write_csv(path: Path, rows: Sequence[Mapping], columns: Sequence[str],
               durable: bool = True) -> None:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        cells = []
        for c in columns:
            v = r.get(c)
            cells.append("" if v is None or (isinstance(v, float) and math.isnan(v)) else
                         (repr(v) if isinstance(v, float) else v))
        w.writerow(cells)
    _atomic_write_bytes(path, buf.getvalue().encode(), durable)


# --------------------------------------------------------------------------------------------
# checkpoints


def _rng_state() -> dict:
    name, keys, pos, has_gauss, cached = np.random.get_state()  # noqa: NPY002 - global state
    version, state, gauss_next = random.getstate()
    out = {
        "torch": torch.get_rng_state(),
        "numpy": {"name": name, "keys": torch.from_numpy(keys.astype(np.int64)), "pos": int(pos),
                  "has_gauss": int(has_gauss), "cached_gaussian": float(cached)},
        "python": {"version": int(version), "state": torch.tensor(state, dtype=torch.int64),
                   "gauss_next": gauss_next},
    }
    if torch.cuda.is_available():
        out["cuda"] = torch.cuda.get_rng_state_all()
    return out


def _set_rng_state(s: Mapping) -> None:
    torch.set_rng_state(s["torch"].cpu())
    n = s["numpy"]
    np.random.set_state((n["name"], n["keys"].numpy().astype(np.uint32), n["pos"],  # noqa: NPY002
                         n["has_gauss"], n["cached_gaussian"]))
    p = s["python"]
    random.setstate((p["version"], tuple(int(x) for x in p["state"].tolist()), p["gauss_next"]))
    if "cuda" in s and torch.cuda.is_available() and len(s["cuda"]) == torch.cuda.device_count():
        torch.cuda.set_rng_state_all([t.cpu() for t in s["cuda"]])


def save_checkpoint(path: str | os.PathLike, *, model: nn.Module, config: TrainConfig,
                    template_id: str, optimizer=None, scheduler=None, epoch: int = 0,
                    step: int = 0, history: Sequence[Mapping] = (), step_losses=(),
                    best: float = math.inf, extra: Mapping | None = None,
                    durable: bool = True) -> Path:
    """Write a checkpoint atomically (temporary file in the same folder, then ``os.replace``).

    Args:
        path: output file (``.pt``).
        model: the network (a DDP wrapper is unwrapped).
        config: the run's config (stored as a dict).
        template_id: [`template_hash`][handmesh_tutorial.train.template_hash] of the template.
        optimizer: its ``state_dict`` is stored when given.
        scheduler: its ``state_dict`` is stored when given.
        epoch: completed epochs.
        step: completed optimiser steps.
        history: rows of ``metrics.csv``.
        step_losses: per-step losses.
        best: best validation PA-MPVPE so far (mm).
        extra: more weights-only-safe entries.
        durable: fsync before the rename.

    Returns:
        The path. The file loads with ``torch.load(path, weights_only=True)``.
    """
    net = model.module if hasattr(model, "module") else model
    ck = {
        "format": CHECKPOINT_FORMAT,
        "model": {k: v.detach().cpu() for k, v in net.state_dict().items()},
        "optimizer": optimizer.state_dict() if optimizer is not None else None,
        "scheduler": scheduler.state_dict() if scheduler is not None else None,
        "epoch": int(epoch), "step": int(step),
        "rng": _rng_state(),
        "config": config.to_dict(),
        "template_hash": template_id,
        "num_vertices": int(net.joint_regressor.shape[1]) if hasattr(net, "joint_regressor")
        else None,
        "history": [dict(r) for r in history],
        "step_losses": torch.tensor(list(step_losses), dtype=torch.float64),
        "best": float(best),
        "torch_version": str(torch.__version__),
        **dict(extra or {}),
    }
    buf = io.BytesIO()
    torch.save(ck, buf)
    path = Path(path)
    _atomic_write_bytes(path, buf.getvalue(), durable)
    return path


def _read_checkpoint(path: str | os.PathLike, map_location="cpu") -> dict:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint not found: {path}")
    try:
        ck = torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as err:
        # torch's text advises weights_only=False, i.e. running the file's code: say otherwise
        what = [ln.strip().split(". Please")[0][:120] for ln in str(err).splitlines()
                if "Unsupported" in ln]
        raise ValueError(
            f"{path}: refused: the file holds objects other than tensors and plain containers"
            + (f" ({what[0]})" if what else "") + ". It was not written by handmesh_tutorial "
            "or was altered; never load it with weights_only=False, which runs any code it "
            "carries.") from None
    except (RuntimeError, EOFError, OSError) as err:
        raise ValueError(f"{path}: unreadable checkpoint (truncated or not a torch file: "
                         f"{str(err).strip().splitlines()[0][:120]})") from err
    if not isinstance(ck, dict) or ck.get("format") != CHECKPOINT_FORMAT:
        got = ck.get("format") if isinstance(ck, dict) else type(ck).__name__
        raise ValueError(f"{path}: not a handmesh_tutorial checkpoint (format {got!r}, "
                         f"expected {CHECKPOINT_FORMAT!r})")
    return ck


def load_checkpoint(path: str | os.PathLike, device: str | torch.device = "cpu",
                    template=None) -> tuple[nn.Module, dict]:
    """Rebuild the network of a checkpoint and load its weights (``weights_only=True``).

    Args:
        path: a file written by [`train`][handmesh_tutorial.train.train] /
            [`save_checkpoint`][handmesh_tutorial.train.save_checkpoint].
        device: where the model goes (``map_location`` too).
        template: the mesh template (default: the config's ``template``, i.e. the MakeHuman hand
            unless a template file was used); its hash must equal the checkpoint's.

    Returns:
        ``(model, checkpoint)``: the network in eval mode, and the checkpoint dict (``config``,
        ``epoch``, ``step``, ``history``...).

    Raises:
        FileNotFoundError: no such file (or template file).
        ValueError: not a checkpoint, a different template, or weights that do not fit the
            architecture (the message names the mismatching keys).
    """
    device = _resolve_device(device)
    ck = _read_checkpoint(path, map_location=device)
    cfg = TrainConfig.from_dict(ck["config"])
    tmpl = resolve_template(cfg.template if template is None else template)
    got = template_hash(tmpl)
    if got != ck["template_hash"]:
        raise ValueError(
            f"{path}: trained with template {ck['template_hash']} "
            f"({ck.get('num_vertices')} vertices), but the template given has hash {got} "
            f"({len(tmpl.vertices)} vertices); pass template= the training template")
    net = build_model_from_config(cfg, tmpl)
    try:
        net.load_state_dict(ck["model"], strict=True)
    except RuntimeError as e:
        raise ValueError(f"{path}: weights do not fit the architecture "
                         f"{cfg.architecture()}: {e}") from None
    return net.to(device).eval(), ck


# --------------------------------------------------------------------------------------------
# distributed helpers


def _resolve_device(device: str | torch.device, local_rank: int = 0) -> torch.device:
    if isinstance(device, torch.device):
        return device
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda":
        if not torch.cuda.is_available():
            raise ValueError("device 'cuda' requested but torch.cuda.is_available() is False")
        return torch.device("cuda", local_rank)
    return torch.device(device)


def _init_distributed(device: torch.device) -> tuple[int, int, bool]:
    """``(rank, world_size, initialised_here)``; initialises from torchrun's env vars."""
    import torch.distributed as dist

    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size(), False
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, False
    if not dist.is_available():
        raise RuntimeError("WORLD_SIZE > 1 but torch.distributed is not available")
    backend = "nccl" if device.type == "cuda" else "gloo"
    dist.init_process_group(backend=backend, init_method="env://")
    return dist.get_rank(), dist.get_world_size(), True


def _barrier(world: int) -> None:
    if world > 1:
        import torch.distributed as dist

        dist.barrier()


def _mean_over_ranks(value: float, world: int, device: torch.device) -> float:
    if world == 1:
        return value
    import torch.distributed as dist

    t = torch.tensor([value], dtype=torch.float64, device=device)
    dist.all_reduce(t)
    return float(t.item()) / world


# --------------------------------------------------------------------------------------------
# prediction and validation


def predict(model: nn.Module, images, batch_size: int = 32,
            device: str | torch.device | None = None) -> dict:
    """Run the network on crops, in eval mode, without gradients.

    Args:
        model: an [`MSMRNet`][handmesh_tutorial.model.MSMRNet].
        images: ``(B, 3, S, S)`` normalised float tensor (as the datasets return), or uint8
            ``(B, S, S, 3)`` / ``(S, S, 3)`` RGB crops (normalised here).
        batch_size: images per forward pass.
        device: default: the model's device.

    Returns:
        dict with ``vertices`` ``(B, V, 3)`` and ``joints`` ``(B, 21, 3)`` CPU float32 tensors:
        right-hand, root-relative network frame (see
        [`to_camera`][handmesh_tutorial.augment.to_camera] to go back to the camera).
    """
    if not isinstance(images, torch.Tensor) or images.dtype == torch.uint8:
        arr = images if isinstance(images, torch.Tensor) else np.asarray(images)
        if arr.dtype not in (np.uint8, torch.uint8):
            raise ValueError(f"array images must be uint8 RGB (B, S, S, 3), got {arr.dtype}")
        images = A.normalize_image(arr)
    if images.dim() == 3:
        images = images[None]
    if images.dim() != 4 or images.shape[1] != 3:
        raise ValueError(f"images must be (B, 3, S, S), got {tuple(images.shape)}")
    dev = next(model.parameters()).device if device is None else _resolve_device(device)
    was_training = model.training
    model.eval()
    outs = []
    try:
        with torch.no_grad():
            for s in range(0, images.shape[0], batch_size):
                o = model(images[s:s + batch_size].to(dev))
                outs.append({k: o[k].float().cpu() for k in ("vertices", "joints")})
    finally:
        model.train(was_training)
    return {k: torch.cat([o[k] for o in outs]) for k in ("vertices", "joints")}


def _run_dataset(model: nn.Module, dataset, batch_size: int, device: torch.device,
                 num_workers: int = 0, progress: bool = False, desc: str = "eval") -> dict:
    loader = torch.utils.data.DataLoader(dataset, batch_size=batch_size, shuffle=False,
                                         num_workers=num_workers)
    keys = ("vertices", "joints", "root", "R", "mirrored", "vr", "index", "K")
    acc: dict[str, list] = {k: [] for k in (*keys, "pred_vertices", "pred_joints")}
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            for batch in progress_bar(loader, desc=desc, disable=not progress, leave=False):
                out = model(batch["image"].to(device))
                acc["pred_vertices"].append(out["vertices"].float().cpu())
                acc["pred_joints"].append(out["joints"].float().cpu())
                for k in keys:
                    acc[k].append(batch[k])
    finally:
        model.train(was_training)
    return {k: torch.cat(v) for k, v in acc.items()}


def validate(model: nn.Module, dataset, batch_size: int = 16, device=None,
             progress: bool = False) -> dict:
    """Loss and FreiHAND-style scores of a model on a (non-augmented) dataset.

    Errors are computed in the root-centred network frame (ground-truth root; mirroring and
    rotation do not change distances).

    Args:
        model: the network.
        dataset: a [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset] (``train=False``).
        batch_size: evaluation batch size.
        device: default: the model's device.
        progress: tqdm bar.

    Returns:
        dict: ``loss`` (metres) and the keys of
        [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] (mm, AUCs, F-scores).
    """
    dev = next(model.parameters()).device if device is None else _resolve_device(device)
    r = _run_dataset(model, dataset, batch_size, dev, progress=progress, desc="validate")
    scores = M.freihand_scores(pred_joints=r["pred_joints"], gt_joints=r["joints"],
                               pred_verts=r["pred_vertices"], gt_verts=r["vertices"])
    scores["loss"] = float(vertex_loss(r["pred_vertices"], r["vertices"]))
    return scores


# --------------------------------------------------------------------------------------------
# training


def training_loss(out: dict, batch: Mapping, config: TrainConfig,
                  faces: torch.Tensor | None = None) -> tuple[torch.Tensor, dict]:
    """The objective of one (micro-)batch: the paper's L1 vertex loss plus the optional terms.

    Args:
        out: the network's output (``vertices``, ``joints``, and ``uv`` with a keypoint
            encoder).
        batch: the items (``vertices``, ``joints``, ``root``, ``K``), on ``out``'s device.
        config: weights ``keypoint_weight``, ``aligned_weight``, ``edge_weight``, ``normal_weight``
            (0 = term off; see [`handmesh_tutorial.losses`][handmesh_tutorial.losses]) and
            ``image_size``.
        faces: ``(F, 3)`` int64 faces (needed by the edge and normal terms).

    Returns:
        ``(total, parts)``: the scalar to minimise and a dict of each active term's value
        (floats; ``vertex`` in metres).

    Raises:
        ValueError: a keypoint weight without a ``uv`` output, or a mesh term without faces.
    """
    loss = vertex_loss(out["vertices"], batch["vertices"])
    parts = {"vertex": float(loss.detach())}

    def add(name, weight, value):
        nonlocal loss
        loss = loss + weight * value
        parts[name] = float(value.detach())

    if config.keypoint_weight:
        if "uv" not in out:
            raise ValueError("keypoint_weight > 0 needs a model with a keypoint encoder "
                             "(model_kwargs={'keypoints': True})")
        target = normalised_keypoints(batch["joints"], batch["root"], batch["K"],
                                      config.image_size)
        add("keypoint", config.keypoint_weight, keypoint_loss(out["uv"], target))
    if config.aligned_weight:
        add("aligned", config.aligned_weight, aligned_joint_loss(out["joints"], batch["joints"]))
    if config.edge_weight or config.normal_weight:
        if faces is None:
            raise ValueError("edge_weight / normal_weight need the mesh faces")
        if config.edge_weight:
            add("edge", config.edge_weight,
                edge_length_loss(out["vertices"], batch["vertices"], faces))
        if config.normal_weight:
            add("normal", config.normal_weight,
                normal_loss(out["vertices"], batch["vertices"], faces))
    return loss, parts


def _train_step(net, batch: dict, chunks: int, device: torch.device, ddp: bool,
                config: TrainConfig, faces: torch.Tensor | None) -> float:
    """Forward/backward over ``chunks`` equal micro-batches.

    Returns the mean chunk L1 vertex loss (metres; comparable across recipes), or NaN when the
    objective was not finite."""
    import contextlib

    images = batch["image"]
    n = images.shape[0]
    if n % chunks:
        raise RuntimeError(f"batch of {n} not divisible into {chunks} micro-batches")
    per = n // chunks
    total = 0.0
    keys = ("vertices", "joints", "root", "K")
    for c in range(chunks):
        sl = slice(c * per, (c + 1) * per)
        sync = (not ddp) or c == chunks - 1
        ctx = contextlib.nullcontext() if sync else net.no_sync()
        half = config.precision == "bfloat16"
        with ctx:
            with torch.autocast(device.type, dtype=torch.bfloat16, enabled=half):
                out = net(images[sl].to(device, non_blocking=True))
                if half:  # the losses (Procrustes, keypoints) in float32
                    out = {k: v.float() for k, v in out.items()}
            part = {k: batch[k][sl].to(device, non_blocking=True) for k in keys if k in batch}
            loss, parts = training_loss(out, part, config, faces)
            (loss / chunks).backward()
        if not math.isfinite(float(loss.detach())):
            return math.nan
        total += parts["vertex"] / chunks
    return total


def train(config: TrainConfig, *, resume: bool = False, overwrite: bool = False, dataset=None,
          val_dataset=None, template=None,
          callback: Callable[[dict], None] | None = None) -> TrainResult:
    """Train MSMR-Net (single process, or one rank of a ``torchrun`` job).

    Args:
        config: the run (see [`TrainConfig`][handmesh_tutorial.train.TrainConfig]).
        resume: continue from ``out_dir/checkpoint_last.pt`` (must exist); the architecture
            and template must match; ``epochs`` may be larger than before.
        overwrite: start afresh in an ``out_dir`` that already holds a run's checkpoints
            (they are replaced). Without ``resume`` or ``overwrite`` such a folder is refused,
            so a forgotten ``--resume`` never destroys a run.
        dataset: a training dataset to use instead of ``config.data`` (items as
            [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset] returns; ``set_epoch`` is
            called when it exists).
        val_dataset: a validation dataset (with ``dataset``), or ``None``.
        template: overrides ``config.template`` (object or path; only its hash is stored).
        callback: called on every rank after each epoch with that epoch's metrics row.

    Returns:
        A [`TrainResult`][handmesh_tutorial.train.TrainResult].

    Raises:
        FloatingPointError: the loss became NaN or infinite (message names epoch and step).
        FileNotFoundError: ``resume`` without a checkpoint, or missing data.
        FileExistsError: ``out_dir`` holds a run's checkpoints and neither ``resume`` nor
            ``overwrite`` was given.
        ValueError: inconsistent config, template/data vertex counts that differ, or a
            checkpoint of another architecture.
    """
    t_start = time.perf_counter()
    if config.threads is not None:
        torch.set_num_threads(int(config.threads))
    local_rank = int(os.environ.get("LOCAL_RANK", "0"))
    device = _resolve_device(config.device, local_rank)
    if device.type == "cuda":
        torch.cuda.set_device(device)
    rank, world, owns_pg = _init_distributed(device)
    try:
        return _train(config, resume, overwrite, dataset, val_dataset, template, callback,
                      device, rank, world, t_start)
    finally:
        if owns_pg:
            import torch.distributed as dist

            dist.destroy_process_group()


def changed_settings(saved: Mapping, config: TrainConfig) -> dict:
    """Fields of ``config`` that differ from a checkpoint's ``saved`` config and may not.

    Fields in [`RESUMABLE_KEYS`][handmesh_tutorial.train.RESUMABLE_KEYS] may change; paths
    (``data``, ``val_data``, ``template``) count as equal when they name the same file or folder.

    Returns:
        ``{field: (saved value, new value)}``, empty when the run can resume.
    """
    now = config.to_dict()
    diff = {}
    for k, v in now.items():
        if k in RESUMABLE_KEYS or k in _ARCH_KEYS:
            continue
        old = saved.get(k, TrainConfig.__dataclass_fields__[k].default)
        if k in _PATH_KEYS and old is not None and v is not None \
                and os.path.realpath(old) == os.path.realpath(v):
            continue
        if old != v:
            diff[k] = (old, v)
    return diff


RUN_CHECKPOINTS = ("checkpoint_last.pt", "checkpoint_best.pt")
"""Files of a run that a fresh start would replace ([`train`][handmesh_tutorial.train.train] refuses
them by default)."""


def existing_run(out_dir) -> list[str]:
    """Names of the checkpoints in ``out_dir`` that a fresh (non-resumed) run would replace."""
    out = Path(out_dir)
    return [n for n in RUN_CHECKPOINTS if (out / n).exists()]


def remove_stale_temp_files(out_dir) -> list[Path]:
    """Delete the half-written temp files a killed run left in ``out_dir``.

    Only names that this module's atomic writes make (``.<file>.<random>.tmp`` for its own
    checkpoint, metrics and config files) are removed, never other files of the folder.

    Returns:
        The removed paths.
    """
    out = Path(out_dir)
    gone = [tmp for name in (*RUN_CHECKPOINTS, "metrics.csv", "steps.csv", "config.json")
            for tmp in leftover_temporaries(out / name)]
    for tmp in gone:
        tmp.unlink()
    return gone


def _train(config, resume, overwrite, dataset, val_dataset, template, callback, device, rank,
           world, t_start) -> TrainResult:
    out = Path(config.out_dir)
    is_main = rank == 0
    if not resume and not overwrite and (found := existing_run(out)):
        raise FileExistsError(
            f"{out} already holds a training run ({', '.join(found)}): resume it "
            "(train(..., resume=True), handmesh train --resume), replace it (overwrite=True, "
            "--overwrite) or choose another out_dir")
    if is_main:
        out.mkdir(parents=True, exist_ok=True)
        remove_stale_temp_files(out)
    tmpl = resolve_template(config.template if template is None else template)
    t_id = template_hash(tmpl)

    last, best_path = out / "checkpoint_last.pt", out / "checkpoint_best.pt"
    ck = None
    if resume and not last.exists() and (out / "config.json").exists():
        # a run killed before its first checkpoint: nothing to continue, nothing to lose
        warnings.warn(f"{out}: no checkpoint_last.pt yet (the run stopped before its first "
                      "checkpoint); starting from epoch 1", stacklevel=3)
        resume = False
    if resume:  # check before building anything
        ck = _read_checkpoint(last, map_location=device)
        if ck["template_hash"] != t_id:
            raise ValueError(f"{last}: trained with template {ck['template_hash']}, this run "
                             f"uses {t_id}")
        old = TrainConfig.from_dict(ck["config"]).architecture()
        if old != config.architecture():
            diff = {k: (old[k], config.architecture()[k]) for k in old
                    if old[k] != config.architecture()[k]}
            raise ValueError(f"{last}: architecture differs from the config (checkpoint, "
                             f"config): {diff}")
        changed = changed_settings(ck["config"], config)
        if changed:
            raise ValueError(
                f"{last}: cannot resume with other settings (checkpoint, now): {changed}. "
                f"Resume with the run's settings (only {', '.join(RESUMABLE_KEYS)} may "
                "change), or start a new run in another out_dir")

    torch.manual_seed(config.seed)
    np.random.seed(config.seed % 2**32)  # noqa: NPY002 - for user code relying on it
    random.seed(config.seed)
    net = build_model_from_config(config, tmpl).to(device)
    faces = torch.as_tensor(np.asarray(tmpl.faces), dtype=torch.int64, device=device)
    # fused: one kernel for all parameters instead of ~10 small ops per tensor (about 300
    # tensors here); same update rule (a resumed run keeps the flag saved in its checkpoint)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr, weight_decay=config.weight_decay,
                           fused=device.type in ("cpu", "cuda"))
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=config.lr_step, gamma=config.lr_gamma)

    start_epoch, step, history, step_losses, best = 0, 0, [], [], math.inf
    rng_to_restore = None
    if ck is not None:
        net.load_state_dict(ck["model"])
        opt.load_state_dict(ck["optimizer"])
        sched.load_state_dict(ck["scheduler"])
        # the config's schedule wins (a resumed run may change epochs / lr_step)
        sched.step_size, sched.gamma = config.lr_step, config.lr_gamma
        start_epoch, step = int(ck["epoch"]), int(ck["step"])
        history = [dict(r) for r in ck["history"]]
        step_losses = [float(x) for x in ck["step_losses"].tolist()]
        best = float(ck["best"])
        rng_to_restore = ck["rng"]
        if is_main:  # logs written after the checkpoint by a killed run go back to it
            _write_logs(out, history, step_losses, config.durable)

    if dataset is None:
        train_ds, val_ds = make_datasets(config)
    else:
        train_ds, val_ds = dataset, val_dataset
    skipped = []
    if config.skip_bad:
        train_ds, val_ds, skipped = _skip_bad_items(train_ds, val_ds, config.progress and is_main)
        if is_main:
            write_json(out / "skipped.json", {"skipped": skipped})
    n_vert = int(net.joint_regressor.shape[1])
    got = tuple(train_ds[0]["vertices"].shape)
    if got != (n_vert, 3):
        raise ValueError(f"training targets have vertices {got}, the template has ({n_vert}, 3):"
                         " train with the template of the data (TrainConfig.template)")

    model = net
    if world > 1:
        from torch.nn.parallel import DistributedDataParallel as DDP  # noqa: N817

        model = DDP(net, device_ids=[device.index] if device.type == "cuda" else None)
    if rng_to_restore is not None:
        _set_rng_state(rng_to_restore)
    if is_main:
        write_json(out / "config.json", {"config": config.to_dict(), "template_hash": t_id,
                                          "world_size": world})
    sampler = EpochBatchSampler(len(train_ds), config.batch_size, config.seed, rank, world,
                                config.micro_batches)
    val_bs = config.val_batch_size or config.batch_size

    for epoch in range(start_epoch, config.epochs):
        t_epoch = time.perf_counter()
        sampler.set_epoch(epoch)
        if hasattr(train_ds, "set_epoch"):
            train_ds.set_epoch(epoch)
        loader = torch.utils.data.DataLoader(
            train_ds, batch_sampler=sampler, num_workers=config.num_workers,
            pin_memory=device.type == "cuda",
            generator=torch.Generator().manual_seed(config.seed * 100003 + epoch))
        model.train()
        lr = opt.param_groups[0]["lr"]
        losses = []
        bar = progress_bar(loader, desc=f"epoch {epoch + 1}/{config.epochs}", per="epoch",
                   disable=not (config.progress and is_main), leave=False)
        for batch in bar:
            opt.zero_grad(set_to_none=True)
            loss = _train_step(model, batch, config.micro_batches, device, world > 1,
                               config, faces)
            loss = _mean_over_ranks(loss, world, device)
            if not math.isfinite(loss):
                raise FloatingPointError(
                    f"loss is {loss} at epoch {epoch + 1} (1-based), step {step + 1} (global, "
                    f"1-based), batch {len(losses) + 1} of the epoch; the optimiser step was "
                    f"not taken. Check the data for NaN/inf targets or lower lr ({lr:g}).")
            opt.step()
            step += 1
            losses.append(loss)
            step_losses.append(loss)
            bar.set_postfix(loss_mm=f"{1000 * loss:.2f}", lr=f"{lr:.2g}")
        bar.close()
        sched.step()
        row = {c: math.nan for c in METRIC_COLUMNS}
        row.update(epoch=epoch + 1, step=step, train_loss=float(np.mean(losses)), lr=lr,
                   seconds=time.perf_counter() - t_epoch)
        last_epoch = epoch + 1 == config.epochs
        if val_ds is not None and ((epoch + 1) % config.val_every == 0 or last_epoch):
            if is_main:
                v = validate(net, val_ds, val_bs, device)
                row["val_loss"] = v["loss"]
                row.update({f"val_{k}": float(v[k]) for k in _VAL_KEYS})
            row = _broadcast_row(row, world)
        history.append(row)
        improved = math.isfinite(row["val_pa_mpvpe"]) and row["val_pa_mpvpe"] < best
        if improved:
            best = row["val_pa_mpvpe"]
        if is_main:
            kw = dict(model=net, config=config, template_id=t_id, epoch=epoch + 1, step=step,
                      history=history, step_losses=step_losses, best=best,
                      durable=config.durable)
            # Order matters for a kill between two writes: best before last, so that a resume
            # from the older last checkpoint redoes this epoch and rewrites best; the CSVs
            # after both, and a resume rewrites them from the checkpoint's history.
            if improved:  # weights only (no optimiser state): for evaluation, not for resuming
                save_checkpoint(best_path, **kw)
            if (epoch + 1) % config.checkpoint_every == 0 or last_epoch:
                save_checkpoint(last, optimizer=opt, scheduler=sched, **kw)
            _write_logs(out, history, step_losses, config.durable)
        if callback is not None:
            callback(dict(row))
        _barrier(world)

    done = len(history)
    return TrainResult(
        out_dir=out, checkpoint=last if is_main and last.exists() else None,
        best_checkpoint=best_path if is_main and best_path.exists() else None,
        metrics_csv=out / "metrics.csv" if is_main and history else None,
        history=history, step_losses=step_losses, final=dict(history[-1]) if history else {},
        epochs=done, steps=step, seconds=time.perf_counter() - t_start, model=net, rank=rank,
        world_size=world, skipped=skipped)


def _skip_bad_items(train_ds, val_ds, progress: bool):
    """``(train_ds, val_ds, skipped)`` without the items that cannot be loaded."""
    skipped = []
    found = {}
    for split, ds in (("train", train_ds), ("val", val_ds)):
        if ds is None:
            continue
        found[split], bad = A.drop_bad_items(ds, progress, "training" if split == "train"
                                             else "validation", allow_empty=split == "val")
        skipped += [{"split": split, "index": b["index"], "error": b["error"]} for b in bad]
        if bad:
            warnings.warn(f"skipping {len(bad)} of {len(ds)} {split} samples that cannot be "
                          f"read (first: {bad[0]['error']})", stacklevel=4)
    val = found.get("val")
    return found["train"], None if val is not None and len(val) == 0 else val, skipped


def _write_logs(out: Path, history: list[dict], step_losses: list[float], durable: bool) -> None:
    """``metrics.csv`` (one row per epoch) and ``steps.csv`` (one loss per step)."""
    _write_csv(out / "metrics.csv", history, METRIC_COLUMNS, durable)
    _write_csv(out / "steps.csv", [{"step": i + 1, "loss": x} for i, x in enumerate(step_losses)],
               ("step", "loss"), durable)


def _broadcast_row(row: dict, world: int) -> dict:
    """Rank 0's validation numbers to every rank (so callbacks and results agree)."""
    if world == 1:
        return row
    import torch.distributed as dist

    obj = [row]
    dist.broadcast_object_list(obj, src=0)
    return obj[0]


# --------------------------------------------------------------------------------------------
# evaluation


REST_HAND, MEAN_HAND = "rest hand (no network)", "mean training hand (no network)"
"""Names of the two constant baselines in tables and reports."""


def constant_hand_predictions(template_vertices, joint_regressor, num: int):
    """A constant baseline's answer for ``num`` images: the same hand every time.

    Args:
        template_vertices: ``(V, 3)`` the constant hand in the network frame (the rest hand,
            [`root_centred_template`][handmesh_tutorial.model.root_centred_template], or
            [`mean_hand`][handmesh_tutorial.train.mean_hand]), metres; numpy or torch.
        joint_regressor: ``(21, V)`` regressor the network uses for its joints.
        num: number of predictions.

    Returns:
        ``(vertices (num, V, 3), joints (num, 21, 3))`` float32 tensors, metres.
    """
    tv = torch.as_tensor(template_vertices, dtype=torch.float32).detach().cpu()
    jr = torch.as_tensor(joint_regressor, dtype=torch.float32).detach().cpu()
    if tv.ndim != 2 or tv.shape[1] != 3 or jr.ndim != 2 or jr.shape[1] != tv.shape[0]:
        raise ValueError(f"template_vertices must be (V, 3) and joint_regressor (J, V), got "
                         f"{tuple(tv.shape)} and {tuple(jr.shape)}")
    return tv.expand(num, -1, -1).clone(), (jr @ tv).expand(num, -1, -1).clone()


def mean_hand(dataset, template=None, iterations: int = 5) -> np.ndarray:
    """The mean training hand: the generalised Procrustes mean of a dataset's target meshes.

    Each target is aligned to the current mean by a similarity transform (rotations only, no
    reflection) and the aligned meshes are averaged, ``iterations`` times, starting from the rest
    hand. The result is the average *articulation* of the data with orientation and size removed:
    predicted for every image it is a constant answer, like the rest hand, but the best one for
    the aligned metrics. A network whose PA- errors are not below it has learnt the data's mean
    pose, not to read each hand's pose from its image.

    Args:
        dataset: a [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset] (e.g. the training
            split of [`make_datasets`][handmesh_tutorial.train.make_datasets]; its ``target_shape``,
            without images) or any dataset of items with ``vertices``.
        template: the network's template (default: the library's hand).
        iterations: alignment-and-average rounds (the mean changes by < 0.01 mm after 3 on
            INTER-SH).

    Returns:
        ``(V, 3)`` float64 vertices in the network frame (aligned to the root-centred rest hand,
        then joint 9 moved to the origin), metres.
    """
    tmpl = resolve_template(template)
    if len(dataset) == 0:
        raise ValueError("the dataset is empty")
    rest = _rest_template(tmpl)
    shape = getattr(dataset, "target_shape", None)  # without images where the dataset can
    verts = np.stack([shape(i) if shape else dataset[i]["vertices"].double().numpy()
                      for i in range(len(dataset))])
    if verts.shape[1:] != rest.shape:
        raise ValueError(f"the dataset's vertices {verts.shape[1:]} do not match the template's "
                         f"{rest.shape}")
    mean = rest
    for _ in range(int(iterations)):
        mean = M.procrustes_align(verts, np.broadcast_to(mean, verts.shape),
                                  allow_reflection=False).mean(0)
    mean = M.procrustes_align(mean[None], rest[None], allow_reflection=False)[0]
    return mean - tmpl.joint_regressor[9] @ mean


def _rest_template(template):
    from .model import root_centred_template

    return root_centred_template(template)


def constant_hand_scores(dataset, vertices=None, template=None) -> dict:
    """FreiHAND-style scores of one constant mesh predicted for every item (no network).

    Args:
        dataset: a [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset] (or a ``Subset``
            of one); only its ``vertices`` and ``joints`` are read.
        vertices: ``(V, 3)`` the constant mesh in the network frame, e.g.
            [`mean_hand`][handmesh_tutorial.train.mean_hand]; default the rest hand (the template's
            root-centred open hand).
        template: the network's template (default: the library's hand); its joint regressor
            gives the constant mesh's joints.

    Returns:
        [`freihand_scores`][handmesh_tutorial.metrics.freihand_scores] (mm, AUC, F-scores).
    """
    tmpl = resolve_template(template)
    if len(dataset) == 0:
        raise ValueError("the dataset is empty")
    items = [dataset[i] for i in range(len(dataset))]
    gv = torch.stack([it["vertices"] for it in items])
    gj = torch.stack([it["joints"] for it in items])
    const = _rest_template(tmpl) if vertices is None else vertices
    rv, rj = constant_hand_predictions(const, tmpl.joint_regressor, len(items))
    return M.freihand_scores(pred_joints=rj, gt_joints=gj, pred_verts=rv, gt_verts=gv)


def _item_kinds(dataset, index: np.ndarray) -> list | None:
    """Scene kind of each evaluated item (INTER-SH readers only), else ``None``."""
    base = dataset
    while isinstance(base, torch.utils.data.Subset):
        base = base.dataset
    source = getattr(base, "source", None)
    if source is None or not hasattr(source, "annotation"):
        return None
    return [source.annotation(int(i)).get("kind") for i in index]


def _score_predictions(pred_joints, pred_vertices, r: dict, vr: np.ndarray, kinds,
                       faces) -> dict:
    """Scores, per-sample errors and the VR / kind / overall rows of one set of predictions."""
    from .surface import flipped_face_fraction, roughness_deg

    errors = M.per_sample_scores(pred_joints=pred_joints, gt_joints=r["joints"],
                                 pred_verts=pred_vertices, gt_verts=r["vertices"])
    scores = M.scores_from_errors(errors)
    if faces is not None:
        pv, gv = pred_vertices.double().numpy(), r["vertices"].double().numpy()
        errors["roughness_deg"] = roughness_deg(pv, gv, faces)
        errors["flipped"] = flipped_face_fraction(pv, gv, faces)
        scores["roughness_deg"] = float(errors["roughness_deg"].mean())
        scores["flipped"] = float(errors["flipped"].mean())
    per_sample = {
        "index": r["index"].numpy(), "vr": vr, "mirrored": r["mirrored"].numpy(),
        "mpjpe": 1000 * errors["joint_err"].mean(1), "mpvpe": 1000 * errors["vert_err"].mean(1),
        "pa_mpjpe": 1000 * errors["joint_err_pa"].mean(1),
        "pa_mpvpe": 1000 * errors["vert_err_pa"].mean(1),
        "f_at_5mm": errors["fscore"][:, 0], "f_at_15mm": errors["fscore"][:, 1],
    }
    for key in M.SURFACE_KEYS:
        if key in errors:
            per_sample[key] = errors[key]
    if kinds is not None:
        per_sample["kind"] = np.array([str(k) for k in kinds])
    vr_table = M.scores_by_vr_bin(errors, vr) if np.isfinite(vr).any() else []
    kind_table = [] if kinds is None else M.scores_by_group(
        errors, kinds, order=[k for k in KINDS if k in set(kinds)])
    overall = {"bin": "all", "count": len(vr), "mpjpe": scores["mpjpe"],
               "rr_mpjpe": 1000 * float(errors["joint_err_rr"].mean()),
               "pa_mpjpe": scores["pa_mpjpe"], "auc": scores["auc_joints_20mm"],
               "pa_mpvpe": scores["pa_mpvpe"], "f_at_5mm": scores["f_at_5mm"],
               "f_at_15mm": scores["f_at_15mm"]}
    for key in M.SURFACE_KEYS:
        if key in scores:
            overall[key] = scores[key]
    return {"errors": errors, "scores": scores, "per_sample": per_sample, "vr_table": vr_table,
            "kind_table": kind_table, "overall": overall}


def evaluate(checkpoint_or_model, data=None, *, dataset=None, kind: str | None = None,
             split: str = "evaluation", image_size: int | None = None, batch_size: int = 16,
             device: str = "auto", out_dir: str | os.PathLike | None = None,
             camera_frame: bool = True, num_samples: int | None = None, template=None,
             progress: bool = True, threads: int | None = None, baseline: bool = True,
             mean_hand=None, skip_bad: bool = False) -> dict:
    """Evaluate a trained network: FreiHAND-style scores, per-sample errors, VR table, figures.

    Every item is the deterministic crop of its target hand (no augmentation); errors are
    measured in the root-centred frame with the ground-truth root (FreiHAND's protocol reports
    aligned and root-relative numbers; mirroring is undone for the predictions only where
    ``camera_frame`` asks for it, distances do not change).

    Args:
        checkpoint_or_model: a checkpoint path, or a network (then give ``image_size``).
        data: INTER-SH root (``kind="intersh"``) or FreiHAND root (``kind="freihand"``, split
            ``split``).
        dataset: a ready [`HandCropDataset`][handmesh_tutorial.augment.HandCropDataset] instead of
            ``data``.
        kind: ``"intersh"`` or ``"freihand"`` (default: the checkpoint's ``dataset``, else
            ``"intersh"``).
        split: FreiHAND split.
        image_size: crop side (default: the checkpoint's ``image_size``).
        batch_size: evaluation batch size.
        device: ``"auto"``, ``"cpu"``, ``"cuda"``.
        out_dir: when given, writes ``eval.json``, ``predictions.npz``, ``pck.png``,
            ``vr.png``.
        camera_frame: predictions un-mirrored and moved back to the source camera frame
            (ground-truth root added); ``False``: the network's root-centred right-hand frame.
        num_samples: evaluate only the first ``num_samples`` items.
        template: template for loading a checkpoint (see
            [`load_checkpoint`][handmesh_tutorial.train.load_checkpoint]).
        progress: tqdm bar.
        threads: ``torch.set_num_threads`` value.
        baseline: also score the **rest-hand baseline** on the same items: the network's template
            (the open rest-pose hand, root-centred) predicted for every image, no network at all
            ([`constant_hand_predictions`][handmesh_tutorial.train.constant_hand_predictions]).
            After Procrustes alignment it is the bar a model must clear to have learnt the hand's
            articulation.
        mean_hand: ``(V, 3)`` network-frame vertices of a second constant baseline scored the same
            way, normally [`mean_hand`][handmesh_tutorial.train.mean_hand] of the training data (the
            data's average articulation): the bar a model must clear to read *each* hand's pose from
            its image.
        skip_bad: load every item once first and leave out those that cannot be read (listed
            in ``skipped``); ``False``: the first bad sample stops the evaluation, named.

    Returns:
        dict with ``scores`` ([`freihand_scores`][handmesh_tutorial.metrics.freihand_scores]: mm,
        AUC, F-scores, plus the surface scores ``roughness_deg`` and ``flipped`` when the network
        has ``faces``: [`roughness_deg`][handmesh_tutorial.surface.roughness_deg], the mean
        [`flipped_face_fraction`][handmesh_tutorial.surface.flipped_face_fraction]), ``per_sample``
        (``index``, ``vr``, ``mirrored``, ``kind`` (INTER-SH) and per-sample ``mpjpe``, ``mpvpe``,
        ``pa_mpjpe``, ``pa_mpvpe`` in mm, ``f_at_5mm``, ``f_at_15mm``, ``roughness_deg``,
        ``flipped``; (N,) arrays), ``errors``
        ([`per_sample_scores`][handmesh_tutorial.metrics.per_sample_scores], metres), ``vr_table``
        (rows of [`scores_by_vr_bin`][handmesh_tutorial.metrics.scores_by_vr_bin] over the target
        hands' VR; empty when no sample has a VR), ``kind_table`` (rows of
        [`scores_by_group`][handmesh_tutorial.metrics.scores_by_group] per scene kind, INTER-SH
        only, else empty), ``table`` (markdown), ``baseline`` (with ``baseline=True``: the rest
        hand's ``scores``, ``per_sample``, ``errors``, ``vr_table``, ``kind_table`` on the same
        items, else ``None``), ``mean_hand_baseline`` (the same for ``mean_hand``, or ``None``),
        ``comparison`` (markdown, model / rest hand / mean hand, those scored, per VR bin, kind and
        overall; ``""`` without either baseline), ``predictions`` (``vertices`` (N, V, 3),
        ``joints`` (N, 21, 3) numpy, metres), ``num_samples``, ``files`` (paths written) and
        ``skipped`` (``[{"index": reader index, "error": message}, ...]``, the items ``skip_bad``
        left out; also in ``eval.json``).
    """
    if threads is not None:
        torch.set_num_threads(int(threads))
    dev = _resolve_device(device)
    source = None
    if isinstance(checkpoint_or_model, str | os.PathLike):
        source = str(checkpoint_or_model)
        net, ck = load_checkpoint(checkpoint_or_model, dev, template)
        cfg = ck["config"]
        image_size = image_size or cfg["image_size"]
        box_scale = cfg.get("box_scale", 1.5)
        kind = kind or cfg.get("dataset", "intersh")
    else:
        net = checkpoint_or_model.to(dev)
        box_scale = 1.5
    if dataset is None:
        if data is None:
            raise ValueError("give data (a data root) or dataset")
        if image_size is None:
            raise ValueError("image_size is needed when evaluating a model object")
        kind = kind or "intersh"
        if kind == "intersh":
            dataset = A.InterSHTorchDataset(data, image_size, train=False, box_scale=box_scale)
        elif kind == "freihand":
            dataset = A.FreiHANDTorchDataset(data, split, image_size, train=False)
        else:
            raise ValueError(f"kind must be 'intersh' or 'freihand', got {kind!r}")
        if num_samples is not None:
            dataset = torch.utils.data.Subset(dataset, range(min(num_samples, len(dataset))))
    elif num_samples is not None:
        dataset = torch.utils.data.Subset(dataset, range(min(num_samples, len(dataset))))
    skipped = []
    if skip_bad:
        dataset, bad = A.drop_bad_items(dataset, progress, "evaluation")
        skipped = [{"index": b["index"], "error": b["error"]} for b in bad]
    if len(dataset) == 0:
        raise ValueError("the evaluation set is empty")

    r = _run_dataset(net, dataset, batch_size, dev, progress=progress, desc="evaluate")
    faces = getattr(net, "faces", None)
    kinds = _item_kinds(dataset, r["index"].numpy())
    vr = r["vr"].double().numpy()
    model = _score_predictions(r["pred_joints"], r["pred_vertices"], r, vr, kinds, faces)
    rest = None
    if baseline:
        tv = getattr(net, "template", None)
        rest_v, rest_j = constant_hand_predictions(
            tv if tv is not None else _rest_template(resolve_template(template)),
            net.joint_regressor, len(vr))
        rest = _score_predictions(rest_j, rest_v, r, vr, kinds, faces)
    mean = None
    if mean_hand is not None:
        mv = torch.as_tensor(mean_hand, dtype=torch.float64).detach().cpu().numpy()
        if mv.shape != tuple(r["vertices"].shape[1:]):
            raise ValueError(f"mean_hand must be {tuple(r['vertices'].shape[1:])}, got "
                             f"{mv.shape}")
        mean_v, mean_j = constant_hand_predictions(mv, net.joint_regressor, len(vr))
        mean = _score_predictions(mean_j, mean_v, r, vr, kinds, faces)
    table = M.format_table([*model["vr_table"], *model["kind_table"], model["overall"]])
    comparison = ""
    if rest is not None or mean is not None:
        comparison = M.comparison_table(
            *[[*x["vr_table"], *x["kind_table"], x["overall"]]
              for x in (model, rest, mean) if x is not None], first="VR bin / kind")
    scores, errors, per_sample = model["scores"], model["errors"], model["per_sample"]
    vr_table = model["vr_table"]
    if camera_frame:
        batch = {"root": r["root"], "R": r["R"], "mirrored": r["mirrored"]}
        pv, pj = A.to_camera(r["pred_vertices"], batch), A.to_camera(r["pred_joints"], batch)
    else:
        pv, pj = r["pred_vertices"], r["pred_joints"]
    result = {
        "scores": scores, "per_sample": per_sample, "errors": errors, "vr_table": vr_table,
        "kind_table": model["kind_table"], "table": table, "num_samples": int(len(vr)),
        "baseline": None if rest is None else {k: rest[k] for k in (
            "scores", "per_sample", "errors", "vr_table", "kind_table")},
        "mean_hand_baseline": None if mean is None else {k: mean[k] for k in (
            "scores", "per_sample", "errors", "vr_table", "kind_table")},
        "comparison": comparison,
        "predictions": {"vertices": pv.numpy(), "joints": pj.numpy(),
                        "frame": "camera" if camera_frame else "network"},
        "files": {},
        "skipped": skipped,
    }
    if out_dir is not None:
        result["files"] = _write_eval(Path(out_dir), result, source, errors)
    return result


def _write_eval(out: Path, res: dict, source: str | None, errors: dict) -> dict:
    import matplotlib.pyplot as plt

    from . import viz

    out.mkdir(parents=True, exist_ok=True)
    files = {}
    summary = {"checkpoint": source, "scores": res["scores"], "vr_table": res["vr_table"],
               "kind_table": res["kind_table"], "num_samples": res["num_samples"],
               "per_sample": {k: v.tolist() for k, v in res["per_sample"].items()},
               "baseline": None if res["baseline"] is None else {
                   "name": REST_HAND, "scores": res["baseline"]["scores"],
                   "vr_table": res["baseline"]["vr_table"],
                   "kind_table": res["baseline"]["kind_table"],
                   "per_sample": {k: v.tolist()
                                  for k, v in res["baseline"]["per_sample"].items()}},
               "mean_hand_baseline": None if res["mean_hand_baseline"] is None else {
                   "name": MEAN_HAND, "scores": res["mean_hand_baseline"]["scores"],
                   "vr_table": res["mean_hand_baseline"]["vr_table"],
                   "kind_table": res["mean_hand_baseline"]["kind_table"]},
               "comparison": res["comparison"],
               "predictions_frame": res["predictions"]["frame"],
               "skipped": res.get("skipped", [])}
    files["json"] = out / "eval.json"
    write_json(files["json"], summary)
    buf = io.BytesIO()
    p = res["predictions"]
    np.savez(buf, vertices=p["vertices"].astype(np.float32), joints=p["joints"].astype(np.float32),
             index=res["per_sample"]["index"], vr=res["per_sample"]["vr"],
             mirrored=res["per_sample"]["mirrored"])
    files["predictions"] = out / "predictions.npz"
    _atomic_write_bytes(files["predictions"], buf.getvalue())

    fig, ax = plt.subplots(figsize=(5, 3.6))
    curves = {"joints (PA)": errors["joint_err_pa"], "vertices (PA)": errors["vert_err_pa"],
              "joints (root-rel.)": errors["joint_err_rr"]}
    if res["baseline"] is not None:  # the bar to clear, on the same samples
        curves["rest hand, joints (PA)"] = res["baseline"]["errors"]["joint_err_pa"]
    if res["mean_hand_baseline"] is not None:
        curves["mean hand, joints (PA)"] = res["mean_hand_baseline"]["errors"]["joint_err_pa"]
    viz.plot_pck_curves(ax, curves)
    ax.set_title(f"3D PCK, {res['num_samples']} samples")
    files["pck"] = viz.save_figure(fig, out / "pck.png", dpi=90)
    plt.close(fig)
    if res["vr_table"]:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
        viz.plot_error_vs_vr(axes[0], res["per_sample"]["vr"], res["per_sample"]["pa_mpjpe"],
                             label="PA-MPJPE")
        viz.plot_vr_table(axes[1], res["vr_table"], metric="pa_mpjpe")
        axes[1].set_ylabel("PA-MPJPE (mm)")
        files["vr"] = viz.save_figure(fig, out / "vr.png", dpi=90)
        plt.close(fig)
    return files
