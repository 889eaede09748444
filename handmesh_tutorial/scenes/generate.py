"""The one driver of the scene generator: `generate_interactions` (``handmesh generate``, the
demo's and the pretraining's scenes), a thin wrapper of
[`data.generate_dataset`][handmesh_tutorial.data.generate_dataset].

Taught in notebook 05 ("Rendering and visibility").
"""

from __future__ import annotations

import functools
from dataclasses import asdict

import numpy as np

from ..budget import MAX_IMAGE_SIZE, MIN_IMAGE_SIZE  # one source of the image-size range
from ..data import KINDS, generate_dataset, read_meta
from ..lcs import THUMB_ZERO_ELEVATION_DEG
from .config import InteractionConfig
from .framing import _check_share
from .sample import init_worker, make_sample

__all__ = ["MAX_IMAGE_SIZE", "MIN_IMAGE_SIZE", "generate_interactions"]

_LABELS = ("handmesh_tutorial.scenes", "handmesh_tutorial.scenes.make_sample")
"""``meta.json`` ``params.generator`` of the roots this driver writes (the first), and of the
roots of the demo's former generator (the same scenes): a root labelled either way resumes."""


def _label(root) -> str:
    """The ``params.generator`` label that ``root`` already has, else this driver's."""
    try:
        on_disk = read_meta(root).get("params", {}).get("generator")
    except (OSError, ValueError, AttributeError):  # no root yet (or a broken one: named later)
        return _LABELS[0]
    return on_disk if on_disk in _LABELS else _LABELS[0]


def generate_interactions(root, kind: str, num: int, seed: int, *, image_size: int = 224,
                          workers: int = 1, balance_vr: bool = False,
                          shard: tuple[int, int] | None = None, limits: str = "anatomical",
                          durable: bool = True, progress: bool = True, max_attempts: int = 100,
                          vr_probe: int = 64, mp_context: str = "auto",
                          frame_share: tuple[float, float] | None = None,
                          thumb_zero_elevation: float | None = THUMB_ZERO_ELEVATION_DEG,
                          parts: int = 1, max_seconds: float | None = None):
    """Generate (or resume) an INTER-SH dataset of rendered interactions on disk.

    A thin wrapper of
    [`handmesh_tutorial.data.generate_dataset`][handmesh_tutorial.data.generate_dataset] with
    ``make_sample = functools.partial(make_sample, kind=..., image_size=..., limits=...)`` and one
    renderer per worker process ([`init_worker`][handmesh_tutorial.scenes.sample.init_worker]).
    Rerunning the same call skips the samples already written (resume).

    Args:
        root: output folder.
        kind: ``"hand-hand"``, ``"hand-object"``, ``"hand-chain"`` or ``"mixed"``.
        num: samples of the whole dataset (all shards).
        seed: base seed.
        image_size: square image side, pixels.
        workers: processes.
        balance_vr: spread the target VRs evenly over the paper's VR bins: bins that a probe of
            candidates never reaches (e.g. [0.4, 0.6) for hand-chain scenes) are reported up front
            and left out (see
            [`handmesh_tutorial.data.generate_dataset`][handmesh_tutorial.data.generate_dataset]).
        shard: ``(k, n)``: only the k-th of n equal index ranges.
        limits: ``"anatomical"`` joint limits (default: natural poses) or ``"paper"`` (±60°
            about every LCS axis, as in the paper).
        durable: fsync every file (slower, safe against power cuts).
        progress: tqdm progress bar.
        max_attempts: candidates per sample (VR balancing rejects some).
        vr_probe: candidates of the VR probe that finds the reachable bins (``balance_vr``).
        frame_share: (min, max) share of the image side covered by the target hand's bounding
            box; ``None`` = [`FRAME_SHARE`][handmesh_tutorial.scenes.framing.FRAME_SHARE]
            (0.45-0.75, FreiHAND-like crops). Smaller shares show more of the arm and the
            surroundings (docs page "Realistic scenes" measures what that does to a real-photo
            hand detector). Stored in ``meta.json`` (``params.frame_share``) when given.
        thumb_zero_elevation: degrees out of the palm plane that the thumb's zero angles mean
            ([`InteractionConfig.thumb_zero_elevation`][handmesh_tutorial.scenes.config.InteractionConfig]:
            5° by default; ``None`` = the template's rest thumb, the generator before that option,
            byte for byte). Stored in ``meta.json`` (``params.config``).
        mp_context: start method of the worker processes: ``"auto"`` (fork where it is safe,
            else spawn; same bytes either way), ``"spawn"`` or ``"fork"`` (see
            [`generate_dataset`][handmesh_tutorial.data.generate_dataset]).
        parts: make the set as this many shards, merged into ``root`` when done (the same files
            as one run); a rerun keeps the merged root as it is.
        max_seconds: time budget of a run in ``parts``: no new shard starts when the next would
            end past it (``None``: all). A set cut short is a valid root of what it has.

    Returns:
        The
        [`handmesh_tutorial.data.GenerationSummary`][handmesh_tutorial.data.GenerationSummary].
    """
    # every argument is checked before anything is written (a bad one never leaves a
    # meta.json behind that blocks the corrected rerun); generate_dataset checks the rest
    if kind not in KINDS + ("mixed",):
        raise ValueError(f"kind must be one of {KINDS + ('mixed',)}, got {kind!r}")
    if isinstance(image_size, bool) or not isinstance(image_size, int | np.integer) \
            or not MIN_IMAGE_SIZE <= image_size <= MAX_IMAGE_SIZE:
        raise ValueError(f"image_size must be an integer in [{MIN_IMAGE_SIZE}, "
                         f"{MAX_IMAGE_SIZE}] pixels, got {image_size!r}")
    config = InteractionConfig(limits=limits, thumb_zero_elevation=thumb_zero_elevation)  # checks
    extra = {}
    if frame_share is not None:
        extra["share"] = _check_share(frame_share, name="frame_share")
    fn = functools.partial(make_sample, kind=kind, image_size=int(image_size), config=config,
                           **extra)
    kinds = list(KINDS) if kind == "mixed" else kind
    params = {"generator": _label(root), "kind": kind, "limits": limits,
              "config": {k: (list(v) if isinstance(v, tuple) else v)
                         for k, v in asdict(config).items()}}
    if extra:  # only when given: roots made before this option keep their meta.json
        params["frame_share"] = list(extra["share"])
    return generate_dataset(root, fn, int(num), int(seed), kinds, shard=shard, workers=workers,
                            progress=progress, params=params, image_size=int(image_size),
                            balance_vr=balance_vr, max_attempts=max_attempts,
                            vr_probe=vr_probe,
                            worker_init=functools.partial(init_worker, int(image_size)),
                            durable=durable, mp_context=mp_context, parts=parts,
                            max_seconds=max_seconds)
