"""The network's architecture as one value: [`ModelConfig`][handmesh_tutorial.nn.config.ModelConfig]
with named presets, and the default widths.

[`build_model`][handmesh_tutorial.nn.model.build_model] takes a config (``config=`` or as its first
argument) or the same fields as keywords; ``ModelConfig.preset("paper")`` names a whole
architecture, ``config.replace(...)`` changes a part of it. The names are re-exported by
[`handmesh_tutorial.nn.model`][handmesh_tutorial.nn.model]. Taught in notebook 07 ("The
multi-path decoder"); docs page "The network".
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

from torch import nn

from .decoder import HEADS
from .outputs import OUTPUTS

__all__ = ["ModelConfig", "DEFAULT_LATENT_CHANNELS", "DEFAULT_SINGLE_CHANNELS",
           "DEFAULT_MULTI_CHANNELS", "DEFAULT_SMOOTHING_LENGTH"]

DEFAULT_SINGLE_CHANNELS = (32, 32, 64, 64, 128)
"""Per-level decoder channels of the single-path baseline, finest level first."""
DEFAULT_MULTI_CHANNELS = (16, 24, 32, 48, 64)
"""Per-level branch channels of the multi-path decoder, finest first: narrower than the single
path's because level ``l`` (0 = finest) runs in ``L - l`` stages."""
DEFAULT_SMOOTHING_LENGTH = 0.009
"""Default ``smoothing_length`` of [`build_model`][handmesh_tutorial.nn.model.build_model], metres
(steps: [`smoothing_steps`][handmesh_tutorial.nn.smoothing.smoothing_steps])."""
DEFAULT_LATENT_CHANNELS = 16
"""Channels per coarse-mesh token (output of the FC, width of the transformer)."""


@dataclass(frozen=True)
class ModelConfig:
    """The architecture [`build_model`][handmesh_tutorial.nn.model.build_model] builds, one field
    per keyword (see there for each one's meaning); named presets in ``PRESETS``.

    Fields hold plain values (names, numbers, tuples), which
    [`to_dict`][handmesh_tutorial.nn.config.ModelConfig.to_dict] gives back as ``build_model``
    keywords; ``encoder``, ``output`` and ``global_rotation`` may also hold a module and
    ``keypoints`` a factory (such a config has no plain form).

    Raises:
        ValueError: a field out of its range (names the field, the value and what is allowed).
    """

    encoder: str | nn.Module = "resnet18"
    decoder: str = "multi"
    attention: bool = True
    channels: tuple[int, ...] | None = None
    latent_channels: int = DEFAULT_LATENT_CHANNELS
    spiral_length: int = 9
    dilation: int = 1
    num_blocks: int = 1
    factors: tuple[float, ...] = (2, 2, 2, 2)
    num_heads: int = 2
    transformer_layers: int = 1
    fuse_head: bool = False
    output_scale: float = 0.1
    output: str | nn.Module = "affine"
    smoothing_length: float = DEFAULT_SMOOTHING_LENGTH
    zero_head: bool = True
    head: str = "linear"
    keypoints: bool | Callable[..., nn.Module] = False
    global_rotation: bool | nn.Module = False

    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {
        "default": {},
        "paper": {"output": "xyz", "smoothing_length": 0.0},
        "cpu": {"encoder": "resnet10", "keypoints": True, "global_rotation": True,
                "output": "skinned"},
        "single-path": {"decoder": "single", "attention": False},
        "multi-path": {"decoder": "multi", "attention": False},
    }
    """``default``: ``build_model``'s defaults (the paper's Table 3 multi-path + attention row,
    with the library's affine output); ``paper``: the decoder regresses coordinates, no output
    smoothing; ``cpu``: the demo's recipe for training from scratch on a CPU (ResNet-10, 2D
    keypoint head, rotation head, skinned output); ``single-path`` and ``multi-path``: the other
    two rows of Table 3."""

    def __post_init__(self):
        fix = dict(channels=None if self.channels is None else tuple(int(c) for c in self.channels),
                   factors=tuple(self.factors))
        for name, value in fix.items():
            object.__setattr__(self, name, value)
        if self.decoder not in ("multi", "single"):
            raise ValueError(f"decoder must be 'multi' or 'single', got {self.decoder!r}")
        if not isinstance(self.output, nn.Module) and self.output not in OUTPUTS:
            raise ValueError(f"output must be one of {OUTPUTS} or a module, got {self.output!r}")
        if self.head not in HEADS:
            raise ValueError(f"head must be one of {HEADS}, got {self.head!r}")
        for name in ("latent_channels", "spiral_length", "dilation", "num_blocks", "num_heads",
                     "transformer_layers"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"ModelConfig.{name} must be a positive integer, got {v!r}")
        if self.channels is not None and (not self.channels or min(self.channels) < 1):
            raise ValueError(f"channels must be positive integers, got {self.channels}")
        if not self.smoothing_length >= 0 or not self.output_scale > 0:
            raise ValueError(f"smoothing_length must be >= 0 and output_scale > 0, got "
                             f"{self.smoothing_length} and {self.output_scale}")

    @classmethod
    def preset(cls, name: str, **changes) -> ModelConfig:
        """The preset ``name`` (a key of ``PRESETS``) with ``changes`` (fields) on top.

        Raises:
            ValueError: unknown preset name.
        """
        if name not in cls.PRESETS:
            raise ValueError(f"unknown model preset {name!r}; presets: {sorted(cls.PRESETS)}")
        return cls(**{**cls.PRESETS[name], **changes})

    def replace(self, **changes) -> ModelConfig:
        """A copy with ``changes`` (fields), validated."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The fields as ``build_model`` keywords (plain values, JSON-serialisable).

        Raises:
            ValueError: a field holds a module or a factory.
        """
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        odd = [k for k, v in d.items() if not isinstance(v, str | int | float | tuple | None)]
        if odd:
            raise ValueError(f"ModelConfig fields {odd} hold modules or factories: no plain form")
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}
