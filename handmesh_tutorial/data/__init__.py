"""INTER-SH on disk: a sample writer and reader, and a resumable, sharded generation driver.

One INTER-SH *sample* is one rendered scene (paper, Sec. "INTER-SH dataset"): the RGB image, the
label mask of the whole scene, the mask of every body rendered alone, the meshes and 21 joints in
the camera frame, the intrinsics ``K`` and the visibility ratio ``VR`` of every body. A *root*
holds ``meta.json`` and one folder per sample::

    root/
      meta.json                    format, generator version, seed, kinds, sizes, params, shards
      samples/000000/
        image.png                  (H, W, 3) RGB, 8 bit
        scene_mask.png             (H, W) labels, 0 = background; 8 bit (16 bit if a label > 255)
        alone_1.png, alone_2.png   (H, W) 1-bit masks of each body rendered alone
        annotation.npz             K, vertices_<l>, faces_<l>, joints_<l>, pose_<l> (no pickles)
        annotation.json            kind, target, sides, names, vr, seed, stats (small, readable)

Every file is deterministic (same sample -> same bytes: no time stamps in PNG, JSON or zip headers),
every sample folder appears atomically (written in a temporary folder, then renamed), and
[`generate_dataset`][handmesh_tutorial.data.generate.generate_dataset] resumes an interrupted
run to the same bytes as an uninterrupted one. See ``docs/concepts/dataset_format.md`` for the
format in full. Taught in notebook 05 ("Rendering and the visibility ratio").

Submodules (every public name is re-exported here, ``hmt.data.InterSHDataset`` etc.):

* ``schema``: format names, versions and limits (``KINDS``, ``META_FILE``...), sample validation
  and its plausibility ranges (``MAX_DISTANCE_M``, ``FOCAL_RANGE``...).
* ``seeds``: ``sample_seed``, ``probe_seed``, ``shard_range``, ``index_width``, VR bins.
* ``files``: one sample folder: ``encode_sample``, ``write_sample``, ``read_sample``,
  ``read_annotation``, ``npz_bytes``; atomic writes and the names of temporaries.
* ``reader``: ``read_meta``, ``InterSHDataset`` (numpy, lazy), ``verify_dataset``.
* ``root``: a root being written (meta check, writer lock, stale temporaries), ``merge_shards``.
* ``candidates``: one sample from successive seeds, acceptance, VR balancing (``SampleRejected``).
* ``workers``: the worker processes of the driver.
* ``generate``: ``generate_dataset`` and ``GenerationSummary``.
* ``torch_views``: the torch training crops (``HandCropDataset``, ``InterSHTorchDataset``,
  ``FreiHANDTorchDataset``, bad-item helpers), taught in notebook 08 ("Training"). It loads
  torch, so it is imported only on first use: ``import handmesh_tutorial.data`` stays torch-free.

The driver knows nothing about hands or rendering: it calls ``make_sample(sample_seed) -> dict``.
[`synthetic_sample`][handmesh_tutorial.testing.synthetic_sample] is a tiny stand-in (two spheres
ray-cast with numpy) for tests and demos.
"""

from __future__ import annotations

import importlib

from ..visibility import VR_BINS
from .candidates import SampleRejected
from .files import (
    _write_folder,  # noqa: F401 - benchmarks/generate.py times it
    encode_sample,
    read_annotation,
    read_sample,
    write_sample,
)
from .generate import GenerationSummary, generate_dataset
from .reader import InterSHDataset, VerifyReport, read_meta, verify_dataset
from .root import merge_shards
from .schema import (
    FOCAL_RANGE,
    FORMAT_VERSION,
    KINDS,
    MAX_DISTANCE_M,
    MAX_IMAGE_SIZE,
    MAX_LABEL,
    MAX_SAMPLES,
    META_FILE,
    MIN_DEPTH_M,
    PRINCIPAL_POINT_MARGIN,
    SAMPLES_DIR,
)
from .seeds import sample_seed, vr_bins, vr_histogram

__all__ = [
    "FORMAT_VERSION", "KINDS", "META_FILE", "SAMPLES_DIR", "MAX_SAMPLES", "MAX_LABEL",
    "MAX_IMAGE_SIZE", "MAX_DISTANCE_M", "MIN_DEPTH_M", "FOCAL_RANGE", "PRINCIPAL_POINT_MARGIN",
    "SampleRejected", "sample_seed", "vr_bins", "vr_histogram", "encode_sample", "write_sample",
    "read_annotation", "read_sample", "read_meta", "InterSHDataset", "VerifyReport",
    "verify_dataset", "GenerationSummary", "generate_dataset", "merge_shards", "VR_BINS",
]

_TORCH_VIEWS = ("HandCropDataset", "InterSHTorchDataset", "FreiHANDTorchDataset",
                "BadSampleError", "BAD_SAMPLE_ERRORS", "find_bad_items", "without_items",
                "drop_bad_items")
"""Names of ``torch_views``, loaded (with torch) on first access."""

_PLUMBING = {
    "FORMAT_NAME": "schema", "READABLE_FORMAT_VERSIONS": "schema", "MIN_INDEX_WIDTH": "schema",
    "PROBE_MIN_HITS": "candidates", "probe_seed": "seeds", "shard_range": "seeds",
    "index_width": "seeds", "npz_bytes": "files",
}
"""Names of 0.1's ``hmt.data`` that are plumbing (not in ``__all__``): they keep working from
here, without a warning, as they do from their submodules."""


def __getattr__(name: str):
    if name in _TORCH_VIEWS:
        return getattr(importlib.import_module(f"{__name__}.torch_views"), name)
    if name in _PLUMBING:  # not public, still importable from here
        return getattr(importlib.import_module(f"{__name__}.{_PLUMBING[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
