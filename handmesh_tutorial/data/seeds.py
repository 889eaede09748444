"""Seeds and shards: which seed makes sample ``i``, which indices a shard holds, the VR bins.

Sample ``i`` of a dataset with base seed ``s`` comes from
[`sample_seed(s, i, attempt)`][handmesh_tutorial.data.seeds.sample_seed], whatever the shard,
worker or order, so a dataset made in pieces is the same bytes as one made at once. Taught in
notebook 05 ("Rendering and the visibility ratio").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..visibility import VR_BINS, vr_bin
from .schema import MIN_INDEX_WIDTH

__all__ = ["sample_seed", "vr_bins", "vr_histogram"]

_SEED_RULE = ("numpy.random.SeedSequence(entropy=seed, spawn_key=(index, attempt))"
              ".generate_state(1, uint64)[0] >> 11")


def sample_seed(seed: int, index: int, attempt: int = 0) -> int:
    """The seed passed to ``make_sample`` for sample ``index`` (``attempt``-th candidate).

    Derived with ``numpy.random.SeedSequence(seed, spawn_key=(index, attempt))``, so it depends
    only on the base seed, the global index and the attempt: not on shards, workers or order.

    Args:
        seed: base seed of the dataset, a non-negative integer.
        index: global sample index, >= 0.
        attempt: candidate number when candidates can be rejected (VR balancing), >= 0.

    Returns:
        A non-negative integer below 2**53 (exact in JSON and JavaScript).
    """
    for name, v in (("seed", seed), ("index", index), ("attempt", attempt)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"{name} must be a non-negative integer, got {v!r}")
    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(int(index), int(attempt)))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(11))


def probe_seed(seed: int, k: int) -> int:
    """The seed of the ``k``-th candidate of the VR probe of a balanced set (see
    [`generate_dataset`][handmesh_tutorial.data.generate.generate_dataset]):
    ``SeedSequence(seed, spawn_key=(k, 0, 1))``, independent of every sample seed (whose spawn keys
    have two entries).
    """
    sample_seed(seed, k)  # validates
    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(int(k), 0, 1))
    return int(ss.generate_state(1, dtype=np.uint64)[0] >> np.uint64(11))


def shard_range(num: int, shard_index: int, num_shards: int) -> range:
    """Global indices of one shard: ``num`` samples cut into ``num_shards`` contiguous ranges.

    Args:
        num: total number of samples planned.
        shard_index: which shard, ``0 <= shard_index < num_shards``.
        num_shards: number of shards (machines), >= 1.

    Returns:
        ``range(num * k // n, num * (k + 1) // n)``; the ranges of all shards are disjoint and
        cover ``range(num)``.
    """
    if num_shards < 1 or not 0 <= shard_index < num_shards:
        raise ValueError(f"shard must satisfy 0 <= shard_index < num_shards, got "
                         f"({shard_index}, {num_shards})")
    return range(num * shard_index // num_shards, num * (shard_index + 1) // num_shards)


def index_width(num: int) -> int:
    """Digits of the zero-padded sample folder names (at least 6: ``000123``)."""
    return max(MIN_INDEX_WIDTH, len(str(max(num - 1, 0))))


def vr_bins(bins: Sequence | None = None) -> tuple[tuple[float, float], ...]:
    """VR bins as ``((lo, hi), ...)``: ``bins`` if given, else the paper's ``visibility.VR_BINS``.

    Accepts pairs ``[(lo, hi), ...]`` or bin edges ``[e0, e1, ..., en]``.

    Raises:
        ValueError: no bin, a pair outside ``0 <= lo < hi <= 1``, or bins that are not
            increasing and non-overlapping (the bin rule, ``visibility.vr_bin_index``, needs
            them so: an overlap was counted in the first bin only).
    """
    seq = list(VR_BINS if bins is None else bins)
    if seq and all(np.ndim(b) == 0 for b in seq):  # edges
        seq = list(zip(seq[:-1], seq[1:], strict=True))
    out = tuple((float(lo), float(hi)) for lo, hi in seq)
    if not out or any(not 0.0 <= lo < hi <= 1.0 for lo, hi in out):
        raise ValueError(f"VR bins must be non-empty pairs 0 <= lo < hi <= 1, got {bins!r}")
    if any(b[0] < a[1] for a, b in zip(out[:-1], out[1:], strict=True)):
        raise ValueError(f"VR bins must be increasing and non-overlapping, got {bins!r}")
    return out


def vr_histogram(values: Sequence[float], bins: Sequence[tuple[float, float]]) -> list[int]:
    """Counts of ``values`` per bin (a value in no bin is not counted).

    Shapes:
        ``values (N,)``, ``bins (K, 2)`` -> ``K`` counts.
    """
    idx = [vr_bin(v, bins) for v in values]
    return [idx.count(k) for k in range(len(bins))]
