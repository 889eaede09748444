"""FreiHAND-exact hand pose and mesh metrics, PCK/AUC, F-scores and visibility-ratio tables.

Everything here reproduces the official FreiHAND evaluation (``eval.py`` and
``utils/eval_util.py`` of the ``lmb-freiburg/freihand`` repository) to 1e-6, batched over samples:

* **Procrustes with scale, per sample**
  ([`procrustes_align`][handmesh_tutorial.metrics.procrustes.procrustes_align]): both point sets
  are centred, divided by their Frobenius norm plus ``1e-8``, and the rotation comes from the
  orthogonal Procrustes solution ``R = U V^T`` of ``svd(A^T B)`` with scale
  ``sum(singular values)`` (``scipy.linalg.orthogonal_procrustes``). That ``R`` may be a
  *reflection* (det -1); this is the default, as in the official code. ``allow_reflection=False``
  gives the proper-rotation (Kabsch / Umeyama) variant.
* **Joints and vertices are aligned separately**, each with its own Procrustes.
* **MPJPE / MPVPE**: mean Euclidean distance, raw and aligned (PA-), reported in millimetres.
* **PCK** counts an error as correct when ``error <= threshold``; **AUC** is the trapezoid integral
  of the PCK curve over ``linspace(0, 0.05, 100)`` metres divided by the integral of 1 over the
  same thresholds (= 0.05). The paper's INTER-SH table uses 0-20 mm with 20 thresholds.
* **F-score at d** on aligned vertices: nearest-neighbour distances in both directions, a point
  counts when its distance is ``< d`` (strict); ``F = 2PR/(P+R)``, 0 when ``P+R = 0``, averaged
  over samples.

Inputs are metres, numpy arrays or torch tensors; everything is computed in float64 numpy (the
F-score's candidate search runs in float32 torch with a proven error margin; see
[`f_score`][handmesh_tutorial.metrics.fscore.f_score]).

Submodules (each name below is also importable from ``handmesh_tutorial.metrics``; taught in
notebook 09, "Evaluation"):

* `procrustes`: `procrustes_align` (with scale, reflections allowed by default).
* `pck`: `point_errors`, `pck_curve`, `auc`, the thresholds `FREIHAND_THRESHOLDS` and
  `PAPER_THRESHOLDS`.
* `fscore`: `f_score`, `nearest_distances`, `FSCORE_THRESHOLDS`.
* `scores`: `per_sample_scores`, `freihand_scores`, `scores_from_errors`, `ROOT_INDEX`.
* `surface` (imported on first use): `roughness_deg`, `flipped_face_fraction`, the signed
  dihedral angles behind them.
* `intervals` (imported on first use): `paired_difference`, `seed_difference`,
  `detectable_difference`: two methods compared on the same scenes or over seeds, with 95 %
  intervals and the smallest difference a design can detect.
* `tables`: `scores_by_vr_bin`, `scores_by_group`, `comparison_table`, `format_table`,
  `VR_BIN_LABELS`, `SURFACE_KEYS`; the VR bins (`VR_BINS`, `vr_bin_index`) are re-exported from
  [`visibility`][handmesh_tutorial.visibility].
"""

from __future__ import annotations

from ..visibility import VR_BINS, vr_bin_index
from .fscore import FSCORE_THRESHOLDS, f_score, nearest_distances
from .pck import FREIHAND_THRESHOLDS, PAPER_THRESHOLDS, auc, pck_curve, point_errors
from .procrustes import procrustes_align
from .scores import (  # noqa: F401 - scores_from_errors: not public, importable as in 0.1
    ROOT_INDEX,
    freihand_scores,
    per_sample_scores,
    scores_from_errors,
)
from .tables import (  # noqa: F401 - SURFACE_KEYS: not public, importable as in 0.1
    SURFACE_KEYS,
    VR_BIN_LABELS,
    comparison_table,
    format_table,
    scores_by_group,
    scores_by_vr_bin,
)

__all__ = [
    "FREIHAND_THRESHOLDS",
    "FSCORE_THRESHOLDS",
    "PAPER_THRESHOLDS",
    "ROOT_INDEX",
    "VR_BINS",
    "VR_BIN_LABELS",
    "auc",
    "comparison_table",
    "f_score",
    "format_table",
    "freihand_scores",
    "nearest_distances",
    "pck_curve",
    "per_sample_scores",
    "point_errors",
    "procrustes_align",
    "scores_by_group",
    "scores_by_vr_bin",
    "vr_bin_index",
]


def __getattr__(name: str):
    # submodules imported on first use: surface quality (roughness, flipped faces) and the
    # intervals of differences (scipy.stats)
    if name in ("surface", "intervals"):
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
