"""The settings of a training run: [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig].

Paper, Sec. "Training": the loss is the L1 distance between predicted and ground-truth mesh
vertices, the vertices translated so that the middle MCP joint (keypoint 9) is at the origin; Adam
with learning rate ``1e-4`` for 200 epochs, halved every 50 epochs; batch size 32; images normalised
with mean 0.5 and standard deviation 1.0; random crops and transformations. Those are the defaults
of [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig]; the other recipes of the project
(the CPU recipe, the demo's, the pretrained network's) are named presets of it
([`TrainConfig.preset`][handmesh_tutorial.train.config.TrainConfig.preset]). Also here: which
fields define the
network (compared when resuming or loading a checkpoint) and which a resumed run may change
([`RESUMABLE_KEYS`][handmesh_tutorial.train.config.RESUMABLE_KEYS],
[`changed_settings`][handmesh_tutorial.train.config.changed_settings]).

Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import copy
import math
import os
import textwrap
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

from ..budget import (
    MAX_BATCH_SIZE,
    MAX_CHANNELS,
    check_count,
    check_image_size,
)
from ..budget import budget as _budget

__all__ = ["TrainConfig", "changed_settings", "RESUMABLE_KEYS", "PRESETS"]

# the paper's decoder regresses the vertex coordinates (no output smoothing); one L1 loss
_PAPER = {"model_kwargs": {"output": "xyz", "smoothing_length": 0.0}}
_CPU = {"model_kwargs": {"keypoints": True, "global_rotation": True, "output": "skinned"},
        "keypoint_weight": 0.5, "aligned_weight": 1.0}
_SMALL = {"encoder": "resnet10", "image_size": 128, "lr": 1e-3}

PRESETS: dict[str, dict] = {
    "paper": _PAPER,
    "cpu": _CPU,
    "demo": {**_CPU, **_SMALL, "epochs": 10, "batch_size": 16, "lr_step": 8, "augment": False,
             "val_fraction": 0.1, "device": "cpu", "threads": 2, "cache_data": True,
             "init_encoder": "pretrained", "freeze_encoder": 10, "encoder_lr_scale": 0.1},
    "pretraining": {**_CPU, **_SMALL, "epochs": 16, "batch_size": 128, "lr_step": 6,
                    "lr_gamma": 0.3, "augment": True, "precision": "bfloat16",
                    "val_fraction": 0.0, "val_batch_size": 256},
}
"""The named recipes of [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig], each a plain
dict of its fields on top of the defaults; the table and the way to build one:
[`TrainConfig.preset`][handmesh_tutorial.train.config.TrainConfig.preset]."""

# config keys that define the network: they must match when resuming or loading
_ARCH_KEYS = ("encoder", "decoder", "attention", "channels", "latent_channels", "model_kwargs")
RESUMABLE_KEYS = ("epochs", "lr_step", "out_dir", "device", "threads", "num_workers", "cache_data",
                  "val_every", "checkpoint_every", "val_batch_size", "progress", "durable",
                  "skip_bad")
"""[`TrainConfig`][handmesh_tutorial.train.config.TrainConfig] fields a resumed run may change (how
long, where, how fast, what is logged, whether bad samples are skipped); every other field must
equal the checkpoint's, so a run never silently mixes data, seeds, batch sizes or learning rates.
"""
_PATH_KEYS = ("data", "val_data", "template", "init", "init_encoder")


@dataclass
class TrainConfig:
    """Everything a training run needs; the defaults are the paper's recipe but for the output
    (``TrainConfig.preset("paper")`` adds the paper's: the decoder regresses the coordinates).

    Attributes:
        data: training data root (INTER-SH root, or FreiHAND root with ``dataset="freihand"``). May
            be ``None`` when datasets are passed to [`train`][handmesh_tutorial.train.loop.train]
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
        model_kwargs: further [`build_model`][handmesh_tutorial.nn.model.build_model] arguments
            (``spiral_length``, ``num_blocks``, ``num_heads``, ...).
        template: ``None`` = the open right hand; else a ``.npz`` path written by
            [`save_template`][handmesh_tutorial.train.templates.save_template] (``vertices``,
            ``faces``, ``joint_regressor``) or a right-hand MANO pickle (``MANO_RIGHT.pkl``,
            see [`resolve_template`][handmesh_tutorial.train.templates.resolve_template]).
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
            [`training_loss`][handmesh_tutorial.train.loop.training_loss],
            [`handmesh_tutorial.nn.losses`][handmesh_tutorial.nn.losses].)
        skip_bad: before training, load every training and validation item once and leave out
            those that cannot be read (listed in ``TrainResult.skipped`` and ``skipped.json``);
            ``False``: the first bad sample stops the run with its file named. May change on
            resume (the batches after the resume point then differ; ``skipped.json`` says why).
        precision: ``"float32"`` (default) or ``"bfloat16"``: forward pass and loss under
            ``torch.autocast`` in bfloat16 (weights, gradients and the optimiser stay float32).
            Faster on CPUs with bfloat16 units (AVX-512 BF16 / AMX), at a measured cost in
            accuracy (``benchmarks/train.py``, docs page "Performance").
        init: weights to start from instead of random ones: a checkpoint path, or
            ``"pretrained"`` (the shipped network). Its architecture and template must equal
            this run's; only the weights are taken (no optimiser state, no epoch count). A
            resumed run continues from its own checkpoint (``init`` must stay the run's).
        init_encoder: start only the encoder from pretrained weights: ``"pretrained"`` (the
            shipped hand encoder,
            [`pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder]) or the
            path of a pose-encoder file; the rest of the network starts from random weights (the
            paper's protocol). Needs a ``resnet10`` encoder (with ``model_kwargs={"keypoints":
            True}`` it gets the keypoint head too, else the ResNet only); not with ``init``.
        freeze_encoder: epochs at the start during which the encoder's weights and BatchNorm
            statistics stay fixed (0: trained from the first step; ``>= epochs``: frozen
            throughout).
        encoder_lr_scale: the encoder's learning rate as a share of ``lr`` once it trains.
        train_only: names of the network's parts that train (its child modules: ``encoder``,
            ``latent_to_mesh``, ``transformer``, ``decoder``, ...); every other weight stays
            fixed for the whole run, BatchNorm statistics included. ``("decoder",)`` fine-tunes
            the mesh decoder alone, e.g. of ``init="pretrained"``. ``None``: everything trains
            (as ``freeze_encoder`` says).

    Raises:
        ValueError: a field out of its range, checked before anything is allocated (also for
            a checkpoint's config): ``batch_size`` and ``val_batch_size`` above
            [`MAX_BATCH_SIZE`][handmesh_tutorial.budget.MAX_BATCH_SIZE], ``channels`` or
            ``latent_channels`` above [`MAX_CHANNELS`][handmesh_tutorial.budget.MAX_CHANNELS],
            an unknown ``encoder`` or ``decoder``, an ``lr`` that is not finite and > 0... The
            machine's bounds (``threads``, ``num_workers`` by its cores) are checked by
            [`train`][handmesh_tutorial.train.loop.train], so a checkpoint made elsewhere loads.
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
    init: str | None = None
    init_encoder: str | None = None
    freeze_encoder: int = 0
    encoder_lr_scale: float = 1.0
    train_only: tuple[str, ...] | None = None

    def __post_init__(self):
        for name in ("data", "val_data", "template", "init", "init_encoder"):
            v = getattr(self, name)
            if v is not None:
                setattr(self, name, str(v))
        self.out_dir = str(self.out_dir)
        if self.channels is not None:
            if isinstance(self.channels, str | bytes) or not all(
                    hasattr(c, "__index__") and not isinstance(c, bool) for c in self.channels):
                raise ValueError(f"channels must be positive integers, got "
                                 f"{str(self.channels)[:80]}")
            self.channels = tuple(int(c) for c in self.channels)
            if not self.channels or min(self.channels) < 1:
                raise ValueError(f"channels must be positive integers, got {self.channels}")
            if max(self.channels) > MAX_CHANNELS:  # before any layer is allocated
                raise ValueError(f"channels must be at most {MAX_CHANNELS:,} (MAX_CHANNELS), got "
                                 f"{max(self.channels):,}")
        check_count(self.latent_channels, "latent_channels", 1, MAX_CHANNELS, "MAX_CHANNELS")
        if self.threads is not None:
            if isinstance(self.threads, bool) or not isinstance(self.threads, int) \
                    or self.threads < 1:
                raise ValueError(f"threads must be a positive integer or None, got "
                                 f"{self.threads!r}")
        from ..nn.encoder import ENCODERS

        if self.encoder not in ENCODERS:
            raise ValueError(f"encoder must be one of {', '.join(ENCODERS)}, got "
                             f"{str(self.encoder)[:40]!r}")
        if self.decoder not in ("multi", "single"):
            raise ValueError(f"decoder must be 'multi' or 'single', got {str(self.decoder)[:40]!r}")
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
        for name in ("batch_size", "val_batch_size"):
            if getattr(self, name) is not None:
                check_count(getattr(self, name), name, 1, MAX_BATCH_SIZE, "MAX_BATCH_SIZE")
        check_image_size(self.image_size)
        if not 0.0 <= self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in [0, 1), got {self.val_fraction}")
        if isinstance(self.lr, bool) or not isinstance(self.lr, int | float) \
                or not math.isfinite(self.lr) or not self.lr > 0:
            raise ValueError(f"lr must be a finite number > 0, got {self.lr!r}")
        for name in ("keypoint_weight", "aligned_weight", "edge_weight", "normal_weight"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not v >= 0:
                raise ValueError(f"{name} must be a number >= 0, got {v!r}")
            setattr(self, name, float(v))
        if self.keypoint_weight and not self.model_kwargs.get("keypoints", False):
            raise ValueError("keypoint_weight > 0 needs model_kwargs={'keypoints': True} (a "
                             "model with a 2D keypoint head)")
        if self.init_encoder is not None and self.init is not None:
            raise ValueError("init and init_encoder exclude each other: init starts the whole "
                             "network from a checkpoint, init_encoder only its encoder")
        if isinstance(self.freeze_encoder, bool) or not isinstance(self.freeze_encoder, int) \
                or self.freeze_encoder < 0:
            raise ValueError(f"freeze_encoder must be an integer >= 0 (epochs), got "
                             f"{self.freeze_encoder!r}")
        if self.train_only is not None:
            names = (self.train_only,) if isinstance(self.train_only, str) else self.train_only
            self.train_only = tuple(str(n) for n in names)
            if not self.train_only:
                raise ValueError("train_only must name at least one part of the network (e.g. "
                                 "('decoder',)), or be None to train everything")
        # the rest of the optimiser's numbers: finite (inf gave NaN weights at step 2)
        for name, ok, want in (("encoder_lr_scale", lambda x: 0 <= x < math.inf,
                                "a finite number >= 0"),
                               ("lr_gamma", lambda x: 0 < x <= 1, "in (0, 1]"),
                               ("weight_decay", lambda x: 0 <= x < math.inf,
                                "a finite number >= 0"),
                               ("box_scale", lambda x: 0 < x < math.inf, "a finite number > 0")):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not ok(v):
                raise ValueError(f"{name} must be {want}, got {v!r}")
        if isinstance(self.num_workers, bool) or not isinstance(self.num_workers, int) \
                or self.num_workers < 0:
            raise ValueError(f"num_workers must be an integer >= 0, got {self.num_workers!r}")

    @classmethod
    def preset(cls, name: str, **overrides) -> TrainConfig:
        """A named recipe ([`PRESETS`][handmesh_tutorial.train.config.PRESETS]) with overrides.

        ``TrainConfig.preset("cpu", data="runs/intersh", epochs=5)`` is
        ``TrainConfig(**PRESETS["cpu"], data="runs/intersh", epochs=5)``; nothing else is
        derived (``lr_step`` stays the preset's when ``epochs`` changes). One recipe, one place:
        the demo ([`train_config`][handmesh_tutorial.apps.demo.config.train_config]), its
        [`RECIPES`][handmesh_tutorial.apps.demo.config.RECIPES] and the pretrained network's
        [`PretrainedRecipe`][handmesh_tutorial.apps.pretrain_network.PretrainedRecipe] build on
        these. The fields each preset sets (``xyz``: ``model_kwargs={"output": "xyz",
        "smoothing_length": 0.0}``, the paper's decoder regressing the vertex coordinates;
        ``cpu_heads``: ``model_kwargs={"keypoints": True, "global_rotation": True, "output":
        "skinned"}``: a 2D keypoint head with pose pooling, a global-rotation head, the skinned
        output):

        | field | `paper` | `cpu` | `demo` | `pretraining` |
        |---|---|---|---|---|
        | `model_kwargs` | xyz | cpu_heads | cpu_heads | cpu_heads |
        | `keypoint_weight` | 0.0 | 0.5 | 0.5 | 0.5 |
        | `aligned_weight` | 0.0 | 1.0 | 1.0 | 1.0 |
        | `encoder` | "resnet18" | "resnet18" | "resnet10" | "resnet10" |
        | `image_size` | 224 | 224 | 128 | 128 |
        | `epochs` | 200 | 200 | 10 | 16 |
        | `batch_size` | 32 | 32 | 16 | 128 |
        | `lr` | 1e-4 | 1e-4 | 1e-3 | 1e-3 |
        | `lr_step` | 50 | 50 | 8 | 6 |
        | `lr_gamma` | 0.5 | 0.5 | 0.5 | 0.3 |
        | `augment` | True | True | False | True |
        | `precision` | "float32" | "float32" | "float32" | "bfloat16" |
        | `val_fraction` | 0.1 | 0.1 | 0.1 | 0.0 |
        | `val_batch_size` | None | None | None | 256 |
        | `device` | "auto" | "auto" | "cpu" | "auto" |
        | `threads` | None | None | 2 | None |
        | `cache_data` | False | False | True | False |
        | `init_encoder` | None | None | "pretrained" | None |
        | `freeze_encoder` | 0 | 0 | 10 | 0 |
        | `encoder_lr_scale` | 1.0 | 1.0 | 0.1 | 1.0 |

        `demo` is the demo at its ``default`` run-size tier (other tiers:
        [`DemoConfig.from_budget`][handmesh_tutorial.apps.demo.config.DemoConfig.from_budget]);
        `pretraining` makes the shipped network. Why the CPU recipe: docs page "Why the paper
        starts from pretrained weights".

        Args:
            name: ``"paper"``, ``"cpu"``, ``"demo"`` or ``"pretraining"``.
            **overrides: any field of [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig].

        Returns:
            The config.

        Raises:
            ValueError: an unknown ``name`` (the message lists the presets) or field.
        """
        if name not in PRESETS:
            raise ValueError(f"unknown TrainConfig preset {name!r}; the presets are "
                             f"{sorted(PRESETS)} (train.config.PRESETS)")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ValueError(f"unknown TrainConfig fields {unknown} given to preset {name!r}")
        return cls(**{**copy.deepcopy(PRESETS[name]), **overrides})

    @classmethod
    def from_budget(cls, budget=None, **overrides) -> TrainConfig:
        """A config sized by a run-size tier.

        ``epochs``, ``batch_size``, ``image_size`` and ``threads`` come from the budget; the
        learning rate decays four times per run (``lr_step = max(1, round(epochs / 4))``: 50 at
        the ``full`` tier's 200 epochs, as in the paper).

        Args:
            budget: a [`Budget`][handmesh_tutorial.budget.Budget] (default ``hmt.budget()``).
            **overrides: any field of [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig].

        Returns:
            The config.
        """
        if budget is None:
            budget = _budget()
        sized = {"epochs": budget.epochs, "batch_size": budget.batch_size,
                 "image_size": budget.image_size, "threads": budget.threads,
                 "lr_step": max(1, round(budget.epochs / 4))}
        if "epochs" in overrides and "lr_step" not in overrides:
            sized["lr_step"] = max(1, round(overrides["epochs"] / 4))
        sized.update(overrides)
        return cls(**sized)

    def __str__(self) -> str:
        """Every field as ``name=value`` on lines of at most 96 characters (``repr``: one line)."""
        fields_text = ", ".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self))
        return textwrap.fill(fields_text, 96, initial_indent="TrainConfig: ",
                             subsequent_indent="  ", break_long_words=False)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (tuples become lists)."""
        d = asdict(self)
        d["channels"] = None if self.channels is None else list(self.channels)
        d["train_only"] = None if self.train_only is None else list(self.train_only)
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> TrainConfig:
        """Inverse of [`to_dict`][handmesh_tutorial.train.config.TrainConfig.to_dict]; unknown keys
        raise
        ``ValueError``."""
        if not isinstance(d, Mapping):
            raise ValueError(f"a TrainConfig is a mapping of its fields, got "
                             f"{type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(map(str, set(d) - known))
        if unknown:
            raise ValueError(f"unknown TrainConfig keys {unknown[:8]}"
                             + (f" and {len(unknown) - 8} more" if len(unknown) > 8 else ""))
        return cls(**dict(d))

    def architecture(self) -> dict:
        """The entries that define the network (compared when resuming or loading)."""
        d = self.to_dict()
        return {k: d[k] for k in _ARCH_KEYS}


def _saved_folder(run_dir: str | os.PathLike, saved_out_dir: str) -> str | None:
    """The folder a run's relative paths were written from: ``run_dir`` (where its checkpoint
    is now) less the trailing parts of the ``out_dir`` it recorded; ``None`` when they do not
    match or ``saved_out_dir`` is absolute. Lets a run made from the repository root resume from
    ``notebooks/`` and back."""
    parts, where = Path(saved_out_dir).parts, Path(os.path.realpath(run_dir))
    clean = [p for p in parts if p not in ("", ".")]
    if Path(saved_out_dir).is_absolute() or not clean or ".." in clean \
            or len(where.parts) <= len(clean) or list(where.parts[-len(clean):]) != clean:
        return None
    return str(Path(*where.parts[:-len(clean)]))


def changed_settings(saved: Mapping, config: TrainConfig,
                     run_dir: str | os.PathLike | None = None) -> dict:
    """Fields of ``config`` that differ from a checkpoint's ``saved`` config and may not.

    Fields in [`RESUMABLE_KEYS`][handmesh_tutorial.train.config.RESUMABLE_KEYS] may change; paths
    (``data``, ``val_data``, ``template``, ``init``, ``init_encoder``) count as equal when they
    name the same file or folder, read from the current folder or, for the saved ones, from the
    folder the run was started in (found from ``run_dir``, where its checkpoint is now, and the
    ``out_dir`` it recorded).

    Returns:
        ``{field: (saved value, new value)}``, empty when the run can resume.
    """
    now = config.to_dict()
    saved_from = None if run_dir is None else _saved_folder(run_dir, saved.get("out_dir") or "")
    diff = {}
    for k, v in now.items():
        if k in RESUMABLE_KEYS or k in _ARCH_KEYS:
            continue
        old = saved.get(k, TrainConfig.__dataclass_fields__[k].default)
        if k in _PATH_KEYS and old is not None and v is not None and (
                os.path.realpath(old) == os.path.realpath(v) or (
                    saved_from is not None and
                    os.path.realpath(os.path.join(saved_from, old)) == os.path.realpath(v))):
            continue
        if old != v:
            diff[k] = (old, v)
    return diff
