"""The demo's sizes and choices: [`DemoConfig`][handmesh_tutorial.apps.demo.config.DemoConfig] (per
run-size tier), the training recipes, and the training config of the demo and of notebooks 08-10
([`train_config`][handmesh_tutorial.apps.demo.config.train_config]).

Why these values: the docstring of [`handmesh_tutorial.apps.demo`][handmesh_tutorial.apps.demo] and
the docs page "Why the paper starts from pretrained weights". Taught in notebook 00 ("Quickstart")
and
notebook 08 ("Training").
"""

from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from dataclasses import dataclass

from ...budget import budget as _budget

__all__ = ["DemoConfig", "train_config", "RECIPES"]

class _Recipes(Mapping):
    """The training recipes by name: the ``paper`` and ``cpu`` presets of ``TrainConfig``.

    The names are known here; the fields are read from the presets on first use, since
    importing ``train`` imports torch, which the scene generator's forked workers must not
    inherit (the demo and ``handmesh pretrain`` check a recipe name before they generate).
    """

    _names = ("paper", "cpu")

    def __getitem__(self, name: str) -> dict:
        if name not in self._names:
            raise KeyError(name)
        from ...train.config import PRESETS  # lazy: torch

        return copy.deepcopy(PRESETS[name])

    def __contains__(self, name) -> bool:
        return name in self._names

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def __repr__(self) -> str:
        return repr(dict(self))


RECIPES: Mapping[str, dict] = _Recipes()
"""Training recipes by name, [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig] fields on
top of [`train_config`][handmesh_tutorial.apps.demo.config.train_config]: the ``paper`` and
``cpu`` presets of [`TrainConfig.preset`][handmesh_tutorial.train.config.TrainConfig.preset]
(the paper's L1 vertex loss with a globally pooled encoder; the CPU recipe adds a 2D keypoint
head with pose pooling, a global-rotation head, the skinned output and the keypoint and
aligned-joint losses). Why: docs page "Why the paper starts from pretrained weights".
"""


def _recipe_fields(name: str) -> dict:
    """The fields of recipe ``name`` with those of the other recipe set back to the defaults
    (the ``demo`` and ``pretraining`` presets start from ``cpu``)."""
    from ...train import TrainConfig  # lazy: torch

    if name not in RECIPES:
        raise ValueError(f"recipe must be one of {sorted(RECIPES)}, got {name!r}")
    default = TrainConfig()
    reset = {k: getattr(default, k) for r in RECIPES for k in RECIPES[r]}
    return {**reset, **RECIPES[name]}


