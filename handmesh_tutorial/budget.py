"""Run-size tiers: one environment variable, read in one place.

``HANDMESH_BUDGET`` selects how big every run is:

* ``smoke``: seconds per notebook; what tests and CI use.
* ``default``: minutes on a 2-core laptop; what the committed notebooks were executed with.
* ``full``: approaches the paper's scale (hours to days; a GPU helps).

Nothing else in the library reads the variable: code asks
[`budget`][handmesh_tutorial.budget.budget] for sizes.

Used by every notebook (``hmt.budget()``); notebook 00 ("Quick start") introduces it.

"""

from __future__ import annotations

import os
import textwrap
from dataclasses import asdict, dataclass

__all__ = ["ENV_VAR", "TIERS", "Budget", "budget", "MIN_IMAGE_SIZE", "MAX_IMAGE_SIZE",
           "MAX_BATCH_SIZE", "MAX_CHANNELS", "MAX_INPUT_PIXELS", "max_threads", "max_workers"]

ENV_VAR = "HANDMESH_BUDGET"
TIERS = ("smoke", "default", "full")

MIN_IMAGE_SIZE = 32
"""Smallest image side an argument may set, pixels (below it a hand is a few pixels and a
ResNet's 32x downsampling leaves nothing)."""
MAX_IMAGE_SIZE = 4096
"""Largest image side an argument may set, pixels: generated scenes (``generate --image-size``),
network crops (``train`` / ``evaluate --image-size``) and pose-pretraining crops and renders
(above it one image or batch needs gigabytes)."""


def check_image_size(value, name: str = "image_size") -> int:
    """Check an image side against [`MIN_IMAGE_SIZE`][handmesh_tutorial.budget.MIN_IMAGE_SIZE] and
    [`MAX_IMAGE_SIZE`][handmesh_tutorial.budget.MAX_IMAGE_SIZE] before anything is allocated.

    Args:
        value: the side, pixels.
        name: the argument's name, for the message.

    Returns:
        ``value`` as an ``int``.

    Raises:
        ValueError: not an integer in the range (the message names ``name`` and the range).
    """
    if isinstance(value, bool) or not hasattr(value, "__index__") \
            or not MIN_IMAGE_SIZE <= int(value) <= MAX_IMAGE_SIZE:
        raise ValueError(f"{name} must be an integer in [{MIN_IMAGE_SIZE}, {MAX_IMAGE_SIZE}] "
                         f"pixels, got {value!r}")
    return int(value)


MAX_INPUT_PIXELS = 8192 * 8192
"""Most pixels an input image of `inference` may have (a file is checked from its header,
before it is decoded; an array from its shape): 67 megapixels, more than a 48 MP camera's
photo. Above it one decoded image needs gigabytes; resize it first."""

MAX_BATCH_SIZE = 65_536
"""Largest batch an argument may set (the paper's is 32; a batch of 224-px crops this big
already holds 10 GB of images). A training batch is also at most twice the training items
(`train.EpochBatchSampler`)."""
MAX_CHANNELS = 4096
"""Largest width of a network layer a config may set (``channels``, ``latent_channels``: the
paper's are at most 256); checked before any layer is allocated, as a checkpoint's config too."""


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def max_threads() -> int:
    """Most CPU threads an argument may set (``--threads``): 4 x this machine's cores, at
    least 8 (more only slice the same cores thinner, and each costs a stack)."""
    return max(8, 4 * _cores())


def max_workers() -> int:
    """Most worker processes an argument may set (``--loader-workers``, ``--workers``): 4 x
    this machine's cores, at least 8 (each is a copy of the process: hundreds of MB)."""
    return max(8, 4 * _cores())


def check_count(value, name: str, low: int, high: int, why: str = "") -> int:
    """Check an integer option against ``[low, high]`` before any work or allocation.

    Args:
        value: the value.
        name: the option's name, for the message.
        low: the smallest value allowed.
        high: the largest value allowed.
        why: what the upper bound is (``"4 x the 2 CPU cores"``), for the message.

    Returns:
        ``value`` as an ``int``.

    Raises:
        ValueError: not an integer in the range; the message names ``name`` and the range.
    """
    if isinstance(value, bool) or not hasattr(value, "__index__") or not low <= int(value) <= high:
        raise ValueError(f"{name} must be an integer in [{low}, {high:,}]"
                         + (f" ({why})" if why else "") + f", got {value!r}")
    return int(value)


