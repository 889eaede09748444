"""FreiHAND on-disk format: a reader for the data set and a writer for ``pred.json`` submissions.

The layout follows the official toolbox (``lmb-freiburg/freihand``: ``utils/fh_utils.py``,
``pred.py``, ``eval.py``). Under the data set root::

    training_K.json  training_xyz.json  training_verts.json  training_mano.json
    training_scale.json
    training/rgb/00000000.jpg ...   (4 x 32560 images: the sample versions gs, hom, sample, auto)
    training/mask/00000000.jpg ...  (32560 masks, one per unique sample)
    evaluation_K.json  evaluation_scale.json
    evaluation_xyz.json  evaluation_verts.json  evaluation_mano.json   (released with v2)
    evaluation/rgb/00000000.jpg ... (3960 images, one version)

Each JSON file is a list with one entry per *unique* sample: ``K`` a 3x3 intrinsic matrix,
``xyz`` 21 keypoints in metres (camera frame, FreiHAND order), ``verts`` 778 MANO vertices in
metres, ``mano`` 61 numbers (48 pose, 10 shape, 2 root uv, 1 scale; stored as ``[[...61]]``),
``scale`` the metric length of a reference bone. Training image ``i`` shows unique sample
``i % 32560`` in version ``i // 32560`` (``sample_version.map_id`` in ``fh_utils.py``).

A prediction file ``pred.json`` is ``[xyz_list, verts_list]``: two lists with one entry per
evaluation sample, each a list of ``[x, y, z]`` in metres (21 keypoints; 778 vertices). The official
server wants it zipped at the top level of ``pred.zip``
([`zip_predictions`][handmesh_tutorial.data.freihand.zip_predictions]).

**From a network to ``pred.json``.** FreiHAND compares meshes vertex by vertex with MANO's, so
only a network trained on a MANO-topology template can be submitted: give your ``MANO_RIGHT.pkl``
as the template (``handmesh train --dataset freihand --template MANO_RIGHT.pkl``, or
``TrainConfig(template=...)``), then ``handmesh evaluate --dataset freihand --out DIR`` writes
``DIR/pred.json`` beside ``eval.json`` (camera frame, the evaluated items in order). The library's
own hand has 779 vertices: its 778 skin vertices (all but the last, the wrist cap's centre) are
the MakeHuman mesh's, not MANO's, so no conversion gives meaningful vertex scores; its joints can
be scored alone ([`freihand_scores`][handmesh_tutorial.metrics.scores.freihand_scores] with
``pred_verts=None``; ``handmesh evaluate --dataset freihand`` does so for such a network, and
says so). [`handmesh_tutorial.testing`][handmesh_tutorial.testing] writes a tiny
MANO-format pickle and a tiny FreiHAND-format root to try the whole way on.

No notebook reads FreiHAND (it cannot be downloaded here); notebook 09 ("Evaluation") scores
with the same metrics ([`freihand_scores`][handmesh_tutorial.metrics.scores.freihand_scores]).
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from .._io import atomic_write_with
from ..render.camera import project  # FreiHAND's projectPoints (the library's one projection)

__all__ = [
    "project", "SAMPLE_VERSIONS", "SPLITS", "OFFICIAL_SIZES", "NUM_VERTICES",
    "MAX_ANNOTATION_VALUE", "FreiHAND", "write_predictions", "load_predictions", "zip_predictions",
    "evaluate_predictions",
]

SAMPLE_VERSIONS = ("gs", "hom", "sample", "auto")
"""The sample versions of the training images, in file order (image id = sample + n * version)."""
SPLITS = ("training", "evaluation")
"""The two splits."""
OFFICIAL_SIZES = {"training": 32560, "evaluation": 3960}
"""Unique samples per split in the official release (``db_size`` in ``fh_utils.py``)."""
NUM_VERTICES = 778
"""Number of MANO vertices."""

# per-sample shape of each annotation file; None = a scalar
_SHAPES = {"K": (3, 3), "xyz": (21, 3), "verts": (NUM_VERTICES, 3), "mano": (61,), "scale": ()}
_REQUIRED = {"training": ("K", "xyz"), "evaluation": ("K",)}


def _to_numpy(x) -> np.ndarray:
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


def _read_json(path: Path):
    try:
        with open(path) as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise FileNotFoundError(f"FreiHAND file not found: {path}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path}: not valid JSON (truncated or corrupt?): {err}") from None
    except RecursionError:  # '[[[[...' deeper than the interpreter's stack
        raise ValueError(f"{path}: not valid JSON (nested too deeply)") from None


def _stack(data, path: Path, shape: tuple, what: str) -> np.ndarray:
    """List of per-sample entries -> (N, *shape) float64, or a ValueError naming the sample."""
    if not isinstance(data, list):
        raise ValueError(f"{path}: expected a JSON list of {what}, got {type(data).__name__}")
    try:
        arr = np.asarray(data, dtype=np.float64)
    except (ValueError, TypeError, OverflowError):  # OverflowError: an integer beyond float
        arr = None
    if arr is not None and arr.ndim >= 1:
        n = arr.shape[0]
        if arr.shape[1:] == shape:
            return arr
        if shape == (61,) and arr.shape[1:] == (1, 61):  # official mano files: [[...61]]
            return arr.reshape(n, 61)
        if shape == () and arr.shape[1:] == (1,):
            return arr.reshape(n)
    for i, item in enumerate(data):  # find the first offending sample for the message
        got = _shape_of(item)
        got = "non-numeric/ragged" if got is None else got
        ok = got == shape or (shape == (61,) and got == (1, 61)) or (shape == () and got == (1,))
        if not ok:
            raise ValueError(f"{path}: sample {i} has shape {got}, expected {shape} ({what})")
    raise ValueError(f"{path}: cannot read as an array of {what} with per-sample shape {shape}")


MAX_ANNOTATION_VALUE = 1e6
"""Largest magnitude accepted in an annotation file (metres, pixels, MANO parameters): far above
any real value, far below overflow in later arithmetic.
"""


def _check_values(arr: np.ndarray, path: Path, key: str) -> None:
    """Refuse NaN/inf, absurd magnitudes and singular intrinsics, naming the file and sample."""
    flat = arr.reshape(len(arr), -1) if arr.ndim > 1 else arr.reshape(-1, 1)
    bad = ~np.isfinite(flat).all(1)
    if bad.any():
        raise ValueError(f"{path}: sample {int(np.argmax(bad))} holds NaN or infinity ({key})")
    big = (np.abs(flat) > MAX_ANNOTATION_VALUE).any(1)
    if big.any():
        i = int(np.argmax(big))
        raise ValueError(f"{path}: sample {i} holds {np.abs(flat[i]).max():.3g}, beyond "
                         f"+-{MAX_ANNOTATION_VALUE:g} ({key})")
    if key == "K":
        focal = np.minimum(arr[:, 0, 0], arr[:, 1, 1])
        singular = (np.abs(np.linalg.det(arr)) < 1e-9) | (focal <= 0)
        if singular.any():
            raise ValueError(f"{path}: sample {int(np.argmax(singular))} has a singular "
                             "intrinsic matrix or a focal length <= 0")


def _shape_of(item) -> tuple | None:
    """Shape of a nested numeric list, ``None`` when ragged or not numeric."""
    try:
        return np.asarray(item, dtype=np.float64).shape
    except (ValueError, TypeError, OverflowError):
        return None


class FreiHAND:
    """Reader for the official FreiHAND layout (map-style: ``len`` and ``[i]``).

    Annotation files are read lazily, once, on first use, and kept as float64 arrays. Missing
    optional files (``verts``, ``mano``, ``scale``; ``xyz`` in the evaluation split) give
    ``None`` entries; missing required files (``K``; ``xyz`` for training), corrupt JSON, wrong
    per-sample shapes and missing images raise errors that name the file.

    Args:
        root: the data set root (where ``training_K.json`` and ``training/`` live).
        split: ``"training"`` or ``"evaluation"``.
        versions: sample versions to index (training only; default all four, in file order
            ``gs, hom, sample, auto``). The evaluation split has only ``gs``.

    Examples:
        >>> ds = FreiHAND("~/FreiHAND_pub_v2", "training")  # doctest: +SKIP
        >>> s = ds[0]; s["image"].shape, s["joints"].shape  # doctest: +SKIP
        ((224, 224, 3), (21, 3))

    Note:
        Entries can be ``None``, which torch's default ``collate_fn`` rejects; wrap the reader
        (or drop those keys) before using it in a ``DataLoader``.
    """

    def __init__(self, root: str | os.PathLike, split: str = "training", versions=None):
        self.root = Path(root).expanduser()
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        if not self.root.is_dir():
            raise FileNotFoundError(f"FreiHAND root directory not found: {self.root}")
        self.split = split
        if versions is None:
            versions = SAMPLE_VERSIONS if split == "training" else ("gs",)
        versions = (versions,) if isinstance(versions, str) else tuple(versions)
        allowed = SAMPLE_VERSIONS if split == "training" else ("gs",)
        bad = [v for v in versions if v not in allowed]
        if bad or not versions:
            raise ValueError(f"versions for the {split} split must be among {allowed}, "
                             f"got {versions!r}")
        self.versions = versions
        self._cache: dict[str, np.ndarray | None] = {}
        for key in _REQUIRED[split]:
            path = self.annotation_path(key)
            if not path.is_file():
                raise FileNotFoundError(f"FreiHAND {split} annotation file not found: {path}")

    # -- annotations ---------------------------------------------------------------------

    def annotation_path(self, key: str) -> Path:
        """Path of an annotation file, e.g. ``root/training_xyz.json`` for ``key="xyz"``."""
        if key not in _SHAPES:
            raise ValueError(f"unknown annotation {key!r}; expected one of {tuple(_SHAPES)}")
        return self.root / f"{self.split}_{key}.json"

    def annotation(self, key: str) -> np.ndarray | None:
        """All entries of one annotation file as an array (loaded once), or ``None`` if absent.

        Args:
            key: ``"K"`` (N,3,3), ``"xyz"`` (N,21,3) m, ``"verts"`` (N,778,3) m, ``"mano"``
                (N,61), ``"scale"`` (N,).

        Returns:
            float64 array with one row per unique sample, or ``None`` for a missing optional
            file.
        """
        if key in self._cache:
            return self._cache[key]
        path = self.annotation_path(key)
        if not path.is_file():
            if key in _REQUIRED[self.split]:
                raise FileNotFoundError(f"FreiHAND {self.split} annotation file not found: {path}")
            self._cache[key] = None
            return None
        arr = _stack(_read_json(path), path, _SHAPES[key], key)
        _check_values(arr, path, key)
        if key != "K":
            n = self.num_unique
            if arr.shape[0] != n:
                raise ValueError(f"{path} has {arr.shape[0]} samples but "
                                 f"{self.annotation_path('K')} has {n}")
        self._cache[key] = arr
        return arr

    @property
    def num_unique(self) -> int:
        """Number of unique samples (annotation entries), e.g. 32560 for official training."""
        return int(self.annotation("K").shape[0])

    # -- indexing ------------------------------------------------------------------------

    def __len__(self) -> int:
        return self.num_unique * len(self.versions)

    def _resolve(self, index: int) -> tuple[int, int, str]:
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"index {index} out of range for {n} FreiHAND {self.split} images")
        index %= n
        version = self.versions[index // self.num_unique]
        return index, index % self.num_unique, version

    def annotation_index(self, index: int) -> int:
        """Unique-sample index of image ``index`` (``index % num_unique`` with all versions)."""
        return self._resolve(index)[1]

    def image_path(self, index: int) -> Path:
        """Path of the RGB image of item ``index``."""
        _, ann, version = self._resolve(index)
        image_id = ann + self.num_unique * SAMPLE_VERSIONS.index(version)
        return self.root / self.split / "rgb" / f"{image_id:08d}.jpg"

    def mask_path(self, index: int) -> Path:
        """Path of the hand mask of item ``index`` (training only; one per unique sample)."""
        if self.split != "training":
            raise ValueError("FreiHAND masks exist only for the training split")
        return self.root / "training" / "mask" / f"{self.annotation_index(index):08d}.jpg"

    def __getitem__(self, index: int) -> dict:
        """One sample.

        Returns:
            dict with ``image`` (H,W,3) uint8 RGB, ``K`` (3,3) float64, ``joints`` (21,3)
            metres or ``None``, ``vertices`` (778,3) metres or ``None``, ``mano`` (61,) or
            ``None``, ``scale`` float or ``None``, ``index`` (int), ``annotation_index`` (int),
            ``version`` (str).
        """
        index, ann, version = self._resolve(int(index))
        out = {"image": _read_image(self.image_path(index)), "K": self.annotation("K")[ann]}
        for key, name in (("xyz", "joints"), ("verts", "vertices"), ("mano", "mano")):
            arr = self.annotation(key)
            out[name] = None if arr is None else arr[ann]
        scale = self.annotation("scale")
        out["scale"] = None if scale is None else float(scale[ann])
        out.update(index=index, annotation_index=ann, version=version)
        return out

    def load_mask(self, index: int) -> np.ndarray:
        """The training mask of item ``index`` as an (H,W) uint8 array (JPEG, not exactly 0/255)."""
        path = self.mask_path(index)
        return _read_image(path, mode="L")

    def __repr__(self) -> str:
        return f"FreiHAND(root={str(self.root)!r}, split={self.split!r}, versions={self.versions})"


_MAX_IMAGE_SIDE = 4096  # = dataset.MAX_IMAGE_SIZE (tested); FreiHAND's images are 224 x 224


def _read_image(path: Path, mode: str = "RGB") -> np.ndarray:
    """Decode an image; one over 4096 pixels a side is refused from its header, before decoding
    (a decompression bomb), as is anything PIL calls one."""
    import warnings

    from PIL import Image, UnidentifiedImageError

    if not path.is_file():
        raise FileNotFoundError(f"FreiHAND image not found: {path}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                if max(im.size) > _MAX_IMAGE_SIDE:
                    raise ValueError(f"{path}: {im.width} x {im.height} pixels, over "
                                     f"{_MAX_IMAGE_SIDE} a side: not decoded (FreiHAND images "
                                     "are 224 x 224)")
                return np.asarray(im.convert(mode), dtype=np.uint8)
    except (UnidentifiedImageError, OSError, Image.DecompressionBombError,
            Image.DecompressionBombWarning) as err:
        raise ValueError(f"{path}: cannot decode image: {err}") from None


# -------------------------------------------------------------------------------- predictions


def _check_predictions(joints, vertices) -> tuple[np.ndarray, np.ndarray]:
    j = _to_numpy(joints).astype(np.float64)
    v = _to_numpy(vertices).astype(np.float64)
    if j.ndim != 3 or j.shape[1:] != (21, 3):
        raise ValueError(f"joints must have shape (N,21,3), got {j.shape}")
    if v.ndim != 3 or v.shape[2] != 3:
        raise ValueError(f"vertices must have shape (N,V,3), got {v.shape}")
    if j.shape[0] != v.shape[0]:
        raise ValueError(f"joints has {j.shape[0]} samples but vertices has {v.shape[0]}")
    if not (np.all(np.isfinite(j)) and np.all(np.isfinite(v))):
        raise ValueError("predictions contain NaN or inf (JSON cannot store them)")
    return j, v


def write_predictions(path: str | os.PathLike, joints, vertices) -> Path:
    """Write a FreiHAND prediction file ``[xyz_list, verts_list]`` (as the official ``pred.py``).

    Args:
        path: output file, conventionally ``pred.json``; written atomically.
        joints: (N,21,3) predicted keypoints, metres, FreiHAND order; numpy or torch.
        vertices: (N,778,3) predicted vertices, metres, in MANO's topology (the official
            evaluation compares them vertex by vertex with MANO meshes).

    Returns:
        The path written.

    Raises:
        ValueError: bad shapes, sample counts that differ, NaN or inf, or a vertex count other
            than 778 (e.g. the library's 779-vertex hand: FreiHAND's evaluation could not score
            the file; see the module text for the way from a network to ``pred.json``). Nothing
            is written then.
    """
    j, v = _check_predictions(joints, vertices)
    if v.shape[1] != NUM_VERTICES:
        raise ValueError(
            f"vertices has {v.shape[1]} vertices per sample, but FreiHAND's evaluation expects "
            f"MANO's {NUM_VERTICES} (it compares the meshes vertex by vertex) and could not score "
            "this file; train with a MANO template (handmesh train --template MANO_RIGHT.pkl). "
            "The library's 779-vertex hand has no vertex correspondence with MANO (dropping its "
            "last, wrist-cap vertex gives 778 vertices, not MANO's); score its joints alone with "
            "metrics.freihand_scores(pred_verts=None, gt_verts=None)")
    payload = [j.tolist(), v.tolist()]  # float64 -> shortest round-trip decimal
    return atomic_write_with(path, lambda fh: json.dump(payload, fh), binary=False)


def load_predictions(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a ``pred.json`` written by
    [`write_predictions`][handmesh_tutorial.data.freihand.write_predictions] or the official
    ``pred.py``.

    Args:
        path: the prediction file.

    Returns:
        ``(joints, vertices)``: (N,21,3) and (N,V,3) float64 arrays, metres.
    """
    path = Path(path)
    data = _read_json(path)
    if not (isinstance(data, list) and len(data) == 2):
        raise ValueError(f"{path}: expected [xyz_list, verts_list] (a list of two lists)")
    if len(data[0]) != len(data[1]):
        raise ValueError(f"{path}: {len(data[0])} joint entries but {len(data[1])} vertex entries")
    if not data[0]:
        raise ValueError(f"{path}: the prediction lists are empty")
    joints = _stack(data[0], path, (21, 3), "keypoints")
    first = _shape_of(data[1][0])
    if first is None or len(first) != 2 or first[1] != 3:
        raise ValueError(f"{path}: sample 0 has vertex shape {first}, expected (V, 3)")
    verts = _stack(data[1], path, first, "vertices")
    return joints, verts