@dataclass
class DemoConfig:
    """Sizes and choices of one demo run (see the module docstring for why these values).

    Attributes:
        train_samples: training scenes generated (all kinds together).
        test_samples: held-out test scenes (always VR-balanced).
        render_size: side of the rendered scene images, pixels.
        image_size: side of the network's input crop, pixels.
        epochs: training epochs.
        batch_size: training batch size.
        lr: Adam learning rate.
        lr_step: epochs between halvings of the learning rate; ``None``: the recipe's schedule,
            halved once after three quarters of the run (CPU recipe) or after each quarter
            (paper recipe: the paper's shape, 50 of its 200 epochs; why: docs page "Why the paper
            starts from pretrained weights").
        encoder: image encoder name.
        decoder: ``"multi"`` or ``"single"``.
        attention: coarse-mesh transformer on.
        augment: random crop / scale / rotation / colour jitter of training crops.
        recipe: ``"cpu"`` (default; [`RECIPES`][handmesh_tutorial.apps.demo.config.RECIPES]: 2D
            keypoint head with pose pooling, a global-rotation head, the skinned decoder output,
            keypoint and aligned-joint losses beside the paper's L1) or ``"paper"`` (L1 vertex loss
            only, global-pooling encoder).
        pooling: where the paper recipe's network reads the frozen pretrained encoder:
            ``"joints"`` (default: its features pooled at its own predicted 2D joints, as the
            encoder was pretrained; no keypoint loss, the encoder is not trained) or ``"global"``
            (the ResNet part only, globally pooled, as the paper's ImageNet encoder). The CPU
            recipe always pools at the joints. Docs page "Why the paper starts from pretrained
            weights".
        balance_train: VR-balance the training scenes too (several times slower to generate:
            docs page "INTER-SH on disk", "VR-balanced sets").
        init_encoder: where the encoder starts: ``"pretrained"`` (the shipped hand encoder,
            [`pretrained_encoder`][handmesh_tutorial.nn.pose_encoder.pretrained_encoder]; the
            paper's protocol with our stand-in for ImageNet weights), a pose-encoder file, or
            ``None`` (random weights). The rest of the network always starts from random weights.
        freeze_encoder: epochs at the start with the encoder's weights and statistics fixed
            (default: the demo's whole run).
        encoder_lr_scale: the encoder's learning rate as a share of ``lr`` after that.
        threads: torch threads.
        workers: data-generation processes.
        overlays: held-out samples drawn in ``overlays.png``.
        budget: name of the tier the sizes came from.
    """

    train_samples: int = 3000
    test_samples: int = 100
    render_size: int = 128
    image_size: int = 128
    epochs: int = 10
    batch_size: int = 16
    lr: float = 1e-3
    lr_step: int | None = None
    encoder: str = "resnet10"
    decoder: str = "multi"
    attention: bool = True
    augment: bool = False
    recipe: str = "cpu"
    pooling: str = "joints"
    balance_train: bool = False
    init_encoder: str | None = "pretrained"
    freeze_encoder: int = 10
    encoder_lr_scale: float = 0.1
    threads: int = 2
    workers: int = 2
    overlays: int = 8
    budget: str = "default"

    @classmethod
    def from_budget(cls, budget=None, **overrides) -> DemoConfig:
        """The demo's sizes for a run-size tier.

        Args:
            budget: a [`Budget`][handmesh_tutorial.budget.Budget] (default ``hmt.budget()``).
            **overrides: any field.

        Returns:
            The config.
        """
        if budget is None:
            budget = _budget()
        full = budget.name == "full"  # the paper's scale: its data size, epochs, augmentation
        sized = dict(train_samples=budget.samples if full else max(8, 5 * budget.samples),
                     test_samples=max(4, budget.eval_samples // 2),
                     render_size=budget.image_size,
                     image_size=budget.image_size,
                     epochs=budget.epochs if full else max(1, budget.epochs // 2),
                     batch_size=max(2, budget.batch_size), augment=full,
                     threads=budget.threads, workers=min(2, budget.threads),
                     overlays=8 if budget.name != "smoke" else 4, budget=budget.name)
        sized.update(overrides)
        return cls(**sized)


def train_config(config: DemoConfig, data: str | os.PathLike, out_dir: str | os.PathLike,
                 seed: int = 0, progress: bool = True, **overrides):
    """The demo's [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig] (notebooks 08-10 train
    with it): the ``demo`` preset
    ([`TrainConfig.preset`][handmesh_tutorial.train.config.TrainConfig.preset]) at the sizes and
    choices of ``config``.

    10% of ``data`` is held out for per-epoch validation; the learning rate is halved every
    ``config.lr_step`` epochs (by default once, after three quarters of the epochs, for the CPU
    recipe; after each quarter for the paper's); crops are cached in memory; CPU; the loss
    terms and keypoint head of ``config.recipe``
    ([`RECIPES`][handmesh_tutorial.apps.demo.config.RECIPES]).

    Args:
        config: the demo's sizes and choices.
        data: INTER-SH training root.
        out_dir: the run's folder.
        seed: initialisation, data order, split and augmentation seed.
        progress: tqdm bars.
        **overrides: any [`TrainConfig`][handmesh_tutorial.train.config.TrainConfig] field (e.g.
            ``decoder``, ``attention`` for the ablation).

    Returns:
        The config.
    """
    from ...train import TrainConfig  # lazy: torch

    if config.pooling not in ("joints", "global"):
        raise ValueError(f"pooling must be 'joints' or 'global', got {config.pooling!r}")
    if config.pooling == "global" and config.recipe != "paper":
        raise ValueError("pooling='global' is a choice of the paper recipe; the CPU recipe "
                         "pools at the joints")
    recipe = _recipe_fields(config.recipe)
    if config.recipe == "paper" and config.pooling == "joints" and config.init_encoder:
        # the pretrained encoder as it was trained: its features pooled at its own joints
        recipe["model_kwargs"] = {**recipe["model_kwargs"], "keypoints": True}
    kw = dict(data=str(data), out_dir=str(out_dir), image_size=config.image_size,
              epochs=config.epochs, batch_size=config.batch_size, lr=config.lr,
              lr_step=config.lr_step, augment=config.augment,
              encoder=config.encoder, decoder=config.decoder, attention=config.attention,
              seed=seed, threads=config.threads, progress=progress,
              init_encoder=config.init_encoder, freeze_encoder=config.freeze_encoder,
              encoder_lr_scale=config.encoder_lr_scale if config.init_encoder else 1.0,
              **recipe)
    kw.update(overrides)
    if kw["lr_step"] is None:  # the recipe's schedule over config.epochs
        quarters = config.recipe == "paper"
        kw["lr_step"] = max(1, -(-config.epochs // 4) if quarters
                            else round(0.75 * config.epochs))
    if kw["lr_step"] < 1:
        raise ValueError(f"lr_step must be >= 1 epoch, got {kw['lr_step']}")
    if not kw["init_encoder"]:
        kw["freeze_encoder"] = 0
    return TrainConfig.preset("demo", **kw)
