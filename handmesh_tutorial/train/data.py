"""The data of a training run: the per-epoch batch order and the train / validation datasets.

Determinism: the sample order of epoch ``e`` is ``numpy.random.default_rng([seed, e]).permutation``;
the validation split is drawn from its own seeded stream; augmentation draws come from
``(seed, epoch, index)`` (see [`handmesh_tutorial.data.augment`][handmesh_tutorial.data.augment]).

Taught in notebook 08 ("Training").
"""

from __future__ import annotations

import hashlib
import math
import warnings
from pathlib import Path

import numpy as np
import torch

from ..data import InterSHDataset, read_meta
from ..data import torch_views as TV
from ..data.freihand import FreiHAND
from ..data.reader import _present
from ..data.schema import MIN_INDEX_WIDTH, SAMPLES_DIR
from .config import TrainConfig

__all__ = ["make_datasets"]


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
        ValueError: ``batch_size`` is not divisible by ``world_size * micro_batches``, is
            more than ``2 * n`` (checked before any batch is built), or ``n`` is 0.
    """

    def __init__(self, n: int, batch_size: int, seed: int = 0, rank: int = 0,
                 world_size: int = 1, micro_batches: int = 1, shuffle: bool = True):
        chunks = world_size * micro_batches
        if n < 1:
            raise ValueError("the training set is empty")
        if batch_size > 2 * n:  # padded item by item: every batch would repeat every item
            raise ValueError(f"batch_size {batch_size} is more than twice the {n} training "
                             f"items (every batch would repeat each of them); use --batch-size "
                             f"{2 * n} or less")
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


def _non_empty(src: InterSHDataset) -> InterSHDataset:
    """``src``, refused when it holds no sample (`InterSHDataset.coverage` says why); a
    warning says when planned samples are missing (a generation not finished)."""
    if len(src) == 0:
        raise ValueError(f"no sample to train on: {src.coverage()}")
    if coverage := src.coverage():
        warnings.warn(f"training on {len(src)} samples: {coverage}", UserWarning, stacklevel=3)
    return src


def make_datasets(config: TrainConfig):
    """Training and validation torch datasets of a config.

    Returns:
        ``(train_dataset, val_dataset or None)``:
        [`InterSHTorchDataset`][handmesh_tutorial.data.torch_views.InterSHTorchDataset] or
        [`FreiHANDTorchDataset`][handmesh_tutorial.data.torch_views.FreiHANDTorchDataset];
        validation without
        augmentation.

    Raises:
        ValueError: ``config.data`` is not set, or an INTER-SH root has no sample (named, with
            how many it plans and why none may be there). A root missing some of its planned
            samples is read with a ``UserWarning`` saying how many and why.
    """
    if config.data is None:
        raise ValueError("TrainConfig.data is None: give a data root or pass dataset= to train()")
    common = {"image_size": config.image_size, "seed": config.seed, "cache": config.cache_data}
    if config.dataset == "intersh":
        src = _non_empty(InterSHDataset(config.data))

        def make(source, idx, train):
            return TV.InterSHTorchDataset(source, train=train, augment=config.augment and train,
                                         indices=idx, box_scale=config.box_scale, **common)

        if config.val_data is not None:
            return make(src, None, True), make(_non_empty(InterSHDataset(config.val_data)), None,
                                               False)
        tr, va = _split(len(src), config.val_fraction, config.seed)
        return make(src, tr, True), (make(src, va, False) if va else None)

    src = FreiHAND(config.data, "training")

    def make_fh(source, idx, train):
        return TV.FreiHANDTorchDataset(source, train=train, augment=config.augment and train,
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


def _root_fingerprint(root: str, dataset: str) -> dict:
    """A cheap identity of a data root: its ``meta.json`` (less ``generator_version``) and a
    hash of its sample ids (INTER-SH), or the names and sizes of its ``*.json`` annotation files
    (FreiHAND). No image is read."""
    path = Path(root)
    if dataset == "intersh":
        meta = {k: v for k, v in read_meta(path).items() if k != "generator_version"}
        ids = _present(path / SAMPLES_DIR, meta.get("index_width", MIN_INDEX_WIDTH))
        digest = hashlib.sha256(",".join(map(str, ids)).encode()).hexdigest()[:16]
        return {"format": dataset, "meta": meta, "samples": len(ids), "ids_sha256": digest}
    files = {p.name: p.stat().st_size for p in sorted(path.glob("*.json"))}
    return {"format": dataset, "files": files}


def _data_fingerprint(config: TrainConfig) -> dict | None:
    """``{"data": ..., "val_data": ...}`` fingerprints of a config's roots (`_root_fingerprint`),
    stored in checkpoints and compared on resume; ``None`` without ``config.data``."""
    if config.data is None:
        return None
    return {"data": _root_fingerprint(config.data, config.dataset),
            "val_data": None if config.val_data is None
            else _root_fingerprint(config.val_data, config.dataset)}


def _fingerprint_changes(saved: dict, now: dict) -> list[str]:
    """What differs between two `_data_fingerprint` results, one phrase per difference."""
    out = []
    for role in ("data", "val_data"):
        a, b = saved.get(role), now.get(role)
        if a == b:
            continue
        if a is None or b is None or a.get("format") != b.get("format"):
            out.append(f"{role}: {'none' if a is None else a.get('format')} -> "
                       f"{'none' if b is None else b.get('format')}")
            continue
        ma, mb = a.get("meta") or {}, b.get("meta") or {}
        keys = sorted(k for k in set(ma) | set(mb) if ma.get(k) != mb.get(k))
        shown = [f"{k} {ma.get(k)!r} -> {mb.get(k)!r}" for k in keys
                 if len(repr(ma.get(k))) + len(repr(mb.get(k))) < 60]
        if keys:
            out.append(f"{role} meta.json: {', '.join(shown)}"
                       + (f" (differing keys {keys})" if len(shown) < len(keys) else ""))
        if a.get("ids_sha256") != b.get("ids_sha256"):
            same = a.get("samples") == b.get("samples")
            out.append(f"{role} sample ids: {a.get('samples')} -> {b.get('samples')} samples"
                       + (" (as many, other ids)" if same else ""))
        fa, fb = a.get("files") or {}, b.get("files") or {}
        if fa != fb:
            names = sorted(k for k in set(fa) | set(fb) if fa.get(k) != fb.get(k))
            out.append(f"{role} annotation files differ (names or sizes): {names}")
    return out


def _checked_fingerprint(config, dataset, ck: dict | None, last) -> dict | None:
    """The data's fingerprint (``None`` for a dataset object); on resume (``ck`` the checkpoint
    read from ``last``), data that changed since the run started is refused: the data itself is
    compared, not only its path, so a folder replaced by another set is caught."""
    fingerprint = _data_fingerprint(config) if dataset is None else None
    if ck is not None and fingerprint is not None:
        if "data_fingerprint" not in ck:
            warnings.warn(f"{last} predates data fingerprints: cannot check that {config.data} "
                          "holds the data this run started with", stacklevel=4)
        elif ck["data_fingerprint"] is not None and \
                (diff := _fingerprint_changes(ck["data_fingerprint"], fingerprint)):
            raise ValueError(
                f"{last}: the data changed since this run started ({'; '.join(diff)}): "
                "resuming would mix two data sets in one run. Restore the run's data, or "
                "start a new run in another out_dir")
    return fingerprint