def check_pixels(height: int, width: int, where: str) -> None:
    """Refuse an input image of more than `MAX_INPUT_PIXELS`, before it is decoded or copied.

    Raises:
        ValueError: naming ``where`` (the file, or ``"image"``), its size and the bound.
    """
    if int(height) * int(width) > MAX_INPUT_PIXELS:
        raise ValueError(f"{where}: {width} x {height} pixels, more than the "
                         f"{MAX_INPUT_PIXELS:,} (MAX_INPUT_PIXELS, 8192 x 8192) an input image "
                         "may have; resize it first (the network sees a crop of the hand)")


def check_threads(value, name: str = "threads") -> int:
    """`check_count` of a thread count, 1 to
    [`max_threads`][handmesh_tutorial.budget.max_threads]."""
    return check_count(value, name, 1, max_threads(),
                       f"at most 4 x the {_cores()} CPU cores of this machine, at least 8")


def check_workers(value, name: str = "num_workers", low: int = 0) -> int:
    """`check_count` of a process count, ``low`` to
    [`max_workers`][handmesh_tutorial.budget.max_workers]."""
    return check_count(value, name, low, max_workers(),
                       f"at most 4 x the {_cores()} CPU cores of this machine, at least 8")


@dataclass(frozen=True)
class Budget:
    """Sizes of a run. All counts are plain integers; ``image_size`` is in pixels (square).

    Attributes:
        name: the tier, one of ``smoke``, ``default``, ``full``.
        samples: scenes generated for a dataset (all kinds together).
        epochs: training epochs.
        image_size: side of the square network input image, pixels.
        batch_size: training batch size.
        threads: CPU threads for torch (``torch.set_num_threads``).
        steps: optimisation steps of small in-notebook demos (e.g. overfitting a decoder).
        eval_samples: samples in evaluation or metric demos.
        test_pairs: random primitive pairs in geometry checks and in-notebook benchmarks.
    """

    name: str
    samples: int
    epochs: int
    image_size: int
    batch_size: int
    threads: int
    steps: int
    eval_samples: int
    test_pairs: int

    def as_dict(self) -> dict:
        """The sizes as a plain dict (for logs and reports)."""
        return asdict(self)

    def __str__(self) -> str:
        """The sizes on lines of at most 96 characters (``repr`` keeps the one-line form)."""
        fields = ", ".join(f"{k}={v}" for k, v in asdict(self).items() if k != "name")
        return textwrap.fill(fields, 96, initial_indent=f"Budget {self.name!r}: ",
                             subsequent_indent="  ", break_long_words=False)


_TIERS = {
    "smoke": Budget("smoke", samples=12, epochs=1, image_size=64, batch_size=4, threads=2,
                    steps=20, eval_samples=8, test_pairs=2_000),
    "default": Budget("default", samples=600, epochs=20, image_size=128, batch_size=16, threads=2,
                      steps=400, eval_samples=200, test_pairs=100_000),
    "full": Budget("full", samples=40_000, epochs=200, image_size=224, batch_size=32, threads=8,
                   steps=3_000, eval_samples=3_960, test_pairs=1_000_000),
}


def budget(name: str | None = None) -> Budget:
    """Return the run sizes of a tier.

    Args:
        name: a tier name; when ``None`` the tier comes from the ``HANDMESH_BUDGET`` environment
            variable, and ``default`` when it is unset or empty.

    Returns:
        The [`Budget`][handmesh_tutorial.budget.Budget] of that tier.

    Raises:
        ValueError: the tier name is not one of ``smoke``, ``default``, ``full``.
    """
    if name is None:
        name = os.environ.get(ENV_VAR, "").strip() or "default"
    key = name.lower()
    if key not in _TIERS:
        raise ValueError(f"unknown budget tier {name!r} (from {ENV_VAR} or the argument); "
                         f"expected one of {', '.join(TIERS)}")
    return _TIERS[key]