def zip_predictions(json_path: str | os.PathLike, zip_path: str | os.PathLike | None = None):
    """Zip a prediction file for the FreiHAND Codalab server (``zip -j pred.zip pred.json``).

    Args:
        json_path: the ``pred.json`` file.
        zip_path: output archive; ``pred.zip`` next to the JSON file when ``None``.

    Returns:
        The path of the archive (written atomically, the JSON at its top level).
    """
    json_path = Path(json_path)
    if not json_path.is_file():
        raise FileNotFoundError(f"prediction file not found: {json_path}")
    zip_path = Path(zip_path) if zip_path is not None else json_path.with_name("pred.zip")

    def write(fh):
        with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.write(json_path, arcname=json_path.name)

    return atomic_write_with(zip_path, write)


def evaluate_predictions(pred_path: str | os.PathLike, root: str | os.PathLike,
                         split: str = "evaluation", allow_reflection: bool = True) -> dict:
    """Score a ``pred.json`` against the ground truth of a split, as the official ``eval.py``.

    Args:
        pred_path: prediction file (``[xyz_list, verts_list]``).
        root: FreiHAND root holding ``<split>_xyz.json`` and ``<split>_verts.json``.
        split: ``"evaluation"`` (needs the v2 annotations) or ``"training"``.
        allow_reflection: see
            [`handmesh_tutorial.metrics.procrustes_align`][handmesh_tutorial.metrics.procrustes.procrustes_align].

    Returns:
        The dict of
        [`handmesh_tutorial.metrics.freihand_scores`][handmesh_tutorial.metrics.scores.freihand_scores].
    """
    from .. import metrics

    ds = FreiHAND(root, split, versions=("gs",))
    gt_j, gt_v = ds.annotation("xyz"), ds.annotation("verts")
    if gt_j is None or gt_v is None:
        raise FileNotFoundError(f"ground truth {ds.annotation_path('xyz')} and "
                                f"{ds.annotation_path('verts')} are both needed")
    pj, pv = load_predictions(pred_path)
    if len(pj) != len(gt_j):
        raise ValueError(f"{pred_path} has {len(pj)} samples, the {split} split {len(gt_j)}")
    return metrics.freihand_scores(pred_joints=pj, gt_joints=gt_j, pred_verts=pv, gt_verts=gt_v,
                                   allow_reflection=allow_reflection)
